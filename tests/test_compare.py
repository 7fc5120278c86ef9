"""Equal-time study (``compare``): the JSON schema, ratios, the relMSE definition, outputs and
one-line errors. A 16x12 scene, 1 s per estimator and run."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from app_support import run_app

from psurf_core import load_scene
from psurf_core.estimators import parse_estimator
from psurf_core.render import RenderSettings
from psurf_core.study import (
    OUTPUT_FILES,
    RELMSE_EPS,
    compare,
    load_reference,
    relmse,
    relmse_map,
    write_outputs,
    write_reference_npz,
)

ROOT = Path(__file__).resolve().parent.parent

from tiny_scene import TINY as TINY_AREA  # noqa: E402

TINY = TINY_AREA + """
[render]
min_scatter = 2
max_scatter = 2
"""

ROW_KEYS = {"estimator", "passes", "mean_variance", "relmse", "ratio"}


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    d = tmp_path_factory.mktemp("compare")
    path = d / "tiny.toml"
    path.write_text(TINY)
    return d, load_scene(str(path))


@pytest.fixture(scope="module")
def study(tiny):
    """The path tracer against photon planes at K = 2, two runs of 1 s each: planes are far
    better per second there (the path tracer has 50x their variance at equal time)."""
    d, scene = tiny
    s = compare(scene, ["reference", "planes"], 1.0, runs=2, seed=0,
                settings=RenderSettings(photons=500), reference_seconds=2.0)
    out = d / "out"
    out.mkdir()
    write_outputs(str(out), s)
    write_reference_npz(str(out / "reference.npz"), s, scene)
    return s, out


def test_compare_json_schema(study):
    s, out = study
    data = json.loads((out / "compare.json").read_text())
    assert {"scene", "seconds", "results"} <= set(data)
    assert data["seconds"] == 1.0 and data["runs"] == 2
    assert "arrays" not in data
    assert [r["estimator"] for r in data["results"]] == ["reference", "planes"]
    for r in data["results"]:
        assert ROW_KEYS <= set(r)
        assert r["passes"] >= 2 and len(r["passes_per_run"]) == 2
        assert [run["seed"] for run in r["runs"]] == [0, 1]
        assert r["mean_variance"] > 0 and r["relmse"] > 0
        # mean_variance is the pixel mean of the per-pass variance / passes, run-averaged
        for run in r["runs"]:
            assert run["mean_variance"] == pytest.approx(
                run["per_pass_variance"] / run["passes"])
        curve = r["runs"][0]["curve"]
        pairs = zip(curve, curve[1:], strict=False)
        assert curve and all(b[0] >= a[0] and b[1] > a[1] for a, b in pairs)
        assert curve[-1][1] == r["runs"][0]["passes"]
        assert curve[-1][2] == pytest.approx(r["runs"][0]["relmse"])
    ref = data["reference"]
    assert ref["source"] == "render" and ref["passes"] > 0 and ref["seconds"] >= 2.0
    assert ref["seed"] == 2  # seed + runs: no run uses it
    assert 0 < ref["relmse_floor"] < data["results"][1]["relmse"]


def test_ratio_first_is_one_and_better_estimator_below_one(study):
    s, _ = study
    first, planes = s["results"]
    assert first["ratio"] == 1.0 and first["relmse_ratio"] == 1.0
    assert planes["ratio"] == pytest.approx(planes["mean_variance"] / first["mean_variance"])
    assert planes["ratio"] < 0.3
    assert planes["relmse_ratio"] < 1.0


def test_run_by_run_ratios_pair_run_r_with_the_first_estimators_run_r(study):
    s, out = study
    first, planes = s["results"]
    assert first["run_ratios"] == [1.0, 1.0]
    want = [a["mean_variance"] / b["mean_variance"]
            for a, b in zip(planes["runs"], first["runs"], strict=True)]
    assert planes["run_ratios"] == pytest.approx(want)
    assert planes["ratio_median_run"] == pytest.approx(np.median(want))
    row = next(ln for ln in (out / "compare.md").read_text().splitlines()
               if ln.startswith("| `planes`"))
    assert ", ".join(f"{x:.2g}" for x in want) in row


def test_heavy_tailed_runs_are_noted(study):
    """Every run records the share of its pixels whose error estimate its own passes flag
    (``psurf_core.reliability``), and an estimator gets the heavy-tail note exactly when a
    run flags more than ``WARN_FRACTION`` (in compare.md too)."""
    from psurf_core.reliability import WARN_FRACTION

    s, out = study
    md = (out / "compare.md").read_text()
    for row in s["results"]:
        fr = [run["heavy_tailed_fraction"] for run in row["runs"]]
        assert all(f is not None and 0.0 <= f <= 1.0 for f in fr)
        noted = [n for n in row["notes"] if n.startswith("heavy-tailed passes")]
        assert len(noted) == (1 if max(fr) > WARN_FRACTION else 0)
        for n in noted:
            assert f"- `{row['estimator']}`: {n}" in md


def test_a_flagged_run_gets_the_note(tiny, monkeypatch):
    """The other branch: with the threshold below every share, each estimator is noted."""
    from psurf_core import reliability

    monkeypatch.setattr(reliability, "WARN_FRACTION", -1.0)
    _, scene = tiny
    s = compare(scene, ["planes"], 0.2, runs=2, seed=3, settings=RenderSettings(photons=200),
                reference_seconds=0.2)
    (row,) = s["results"]
    assert any(n.startswith("heavy-tailed passes") and "2 of 2 runs" in n for n in row["notes"])


def test_outputs_written(study):
    _, out = study
    for name in OUTPUT_FILES:
        assert (out / name).stat().st_size > 0
    md = (out / "compare.md").read_text()
    assert "| `planes` |" in md and "relMSE" in md
    import imageio.v3 as iio

    for name in ("variance.png", "error.png", "renders.png", "error_vs_time.png"):
        img = iio.imread(out / name)
        assert img.ndim == 3 and img.shape[0] > 100 and img.std() > 0


def test_relmse_definition():
    rng = np.random.default_rng(1)
    ref = rng.uniform(0.0, 2.0, (3, 4, 3))
    assert relmse(ref, ref) == 0.0
    img = ref + 0.1
    den = ref**2 + RELMSE_EPS * ref.mean() ** 2
    assert relmse(img, ref) == pytest.approx(float(np.mean(0.01 / den)))
    assert relmse_map(img, ref).shape == (3, 4)
    # dark pixels are bounded by the eps term, not infinite
    ref[0, 0] = 0.0
    assert np.isfinite(relmse(img, ref))


def test_reference_file_round_trip_and_checks(study, tiny):
    s, out = study
    d, scene = tiny
    ref = load_reference(str(out / "reference.npz"), scene)
    assert np.allclose(ref.mean, s["arrays"]["reference"], rtol=1e-6)
    assert ref.passes == s["reference"]["passes"]
    from psurf_core.scene import SceneError

    with pytest.raises(SceneError, match="scatter counts"):
        load_reference(str(out / "reference.npz"), scene.with_scatter(1, 2))
    with pytest.raises(SceneError, match="file not found"):
        load_reference(str(d / "missing.npz"), scene)


def test_cli_with_reference_file(study, tiny, tmp_path):
    _, out = study
    d, _ = tiny
    # 3 s, not 1: the ratio needs two passes of planes, and under the full suite's load one
    # run of a 1-s budget once held a single pass (the fresh clone at 80aadb6)
    r = run_app("compare", d / "tiny.toml", "--estimators", "planes,points", "--time", "3",
                   "--photons", "auto,300", "--reference", out / "reference.npz",
                   "--out", tmp_path / "cli", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    data = json.loads((tmp_path / "cli" / "compare.json").read_text())
    n = data["results"][0]["pass_model"]["photons"]
    assert [x["photons_per_pass"] for x in data["results"]] == [n, 300]
    # The pilot is announced as it starts and its choice completes the same line.
    assert f"planes: sizing its passes (a pilot, not timed) ... {n} photons a pass" in r.stdout
    assert data["reference"]["source"].endswith("reference.npz")
    # --jobs auto, the default: one worker process a core (this machine's memory holds them)
    from ui.cli.parallel import usable_cores

    cores = usable_cores()
    assert data["processes"] == cores, data["processes"]
    if cores > 1:
        assert f"passes in {cores} worker processes, one a core (--jobs auto" in r.stderr
        assert f"passes in {cores} worker processes" in (tmp_path / "cli" /
                                                         "compare.md").read_text()
    assert data["results"][0]["passes"] >= 2, data["results"][0]
    assert data["results"][0]["ratio"] == 1.0
    assert not (tmp_path / "cli" / "reference.npz").exists()  # nothing rendered for it
    assert "| `points` |" in r.stdout


@pytest.mark.parametrize("args, message", [
    (["--estimators", "planes,nope"], "unknown estimator 'nope'"),
    (["--estimators", "planes,planes"], "listed twice"),
    (["--estimators", "planes", "--photons", "1,2"], "--photons"),
    (["--estimators", "planes", "--min-scatter", "3", "--max-scatter", "2"], "--max-scatter"),
    (["--estimators", "planes", "--time", "0"], "--time"),
    (["--estimators", "planes", "--clock", "cpu", "--workers", "2"], "--clock cpu"),
])
def test_cli_errors_are_one_line(tiny, tmp_path, args, message):
    d, _ = tiny
    argv = ["compare", d / "tiny.toml", *args, "--out", tmp_path / "o"]
    if "--time" not in args:
        argv += ["--time", "1"]
    r = run_app(*argv, cwd=tmp_path)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("psurf: error: ") and message in lines[0]
    assert not (tmp_path / "o").exists()


def test_default_is_single_process_without_dask(tiny):
    """Without --dask/--workers nothing of Dask is imported (the render hook returns None)."""
    d, _ = tiny
    code = (
        "import sys, argparse\n"
        "from psurf_core import load_scene\n"
        "from psurf_core.render import RenderSettings\n"
        "from psurf_core.study import compare\n"
        "from ui.cli.parallel import maybe_distributed\n"
        f"sc = load_scene({str(d / 'tiny.toml')!r})\n"
        "a = argparse.Namespace(dask=None, workers=None)\n"
        "assert maybe_distributed(a, sc, 'planes', RenderSettings(photons=100), passes=1) is None\n"
        "compare(sc, ['planes'], 0.2, reference_seconds=0.2,"
        " settings=RenderSettings(photons=100))\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in ('dask', 'distributed')))\n"
    )
    env = {**os.environ, "MPLBACKEND": "Agg",
           "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                       timeout=120, cwd=d)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "[]"


def test_cpu_clock_budget(tiny):
    """``clock="cpu"``: every run spends at least the budget of this process's CPU time."""
    _, scene = tiny
    s = compare(scene, ["planes"], 0.3, settings=RenderSettings(photons=300),
                reference_seconds=0.3, clock="cpu")
    row = s["results"][0]
    assert s["clock"] == "cpu" and row["runs"][0]["cpu_seconds"] >= 0.3
    assert row["seconds_per_run"] == row["cpu_seconds_per_run"]
    assert row["runs"][0]["curve"][-1][0] >= 0.3


