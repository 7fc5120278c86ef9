"""The window's interaction: picking a pixel by clicking, coverage (primitive -> pixels), the
inspected pass, buttons, estimator members and the debounced medium / photon controls.

The conversions are pure functions (``ui.views.controls``) checked against VTK's own
display -> world transform; the actions are driven on an off-screen plotter, clicks also as
synthetic VTK mouse events through the interactor (the path a real click takes).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

pv = pytest.importorskip("pyvista")
pv.OFF_SCREEN = True

from ui.views import controls  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
POINT = str(ROOT / "scenes" / "point.toml")


# --------------------------------------------------------------------------- pure picking
def test_panel_to_pixel_cell_layout():
    # pixel (X, Y) is the cell [X, X+1] x [H-Y-1, H-Y]
    assert controls.panel_to_pixel((0.2, 47.9), 64, 48) == (0, 0)
    assert controls.panel_to_pixel((63.99, 0.01), 64, 48) == (63, 47)
    assert controls.panel_to_pixel((10.5, 48 - 5 - 0.5), 64, 48) == (10, 5)
    for outside in ((-0.01, 10), (64.0, 10), (10, -0.5), (10, 48.0)):
        assert controls.panel_to_pixel(outside, 64, 48) is None


def test_display_panel_round_trip():
    vp = (0.5, 0.55, 0.75, 1.0)
    args = ((800, 450), vp, (32.0, 27.0), 30.0)
    for d in ((401.0, 248.0), (600.0, 300.0), (799.0, 449.0)):
        w = controls.display_to_panel(d, *args)
        back = controls.panel_to_display(w, *args)
        assert np.allclose(back, d)
    # the viewport centre is the focal point; the viewport's height spans 2 * parallel_scale
    assert np.allclose(controls.display_to_panel((500.0, 348.75), *args), (32.0, 27.0))
    top = controls.display_to_panel((500.0, 450.0), *args)
    assert np.isclose(top[1] - 27.0, 30.0)


def test_viewport_at():
    vps = [(0.0, 0.0, 0.5, 1.0), (0.5, 0.55, 0.75, 1.0), (0.75, 0.55, 1.0, 1.0),
           (0.5, 0.0, 1.0, 0.55)]
    assert controls.viewport_at((10, 10), (800, 450), vps) == 0
    assert controls.viewport_at((450, 400), (800, 450), vps) == 1
    assert controls.viewport_at((700, 400), (800, 450), vps) == 2
    assert controls.viewport_at((700, 100), (800, 450), vps) == 3
    assert controls.viewport_at((900, 100), (800, 450), vps) is None


# --------------------------------------------------------------------------- pure controls
def test_estimator_members_toggle():
    from psurf_core.estimators import parse_estimator
    from psurf_core.scene_io import load_scene

    scene = load_scene(POINT)
    est = controls.estimator_with("mis:plane-t1t2+plane-t1t3+planes", scene, {"plane-t1t3"})
    assert est.spec == "mis:plane-t1t2+plane-t1t3+planes~plane-t1t3"
    assert controls.members(est) == ("plane-t1t2", "plane-t1t2-short")  # 'planes' is short
    assert est.weighting == "balance" and len(est.groups) == 1
    one = controls.estimator_with("mis-power:plane-t1t2+plane-t1t3", scene, {"plane-t1t2"})
    assert controls.members(one) == ("plane-t1t3",) and est.groups[0] != one.groups[0]
    assert len(one.groups) == 1 and len(one.groups[0]) == 1  # alone: no MIS weight
    with pytest.raises(ValueError, match="at least one"):
        controls.estimator_with("mis:plane-t1t2+plane-t1t3", scene,
                                {"plane-t1t2", "plane-t1t3"})
    preset = controls.estimator_with("paper-multi", scene, {"cone"})
    assert preset.spec == "paper-multi~cone" and preset.weighting == "balance"
    assert controls.members(preset) == ("plane-t1t2", "plane-t1t3", "plane-t2t3", "cylinder")
    # paper-full keeps both MIS sets, and the preset's per-light choice (ss-disk: point only)
    full = controls.estimator_with("paper-full", scene, {"cone", "ss-sphere"})
    sizes = [len(g) for g in parse_estimator("paper-full", scene).groups]
    assert [len(g) for g in full.groups] == [sizes[0] - 1, sizes[1] - 1]
    assert not {"cone", "ss-sphere"} & set(controls.members(full))
    disk = [t for t in full.techniques if t.name == "ss-disk"][0]
    assert disk.lights == ("point",)
    assert controls.estimator_with("paper-full", scene, set()).spec == "paper-full"


def test_without_grammar_errors_and_image():
    """``SPEC~A``: errors name the spec and the member; ``paper-multi~cone`` renders exactly
    ``mis:`` of the remaining members (paper-multi restricts no light)."""
    from psurf_core.estimators import parse_estimator
    from psurf_core.render import RenderSettings, render_pass
    from psurf_core.scene_io import load_scene
    from psurf_core.techniques import UnknownTechnique

    scene = load_scene(POINT)
    for spec, msg in [("paper-multi~ss-cone", "not a member of 'paper-multi'"),
                      ("paper-multi~", "malformed"), ("reference~cone", "path tracer"),
                      ("mis:cone+cylinder~cone~cylinder", "every member")]:
        with pytest.raises(UnknownTechnique, match=msg):
            parse_estimator(spec, scene)
    small = replace(scene, camera=replace(scene.camera, width=24, height=18))
    st = RenderSettings(photons=150)
    a = render_pass(small, parse_estimator("paper-multi~cone", small), 0, 3, st)
    b = render_pass(small, parse_estimator("mis:plane-t1t2+plane-t1t3+plane-t2t3+cylinder",
                                           small), 0, 3, st)
    assert np.array_equal(a, b) and a.max() > 0


def test_medium_params_and_scene():
    from psurf_core.scene_io import load_scene

    scene = load_scene(POINT)
    p = controls.MediumParams(-1.0, 99.0, 1.5, 10).clamped()
    lo_s, hi_a, hi_g = controls.RANGES["sigma_s"][0], controls.RANGES["sigma_a"][1], 0.9
    assert (p.sigma_s, p.sigma_a, p.g) == (lo_s, hi_a, hi_g)
    assert p.photons == controls.RANGES["photons"][0]
    new = controls.scene_with(scene, controls.MediumParams(1.5, 0.25, -0.3, 1000))
    assert new.medium.sigma_s == 1.5 and new.medium.sigma_a == 0.25
    assert new.medium.phase.kind == "hg" and new.medium.phase.g == -0.3
    assert scene.medium.sigma_s != 1.5  # the loaded scene is untouched (frozen copies)
    iso = controls.scene_with(scene, controls.MediumParams(1.0, 0.1, 0.0, 1000))
    assert iso.medium.phase.kind == "isotropic"


def test_debouncer_applies_the_last_value_once_quiet():
    d = controls.Debouncer(delay=0.3)
    assert d.due(0.0) is None
    d.push(1, now=0.0)
    d.push(2, now=0.2)  # a drag: each step restarts the wait
    assert d.due(0.4) is None
    assert d.due(0.5) == 2
    assert d.due(10.0) is None and not d.pending


def test_coverage_mesh_outline():
    from ui.views.coverage_view import coverage_mesh

    m = np.zeros((4, 5), bool)
    m[1, 1:3] = True  # two pixels side by side: 6 outline edges, 2 cells
    cells, outline = coverage_mesh(m)
    assert cells.n_cells == 2 and outline.n_lines == 6
    # pixel (1, 1) spans x in [1, 2], y in [H-Y-1, H-Y] = [2, 3]
    b = cells.bounds
    assert np.allclose([b[0], b[1], b[2], b[3]], [1, 3, 2, 3])
    assert coverage_mesh(np.zeros((3, 3), bool))[0].n_cells == 0


# --------------------------------------------------------------------------- the window
@pytest.fixture(scope="module")
def window():
    from ui.views.interactive import App
    from ui.views.window import build_state, compose, make_plotter

    state = build_state(POINT, "mis:plane-t1t2+planes", seed=1, pixel_xy=(32, 24),
                        photons=100, passes=2)
    plotter = make_plotter((800, 450), off_screen=True)
    compose(plotter, state)
    app = App(plotter, state)
    app.bind()
    plotter.render()
    yield app
    plotter.close()


def test_pixel_display_agrees_with_vtk(window):
    """The pure conversion matches VTK's display -> world transform of the panel."""
    app = window
    for panel in ("render", "variance"):
        ren = app.p.renderers[app._panel_index(panel)]
        for pix in ((0, 0), (10, 5), (63, 47)):
            d = app.pixel_display(panel, pix)
            ren.SetDisplayPoint(d[0], d[1], 0.0)
            ren.DisplayToWorld()
            w = np.array(ren.GetWorldPoint())
            w = w[:3] / w[3]
            px_world = 2.0 * ren.GetActiveCamera().GetParallelScale() / (
                (ren.GetViewport()[3] - ren.GetViewport()[1]) * app.p.window_size[1])
            assert abs(w[0] - (pix[0] + 0.5)) < px_world
            assert abs(w[1] - (48 - pix[1] - 0.5)) < px_world


