"""What one tick of the window draws (issue 13, "never freeze": no UI frame over 100 ms).

A frame that merged new passes draws only the parts that changed (the image panels and the
stage text), and the window's pixels are then those of a full redraw; a new stage is composed
in one tick and rendered in the next (off-screen), or in the window its text at once and its
3D view over the next ticks, one part per step; keys draw only the parts they change;
the footer, the title
and the stage text are left as they are when nothing they show changed; the window's timer
calls ``App.tick`` and nothing else (pyvista's ``add_timer_event`` rendered the whole window
after every tick, five times a second); breakdowns are rendered only while a mode shows them,
without losing a pass; the window prints its start-up times when asked. Speed itself is
measured by ``benchmarks/ui_frames.py``, never here.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pv = pytest.importorskip("pyvista")
pv.OFF_SCREEN = True

ROOT = Path(__file__).resolve().parents[1]
POINT = str(ROOT / "scenes" / "point.toml")
MIS = "mis:plane-t1t2+planes"


@pytest.fixture()
def app(tmp_path, monkeypatch):
    """The window off-screen, ``planes`` beside an MIS set, passes rendered in this process."""
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
    yield a
    a.close()
    plotter.close()


def _drawn(app) -> dict:
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


def _shot(app) -> np.ndarray:
    return np.array(app.p.screenshot(None, return_img=True))


def test_a_new_pass_draws_the_panels_only_and_the_picture_of_a_full_redraw(app):
    from ui.views.window import panel_text

    s = app.s
    count = _drawn(app)
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
    after_frame = _shot(app)  # the screenshot renders again: compare with a full redraw
    app.redraw()
    full = _shot(app)
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
    count = _drawn(app)
    app.tick()
    assert s.inspection is not None and s.inspection.pixel_xy == (31, 20)
    assert sum(count.values()) == 0, count  # composed, not rendered
    app.tick()
    assert count["3d"] == count["render"] == count["panel"] == count["footer"] == 1, count
    app.tick()
    assert count["3d"] == 1  # nothing new: nothing drawn


def _settle_by_ticks(app, limit: int = 60) -> int:
    """Tick until the 3D view's steps are done and rendered; the number of ticks."""
    n = 0
    while app._job is not None or app._render_due:
        app.tick()
        n += 1
        assert n < limit, "the 3D view never completed"
    return n


def test_in_the_window_a_key_draws_at_once_and_the_3d_view_over_the_next_ticks(app, monkeypatch):
    """The window (``App.defer``): ``n`` composes and draws the title, the stage text and the
    3D view's first step (the scene, "drawing...") at once; each later tick adds one part of
    the 3D view (with no time to spare, ``STEP_BUDGET`` 0) and the completed view is drawn;
    the picture is then that of a full redraw."""
    from ui.views import interactive_timer

    s = app.s
    s.prog.pause()  # no passes: only the stage changes
    app.defer = True
    monkeypatch.setattr(interactive_timer, "STEP_BUDGET", 0.0)
    count = _drawn(app)
    app.next()  # trace -> create: paths and the primitives of several techniques
    ren = app.p.renderers[0]
    assert "drawing" in ren.actors
    assert not any(n.startswith("prims-") for n in ren.actors)
    assert count["3d"] == count["title"] == count["panel"] == 1, count
    ticks = _settle_by_ticks(app)
    assert ticks >= 3  # the paths, then one technique per tick
    assert count["3d"] == 2 and count["title"] == 1, count  # drawn once more, when complete
    assert "drawing" not in ren.actors
    assert sum(n.startswith("prims-") and n.endswith(":mesh") for n in ren.actors) >= 2
    deferred = _shot(app)
    app.defer = False
    app.redraw()
    assert np.array_equal(deferred, _shot(app))


def test_in_the_window_a_new_inspection_is_drawn_in_steps(app):
    from ui.views.window import reinspect

    s = app.s
    s.prog.pause()
    app.defer = True
    s.stepper.go("intersect")
    app.redraw()
    _settle_by_ticks(app)
    s.pixel_xy = (31, 20)
    reinspect(s)  # computed at once here (workers=0); the next tick takes it
    count = _drawn(app)
    app.tick()  # the stage text and the 3D view's first step
    assert s.inspection is not None and s.inspection.pixel_xy == (31, 20)
    assert count["panel"] == 1 and count["3d"] == 1 and count["title"] == 0, count
    assert "drawing" in app.p.renderers[0].actors
    _settle_by_ticks(app)
    assert count["3d"] == 2 and count["title"] == 0, count
    assert "hits" in app.p.renderers[0].actors and "drawing" not in app.p.renderers[0].actors
    app.tick()
    assert count["3d"] == 2  # nothing new: nothing drawn


def test_in_the_window_keys_that_change_no_3d_leave_it_alone(app):
    """``m`` (panel mode) and ``l`` (variance scale) redraw the panels, not the 3D view."""
    s = app.s
    s.prog.pause()
    app.defer = True
    app.redraw()
    _settle_by_ticks(app)
    count = _drawn(app)
    app.toggle_scale()
    app.next_mode()
    assert s.mode == "techniques"
    assert count["3d"] == 0 and count["render"] == 2 and count["panel"] == 2, count
    app.tick()
    assert count["3d"] == 0, count
    app.settle()  # a screenshot's render: everything
    assert count["3d"] == 1


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
    code = f"""
import sys
sys.path.insert(0, {str(ROOT)!r})
from ui.views.interactive import App
from ui.views.window import attach_progressive, build_state, make_plotter
state = build_state({POINT!r}, seed=0, photons=100, render_passes=False,
                    estimators=["planes"], inspector_workers=0)
attach_progressive(state, workers=0, breakdown=False)
state.prog.pause()
p = make_plotter((640, 480))
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
    r = subprocess.run(["xvfb-run", "-a", "-s", "-screen 0 800x600x24", sys.executable, "-c",
                        code], capture_output=True, text=True, timeout=300, cwd=tmp_path,
                       env={**os.environ, "PYTHONPATH": str(ROOT)})
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
    code = f"""
