"""Screenshots of every stage of the window, compared with committed baselines.

Every stage of ``ui.views.window`` (and, with two estimators, every image-panel mode) is
rendered off-screen for two bundled scenes (``point.toml``: one estimator, 1024 x 768;
``area_occluder.toml``: photon planes beside an MIS set, at 1024 x 768 and 1920 x 1080, the
large size in make test-slow) at a fixed pixel and seed with tiny budgets (200 photons,
2 passes), and compared with ``tests/baselines/<scene>_<W>x<H>_<stage or mode_NAME>.png`` by SSIM
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

SCENES = ("point", "area_occluder")
#: The window's pictures: every stage, and every panel mode, at the small and the large end of
#: the sizes a lecture uses. ``point``: one estimator; ``area_occluder``: two side by side, the
#: MIS set inspected (its member chips are the footer's, not in screenshots).
CASES = {
    "point": dict(estimators=["planes"], pixel=(32, 24), sizes=[(1024, 768)], modes=False),
    "area_occluder": dict(estimators=["planes", "mis:plane-t1t2+cone+cylinder"],
                          pixel=(32, 24), sizes=[(1024, 768), (1920, 1080)], modes=True),
}
SEED, PHOTONS, PASSES = 1, 200, 2


def _read(path: Path) -> np.ndarray:
    import imageio.v3 as iio

    return np.asarray(iio.imread(path))[..., :3]


def _check(name: str, got: np.ndarray, tmp_path: Path) -> None:
    import imageio.v3 as iio

    baseline = BASELINES / f"{name}.png"
    if UPDATE:
        BASELINES.mkdir(exist_ok=True)
        iio.imwrite(baseline, got)
        return
    if not baseline.exists():
        pytest.fail(f"missing baseline {baseline}; create it with PSURF_UPDATE_BASELINES=1")
    ref = _read(baseline)
    assert got.shape == ref.shape, (name, got.shape, ref.shape)
    ssim = structural_similarity(ref, got, channel_axis=2, data_range=255)
    if ssim < SSIM_MIN:
        iio.imwrite(tmp_path / baseline.name, got)
    assert ssim >= SSIM_MIN, (f"{name}: SSIM {ssim:.3f} < {SSIM_MIN} against {baseline} "
                              f"(new picture: {tmp_path / baseline.name})")


def _state(case: str):
    """The window's state of a case with its panels rendered here (deterministic)."""
    from ui.cli.progressive import Progressive
    from ui.views.image_panels import PanelView
    from ui.views.window import build_state

    c = CASES[case]
    state = build_state(str(ROOT / "scenes" / f"{case}.toml"), seed=SEED, pixel_xy=c["pixel"],
                        photons=PHOTONS, passes=PASSES, render_passes=False,
                        estimators=c["estimators"])
    state.prog = Progressive(state.scene, list(state.specs), state.settings, seed=SEED,
                             workers=0, breakdown=c["modes"])
    state.prog.run(passes=PASSES)
    for r in state.prog.runs:
        r.seconds = 0.0  # wall seconds differ between runs: compare at equal passes
    state.panels, state.acc = PanelView(), state.prog.runs[state.inspected].acc
    return state


#: Sizes whose pictures run in make test-slow only (~25 s of off-screen rendering on the idle
#: machine: composing a stage costs in proportion to the window's pixels).
SLOW_SIZES = {(1920, 1080)}


def _render_group(case: str, size: tuple[int, int]) -> dict:
    """Every stage (and mode) of ``case`` at ``size``, composed into one plotter (as the
    window recomposes: updates and rebuilds)."""
    from ui.views._vtk import rendered_image
    from ui.views.panel_modes import MODES
    from ui.views.window import compose, make_plotter

    out = {}
    c = CASES[case]
    state = _state(case)
    tag = f"{case}_{size[0]}x{size[1]}"
    try:
        plotter = make_plotter(size, off_screen=True)
        try:
            for stage in STAGES:
                state.stepper.go(stage)
                compose(plotter, state)
                out[f"{tag}_{stage}"] = rendered_image(plotter)
            if c["modes"]:
                state.stepper.go("evaluate")
                for mode in MODES:
                    state.mode = mode
                    compose(plotter, state)
                    out[f"{tag}_mode_{mode}"] = rendered_image(plotter)
                state.mode = "render"
        finally:
            plotter.close()
    finally:
        state.prog.close()
        state.inspector.close()
    return out