def test_click_picks_pixel_on_both_panels(window):
    app, s = window, window.s
    assert app.click(app.pixel_display("render", (10, 5))) == "pixel"
    assert s.pixel_xy == (10, 5) and s.inspection.pixel_xy == (10, 5)
    assert app.click(app.pixel_display("variance", (50, 40))) == "pixel"
    assert s.pixel_xy == (50, 40) and s.inspection.pixel_xy == (50, 40)
    # a click in the 3D view is left to the camera
    assert app.click((100, 200)) is None and s.pixel_xy == (50, 40)


def test_synthetic_mouse_event_picks_pixel(window):
    """A left click sent through the VTK interactor reaches the picking observer."""
    app, s = window, window.s
    ii = app.p.iren.interactor
    ii.Enable()  # an off-screen interactor is not started; events need it enabled
    x, y = (int(round(v)) for v in app.pixel_display("render", (20, 30)))
    ii.SetEventPosition(x, y)
    ii.LeftButtonPressEvent()
    ii.LeftButtonReleaseEvent()
    assert s.pixel_xy == (20, 30) and s.inspection.pixel_xy == (20, 30)


def _centre(app, action):
    rect = dict(app.controls.rects())[action]
    return (0.5 * (rect[0] + rect[2]), 0.5 * (rect[1] + rect[3]))