def test_pass_cost_recovers_fixed_and_per_photon_seconds():
    """Two pass sizes fix ``seconds = c0 + c1 N``."""
    import psurf_core.pass_size as ps

    c0, c1 = 0.01, 5e-5
    sizes = (128, 1024)
    got = ps.pass_cost(sizes, [c0 + c1 * n for n in sizes])
    np.testing.assert_allclose(got, (c0, c1), rtol=1e-9)


def test_split_terms_recover_pixel_and_photon_variance():
    """Split passes (one jitter, two photon halves of ``n``), simulated: the halves'
    difference gives ``Vp``, their mean's variance less ``Vp / 2n`` gives ``Vj``, within
    the sampling error of 2000 pixels x 10 passes (a ``Vp / n`` in place of ``Vp / 2n``
    misses ``Vj`` by 60 %)."""
    import psurf_core.pass_size as ps

    rng = np.random.default_rng(3)
    vj, vp, n, m, pixels = 1.5e-7, 3.5e-4, 1024, 10, 2000
    jitter = rng.normal(0.0, np.sqrt(vj), (m, pixels))
    a, b = (jitter + rng.normal(0.0, np.sqrt(vp / n), (m, pixels)) for _ in range(2))
    mean_variance = float(np.mean(np.var(0.5 * (a + b), axis=0, ddof=1)))
    half_difference = float(np.mean(0.5 * (a - b) ** 2))
    got_vj, got_vp = ps.split_terms(n, mean_variance, half_difference)
    assert abs(got_vp / vp - 1.0) < 0.05
    assert abs(got_vj / vj - 1.0) < 0.15
    assert ps.split_terms(n, 0.0, 1e-9) == (0.0, 1e-9 * n)  # Vj clipped at 0


