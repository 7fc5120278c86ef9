"""Photon planes against the reference path tracer: exactly two scatterings from an area light.

The reference is an independent estimator (camera-side path tracing with NEE + MIS), so a
wrong factor in Trace, in the plane Jacobian or in the bounded-scene rules shows up as a
z-score far beyond the bound. Means are compared per image quadrant with the standard error
estimated from independent passes.
"""

from dataclasses import replace

import numpy as np
import pytest

from psurf_core.estimators import parse_estimator
from psurf_core.render import RenderSettings, render_pass
from psurf_core.scene_io import load_scene

Z_BOUND = 4.0


def quadrant_means(img):
    h, w = img.shape[0] // 2, img.shape[1] // 2
    return np.array([img[:h, :w].mean(), img[:h, w:].mean(), img[h:, :w].mean(),
                     img[h:, w:].mean(), img.mean()])


def pass_stats(scene, spec, passes, settings, seed):
    est = parse_estimator(spec, scene)
    vals = np.array([quadrant_means(render_pass(scene, est, i, seed, settings))
                     for i in range(passes)])
    return vals.mean(0), vals.std(0, ddof=1) / np.sqrt(passes)


def small(path, k):
    sc = load_scene(path).with_scatter(k, k)
    return replace(sc, camera=replace(sc.camera, width=16, height=12))


@pytest.mark.parametrize("scene_file", ["scenes/area.toml", "scenes/area_occluder.toml"])
@pytest.mark.parametrize("spec", ["planes", "plane-t1t2"])
def test_planes_match_reference_two_scatterings(scene_file, spec):
    sc = small(scene_file, 2)
    m, se = pass_stats(sc, spec, 8, RenderSettings(photons=12_000), seed=11)
    r, rse = pass_stats(sc, "reference", 8, RenderSettings(spp=256), seed=12)
    z = (m - r) / np.sqrt(se**2 + rse**2)
    assert np.all(np.abs(z) < Z_BOUND), (z, m, r)
    assert r[-1] > 10 * rse[-1]  # the comparison has power: the signal is well resolved


def test_dropping_escaped_photons_biases_long_planes(monkeypatch):
    """Photons whose first flight leaves the box must still sweep planes (spec section 4)."""
    import psurf_core.render as render_mod

    sc = small("scenes/area.toml", 2)
    m, se = pass_stats(sc, "plane-t1t2", 6, RenderSettings(photons=12_000), seed=3)
    real_trace = render_mod.trace

    def dropping(*a, **k):
        p = real_trace(*a, **k)
        gone = ~p.prefix_ok[:, 1]
        p.beta[gone] = 0.0
        return p

    monkeypatch.setattr(render_mod, "trace", dropping)
    d, dse = pass_stats(sc, "plane-t1t2", 6, RenderSettings(photons=12_000), seed=3)
    z = (m[-1] - d[-1]) / np.sqrt(se[-1] ** 2 + dse[-1] ** 2)
    assert z > 5, (m, d)
