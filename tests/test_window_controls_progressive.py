"""The progressive window (``ui.cli.progressive``, ``workers=0``): several estimators' panels
picked, covered and cycled through ticks; the ``--estimators``, ``--reference`` and
``--pixel`` flags' one-line errors; a reference's relMSE in the panels, dropped with the
medium.
"""

from __future__ import annotations

import numpy as np
import pytest

pv = pytest.importorskip("pyvista")
pv.OFF_SCREEN = True

from window_controls_support import POINT  # noqa: E402

from ui.views import controls  # noqa: E402


# --------------------------------------------------------------------------- progressive
def test_progressive_panels_tick_pick_and_modes():
    """The window with ``ui.cli.progressive`` (``workers=0``: the tick renders the pass itself,
    deterministically): passes arrive through ``tick``, a click on a scaled tile of
    ``image_panels.PanelView`` picks the pixel, coverage lands on the inspected estimator's
    tile, ``m`` cycles the panel modes, a medium change restarts the worker's job."""
    from window_frames_support import bound_app

    from ui.views.window import attach_progressive, build_state

    state = build_state(POINT, seed=1, pixel_xy=(32, 24), photons=100, render_passes=False,
                        estimators=["mis:plane-t1t2+planes", "planes"])
    assert state.inspected == 0  # the MIS set
    attach_progressive(state, workers=0)
    with bound_app(state) as (plotter, app):
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
