"""Screenshots of every stage of the window, compared with committed baselines.

Every stage of ``ui.views.window`` is rendered off-screen for two bundled scenes (``point.toml`` and
``area_occluder.toml``) at a fixed pixel and seed with tiny budgets (200 photons, 2 passes,
800 x 450), and compared with ``tests/baselines/<scene>_<stage>.png`` by SSIM
(``skimage.metrics.structural_similarity`` over the RGB channels).

Tolerance: SSIM >= 0.95. The numbers behind each picture are deterministic (seeded passes);
what may differ between machines is rasterisation (EGL vs OSMesa, driver versions, font
hinting), which moves edges by a pixel and costs a few hundredths of SSIM, while a real
change (a missing primitive, a moved ray, another table) costs much more.

Refreshing the baselines (after an intended change to what a stage shows)::

    PSURF_UPDATE_BASELINES=1 .venv/bin/python -m pytest tests/test_ui_screenshots.py

rewrites every baseline PNG and the stage texts ``<scene>_stages.txt`` (the numbers each
stage shows, compared exactly) (the tests then pass); look at the new pictures and diff the
texts before committing them. Without a display VTK renders through EGL or OSMesa
(``pyvista.OFF_SCREEN = True``).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

pv = pytest.importorskip("pyvista")
pv.OFF_SCREEN = True

from skimage.metrics import structural_similarity  # noqa: E402

from ui.views.stepper import STAGES  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
BASELINES = Path(__file__).resolve().parent / "baselines"
SSIM_MIN = 0.95
UPDATE = os.environ.get("PSURF_UPDATE_BASELINES") == "1"

SHOT = dict(pixel_xy=(32, 24), estimator="planes", seed=1, size=(800, 450), passes=2,
            photons=200)
SCENES = ("point", "area_occluder")


def _read(path: Path) -> np.ndarray:
    import imageio.v3 as iio

    return np.asarray(iio.imread(path))[..., :3]


@pytest.mark.parametrize("stage", STAGES)
@pytest.mark.parametrize("scene", SCENES)
def test_stage_matches_baseline(scene, stage, tmp_path):
    from ui.views.window import screenshot

    out = tmp_path / f"{scene}_{stage}.png"
    img = screenshot(str(ROOT / "scenes" / f"{scene}.toml"), stage, out=str(out), **SHOT)
    assert img.shape[:2] == (450, 800)
    assert out.exists()
    baseline = BASELINES / f"{scene}_{stage}.png"
    if UPDATE:
        BASELINES.mkdir(exist_ok=True)
        baseline.write_bytes(out.read_bytes())
        return
    if not baseline.exists():
        pytest.fail(f"missing baseline {baseline}; create it with PSURF_UPDATE_BASELINES=1")
    ref = _read(baseline)
    got = _read(out)
    assert got.shape == ref.shape
    ssim = structural_similarity(ref, got, channel_axis=2, data_range=255)
    assert ssim >= SSIM_MIN, (f"{scene}/{stage}: SSIM {ssim:.3f} < {SSIM_MIN} against "
                              f"{baseline} (new picture: {out})")


@pytest.mark.parametrize("scene", SCENES)
def test_stage_texts_match_baseline(scene):
    """The stage panel's text (the numbers: hit tables, sums, weights) of every stage, exactly:
    SSIM barely notices a changed digit in a table, this does. Refreshed with the PNGs."""
    from ui.views.window import build_state, panel_text

    shot = {k: v for k, v in SHOT.items() if k != "size"}
    state = build_state(str(ROOT / "scenes" / f"{scene}.toml"), render_passes=False, **shot)
    texts = []
    for stage in STAGES:
        state.stepper.go(stage)
        texts.append(f"== {stage}\n{panel_text(state)}")
    got = "\n".join(texts) + "\n"
    baseline = BASELINES / f"{scene}_stages.txt"
    if UPDATE:
        baseline.write_text(got)
        return
    if not baseline.exists():
        pytest.fail(f"missing baseline {baseline}; create it with PSURF_UPDATE_BASELINES=1")
    assert got == baseline.read_text(), f"{scene}: stage texts differ from {baseline}"


def test_coverage_and_pass_match_baseline(tmp_path):
    """Coverage (primitive -> pixels) of the top hit, inspecting pass 1 (``--coverage
    --pass 1``): the tinted pixels on the render panel and the panel's coverage line."""
    from ui.views.window import screenshot

    out = tmp_path / "point_coverage_pass1.png"
    shot = dict(SHOT, estimator="plane-t1t2", pixel_xy=(30, 20))
    img = screenshot(str(ROOT / "scenes" / "point.toml"), "intersect", out=str(out),
                     pass_index=1, coverage=True, **shot)
    assert img.shape[:2] == (450, 800)
    baseline = BASELINES / "point_coverage_pass1.png"
    if UPDATE:
        baseline.write_bytes(out.read_bytes())
        return
    if not baseline.exists():
        pytest.fail(f"missing baseline {baseline}; create it with PSURF_UPDATE_BASELINES=1")
    ssim = structural_similarity(_read(baseline), _read(out), channel_axis=2, data_range=255)
    assert ssim >= SSIM_MIN, f"coverage: SSIM {ssim:.3f} < {SSIM_MIN} (new picture: {out})"


