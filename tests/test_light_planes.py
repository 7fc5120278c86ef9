"""Light strips ``plane-ut`` / ``plane-vt`` (``psurf_core.techniques.light_planes``): the
scaled normal against finite differences, the contract (K = 2, 3; area and mesh lights), and
the reconstructed paths (the light point on the light, the whole later path moved with it).
Unbiasedness and ``X Q = f``: ``test_photon_surfaces_multi_{unbiased,forms}.py``."""

from __future__ import annotations

import numpy as np
import pytest
from photon_surfaces_multi_support import MINE_LIGHT, area_scene, point_scene
from test_photon_surfaces_multi_forms import all_hits

from psurf_core.camera import camera_rays
from psurf_core.geometry import blockers_of
from psurf_core.sampling import sample_uniform_sphere
from psurf_core.techniques import REGISTRY, get_technique
from psurf_core.techniques.base import PassContext
from psurf_core.techniques.light_planes import scaled_normal
from psurf_core.trace import trace


@pytest.mark.parametrize("which", ["ut", "vt"])
def test_scaled_normal_matches_finite_differences(which):
    """``x0 = corner + u e_u + v e_v + t_K w_K + R``: ``dx0/d(u | v) x dx0/dt_K``."""
    rng = np.random.default_rng(3)
    n = 200
    corner, R = rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
    eu, ev = rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
    wK = sample_uniform_sphere(rng, n)
    dims = dict(u=rng.uniform(0, 1, n), v=rng.uniform(0, 1, n), t=rng.uniform(0.1, 2, n))

    def x0(d):
        return (corner + d["u"][:, None] * eu + d["v"][:, None] * ev + d["t"][:, None] * wK
                + R)

    def partial(key, h=1e-6):
        up, dn = dict(dims), dict(dims)
        up[key], dn[key] = dims[key] + h, dims[key] - h
        return (x0(up) - x0(dn)) / (2 * h)

    fd = np.cross(partial("u" if which == "ut" else "v"), partial("t"))
    np.testing.assert_allclose(scaled_normal(which, eu, ev, wK), fd, rtol=1e-6, atol=1e-8)


def test_names_and_contract():
    for name in MINE_LIGHT:
        tech = get_technique(name)
        assert tech.name == name and tech.short == name.endswith("-short")
        assert (tech.min_k, tech.max_k, tech.lights) == (2, 3, ("area", "mesh"))
    assert REGISTRY["plane-ut"].has_short and REGISTRY["plane-vt"].has_short
    # K = 4 paths: the photons' deeper prefixes are not kept (trace_numpy.LOOKBACK).
    assert not get_technique("plane-ut").can_produce(np.array([4]), np.array([1]))[0]


def test_point_lights_make_no_strips():
    scene = point_scene(2)
    blockers = blockers_of(scene)
    paths = trace(scene, 200, np.random.default_rng(1), blockers=blockers)
    assert len(get_technique("plane-ut-short").create(paths, PassContext(scene, blockers))) == 0


@pytest.mark.parametrize("k", [2, 3])
@pytest.mark.parametrize("name", ["plane-ut-short", "plane-vt"])
def test_reconstructed_light_point_lies_on_the_light(k, name):
    """The record's light vertex is ``x_L(u*, v*)`` of its (moved) light coordinates, and
    the later segments keep the photon's own directions and lengths."""
    scene = area_scene(k)
    lt = scene.lights[0]
    blockers = blockers_of(scene)
    rays = camera_rays(scene, 1, np.random.default_rng(2), blockers=blockers)
    paths = trace(scene, 600, np.random.default_rng(3), blockers=blockers)
    n = 0
    for hits, prims, _val, rec, _ctx in all_hits(get_technique(name), scene, paths, rays):
        xl = rec.x3 if k == 3 else rec.x2
        want = lt.corner + rec.uv[:, :1] * lt.edge_u + rec.uv[:, 1:] * lt.edge_v
        np.testing.assert_allclose(xl, want, atol=1e-9)
        assert np.all((rec.uv >= 0) & (rec.uv <= 1))
        ph = prims.photon[hits.prim]
        np.testing.assert_allclose(rec.w1, paths.w[ph, k - 1], atol=1e-12)
        np.testing.assert_allclose(rec.t1, paths.t[ph, k - 1], atol=1e-12)
        kept = 1 if name.startswith("plane-ut") else 0  # the light coordinate it keeps
        np.testing.assert_allclose(rec.uv[:, kept], paths.light_uv[ph, kept], atol=1e-12)
        n += len(hits)
    assert n > 100


def _members(scene):
    from psurf_core.estimators import parse_estimator

    return [t.label for g in parse_estimator("fast-multi", scene).groups for t in g]


def test_fast_multi_takes_the_strips_that_face_the_camera():
    """The study scenes' light has ``e_v`` along the view: its ``[v, t]`` strips are seen
    edge-on, its ``[u, t]`` strips face the camera; swapping the edges swaps the choice; a
    point light keeps ``plane-t2t3-short@0.3`` instead."""
    import dataclasses

    from psurf_core.scene_io import load_scene

    scene = load_scene("scenes/study_medium.toml").with_scatter(2, 3)
    assert _members(scene) == ["plane-t1t2-short", "plane-ut-short", "cone-short@0.2"]
    lt = scene.lights[0]
    swapped = dataclasses.replace(scene, lights=(dataclasses.replace(
        lt, edge_u=lt.edge_v, edge_v=lt.edge_u),))
    assert _members(swapped) == ["plane-t1t2-short", "plane-vt-short", "cone-short@0.2"]
    point = load_scene("scenes/point.toml").with_scatter(2, 3)
    assert _members(point) == ["plane-t1t2-short", "plane-t2t3-short@0.3", "cone-short@0.2"]