def test_split_photons_shrink_the_halves_of_slow_estimators():
    """A split pass's halves are ``PILOT_PHOTONS[1]`` photons, fewer where two of them would
    take more than ``SPLIT_PASS_SECONDS``, never under ``PHOTON_RANGE[0]``."""
    import psurf_core.pass_size as ps

    assert ps.split_photons(0.004, 12e-6) == ps.PILOT_PHOTONS[1]  # fast-multi, study_medium
    n = ps.split_photons(0.02, 7.7e-4)  # paper-full, showcase
    assert ps.PHOTON_RANGE[0] <= n < ps.PILOT_PHOTONS[1]
    assert 2 * (0.02 + 7.7e-4 * n) <= ps.SPLIT_PASS_SECONDS * 1.001
    assert ps.split_photons(1.0, 1e-3) == ps.PHOTON_RANGE[0]


def test_split_variances_share_the_rays_between_halves(monkeypatch):
    """The two halves of a split pass see the same camera rays: an estimate that depends on
    the rays alone reads as pixel variance (``Vp`` ~0), one that depends on the photons
    alone as photon variance (``Vj`` ~0)."""
    import psurf_core.pass_size as ps

    scene = load_scene(Path(__file__).resolve().parent.parent / "scenes" / "area.toml")
    scene = replace(scene, camera=replace(scene.camera, width=16, height=12))
    est = parse_estimator("planes", scene)
    st = RenderSettings(photons=64)

    def by_rays(scene, est, rays, ss, *a):
        return np.repeat(rays.d[:, :1] * 64.0, 3, axis=1)

    def by_photons(scene, est, rays, ss, *a):
        return np.random.default_rng(ss).normal(size=(len(rays), 3)) * 64.0

    monkeypatch.setattr(ps, "photon_pass", by_rays)
    vj, vp = ps.split_variances(scene, est, st)
    assert vj > 1e-6 and vp < 1e-20
    monkeypatch.setattr(ps, "photon_pass", by_photons)
    vj, vp = ps.split_variances(scene, est, st)
    assert vp == pytest.approx(64.0, rel=0.1) and vj < 0.05 * vp / 64