def _groups() -> dict[str, tuple[str, tuple[int, int]]]:
    """Every picture's name with its (case, size) group."""
    from ui.views.panel_modes import MODES

    groups = {}
    for case, c in CASES.items():
        for size in c["sizes"]:
            tag = f"{case}_{size[0]}x{size[1]}"
            names = [f"{tag}_{s}" for s in STAGES]
            names += [f"{tag}_mode_{m}" for m in MODES] if c["modes"] else []
            groups.update({n: (case, tuple(size)) for n in names})
    return groups


class _Pictures(dict):
    """The pictures by name, each (case, size) group rendered when one of its names is
    first asked for: the slow sizes only under make test-slow."""

    def __missing__(self, name: str):
        case, size = _groups()[name]
        self.update(_render_group(case, size))
        return self[name]


@pytest.fixture(scope="module")
def pictures():
    return _Pictures()


def _names() -> list:
    return [pytest.param(n, id=n, marks=[pytest.mark.slow] if size in SLOW_SIZES else [])
            for n, (_, size) in _groups().items()]


@pytest.mark.parametrize("name", _names())
def test_window_matches_baseline(pictures, name, tmp_path):
    got = np.asarray(pictures[name])[..., :3]
    w, h = (int(v) for v in name.split("_")[-2 if "_mode_" not in name else -3].split("x"))
    assert got.shape[:2] == (h, w)
    _check(name, got, tmp_path)


@pytest.mark.parametrize("scene", SCENES)
def test_stage_texts_match_baseline(scene):
    """The stage panel's text (the numbers: hit tables, sums, weights) of every stage, exactly:
    SSIM barely notices a changed digit in a table, this does. Refreshed with the PNGs."""
    from ui.views.window import build_state, panel_text

    c = CASES[scene]
    state = build_state(str(ROOT / "scenes" / f"{scene}.toml"), seed=SEED, pixel_xy=c["pixel"],
                        photons=PHOTONS, passes=PASSES, render_passes=False,
                        estimators=c["estimators"])
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
    img = screenshot(str(ROOT / "scenes" / "point.toml"), "intersect", (30, 20),
                     "plane-t1t2", seed=SEED, out=str(out), size=(1024, 768), passes=PASSES,
                     photons=PHOTONS, pass_index=1, coverage=True)
    assert img.shape[:2] == (768, 1024)
    _check("point_coverage_pass1", np.asarray(img)[..., :3], tmp_path)


def test_stages_differ(pictures):
    """Guard against a baseline set where every stage shows the same picture."""
    imgs = [np.asarray(pictures[f"point_1024x768_{s}"])[..., :3] for s in STAGES]
    for a, b in zip(imgs, imgs[1:], strict=False):
        assert structural_similarity(a, b, channel_axis=2, data_range=255) < 0.99


def test_a_picture_shows_the_change_made_since_the_last_render():
    """pyvista's off-screen ``screenshot`` renders only before the first render and then
    returns the last picture: the pictures compared here are taken by
    :func:`ui.views._vtk.rendered_image`, which renders first (also while rendering is held,
    as the views hold it while adding actors). A change shows, as a fresh plotter draws it."""
    from ui.views._vtk import rendered_image

    def sphere(color):
        p = pv.Plotter(off_screen=True, window_size=(200, 150))
        return p, p.add_mesh(pv.Sphere(), color=color)

    def fresh(color):
        p, _ = sphere(color)
        try:
            return rendered_image(p)
        finally:
            p.close()

    p, actor = sphere("red")
    try:
        red = rendered_image(p)  # the first render
        actor.prop.color = "blue"
        blue = rendered_image(p)
        p.suppress_rendering = True
        actor.prop.color = "green"
        green = rendered_image(p)
        assert p.suppress_rendering  # held again afterwards
    finally:
        p.close()
    for before, after, color in ((red, blue, "blue"), (blue, green, "green")):
        assert after.shape == before.shape == (150, 200, 3) and after.dtype == np.uint8
        assert np.abs(after.astype(int) - before).mean() > 5, color  # not the last picture
        ssim = structural_similarity(fresh(color), after, channel_axis=2, data_range=255)
        assert ssim >= SSIM_MIN, (color, ssim)


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
    (["--pixel", "1,1", "--estimators", "reference"], "--estimators reference"),
    (["--pixel", "1,1", "--estimators", "planes,beams", "--inspect", "nope"],
     "--inspect nope: not one of --estimators"),
    (["--pixel", "1,1", "--estimator", "paper-mutli"], "did you mean 'paper-multi'?"),
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
    from window_frames_support import bound_app

    from ui.views.window import build_state

    monkeypatch.chdir(tmp_path)
    state = build_state(str(ROOT / "scenes" / "point.toml"), "planes", seed=1, pixel_xy=(32, 24),
                        photons=100, passes=1)
    with bound_app(state) as (plotter, app):
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
