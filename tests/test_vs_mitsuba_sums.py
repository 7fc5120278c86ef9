"""The image-sum z of ``benchmarks/vs_mitsuba.py`` (``score``'s ``sum_z``) and the per-pass
image-sum variances it needs: stored by Mitsuba's renders (``mitsuba_scene``), loaded with
psurf's (``mitsuba_renders.psurf_render``) and summed over a reference's parts.

The renders here are built by hand with correlated pixels (a common factor per pass, as one
photon's surface reaching many pixels gives): two unbiased renders whose image sums agree
within their real standard error, where the independent-pixel formula calls them far apart.
"""

from __future__ import annotations

import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import mitsuba_renders as mr  # noqa: E402
import mitsuba_scene as ms  # noqa: E402
import vs_mitsuba  # noqa: E402

H, W = 12, 16


def _passes(n: int, seed: int) -> np.ndarray:
    """(n, H, W, 3) passes of one unbiased estimator (expected image ``pattern``): a common
    factor per pass (mean 1) times the pattern, plus a little independent pixel noise."""
    pattern = np.linspace(0.5, 1.5, H * W * 3).reshape(H, W, 3)
    rng = np.random.default_rng(seed)
    common = rng.gamma(4.0, 0.25, size=(n, 1, 1, 1))
    return common * pattern + 0.02 * rng.normal(size=(n, H, W, 3))


def _render(xs: np.ndarray, sums: bool = True) -> dict:
    """A render dict as ``psurf_render`` / ``mitsuba_render`` return it."""
    d = {"mean": xs.mean(axis=0), "var": xs.var(axis=0, ddof=1), "passes": len(xs)}
    if sums:
        d["sum_var"] = np.var(xs.sum(axis=(1, 2)), axis=0, ddof=1)
    return d


def _reference(xs: np.ndarray, sums: bool = True) -> dict:
    """A reference dict as ``mitsuba_renders.reference`` returns it."""
    n = len(xs)
    d = {"mean": xs.mean(axis=0), "var_mean": xs.var(axis=0, ddof=1) / n}
    if sums:
        d["sum_var_mean"] = np.var(xs.sum(axis=(1, 2)), axis=0, ddof=1) / n
    return d


def test_sum_z_uses_the_per_pass_sums():
    img, ref = _passes(40, seed=1), _passes(400, seed=2)
    new = vs_mitsuba.score(_render(img), _reference(ref))
    old = vs_mitsuba.score(_render(img, sums=False), _reference(ref, sums=False))
    assert new["sum_z_method"] == vs_mitsuba.PER_PASS_SUMS == "per-pass sums"
    assert old["sum_z_method"] == vs_mitsuba.INDEPENDENT_PIXELS == "independent pixels"
    # The z from the passes' own sums, computed here directly.
    s_img, s_ref = img.sum(axis=(1, 2)), ref.sum(axis=(1, 2))
    se = np.sqrt(s_img.var(axis=0, ddof=1) / 40 + s_ref.var(axis=0, ddof=1) / 400)
    np.testing.assert_allclose(new["sum_z"], (s_img.mean(0) - s_ref.mean(0)) / se, rtol=1e-9)
    # Both renders are unbiased: a small |z| from the sums, a large one as if independent.
    assert max(map(abs, new["sum_z"])) < 2.0
    assert min(map(abs, old["sum_z"])) > 8.0
    # One side without its sums is the old formula, said so.
    half = vs_mitsuba.score(_render(img), _reference(ref, sums=False))
    assert half["sum_z"] == old["sum_z"] and half["sum_z_method"] == "independent pixels"
    few = vs_mitsuba.score(_render(img[:vs_mitsuba.MIN_PASSES_FOR_Z - 1]), _reference(ref))
    assert few["sum_z"] is None and few["sum_z_method"] is None


def test_the_table_stars_an_independent_pixel_z():
    img, ref = _passes(40, seed=1), _passes(400, seed=2)
    row = {"case": "c", "min_scatter": 2, "max_scatter": 3, "estimator": "planes",
           "relmse_ratio": 1.0, "relmse_above_floor_ratio": None, "var_ratio": 1.0,
           "relvar_ratio_time_normalized": None, "reference": {"relmse_floor": 1e-4}}
    sides = {k: {"seconds": 1.0, "passes": 40, "spp": 1} for k in ("psurf", "mitsuba")}
    new = vs_mitsuba.score(_render(img), _reference(ref))
    old = vs_mitsuba.score(_render(img, sums=False), _reference(ref))
    table = vs_mitsuba.markdown([row | {"psurf": sides["psurf"] | new,
                                        "mitsuba": sides["mitsuba"] | old}])
    z_new, z_old = (max(x["sum_z"], key=abs) for x in (new, old))
    assert f"| {z_new:.1f}, {z_old:.1f}\\* |" in table
    assert "\\* sum z from per-pixel variances" in table
    alone = vs_mitsuba.markdown([row | {"psurf": sides["psurf"] | new,
                                        "mitsuba": sides["mitsuba"] | new}])
    assert "\\*" not in alone


