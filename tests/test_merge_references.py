"""benchmarks/merge_references.py: two references of other seeds pool into the reference of
all their passes (mean, per-pass variance and higher moments as one accumulator over every
pass image gives them); files that are not the same render's passes are refused."""

from __future__ import annotations

import numpy as np
import pytest
from app_support import run_app
from benchmark_support import run_benchmark
from tiny_scene import TINY

from psurf_core.accumulate import Welford
from psurf_core.estimators import parse_estimator
from psurf_core.render import RenderSettings, render_pass
from psurf_core.scene_io import load_scene

PHOTONS = 120


def _render(scene_path, out, seed, passes, photons=PHOTONS):
    run_app("render", scene_path, "--estimator", "planes", "--photons", photons, "--passes",
            passes, "--seed", seed, "--out", out, check=True)


def _merge(*args):
    return run_benchmark("merge_references", *args, check=False)


@pytest.fixture(scope="module")
def refs(tmp_path_factory):
    d = tmp_path_factory.mktemp("refs")
    scene = d / "tiny.toml"
    scene.write_text(TINY + "\n[render]\nmin_scatter = 2\nmax_scatter = 2\n")
    _render(scene, d / "a.npz", 3, 3)
    _render(scene, d / "b.npz", 4, 4)
    return d, scene


def test_merged_reference_is_the_accumulator_of_every_pass(refs):
    d, scene_path = refs
    r = _merge(d / "a.npz", d / "b.npz", "--out", d / "ab.npz")
    assert r.returncode == 0, r.stderr
    m = np.load(d / "ab.npz")
    scene = load_scene(str(scene_path))
    est = parse_estimator("planes", scene)
    st = RenderSettings(photons=PHOTONS)
    acc = Welford.empty(m["mean"].shape)
    for seed, passes in ((3, 3), (4, 4)):
        for i in range(passes):
            acc.add(render_pass(scene, est, i, seed, st))
    assert int(m["passes"]) == 7 and list(m["seeds"]) == [3, 4]
    scale = np.abs(acc.mean).max()
    assert np.allclose(m["mean"], acc.mean, rtol=1e-6, atol=1e-6 * scale)
    for k in ("m2", "m3", "m4"):
        ref = getattr(acc, k)
        assert np.allclose(m[k], ref, rtol=1e-4, atol=1e-5 * np.abs(ref).max()), k
    assert np.array_equal(m["peak"], acc.peak)
    assert np.allclose(m["sum_var"], acc.sum_variance, rtol=1e-4)


def test_same_seed_or_other_pass_size_is_refused(refs):
    d, scene_path = refs
    r = _merge(d / "a.npz", d / "a.npz", "--out", d / "aa.npz")
    assert r.returncode == 2 and "seed 3 twice" in r.stderr and not (d / "aa.npz").exists()
    _render(scene_path, d / "c.npz", 5, 2, photons=PHOTONS + 1)
    r = _merge(d / "a.npz", d / "c.npz", "--out", d / "ac.npz")
    assert r.returncode == 2 and "photons_per_pass 121" in r.stderr
    assert "Traceback" not in r.stderr and not (d / "ac.npz").exists()
