"""The pass moments behind a render's error estimate and the heavy-tail check built on them.

* :class:`~psurf_core.accumulate.Welford` keeps ``m3``, ``m4`` and the peak pass exactly
  (against direct sums), merges them exactly (Pébay) and leaves ``mean`` and ``m2``
  bit-identical to an accumulator without them.
* :mod:`psurf_core.reliability` flags heavy-tailed pixels and not normal ones, with the
  numbers its docstring promises (skewness of the mean ``1 / sqrt(events)`` for rare events).
* ``compare`` warns (``study["warnings"]``, compare.md, stderr) when the reference it is given
  has such pixels, and says so when it cannot check (an .npz without the moments).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from app_support import run_app
from tiny_scene import TINY

from psurf_core import reliability as rl
from psurf_core.accumulate import Welford
from psurf_core.render import RenderResult
from psurf_core.scene import SceneError
from psurf_core.study import compare, load_reference, write_outputs

ROOT = Path(__file__).resolve().parent.parent
SHAPE = (3, 4, 3)



def _fed(xs, tails=True) -> Welford:
    acc = Welford.empty(xs.shape[1:])
    if not tails:
        acc = Welford(0, np.zeros(xs.shape[1:]), np.zeros(xs.shape[1:]))
    for x in xs:
        acc.add(x)
    return acc


# --------------------------------------------------------------------------- accumulator
def test_higher_moments_match_direct_sums():
    xs = np.random.default_rng(3).lognormal(0.0, 1.5, size=(40, *SHAPE))
    acc = _fed(xs)
    d = xs - xs.mean(axis=0)
    np.testing.assert_allclose(acc.m3, (d**3).sum(axis=0), rtol=1e-9)
    np.testing.assert_allclose(acc.m4, (d**4).sum(axis=0), rtol=1e-9)
    np.testing.assert_array_equal(acc.peak, xs.max(axis=0))
    assert Welford.empty(SHAPE).peak.max() == -np.inf


@pytest.mark.parametrize("split", [0, 1, 7, 29, 30])
def test_merge_with_the_new_fields_equals_sequential(split):
    """Any split (an empty side included) merges to the sequential accumulator: mean, m2,
    m3, m4 to rounding, the peak exactly; unknown higher moments stay unknown."""
    xs = np.random.default_rng(4).pareto(2.5, size=(30, *SHAPE))  # heavy-tailed passes
    seq = _fed(xs)
    a, b = _fed(xs[:split]), _fed(xs[split:])
    a.merge(b)
    assert a.n == seq.n == 30 and a.has_tails
    for k in ("mean", "m2", "m3", "m4"):
        np.testing.assert_allclose(getattr(a, k), getattr(seq, k), rtol=1e-11, atol=1e-12)
    np.testing.assert_array_equal(a.peak, seq.peak)
    # Merging is associative to rounding: three pieces in pass order.
    c, d, e = _fed(xs[:10]), _fed(xs[10:11]), _fed(xs[11:])
    c.merge(d)
    c.merge(e)
    np.testing.assert_allclose(c.m4, seq.m4, rtol=1e-11)
    legacy = _fed(xs[:split], tails=False)
    legacy.merge(_fed(xs[split:]))
    if split:
        assert not legacy.has_tails and legacy.m3 is None and legacy.peak is None
    np.testing.assert_allclose(legacy.m2, seq.m2, rtol=1e-11)


def test_new_fields_leave_mean_and_m2_bit_identical():
    """The higher-moment update changes no operation of mean and m2: a checkpoint written
    before they were kept resumes to the same bits."""
    xs = np.random.default_rng(5).normal(size=(25, *SHAPE))
    new, old = _fed(xs), _fed(xs, tails=False)
    assert not old.has_tails and new.has_tails
    np.testing.assert_array_equal(new.mean, old.mean)
    np.testing.assert_array_equal(new.m2, old.m2)
    # copy() is deep
    c = new.copy()
    c.add(xs[0])
    assert c.n == new.n + 1 and not np.array_equal(c.m3, new.m3)


# --------------------------------------------------------------------------- the check
def _rel(xs):
    acc = _fed(xs)
    return rl.of_accumulator(acc)


def test_normal_passes_are_reliable_heavy_tails_are_not():
    rng = np.random.default_rng(6)
    normal = _rel(rng.normal(5.0, 1.0, size=(400, *SHAPE)))
    assert not normal.unreliable.any() and normal.varies.all()
    assert normal.skew_of_mean.max() < 0.1
    # Effective passes of normal passes: about n (the sample kurtosis is noisy: +-25 %).
    assert np.all(np.abs(normal.effective_passes / 400 - 1) < 0.5)
    # Rare huge passes: 1 in 200 is 500 times the rest.
    rare = np.where(rng.random((400, *SHAPE)) < 1 / 200, 500.0, 1.0)
    heavy = _rel(rare)
    assert heavy.unreliable.mean() > 0.9
    summary = rl.summarize(heavy, "the test image")
    assert summary["warn"] and summary["unreliable"] == int(heavy.unreliable.sum())
    assert "render it longer" in summary["message"].lower()
    assert "the test image" in summary["message"]
    assert not rl.summarize(normal)["warn"]


def test_heavy_tail_note_names_the_worst_run_only_past_the_threshold():
    """``compare``'s note on an estimator whose own passes are heavy-tailed (photon planes at
    K >= 2: 6.6 % of study_medium's pixels in a 15 s render): the worst flagged run, how many
    runs were flagged; nothing at or below ``WARN_FRACTION`` or when unchecked."""
    w = rl.WARN_FRACTION
    assert rl.heavy_tail_note([0.0, w, None]) is None
    assert rl.heavy_tail_note([]) is None
    note = rl.heavy_tail_note([0.01, 0.066, w + 0.001])
    assert note is not None
    assert "6.6% of the pixels of run 2" in note and "2 of 3 runs" in note
    assert "in its favour" in note


@pytest.mark.parametrize("events", [1, 2, 16, 64])
def test_skew_of_mean_counts_the_rare_events(events):
    """``events`` passes of value 1000 among 20000 zeros-or-ones: the skewness of the mean is
    about ``1 / sqrt(events)`` and the effective passes about ``1 + 2 events``, so the check
    trusts a pixel once it has seen its rare passes a few times, not before."""
    n = 20000
    x = np.ones(n)
    x[np.linspace(0, n - 1, events).astype(int)] = 1000.0
    rel = rl.pixel_reliability(n, *(_moments(x)))
    skew, neff = float(rel.skew_of_mean[0, 0]), float(rel.effective_passes[0, 0])
    assert skew == pytest.approx(1 / np.sqrt(events), rel=0.1)
    assert neff == pytest.approx(1 + 2 * events, rel=0.1)
    assert bool(rel.unreliable[0, 0]) == (events <= 2)


def _moments(x):
    """mean, m2, m3, m4 and peak of one pixel's passes, shaped (1, 1, 1)."""
    m = x.mean()
    d = x - m
    return [np.full((1, 1, 1), v) for v in (m, (d**2).sum(), (d**3).sum(), (d**4).sum(),
                                            x.max())]