import os, sys
sys.path.insert(0, {str(ROOT)!r})
from ui.views import script
os.environ[script.TIMES_ENV] = "0"
from ui.views.interactive import App
from ui.views.window import attach_progressive, build_state, make_plotter
state = build_state({POINT!r}, seed=0, photons=100, render_passes=False,
                    estimators=["planes"], inspector_workers=0)
attach_progressive(state, workers=0, breakdown=False)
state.prog.pause()
p = make_plotter((640, 480))
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
    r = subprocess.run(["xvfb-run", "-a", "-s", "-screen 0 800x600x24", sys.executable, "-c",
                        code], capture_output=True, text=True, timeout=300, cwd=tmp_path,
                       env={**env, "PYTHONPATH": str(ROOT)})  # an X window (ui.views._vtk)
    lines = [ln for ln in r.stdout.splitlines()
             if ln.split()[0] in ("before", "samples", "after")
             or ln.startswith("window: time window ")]
    assert len(lines) == 4 and lines[:2] == ["before False", "samples 0"], \
        (r.stdout, r.stderr[-2000:])
    assert lines[2].startswith("window: time window "), (r.stdout, r.stderr[-2000:])
    assert lines[3] == "after True", (r.stdout, r.stderr[-2000:])


@pytest.mark.parametrize("stage", ["create", "intersect"])
def test_baked_light_draws_the_picture_the_shader_draws(stage):
    """The window in software OpenGL shades the translucent primitives on the CPU
    (``ui.views.baked_light``): for the view they were made for, the same picture as VTK's
    lighting (within 2/255 per channel), with the primitives drawn unlit."""
    from ui.views import baked_light
    from ui.views.window import attach_progressive, build_state, compose, make_plotter

    state = build_state(POINT, "mis:plane-t1t2+planes", seed=3, pixel_xy=(30, 20),
                        photons=100, passes=1, stage=stage)
    attach_progressive(state, workers=0, breakdown=False)
    state.prog.run(passes=1)
    shots = []
    try:
        for on in (False, True):
            p = make_plotter((800, 450), off_screen=True)
            baked_light.enable(p, on)
            compose(p, state)
            meshes = [a for n, a in p.renderers[0].actors.items()
                      if n.startswith(("prims-", "context-", "hitprims-")) and n.endswith(":mesh")]
            assert meshes and all(a.GetProperty().GetLighting() != on for a in meshes)
            shots.append(np.asarray(p.screenshot(None, return_img=True), dtype=int))
            p.close()
    finally:
        state.prog.close()
        state.inspector.close()
    diff = np.abs(shots[0] - shots[1])
    assert diff.max() <= 2, (diff.max(), (diff > 2).sum())


def test_baked_light_is_made_again_for_a_turned_view():
    """Turning the 3D view (the window makes the shading again when the turn ends): the
    colours are those of VTK's lighting for the new view, and nothing changes for the same
    view."""
    from ui.views import baked_light
    from ui.views.window import attach_progressive, build_state, compose, make_plotter

    state = build_state(POINT, "mis:plane-t1t2+planes", seed=3, pixel_xy=(30, 20),
                        photons=100, passes=1, stage="create")
    attach_progressive(state, workers=0, breakdown=False)
    state.prog.run(passes=1)
    p = make_plotter((800, 450), off_screen=True)
    try:
        baked_light.enable(p)
        compose(p, state)
        ren = p.renderers[0]
        assert baked_light.relight(ren) == 0  # made for this view already
        ren.GetActiveCamera().Azimuth(40.0)
        ren.ResetCameraClippingRange()
        assert baked_light.relight(ren) > 0
        p.ren_win.Render()  # (pyvista's off-screen screenshot may return the last picture)
        turned = np.asarray(p.screenshot(None, return_img=True), dtype=int)
        for name, actor in ren.actors.items():  # the shader's lighting for the same view
            if name.endswith(":mesh") and actor.GetMapper().GetInput().GetCellData() \
                    .GetArray(baked_light.SHADE) is not None:
                actor.GetMapper().ScalarVisibilityOff()
                actor.GetProperty().LightingOn()
                actor.GetProperty().SetColor(*pv.wrap(actor.GetMapper().GetInput())
                                             .field_data[baked_light.BASE])
        p.ren_win.Render()
        lit = np.asarray(p.screenshot(None, return_img=True), dtype=int)
    finally:
        p.close()
        state.prog.close()
        state.inspector.close()
    assert np.abs(turned - lit).max() <= 2


def test_in_the_window_a_turned_view_is_shaded_again_by_the_next_tick(app):
    """The window with baked shading: after the user turned the 3D view, the next tick shades
    the primitives for the new view and draws the 3D view alone; then nothing more."""
    from ui.views import baked_light

    s = app.s
    s.prog.pause()
    app.defer = True
    baked_light.enable(app.p)
    app.next()  # create: translucent primitives
    _settle_by_ticks(app)
    app.tick()  # (the view as composed: nothing to shade again)
    count = _drawn(app)
    app.tick()
    assert sum(count.values()) == 0, count
    ren = app.p.renderers[0]
    ren.GetActiveCamera().Azimuth(30.0)  # what a drag with the mouse does
    app.tick()
    assert count["3d"] == 1 and count["render"] == count["panel"] == 0, count
    assert baked_light.relight(ren) == 0  # shaded for this view already
    app.tick()
    assert count["3d"] == 1