def test_buttons(window):
    app, s = window, window.s
    s.stepper.reset()
    assert app.click(_centre(app, "next")) == "button" and s.stage == "create"
    assert app.click(_centre(app, "previous")) == "button" and s.stage == "trace"
    assert app.click(_centre(app, "pass+")) == "button" and s.pass_index == 1
    assert s.inspection.pass_index == 1
    app.step_pass(5)  # clamped to the passes the panels hold
    assert s.pass_index == s.acc.n - 1
    app.step_pass(-5)
    assert s.pass_index == 0 and s.inspection.pass_index == 0
    app.click(_centre(app, "help"))
    assert s.show_help
    app.toggle_help()


def test_coverage_follows_the_selected_hit(window):
    from psurf_core.inspect import primitive_pixels
    from ui.views.window import coverage_target, panel_text

    app, s = window, window.s
    app.set_pixel((32, 24))
    assert len(s.inspection.table) > 1
    app.toggle_coverage()
    name, batch, prim = coverage_target(s)
    want = primitive_pixels(s.scene, s.estimator, s.seed, s.pass_index, name, prim,
                            s.settings, batch=batch)
    assert np.array_equal(s.coverage_mask, want) and want.any()
    assert want[24, 32]  # the primitive of a hit of this pixel reaches this pixel
    assert f"reaches {int(want.sum())} pixels" in panel_text(s)
    first = (name, batch, prim)
    app.step_hit(1)
    assert coverage_target(s) != first or len(s.inspection.table) == 1
    app.toggle_coverage()
    assert s.coverage_mask is None and "coverage" not in panel_text(s)


def test_right_click_picks_a_primitive(window):
    from ui.views.window import coverage_target

    app, s = window, window.s
    app.set_pixel((32, 24))
    s.stepper.go("create")
    app.redraw()
    ren = app.p.renderers[0]
    name = next(n for n in ren.actors if n.startswith("prims-") and n.endswith(":mesh"))
    mesh = pv.wrap(ren.actors[name].GetMapper().GetInput())
    cell = int(np.argmax(mesh.compute_cell_sizes(length=False, volume=False)["Area"]))
    centre = mesh.extract_cells([cell]).center
    ren.SetWorldPoint(*centre, 1.0)
    ren.WorldToDisplay()
    dx, dy, _ = ren.GetDisplayPoint()
    target = app.pick_primitive((dx, dy))
    assert target is not None and target[0] == name.split("-", 1)[1][: -len(":mesh")]
    assert target[2] in set(mesh.cell_data["prim_row"].tolist())
    assert s.coverage and coverage_target(s) == target and s.coverage_mask is not None
    assert app.pick_primitive((700, 100)) is None  # the stage panel: no primitive
    app.toggle_coverage()