def test_compare_records_the_pilots_pass_model(tiny, monkeypatch):
    """An ``auto`` estimator's result keeps what its pilot measured and chose
    (``pass_model``, also handed to ``on_pilot``); an estimator given a count has none."""
    import psurf_core.pass_size as ps

    monkeypatch.setattr(ps, "pilot", lambda *a: (0.01, 5e-5, 4e-6, 3e-4))
    _, scene = tiny
    seen = []
    s = compare(scene, ["planes", "points"], 0.2, runs=1, seed=3, photons=["auto", 150],
                reference_seconds=0.2, on_pilot=lambda spec, m: seen.append((spec, m)))
    auto, given = s["results"]
    # Said as the pilot starts, then with what it chose (the CLI prints one line from both).
    assert seen == [("planes", None), ("planes", auto["pass_model"])]
    assert auto["pass_model"]["photons"] == auto["photons_per_pass"] == \
        ps.best_photons(0.01, 5e-5, 4e-6, 3e-4, 0.2)
    assert (auto["pass_model"]["c0"], auto["pass_model"]["vp"]) == (0.01, 3e-4)
    assert auto["pass_model"]["pilot_seconds"] >= 0.0
    assert given["pass_model"] is None and given["photons_per_pass"] == 150
    from psurf_core.study_report import to_json

    assert json.loads(json.dumps(to_json(s), allow_nan=False))["results"][0]["pass_model"] == \
        auto["pass_model"]