def test_constant_and_single_pass_pixels():
    xs = np.zeros((10, *SHAPE))
    xs[:, 0, 0] = 2.0  # constant: zero variance, nothing to judge
    rel = _rel(xs)
    assert not rel.varies.any() and not rel.unreliable.any()
    one = _rel(np.ones((1, *SHAPE)))
    assert one.unreliable.all()  # one pass: no error estimate at all
    with pytest.raises(ValueError):
        rl.pixel_reliability(0, *np.zeros((4, *SHAPE)))


def test_npz_fields_round_trip_and_old_files():
    xs = np.random.default_rng(7).lognormal(size=(12, *SHAPE))
    acc = _fed(xs)
    data = {"mean": acc.mean.astype(np.float32), "passes": np.int64(acc.n),
            **rl.npz_fields(acc)}
    a, b = rl.from_npz(data), rl.of_accumulator(acc)
    np.testing.assert_allclose(a.skew_of_mean, b.skew_of_mean, rtol=1e-5)
    assert rl.from_npz({"mean": data["mean"], "passes": data["passes"]}) is None
    assert rl.npz_fields(_fed(xs, tails=False)) == {}
    assert not rl.summarize(None)["checked"] and rl.summarize(None)["warn"]


# --------------------------------------------------------------------------- compare
@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    from psurf_core import load_scene

    d = tmp_path_factory.mktemp("reliab")
    (d / "tiny.toml").write_text(TINY)
    return d, load_scene(str(d / "tiny.toml"))


def _reference_npz(path, scene, passes, tails=True):
    """An .npz as ``app.py render`` writes it, from synthetic passes (``passes`` (n, H, W, 3))."""
    acc = _fed(passes)
    data = {"mean": acc.mean.astype(np.float32), "var": acc.variance.astype(np.float32),
            "passes": np.int64(acc.n), "estimator": np.str_("reference"),
            "min_scatter": np.int64(scene.min_scatter),
            "max_scatter": np.int64(scene.max_scatter)}
    if tails:
        data.update(rl.npz_fields(acc))
    np.savez(path, **data)
    return acc