def test_stages_differ():
    """Guard against a baseline set where every stage shows the same picture."""
    imgs = [_read(BASELINES / f"point_{s}.png") for s in STAGES
            if (BASELINES / f"point_{s}.png").exists()]
    if len(imgs) < 2:
        pytest.skip("baselines not written yet")
    for a, b in zip(imgs, imgs[1:], strict=False):
        assert structural_similarity(a, b, channel_axis=2, data_range=255) < 0.99


# --------------------------------------------------------------------------- CLI errors
def _cli(argv, capsys):
    import argparse

    from ui.cli.screenshot import add_screenshot_parser

    class P(argparse.ArgumentParser):
        def error(self, message):
            raise SystemExit(f"psurf: error: {message}")

    top = P(prog="psurf")
    add_screenshot_parser(top.add_subparsers(dest="command", parser_class=P))
    args = top.parse_args(argv)
    rc = args.func(args)
    return rc, capsys.readouterr()


@pytest.mark.parametrize("extra, message", [
    (["--pixel", "64,0"], "outside the 64x48 image"),
    (["--pixel", "1,1", "--estimator", "nope"], "unknown estimator"),
    (["--pixel", "1,1", "--estimator", "reference"], "photon estimator"),
    (["--pixel", "1,1", "--passes", "2", "--pass", "2"], "passes 0..1"),
    (["--pixel", "1,1", "--estimators", "planes,nope"], "unknown estimator"),
    (["--pixel", "1,1", "--estimators", "reference,planes"], "--estimators reference"),
])
def test_cli_errors_are_one_line(extra, message, capsys, tmp_path):
    argv = ["screenshot", str(ROOT / "scenes" / "point.toml"), "--stage", "trace",
            "--out", str(tmp_path / "x.png"), *extra]
    rc, cap = _cli(argv, capsys)
    assert rc == 2
    lines = cap.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("psurf: error: ") and message in lines[0]
    assert not (tmp_path / "x.png").exists()


def test_cli_bad_pixel_syntax(capsys, tmp_path):
    with pytest.raises(SystemExit, match="psurf: error: argument --pixel"):
        _cli(["screenshot", "s.toml", "--stage", "trace", "--pixel", "a,b", "--out",
              str(tmp_path / "x.png")], capsys)


# --------------------------------------------------------------------------- window actions
def test_window_actions_offscreen(tmp_path, monkeypatch):
    """The key handlers of the window, driven directly on an off-screen plotter."""
    from ui.views.interactive import App
    from ui.views.window import build_state, compose, make_plotter

    monkeypatch.chdir(tmp_path)
    state = build_state(str(ROOT / "scenes" / "point.toml"), "planes", seed=1, pixel_xy=(32, 24),
                        photons=100, passes=1)
    plotter = make_plotter((800, 450), off_screen=True)
    try:
        compose(plotter, state)
        app = App(plotter, state)
        app.bind()
        for _ in range(6):
            app.next()
        assert state.stage == "reconstruct"
        app.step_hit(1)
        app.previous()
        assert state.stage == "evaluate"
        app.move(1, -1)
        assert state.pixel_xy == (33, 23) and state.inspection.pixel_xy == (33, 23)
        app.paths(2.0)
        assert state.n_paths == 48
        app.toggle_help()
        assert state.show_help
        app.toggle_play()
        app.tick()
        assert state.acc.n == 2
        app.save()
        assert list(tmp_path.glob("psurf-evaluate-33x23-pass2.png"))
        app.reset()
        assert state.stage == "trace" and state.acc.n == 1 and not state.playing
    finally:
        plotter.close()