def test_mitsuba_render_keeps_the_variance_of_its_pass_sums(tmp_path):
    """``MitsubaRenderer.render`` (its pass images faked here: no Mitsuba needed) stores the
    sample variance of the passes' image sums, and ``save_npz`` writes it."""
    xs = _passes(9, seed=3)
    r = object.__new__(ms.MitsubaRenderer)
    r.spp, r.variant = 4, "fake"
    frames = iter(xs)
    r.pass_image = lambda seed: next(frames).copy()
    got = r.render(passes=9, warmup=False)
    np.testing.assert_allclose(got.sum_var, np.var(xs.sum(axis=(1, 2)), axis=0, ddof=1),
                               rtol=1e-10)
    np.testing.assert_allclose(got.var, xs.var(axis=0, ddof=1), rtol=1e-10)
    scene = SimpleNamespace(min_scatter=1, max_scatter=1)
    ms.save_npz(tmp_path / "m.npz", got, scene, 0)
    d = mr.load_npz(tmp_path / "m.npz")
    np.testing.assert_array_equal(d["sum_var"], got.sum_var)


def _npz(path, xs, sums=True, kmin=1, kmax=1):
    r = _render(xs, sums)
    extra = {"sum_var": r["sum_var"]} if sums else {}
    np.savez(path, mean=r["mean"], var=r["var"], passes=np.int64(len(xs)), spp=np.int64(1),
             seconds=np.float64(2.0), photons_per_pass=np.int64(10), min_scatter=np.int64(kmin),
             max_scatter=np.int64(kmax), estimator=np.str_("planes"), **extra)
    return r


@pytest.mark.parametrize("sums", [True, False])
def test_reference_sums_its_parts_sum_variances(tmp_path, monkeypatch, sums):
    """A composite reference's image-sum variance is the sum of its parts' ``sum_var /
    passes`` (independent renders), written to the summed file too; a part without its
    sums (cached before they were kept) leaves it unknown."""
    parts = {"mitsuba": _passes(10, seed=4), "planes": _passes(40, seed=5)}

    def fake_part(renderer, case, sc, path, a, b, args):
        p = tmp_path / f"{renderer}.npz"
        _npz(p, parts[renderer], sums=sums or renderer == "planes", kmin=a, kmax=b)
        return mr.load_npz(p) | {"path": str(p), "render_seconds": None}

    monkeypatch.setattr(mr, "render_part", fake_part)
    args = SimpleNamespace(reference="composite", work=str(tmp_path), ref_time=7.0)
    ref = mr.reference("c", None, "x.toml", 1, -1, args)
    summed = mr.reference_from_file(ref["file"], 1, -1)
    if not sums:
        assert ref["sum_var_mean"] is None and summed["sum_var_mean"] is None
        return
    want = sum(np.var(x.sum(axis=(1, 2)), axis=0, ddof=1) / len(x) for x in parts.values())
    np.testing.assert_allclose(ref["sum_var_mean"], want, rtol=1e-10)
    np.testing.assert_allclose(summed["sum_var_mean"], want, rtol=1e-10)  # passes = 1 there


def test_psurf_render_and_reference_file_read_sum_var(tmp_path, monkeypatch):
    """``psurf_render`` loads ``sum_var`` from ``app.py render``'s .npz (``None`` from an
    older file); ``reference_from_file`` divides it by the passes."""
    xs = _passes(8, seed=6)

    def fake_run(cmd, **kw):  # app.py render, faked: writes its --out
        _npz(cmd[cmd.index("--out") + 1], xs, sums=fake_run.sums, kmin=2, kmax=3)

    monkeypatch.setattr(mr.subprocess, "run", fake_run)
    for fake_run.sums in (True, False):
        d = mr.psurf_render("x.toml", 2, 3, "planes", None, 0, 1, 10, tmp_path / "p.npz",
                            passes=8)
        if fake_run.sums:
            np.testing.assert_allclose(d["sum_var"], _render(xs)["sum_var"], rtol=1e-12)
            ref = mr.reference_from_file(tmp_path / "p.npz", 2, 3)
            np.testing.assert_allclose(ref["sum_var_mean"], d["sum_var"] / 8, rtol=1e-12)
        else:
            assert d["sum_var"] is None
            assert mr.reference_from_file(tmp_path / "p.npz", 2, 3)["sum_var_mean"] is None