def test_member_chip_toggles_and_keeps_one(window):
    app, s = window, window.s
    assert app.members == ("plane-t1t2", "plane-t1t2-short")
    assert app.click(_centre(app, "member:plane-t1t2")) == "button"
    alone = "mis:plane-t1t2+planes~plane-t1t2"
    assert s.estimator.spec == alone and s.disabled == {"plane-t1t2"}
    assert [t.name for t in s.estimator.techniques] == ["plane-t1t2-short"]
    app.toggle_member("plane-t1t2-short")  # would leave none: refused
    assert s.estimator.spec == alone and "at least one" in s.message
    app.toggle_member_index(0)
    assert s.estimator.spec == "mis:plane-t1t2+planes" and not s.disabled


def test_slider_widgets_push_debounced_values(window):
    """A slider's VTK interaction event reaches the debouncer (not a rebuild); the sliders
    start hidden and ``w`` shows them."""
    app, s = window, window.s
    sliders = app.controls.sliders
    assert set(sliders) == {"sigma_s", "sigma_a", "g", "photons"}
    assert not any(w.GetEnabled() for w in sliders.values())
    app.toggle_sliders()
    assert all(w.GetEnabled() for w in sliders.values())
    before = s.scene.medium.sigma_s
    w = sliders["sigma_s"]
    w.GetRepresentation().SetValue(1.7)
    w.InvokeEvent("InteractionEvent")
    assert app.pending.pending and app.params.sigma_s == pytest.approx(1.7)
    assert s.scene.medium.sigma_s == before  # nothing rebuilt while the slider moves
    app.flush()
    assert s.scene.medium.sigma_s == pytest.approx(1.7)
    app.toggle_sliders()
    assert not any(w.GetEnabled() for w in sliders.values())


def test_medium_changes_are_debounced_and_restart(window):
    app, s = window, window.s
    now = [100.0]
    app.clock = lambda: now[0]
    s.playing = False
    before = s.scene.medium.sigma_s
    app.nudge("sigma_s", 1)
    app.slide("g", 0.5)
    app.slide("photons", np.log2(200))
    app.tick()  # not quiet long enough: nothing rebuilt yet
    assert s.scene.medium.sigma_s == before and s.settings.photons == 100
    now[0] += 1.0
    app.tick()
    assert s.scene.medium.sigma_s == pytest.approx(before * 1.25)
    assert s.scene.medium.phase.g == 0.5 and s.settings.photons == 200
    assert s.acc.n == s.initial_passes and s.inspection.settings.photons == 200
    assert s.inspection.scene is s.scene
    app.nudge("photons", -1)
    app.flush()
    assert s.settings.photons == 100