def _fake_runner(scene, est, settings, *, time_budget=None, seed=0, on_pass=None,
                 passes=None):
    """Three passes of a smooth image (the estimators are not what is tested here)."""
    cam = scene.camera
    acc = Welford.empty((cam.height, cam.width, 3))
    rng = np.random.default_rng(seed)
    for i in range(3):
        acc.add(1.0 + 0.01 * rng.normal(size=acc.mean.shape))
        if on_pass is not None:
            on_pass(i, acc, 0.1 * (i + 1))
    return RenderResult(acc.mean.copy(), acc.variance, acc.n, settings.photons, settings.spp,
                        0.3, est.spec, seed, acc)


def test_compare_warns_about_a_heavy_tailed_reference(tiny, tmp_path):
    d, scene = tiny
    h, w = scene.camera.height, scene.camera.width
    rng = np.random.default_rng(8)
    # 300 passes, one in 150 is 400 times the rest: the rare passes of most pixels are few.
    heavy = np.where(rng.random((300, h, w, 3)) < 1 / 150, 400.0, 1.0)
    heavy[..., 1:] = heavy[..., :1]
    _reference_npz(tmp_path / "heavy.npz", scene, heavy)
    ref = load_reference(str(tmp_path / "heavy.npz"), scene)
    assert ref.moments is not None
    s = compare(scene, ["planes"], 0.1, reference=ref, runner=_fake_runner)
    rel = s["reference"]["reliability"]
    expected = int(rl.from_npz({**ref.moments, "mean": ref.mean, "passes": 300})
                   .unreliable.sum())
    assert rel["checked"] and rel["warn"] and rel["unreliable"] == expected
    # Pixels that never saw a rare pass are constant: nothing to judge (not counted).
    assert rel["pixels"] < h * w and expected > 0.5 * rel["pixels"]
    assert len(s["warnings"]) == 1
    assert f"{expected} of {rel['pixels']} pixels" in s["warnings"][0]
    assert "heavy.npz" in s["warnings"][0]
    out = tmp_path / "out"
    out.mkdir()
    write_outputs(str(out), s)
    assert "Warnings:" in (out / "compare.md").read_text()
    assert json.loads((out / "compare.json").read_text())["warnings"] == s["warnings"]

    # A light-tailed reference of the same size: checked, no warning.
    light = 1.0 + 0.1 * rng.normal(size=(300, h, w, 3))
    _reference_npz(tmp_path / "light.npz", scene, light)
    s = compare(scene, ["planes"], 0.1, reference=str(tmp_path / "light.npz"),
                runner=_fake_runner)
    assert s["reference"]["reliability"]["checked"] and s["warnings"] == []
    assert s["reference"]["reliability"]["unreliable"] == 0

    # An older file without the moments still loads: the check says it could not be made.
    _reference_npz(tmp_path / "old.npz", scene, light, tails=False)
    s = compare(scene, ["planes"], 0.1, reference=str(tmp_path / "old.npz"),
                runner=_fake_runner)
    rel = s["reference"]["reliability"]
    assert not rel["checked"] and "could not be checked" in s["warnings"][0]

    # A rendered reference records its own check.
    s = compare(scene, ["planes"], 0.1, runner=_fake_runner, reference_seconds=0.1)
    assert s["reference"]["reliability"]["checked"]
    with np.load(tmp_path / "heavy.npz") as z:
        bad = {k: z[k] for k in z.files}
    bad["m3"] = bad["m3"][:1]
    np.savez(tmp_path / "bad.npz", **bad)
    with pytest.raises(SceneError, match="pass moments m3"):
        load_reference(str(tmp_path / "bad.npz"), scene)


def test_compare_cli_prints_the_warning(tiny, tmp_path):
    d, scene = tiny
    h, w = scene.camera.height, scene.camera.width
    rng = np.random.default_rng(9)
    heavy = np.where(rng.random((200, h, w, 3)) < 1 / 100, 300.0, 1.0)
    _reference_npz(tmp_path / "heavy.npz", scene, heavy)
    argv = ["compare", d / "tiny.toml", "--estimators", "planes", "--time", "0.5",
            "--photons", "200", "--reference", tmp_path / "heavy.npz", "--out", tmp_path / "cli"]
    r = run_app(*argv, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    # (one run with compare's default r2 sampler adds its own warning: see test_compare)
    warn = [ln for ln in r.stderr.splitlines()
            if ln.startswith("psurf: warning: ") and "pixel sampler" not in ln]
    assert len(warn) == 1 and "unreliable error estimates" in warn[0], r.stderr
    assert "render it longer" in warn[0].lower()
