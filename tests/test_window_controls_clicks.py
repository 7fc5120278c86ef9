"""The window's interaction, driven on one off-screen window (a module-scoped fixture; the
tests run in this order on its state): picking a pixel by clicking, also as synthetic VTK
mouse events through the interactor (the path a real click takes), the buttons and the
inspected pass, coverage (primitive -> pixels) from the selected hit or a right click,
estimator member chips, and the debounced medium / photon sliders.

The conversions themselves (pure functions): ``test_window_controls.py``.
"""

from __future__ import annotations

import numpy as np
import pytest

pv = pytest.importorskip("pyvista")
pv.OFF_SCREEN = True

from window_controls_support import POINT  # noqa: E402


# --------------------------------------------------------------------------- the window
@pytest.fixture(scope="module")
def window():
    """One off-screen window for this module: each test takes it as the one before left it."""
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
