"""What one tick of the window draws (issue 13, "never freeze": no UI frame over 100 ms).

A frame that merged new passes draws only the parts that changed (the image panels and the
stage text), and the window's pixels are then those of a full redraw; a new stage is composed
in one tick and rendered in the next; the footer, the title and the stage text are left as
they are when nothing they show changed; the window's timer calls ``App.tick`` and nothing
else (pyvista's ``add_timer_event`` rendered the whole window after every tick, five times a
second); breakdowns are rendered only while a mode shows them, without losing a pass; the
window prints its start-up times when asked, and its first frame is drawn without
multisampling. The 3D view built over ticks: ``test_window_steps.py``; the primitives' CPU
shading: ``test_window_baked_light.py``. Speed itself is measured by
``benchmarks/ui_frames.py``, never here.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys

import numpy as np
import pytest

pv = pytest.importorskip("pyvista")
pv.OFF_SCREEN = True

from window_frames_support import (  # noqa: E402
    MIS,
    POINT,
    ROOT,
    XVFB_WINDOW,
    drawn,
    last_frame,
    run_under_xvfb,
)


def test_a_new_pass_draws_the_panels_only_and_the_picture_of_a_full_redraw(app):
    from ui.views.window import panel_text

    s = app.s
    count = drawn(app)
    n = list(s.prog.passes)
    text = panel_text(s)
    s.prog._engine.spent[s.inspected] = -1.0  # the next pass is the inspected estimator's
    app.tick()  # one more pass: a frame
    assert s.prog.passes[s.inspected] == n[s.inspected] + 1 and sum(s.prog.passes) == sum(n) + 1
    assert count["render"] == count["variance"] == 1
    assert panel_text(s) != text and count["panel"] == 1  # its pass count is in the text
    assert count["3d"] == count["title"] == count["footer"] == 0, count
    for k in count:
        count[k] = 0
    s.prog._engine.spent[s.inspected] = 1e9  # now the other one's: the stage text stays
    app.tick()
    assert count["render"] == 1 and count["panel"] == 0, count
    after_frame = last_frame(app)  # as the frame left it: compare with a full redraw
    app.redraw()
    full = last_frame(app)
    assert after_frame.shape == full.shape
    assert np.array_equal(after_frame, full)
    # the help box lies over every part: with it shown the footer's layer is drawn too
    app.toggle_help()
    for k in count:
        count[k] = 0
    app.tick()
    assert count["footer"] == 1 and count["3d"] == 0


def test_a_new_stage_is_composed_in_one_tick_and_rendered_in_the_next(app):
    from ui.views.window import reinspect

    s = app.s
    s.prog.pause()  # no passes: only the inspection arrives
    s.stepper.go("evaluate")
    app.redraw()
    s.pixel_xy = (31, 20)
    reinspect(s)  # computed at once here (workers=0); the next tick takes it
    count = drawn(app)
    app.tick()
    assert s.inspection is not None and s.inspection.pixel_xy == (31, 20)
    assert sum(count.values()) == 0, count  # composed, not rendered
    app.tick()
    assert count["3d"] == count["render"] == count["panel"] == count["footer"] == 1, count
    app.tick()
    assert count["3d"] == 1  # nothing new: nothing drawn


def test_unchanged_parts_are_kept(app):
    from ui.views.compose import CELL_PANEL

    s, p = app.s, app.p
    props = list(app.controls.props)
    panel = p.renderers[p.renderers.loc_to_index(CELL_PANEL)]
    text_actor = panel.actors["panel"]
    app.tick()
    assert app.controls.props == props  # the footer was not laid out again
    assert panel.actors["panel"] is text_actor  # the stage text changed in place
    assert f"passes {s.acc.n}" in text_actor.GetInput() or f"{s.acc.n} pass" in \
        text_actor.GetInput()
    s.stepper.go("evaluate")
    app.redraw()
    assert app.controls.props == props
    app.toggle_member_index(0)  # a member chip changes: the footer is drawn anew
    assert app.controls.props != props
    assert any("off plane-t1t2" in a.GetInput() for _, a in app.controls.hot)


def test_breakdowns_only_while_shown_and_no_pass_lost(app):
    from psurf_core.render import render

    s = app.s
    prog = s.prog
    assert not prog.job.breakdown and all(r.breakdown is None for r in prog.runs)
    before = list(prog.passes)
    app.next_mode()  # techniques: breakdowns from now on
    assert s.mode == "techniques" and prog.job.breakdown
    assert prog.passes == before
    for _ in range(4):
        app.tick()
    mis = prog.runs[1]
    assert mis.breakdown is not None and 0 < mis.breakdown.n < mis.acc.n
    app.next_mode()
    app.next_mode()  # render again: no more breakdowns
    assert s.mode == "render" and not prog.job.breakdown
    app.tick()
    for run in prog.runs:  # every pass merged once, in order: a serial render's image
        ref = render(s.scene, run.estimator, s.settings, passes=run.acc.n,
                     seed=s.seed).accumulator
        assert np.array_equal(run.acc.mean, ref.mean), run.spec


def test_start_up_times_are_printed_when_asked(app, monkeypatch, capsys):
    from ui.views import script

    monkeypatch.setenv(script.TIMES_ENV, "0")
    monkeypatch.setattr(app, "_launched", script.launch_time())
    app._milestones.clear()
    app.redraw()
    out = capsys.readouterr().out
    for name in ("window", "first-pass", "all-passes", "inspection"):
        assert f"window: time {name} " in out, out
    app.redraw()  # each once
    assert "window: time" not in capsys.readouterr().out


def test_a_started_render_must_be_the_one_shown():
    from psurf_core.render import RenderSettings
    from psurf_core.scene_io import load_scene
    from ui.cli.progressive import Progressive
    from ui.views.window import attach_progressive, build_state

    scene = load_scene(POINT)
    state = build_state(POINT, seed=0, photons=100, render_passes=False,
                        estimators=["planes", MIS], scene=scene)
    other = Progressive(scene, ["planes"], RenderSettings(photons=100, spp=1), workers=0)
    with pytest.raises(ValueError, match="not what the window shows"):
        attach_progressive(state, workers=0, prog=other)
    same = Progressive(scene, ["planes", MIS], RenderSettings(photons=100, spp=1), workers=0,
                       breakdown=True)
    attach_progressive(state, workers=0, prog=same, breakdown=False)
    assert state.prog is same and not same.job.breakdown


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("xvfb-run") is None, reason="needs Xvfb (xvfb-run)")
def test_the_window_timer_renders_nothing_by_itself(tmp_path):
    """Under a virtual X server: the window's TimerEvent runs ``App.tick`` only; a tick with
    nothing new renders nothing (pyvista's timer rendered the whole window every time)."""
    code = XVFB_WINDOW + """
app = App(p, state)
app.bind()
app.redraw()
p.show(interactive_update=True, auto_close=False)
app.settle()  # the 3D view's steps, which the window's ticks would run
renders = []
p.ren_win.AddObserver("StartEvent", lambda *a: renders.append(1))
for _ in range(5):
    p.iren.interactor.InvokeEvent("TimerEvent")
print("renders", len(renders), "ticks ok", app._gl_checked)
app.close()
p.close()
"""
    r = run_under_xvfb(code, tmp_path)
    assert "renders 0 ticks ok True" in r.stdout, (r.stdout, r.stderr[-2000:])


def test_reconstructs_kernel_is_loaded_in_a_thread_after_a_stage_is_drawn(app, monkeypatch):
    """The first Reconstruct stage froze the window ~0.6 s (numba loading the path gather in
    the UI thread): the window loads it in a thread once a stage has been composed and
    rendered, never in the ticks that do those."""
    from psurf_core import path_record
    from ui.views import interactive_timer

    if app._recon_warm is not None:  # the fixture's ticks started one
        app._recon_warm.join(timeout=300)
    app._recon_warm = None
    monkeypatch.setattr(interactive_timer, "accept_results", lambda s: True)
    app.tick()  # a new stage: composed here, rendered in the next tick
    assert app._render_due and app._recon_warm is None
    monkeypatch.setattr(interactive_timer, "accept_results", lambda s: False)
    app.tick()  # rendered; then the kernel is loaded, in a thread
    warm = app._recon_warm
    assert not app._render_due and warm is not None and warm.daemon
    warm.join(timeout=300)
    assert not warm.is_alive() and path_record._gather.signatures
    app.tick()
    assert app._recon_warm is warm  # once


def test_pyplot_and_pooch_wait_until_used():
    """Start-up (issue 13, first picture <= 5 s): the window's imports and its plotter leave
    ``matplotlib.pyplot`` and ``pooch`` (imported by pyvista's plotting package, unused by the
    window) unimported; a program that uses pyplot afterwards gets the real module."""
    code = """if True:
        import sys
        from ui.views import interactive, window
        p = window.make_plotter((320, 240), off_screen=True)
        kinds = [type(sys.modules[m]).__name__ for m in ("matplotlib.pyplot", "pooch")]
        import matplotlib.pyplot as plt
        fig = plt.figure()
        real = sys.modules["matplotlib.pyplot"]
        print(kinds, type(fig).__name__, type(real).__name__, hasattr(real, "subplots"))
    """
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       timeout=300, cwd=ROOT, env={**os.environ, "MPLBACKEND": "Agg"})
    assert r.stdout.split() == ["['_Deferred',", "'_Deferred']", "Figure", "module",
                                "True"], (r.stdout, r.stderr[-2000:])


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("xvfb-run") is None, reason="needs Xvfb (xvfb-run)")
def test_the_first_frame_is_stamped_and_drawn_without_multisampling(tmp_path):
    """Under a virtual X server (software OpenGL): ``open_window`` creates the GL context
    before the first render and turns multisampling off for it; the start-up time
    ``window`` is printed when that first frame has been rendered, not at the first tick."""
    code = XVFB_WINDOW + """
from ui.views import script
os.environ[script.TIMES_ENV] = "0"
app = App(p, state)
app._launched = script.launch_time()
app.bind()
app.redraw(keep_camera=False)
print("before", app._shown, flush=True)
app.open_window()
print("samples", p.ren_win.GetMultiSamples(), flush=True)
p.show(interactive_update=True, auto_close=False)
print("after", app._shown, flush=True)
app.close()
p.close()
"""
    env = {k: v for k, v in os.environ.items() if k != "VTK_DEFAULT_OPENGL_WINDOW"}
    r = run_under_xvfb(code, tmp_path, env)  # an X window (ui.views._vtk)
    lines = [ln for ln in r.stdout.splitlines()
             if ln.split()[0] in ("before", "samples", "after")
             or ln.startswith("window: time window ")]
    assert len(lines) == 4 and lines[:2] == ["before False", "samples 0"], \
        (r.stdout, r.stderr[-2000:])
    assert lines[2].startswith("window: time window "), (r.stdout, r.stderr[-2000:])
    assert lines[3] == "after True", (r.stdout, r.stderr[-2000:])
