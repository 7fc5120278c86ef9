"""Per-technique / per-scatter-count breakdowns (``psurf_core.breakdown``).

Exact identities (the breakdown re-sums to the pass image; weight maps are shares) on single
passes, and one statistical check with bounds that a wrong factor fails: a technique's
*unweighted* K = 2 image estimates the same K = 2 image as the MIS combination.
"""

from __future__ import annotations

import numpy as np
import pytest

from psurf_core.breakdown import (
    BreakdownAccumulator,
    BreakdownLayout,
    render_pass_breakdown,
    weight_maps,
)
from psurf_core.estimators import parse_estimator
from psurf_core.render import RenderSettings, render_pass
from psurf_core.scene_io import load_scene

SCENES = "scenes"


@pytest.fixture(scope="module")
def point3():
    return load_scene(f"{SCENES}/point.toml").with_scatter(max_scatter=3)


@pytest.fixture(scope="module")
def mis_pass(point3):
    est = parse_estimator("mis:plane-t1t2+plane-t1t3+sphere", point3)
    st = RenderSettings(photons=120, spp=2)
    img, b = render_pass_breakdown(point3, est, 3, 11, st)
    return est, st, img, b


def test_pass_image_is_render_pass(point3, mis_pass):
    est, st, img, _ = mis_pass
    assert np.array_equal(img, render_pass(point3, est, 3, 11, st))


def test_techniques_and_bins_sum_to_the_pass_image(mis_pass):
    _, _, img, b = mis_pass
    assert b.weighted.shape == (3, 2, 48, 64, 3)
    assert img.max() > 0
    scale = np.abs(img).max()
    by_tech = b.weighted.sum(axis=1).sum(axis=0)
    by_k = b.weighted.sum(axis=0).sum(axis=0)
    assert np.abs(by_tech - img).max() <= 1e-12 * scale
    assert np.abs(by_k - img).max() <= 1e-12 * scale
    # plane-t1t3 produces K >= 3 only: its K = 2 bin is empty, its K = 3 bin is not
    assert not b.unweighted[1, 0].any() and b.unweighted[1, 1].any()
    # MIS weights are at most 1: weighted <= unweighted, hit by hit and so pixel by pixel
    assert np.all(b.weighted <= b.unweighted + 1e-15 * scale)


def test_layout_bins(point3):
    est = parse_estimator("mis:plane-t1t2+plane-t1t3+sphere", point3)
    lay = BreakdownLayout.of(point3, est)
    assert (lay.k_min, lay.k_max, lay.labels) == (2, 3, ("K=2", "K=3"))
    open_scene = load_scene(f"{SCENES}/point.toml")
    lay = BreakdownLayout.of(open_scene, est, k_max=4)
    assert lay.labels == ("K=2", "K=3", "K>=4")
    assert lay.k_bin(7) == 2
    with pytest.raises(ValueError):
        lay.k_bin(1)


def test_weight_maps_are_shares(mis_pass):
    _, _, img, b = mis_pass
    w = weight_maps(b.weighted.sum(axis=1))
    assert w.shape == (3, 48, 64)
    assert np.all(np.isfinite(w)) and w.min() >= 0 and w.max() <= 1 + 1e-12
    lit = (img @ [0.2126, 0.7152, 0.0722]) > 0
    assert lit.sum() > 100
    assert np.allclose(w.sum(axis=0)[lit], 1.0, atol=1e-12)
    assert not w.sum(axis=0)[~lit].any()
    assert w[0].max() > 0.5 and w[2].max() > 0.5  # both K=2 techniques win somewhere


def test_single_technique_weight_is_one(point3):
    est = parse_estimator("plane-t1t2", point3)
    st = RenderSettings(photons=100)
    img, b = render_pass_breakdown(point3, est, 0, 2, st)
    assert np.array_equal(b.weighted, b.unweighted)  # no MIS: the same contributions
    acc = BreakdownAccumulator(b.layout)
    acc.add(b)
    w = acc.technique_weights()
    lit = (img @ [0.2126, 0.7152, 0.0722]) > 0
    assert np.all(w[0][lit] == 1.0) and not w[0][~lit].any()
    assert np.abs(acc.image - img).max() <= 1e-12 * img.max()


def test_accumulator_means_and_merge(point3):
    est = parse_estimator("mis:plane-t1t2+sphere", point3)
    st = RenderSettings(photons=60)
    lay = BreakdownLayout.of(point3, est)
    acc = BreakdownAccumulator(lay)
    passes = [render_pass_breakdown(point3, est, i, 5, st, layout=lay) for i in range(3)]
    for _, b in passes:
        acc.add(b)
    mean_img = np.mean([img for img, _ in passes], axis=0)
    assert acc.n == 3
    assert np.abs(acc.image - mean_img).max() <= 1e-12 * mean_img.max()
    assert np.abs(acc.technique_images().sum(axis=0) - acc.image).max() <= 1e-12 * mean_img.max()
    assert np.abs(acc.k_images().sum(axis=0) - acc.image).max() <= 1e-12 * mean_img.max()
    np.testing.assert_array_equal(acc.unweighted_k("sphere", 2),
                                  acc.unweighted.mean[1, 0])
    with pytest.raises(KeyError):
        acc.unweighted_k("cone", 2)


def test_unweighted_technique_estimates_its_bin():
    """plane-t1t2 alone (unweighted, K = 2) and the MIS combination (weighted, summed over
    techniques, K = 2) estimate the same K = 2 image: their per-pass image means agree within
    4 standard errors of the paired difference, and that error is below 3% of the mean (it is
    1.1% for plane-t1t2, 2.4% for the sphere: a 5% / 10% wrong factor fails)."""
    scene = load_scene(f"{SCENES}/point.toml").with_scatter(max_scatter=2)
    est = parse_estimator("mis:plane-t1t2+sphere", scene)
    st = RenderSettings(photons=200)
    lay = BreakdownLayout.of(scene, est)
    acc = BreakdownAccumulator(lay)
    unw, sph, mis = [], [], []
    for i in range(24):
        _, b = render_pass_breakdown(scene, est, i, 2024, st, layout=lay)
        acc.add(b)
        unw.append(b.unweighted[0, 0].mean())
        sph.append(b.unweighted[1, 0].mean())
        mis.append(b.weighted[:, 0].sum(axis=0).mean())
    unw, sph, mis = np.array(unw), np.array(sph), np.array(mis)
    assert mis.mean() > 0
    # the sphere's unweighted K = 2 image is an independent estimate of the same bin
    for alone in (unw, sph):
        d = alone - mis
        se = d.std(ddof=1) / np.sqrt(len(d))
        assert se < 0.03 * mis.mean(), (se, mis.mean())
        assert abs(d.mean()) < 4 * se, (d.mean(), se)
    assert np.isclose(acc.unweighted_k("plane-t1t2", 2).mean(), unw.mean(), rtol=1e-12)


def test_breakdown_never_imports_the_ui():
    import subprocess
    import sys

    code = ("import sys, psurf_core.breakdown;"
            "bad = [m for m in sys.modules if m.split('.')[0] in ('pyvista', 'vtk', 'vtkmodules',"
            " 'ui')]; print(bad); sys.exit(1 if bad else 0)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
