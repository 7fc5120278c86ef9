"""The image-panel modes (``ui.views.image_panels``: render, techniques, bounces), off-screen,
compared with ``tests/baselines/panels_<scene>_<mode>.png`` by SSIM >= 0.95 (as the window's
stage screenshots; see ``tests/test_ui_screenshots.py`` for the tolerance and how to refresh:
``PSURF_UPDATE_BASELINES=1``). Synchronous passes (``workers=0``) with a fixed seed, so the
numbers behind each picture are deterministic."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

pv = pytest.importorskip("pyvista")
pv.OFF_SCREEN = True

from skimage.metrics import structural_similarity  # noqa: E402

from psurf_core.render import RenderSettings  # noqa: E402
from psurf_core.scene_io import load_scene  # noqa: E402
from ui.cli.progressive import Progressive  # noqa: E402
from ui.views.image_panels import MODES, FigureMaker  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
BASELINES = Path(__file__).resolve().parent / "baselines"
SSIM_MIN = 0.95
UPDATE = os.environ.get("PSURF_UPDATE_BASELINES") == "1"
SIZE = (640, 480)
CASES = {
    "point": (["planes", "mis:plane-t1t2+plane-t1t3+sphere"], 3),
    "area_occluder": (["beams", "planes"], -1),
}


def _read(path: Path) -> np.ndarray:
    import imageio.v3 as iio

    return np.asarray(iio.imread(path))[..., :3]


@pytest.fixture(scope="module")
def pictures():
    """Every mode of every case, drawn in turn into one figure (updates and rebuilds)."""
    out = {}
    fm = FigureMaker(SIZE)
    try:
        for scene_name, (specs, kmax) in CASES.items():
            scene = load_scene(str(ROOT / "scenes" / f"{scene_name}.toml"))
            if kmax > 0:
                scene = scene.with_scatter(max_scatter=kmax)
            prog = Progressive(scene, specs, RenderSettings(photons=150), seed=3, workers=0,
                               breakdown=True)
            prog.run(passes=2)
            for r in prog.runs:  # measured seconds vary: fix them (titles and Var ratios)
                r.seconds = 0.5 * r.acc.n
            for mode in MODES:
                out[(scene_name, mode)] = fm.frame(prog, mode, pixel_xy=(20, 30))
    finally:
        fm.close()
    return out


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("scene", list(CASES))
def test_panel_mode_matches_baseline(pictures, scene, mode, tmp_path):
    import imageio.v3 as iio

    got = pictures[(scene, mode)]
    assert got.shape == (SIZE[1], SIZE[0], 3)
    baseline = BASELINES / f"panels_{scene}_{mode}.png"
    if UPDATE:
        BASELINES.mkdir(exist_ok=True)
        iio.imwrite(baseline, got)
        return
    if not baseline.exists():
        pytest.fail(f"missing baseline {baseline}; create it with PSURF_UPDATE_BASELINES=1")
    ref = _read(baseline)
    assert ref.shape == got.shape
    ssim = structural_similarity(ref, got, channel_axis=2, data_range=255)
    if ssim < SSIM_MIN:
        iio.imwrite(tmp_path / baseline.name, got)
    assert ssim >= SSIM_MIN, (f"{scene}/{mode}: SSIM {ssim:.3f} < {SSIM_MIN} against "
                              f"{baseline} (new picture: {tmp_path / baseline.name})")


def test_modes_differ(pictures):
    imgs = [pictures[("point", m)].astype(int) for m in MODES]
    for i in range(len(imgs)):
        for j in range(i + 1, len(imgs)):
            assert np.abs(imgs[i] - imgs[j]).mean() > 5


def test_modes_before_any_pass_and_without_breakdown():
    """Right after a reset (no pass yet) and for an estimator without a breakdown, every mode
    draws (a message tile where there is nothing to show), with finite numbers only."""
    from ui.views.image_panels import mode_areas

    scene = load_scene(str(ROOT / "scenes" / "point.toml"))
    empty = Progressive(scene, ["planes", "beams"], RenderSettings(photons=50), workers=0,
                        breakdown=True)
    plain = Progressive(scene, ["planes"], RenderSettings(photons=50), workers=0)
    plain.run(passes=1)
    fm = FigureMaker((320, 240))
    try:
        for prog in (empty, plain):
            for mode in MODES:
                img = fm.frame(prog, mode)
                assert img.shape == (240, 320, 3)
                for area in mode_areas(prog, mode):
                    for t in area.tiles:
                        assert t.values is None or np.isfinite(t.values).all()
        texts = [t.title for a in mode_areas(plain, "techniques") for t in a.tiles]
        assert any("no breakdown" in t for t in texts)
        assert [t.title for t in mode_areas(empty, "render")[1].tiles] == [
            "planes: no pass yet", "beams: no pass yet"]
        titles = [t.title for t in mode_areas(empty, "render")[0].tiles]
        assert all("waiting for the first pass" in t for t in titles)
    finally:
        fm.close()


def test_panel_view_updates_in_place_and_rebuilds_after_a_clear():
    from ui.views.image_panels import MEAN_VARIANCE_BAR, draw_image_panels

    scene = load_scene(str(ROOT / "scenes" / "point.toml"))
    prog = Progressive(scene, ["planes", "beams"], RenderSettings(photons=50), workers=0)
    prog.run(passes=2)
    pl = pv.Plotter(window_size=[640, 320], off_screen=True, shape=(1, 2), border=False)
    try:
        view = draw_image_panels(pl, [(0, 0), (0, 1)], prog, "render", (3, 4))
        pl.subplot(0, 1)
        grid = view._parts["ip1"]["tiles"][0][0]
        prog.run(passes=3)
        assert draw_image_panels(pl, [(0, 0), (0, 1)], prog, "render", (3, 4), view) is view
        assert view._parts["ip1"]["tiles"][0][0] is grid  # same actors, new values
        from ui.views.image_panels import Tile, tile_rgb

        want = tile_rgb(Tile("", values=prog.runs[0].acc.variance.mean(axis=-1) / 3,
                             clim=view_clim(view)))
        np.testing.assert_array_equal(np.asarray(grid.point_data["rgb"]),
                                      want[::-1].reshape(-1, 3))
        pl.renderer.clear_actors()  # what the window's compose() does to its cells
        for title in list(pl.scalar_bars.keys()):
            pl.remove_scalar_bar(title)
        view.draw(pl, [(0, 0), (0, 1)], prog, "render", (3, 4))
        pl.subplot(0, 1)
        assert "ip1-tile0" in pl.renderer.actors
        assert any(title.startswith(MEAN_VARIANCE_BAR) for title in pl.scalar_bars.keys())
    finally:
        pl.close()


def view_clim(view):
    actor = view._parts["ip1"]["bar_actor"]  # the colour bar's lookup table: the maps' range
    return actor.mapper.GetScalarRange()


def test_moving_the_pixel_moves_the_outlines_without_a_rebuild():
    from ui.views.image_panels import PanelView

    scene = load_scene(str(ROOT / "scenes" / "point.toml"))
    prog = Progressive(scene, ["planes"], RenderSettings(photons=50), workers=0)
    prog.run(passes=1)
    pl = pv.Plotter(window_size=[640, 320], off_screen=True, shape=(1, 2), border=False)
    try:
        view = PanelView()
        view.draw(pl, [(0, 0), (0, 1)], prog, "render", (3, 4))
        mesh, _ = view._parts["ip0"]["outlines"][0]
        before = np.array(mesh.points)
        view.draw(pl, [(0, 0), (0, 1)], prog, "render", (5, 4))
        assert view._parts["ip0"]["outlines"][0][0] is mesh
        step = np.array(mesh.points) - before
        assert np.allclose(step[:, 1:], 0) and np.allclose(step[:, 0], step[0, 0])
        assert step[0, 0] > 0  # two pixels to the right
    finally:
        pl.close()
