"""What the window's frame tests (``test_window_frames.py``, ``test_window_steps.py``,
``test_window_baked_light.py``) share: the window off-screen with passes merged in this
process, a count of the renderers each render draws, its pixels, ticks until the 3D view is
complete, and a window opened under a virtual X server. The tests take the window as the
``app`` fixture (``conftest.py``)."""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
POINT = str(ROOT / "scenes" / "point.toml")
MIS = "mis:plane-t1t2+planes"

#: The start of a script run under Xvfb (:func:`run_under_xvfb`): ``state``, one estimator
#: paused (no passes) and ``p``, the window's plotter at 640 x 480; the script makes the
#: ``App`` itself.
XVFB_WINDOW = f"""
import os, sys
sys.path.insert(0, {str(ROOT)!r})
from ui.views.interactive import App
from ui.views.window import attach_progressive, build_state, make_plotter
state = build_state({POINT!r}, seed=0, photons=100, render_passes=False,
                    estimators=["planes"], inspector_workers=0)
attach_progressive(state, workers=0, breakdown=False)
state.prog.pause()
p = make_plotter((640, 480))
"""


@contextlib.contextmanager
def bound_app(state, size=(800, 450)):
    """``(plotter, app)``: an off-screen plotter of ``size`` (pixels) with the window composed
    for ``state`` and its keys bound, for tests that drive the handlers directly; the app and
    the plotter are closed after (``test_ui_screenshots.py``,
    ``test_window_controls_progressive.py``)."""
    from ui.views.interactive import App
    from ui.views.window import compose, make_plotter

    plotter = make_plotter(size, off_screen=True)
    app = None
    try:
        compose(plotter, state)
        app = App(plotter, state)
        app.bind()
        yield plotter, app
    finally:
        if app is not None:
            app.close()
        plotter.close()


@contextlib.contextmanager
def window_app(tmp_path, monkeypatch):
    """The window off-screen, ``planes`` beside an MIS set, passes rendered in this process
    (the body of the ``app`` fixture, ``conftest.py``)."""
    from ui.views.interactive import App
    from ui.views.window import attach_progressive, build_state, make_plotter

    monkeypatch.chdir(tmp_path)
    state = build_state(POINT, seed=3, pixel_xy=(30, 20), photons=100, render_passes=False,
                        estimators=["planes", MIS])
    attach_progressive(state, workers=0, breakdown=False)
    plotter = make_plotter((1024, 768), off_screen=True)
    a = App(plotter, state)
    a.bind()
    a._gl_checked = True
    a.redraw()
    plotter.screenshot(None, return_img=True)  # the first render: pyvista renders from now on
    for _ in range(3):  # one pass per tick (workers=0)
        a.tick()
    a.redraw()
    try:
        yield a
    finally:
        a.close()
        plotter.close()


def drawn(app) -> dict:
    """Renderer name -> how often it was drawn since (VTK's StartEvent of each renderer)."""
    from ui.views.compose import CELL_3D, CELL_PANEL, CELL_RENDER, CELL_TITLE, CELL_VARIANCE

    p = app.p
    rens = {name: p.renderers[p.renderers.loc_to_index(cell)] for name, cell in
            (("3d", CELL_3D), ("render", CELL_RENDER), ("variance", CELL_VARIANCE),
             ("panel", CELL_PANEL), ("title", CELL_TITLE))}
    rens["footer"] = app.controls.overlay
    count = dict.fromkeys(rens, 0)
    for name, ren in rens.items():
        ren.AddObserver("StartEvent", lambda *_a, n=name: count.__setitem__(n, count[n] + 1))
    return count


def last_frame(app) -> np.ndarray:
    """(H, W, 3) uint8: the window's pixels as its last render left them, not rendered again.

    pyvista's off-screen ``screenshot`` reads the last render's pixels (it renders only
    before the first render). That is what these tests compare: a frame that drew only some
    renderers (the others keep their pixels) against a full redraw; a render here would
    draw every part and hide what the frame drew. Pictures of a change not yet rendered are
    taken by :func:`ui.views._vtk.rendered_image` instead."""
    return np.array(app.p.screenshot(None, return_img=True))


def settle_by_ticks(app, limit: int = 60) -> int:
    """Tick until the 3D view's steps are done and rendered; the number of ticks."""
    n = 0
    while app._job is not None or app._render_due:
        app.tick()
        n += 1
        assert n < limit, "the 3D view never completed"
    return n


def run_under_xvfb(code: str, cwd, env: dict | None = None) -> subprocess.CompletedProcess:
    """``python -c code`` under a virtual X server (800 x 600, 24 bit), the checkout on
    ``PYTHONPATH``; ``env`` replaces this process's environment."""
    env = dict(os.environ if env is None else env)
    return subprocess.run(["xvfb-run", "-a", "-s", "-screen 0 800x600x24", sys.executable, "-c",
                           code], capture_output=True, text=True, timeout=300, cwd=cwd,
                          env={**env, "PYTHONPATH": str(ROOT)})