def test_best_photons_minimises_the_equal_time_variance():
    """``N* = sqrt(Vp c0 / (Vj c1))`` beats its neighbours; clipped to PHOTON_RANGE."""
    import psurf_core.pass_size as ps

    c0, c1, vj, vp = 0.01, 5e-5, 4e-6, 3e-4
    n = ps.best_photons(c0, c1, vj, vp, 1e6)
    assert n == int(np.sqrt(vp * c0 / (vj * c1)))

    def cost(m):
        return (vj + vp / m) * (c0 + c1 * m)

    assert cost(n) <= min(cost(n // 2), cost(2 * n))
    # No pixel term: photons up to OVERHEAD_CAP times the fixed part, or what leaves
    # MIN_PASSES passes in a short budget.
    assert ps.best_photons(c0, c1, 0.0, vp, 1e6) == int(ps.OVERHEAD_CAP * c0 / c1)
    budget = 2.4  # 0.05 s a pass at MIN_PASSES = 48
    assert ps.best_photons(c0, c1, 0.0, vp, budget) == int((budget / ps.MIN_PASSES - c0) / c1)
    assert ps.best_photons(1.0, 1e-12, 0.0, vp, 1e9) == ps.PHOTON_RANGE[1]
    assert ps.best_photons(c0, c1, vj, 1e-300, budget) == ps.PHOTON_RANGE[0]


def test_auto_photons_pilots_the_estimator(monkeypatch):
    """``--photons auto`` measures the estimator's pass model on pilot passes (a real
    render: the numbers it returns are finite and ordered) and keeps the path tracer's
    settings."""
    import psurf_core.pass_size as ps

    scene = load_scene(Path(__file__).resolve().parent.parent / "scenes" / "area.toml")
    scene = replace(scene, camera=replace(scene.camera, width=16, height=12))
    est = parse_estimator("planes", scene)
    c0, c1, vj, vp = ps.pilot(scene, est, RenderSettings(photons=7))
    assert c0 >= 0 and c1 > 0 and vj >= 0 and vp > 0
    seen = []
    monkeypatch.setattr(ps, "pilot", lambda *a: seen.append(a) or (0.01, 5e-5, 4e-6, 3e-4))
    assert ps.auto_photons(scene, est, RenderSettings(photons=7), 1e6) == 122
    assert len(seen) == 1
    ref = parse_estimator("reference", scene)
    assert ps.auto_photons(scene, ref, RenderSettings(photons=7), 48.0) == 7


def test_r2_sampler_compares_the_runs_images(tiny):
    """With the r2 pixel sampler a run's passes are not independent: Var is the variance
    across the runs' images (``image_variance`` = ``run_variance``); with one run it can only
    be the per-pass ``mean_variance``, which overstates it, and a warning says so. With
    independent passes it stays the per-pass ``mean_variance``."""
    _, scene = tiny
    kw = dict(runs=2, seed=5, photons=[300, 300], reference_seconds=0.3)
    r2_settings = RenderSettings(photons=300, pixel_sampler="r2")
    r2 = compare(scene, ["planes", "points"], 0.3, settings=r2_settings, **kw)
    assert r2["pixel_sampler"] == "r2"
    assert not any("pixel sampler" in w for w in r2["warnings"])
    one = compare(scene, ["planes"], 0.2, settings=r2_settings,
                  **{**kw, "runs": 1, "photons": [300]})
    assert any("pixel sampler 'r2', photon sampler 'independent' with one run" in w
               for w in one["warnings"])
    assert one["results"][0]["image_variance"] == one["results"][0]["mean_variance"]
    a, b = r2["results"]
    assert a["image_variance"] == a["run_variance"] != a["mean_variance"]
    assert b["ratio"] == pytest.approx(b["run_variance"] / a["run_variance"])
    # relVar likewise: the runs' images, not the per-pass variance.
    assert a["relmse_from_variance"] == a["run_relmse_from_variance"]
    per_pass = np.mean([x["relmse_from_variance"] for x in a["runs"]])
    assert a["relmse_from_variance"] != pytest.approx(per_pass, rel=1e-9)
    ind = compare(scene, ["planes", "points"], 0.3, settings=RenderSettings(photons=300), **kw)
    a, b = ind["results"]
    assert a["image_variance"] == a["mean_variance"]
    assert b["ratio"] == pytest.approx(b["mean_variance"] / a["mean_variance"])
    assert a["relmse_from_variance"] == pytest.approx(
        np.mean([x["relmse_from_variance"] for x in a["runs"]]))
    assert not any("pixel sampler" in w for w in ind["warnings"])


def test_sobol_seq_photons_compare_the_runs_images(tiny):
    """One Sobol sequence over a run's passes (``sobol-seq``) makes them dependent as r2 does:
    with independent pixel points, Var and relVar are still taken across the runs' images,
    and one run warns."""
    _, scene = tiny
    kw = dict(runs=2, seed=5, photons=[300, 300], reference_seconds=0.3)
    seq = RenderSettings(photons=300, photon_sampler="sobol-seq")
    assert not seq.independent_passes and RenderSettings(photon_sampler="sobol").independent_passes
    out = compare(scene, ["planes", "points"], 0.3, settings=seq, **kw)
    assert out["photon_sampler"] == "sobol-seq"
    a, b = out["results"]
    assert a["image_variance"] == a["run_variance"] != a["mean_variance"]
    assert b["ratio"] == pytest.approx(b["run_variance"] / a["run_variance"])
    assert b["relmse_from_variance"] == b["run_relmse_from_variance"]
    one = compare(scene, ["planes"], 0.2, settings=seq, **{**kw, "runs": 1, "photons": [300]})
    assert any("photon sampler 'sobol-seq' with one run" in w for w in one["warnings"])
    assert one["results"][0]["image_variance"] == one["results"][0]["mean_variance"]