# --------------------------------------------------------------------------- progressive
def test_progressive_panels_tick_pick_and_modes():
    """The window with ``ui.cli.progressive`` (``workers=0``: the tick renders the pass itself,
    deterministically): passes arrive through ``tick``, a click on a scaled tile of
    ``image_panels.PanelView`` picks the pixel, coverage lands on the inspected estimator's
    tile, ``m`` cycles the panel modes, a medium change restarts the worker's job."""
    from ui.views.interactive import App
    from ui.views.window import attach_progressive, build_state, compose, make_plotter

    state = build_state(POINT, seed=1, pixel_xy=(32, 24), photons=100, render_passes=False,
                        estimators=["mis:plane-t1t2+planes", "planes"])
    assert state.inspected == 0  # the MIS set
    attach_progressive(state, workers=0)
    plotter = make_plotter((800, 450), off_screen=True)
    try:
        compose(plotter, state)
        app = App(plotter, state)
        app.bind()
        for _ in range(4):
            app.tick()
        assert sum(state.prog.passes) == 4 and state.acc is state.prog.runs[0].acc
        assert state.acc.n >= 1
        tiles = controls.image_tiles(plotter.renderers[app._panel_index("render")], 64, 48)
        assert len(tiles) == 2 and tiles[0][2] != 1.0  # two estimators, scaled tiles
        assert app.click(app.pixel_display("render", (7, 9))) == "pixel"
        assert state.pixel_xy == (7, 9) and state.inspected == 0
        assert app.click(app.pixel_display("variance", (60, 1))) == "pixel"
        assert state.pixel_xy == (60, 1)
        app.set_pixel((32, 24))
        app.toggle_coverage()
        ren = plotter.renderers[app._panel_index("render")]
        assert "coverage-cells" in ren.actors
        b = ren.actors["coverage-cells"].GetBounds()
        (ox, oy), sp = tiles[0][1], tiles[0][2]
        assert ox - 1e-6 <= b[0] and b[1] <= ox + 64 * sp + 1e-6  # on the first tile
        assert oy - 1e-6 <= b[2] and b[3] <= oy + 48 * sp + 1e-6
        for mode in ("techniques", "bounces", "render"):
            app.next_mode()
            assert state.mode == mode
        app.toggle_play()
        assert state.prog.paused and not state.playing
        n = state.acc.n
        app.tick()
        assert state.acc.n == n  # paused: nothing rendered
        app.toggle_play()
        app.nudge("sigma_a", 1)
        app.flush()
        assert state.prog.job.scene is state.scene and state.acc.n == 0
        assert state.prog.job.specs == ("mis:plane-t1t2+planes", "planes")
        app.toggle_member("plane-t1t2")
        assert state.prog.job.specs == ("mis:plane-t1t2+planes~plane-t1t2", "planes")
    finally:
        app.close()
        plotter.close()


@pytest.mark.parametrize("value, message", [("nope", "unknown"), ("reference",
                                                                    "needs a photon estimator"),
                                           ("planes,", "estimator specs"),
                                           ("paper-mutli", "did you mean 'paper-multi'?")])
def test_window_estimators_flag_errors(value, message, capsys, tmp_path):
    import app

    rc = app.main(["demo", POINT, "--estimators", value, "--no-window", "--out",
                   str(tmp_path / "o")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and err[0].startswith("psurf: error: --estimators")
    assert message in err[0] and not (tmp_path / "o").exists()


# --------------------------------------------------------------------------- reference
@pytest.mark.parametrize("flags, message", [
    (["--reference", "missing.npz"], "missing.npz: file not found"),
    (["--pixel", "64,0"], "--pixel 64,0: outside the 64x48 image"),
    (["--pixel", "a,b"], "--pixel"),
])
def test_window_reference_and_pixel_flag_errors(flags, message, capsys, tmp_path):
    import app

    rc = app.main(["demo", POINT, *flags, "--no-window", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and err[0].startswith("psurf: error:")
    assert message in err[0] and not (tmp_path / "o").exists()


def test_reference_gives_relmse_in_the_panels_and_is_dropped_with_the_medium(tmp_path):
    """``--reference``: the render panels show relMSE against it (the window and
    ``screenshot``); a medium change drops it (it is the image of the loaded medium)."""
    from ui.views.image_panels import mode_areas
    from ui.views.interactive import App
    from ui.views.window import (
        attach_progressive,
        build_state,
        load_reference_image,
        make_plotter,
    )

    state = build_state(POINT, "planes", seed=1, pixel_xy=(32, 24), photons=100,
                        render_passes=False)
    ref = tmp_path / "ref.npz"
    np.savez(ref, mean=np.full((48, 64, 3), 0.01), min_scatter=state.scene.min_scatter,
             max_scatter=state.scene.max_scatter)
    state.reference = load_reference_image(str(ref), state.scene)
    attach_progressive(state, workers=0, breakdown=False)
    plotter = make_plotter((800, 450), off_screen=True)
    app = App(plotter, state)
    try:
        state.prog.run(passes=2)
        areas = mode_areas(state.prog, "render", reference=state.reference)
        assert "relMSE" in areas[1].tiles[0].title
        app.nudge("sigma_s", 1)
        app.flush()
        assert state.reference is None and "reference dropped" in state.message
    finally:
        app.close()
        plotter.close()
    # The scatter range is checked: a reference of another range is refused by name.
    bad = tmp_path / "bad.npz"
    np.savez(bad, mean=np.zeros((48, 64, 3)), min_scatter=5, max_scatter=6)
    from psurf_core.scene import SceneError

    with pytest.raises(SceneError, match="bad.npz"):
        load_reference_image(str(bad), state.scene)
