"""Single-scattering photon surfaces (``ss-*``): grazing configurations stay finite.

Photons along and against a light's axis or normal (and 1e-9 away), tangent to an emitter,
flights of radius -> 0, camera rays parallel to a translated light or inside a strip's plane:
every stage and every member density must be finite (the project turns numpy RuntimeWarnings
into errors, so a 0/0 fails here too). Fixed seeds only.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from photon_surfaces_single_support import ALL, MESH, SINGLE, hits_of, unit
from small_scenes import POINT, TOP_AREA, make_scene

from psurf_core.camera import Rays, camera_rays, clip_rays
from psurf_core.geometry import blockers_of
from psurf_core.mis import member_densities, weights_from_densities
from psurf_core.techniques import get_technique
from psurf_core.techniques.base import PassContext
from psurf_core.trace import trace


def _finite_everywhere(scene, paths, rays, names):
    """Run every stage and every member density; all must be finite (and warning-free)."""
    group = [get_technique(n) for n in names]
    total = 0
    for tech in group:
        if not any(tech.applies_to(lt) for lt in scene.lights):
            continue
        _, prims, hits, val, rec, *_, ctx = hits_of(scene, tech, paths=paths, rays=rays)
        assert np.all(np.isfinite(prims.lo) | np.isinf(prims.lo)) and not np.isnan(prims.hi).any()
        assert np.all(np.isfinite(val)) and np.all(val >= 0)
        q = member_densities(rec, group, ctx)
        assert np.all(np.isfinite(q)) and np.all(np.isfinite(weights_from_densities(q, None)))
        total += len(hits)
    return total


def _rays(scene, o, d):
    d = unit(np.asarray(d, float))
    o = np.broadcast_to(np.asarray(o, float), d.shape).copy()
    s_min, s_max = clip_rays(scene, o, d)
    return Rays(o, d, s_min, s_max, np.zeros(len(d), np.int64), 1)


def test_cones_disks_on_and_off_axis_stay_finite():
    """theta -> 0 or pi (w = +-a, and 1e-9 away) and theta = pi/2 for cones and disks."""
    scene = make_scene([POINT], g=0.5)
    paths = trace(scene, 12, np.random.default_rng(2))
    a = POINT.axis
    tilt = unit(a + np.array([1e-9, 0.0, 0.0]))
    w = np.array([a, -a, tilt, -tilt, [1.0, 0, 0], [0, 0, 1.0], unit([1.0, 1e-300, 0.0]),
                  *unit(np.random.default_rng(0).normal(size=(5, 3)))])
    paths = dataclasses.replace(paths, w=w[:, None, :].copy())
    rays = camera_rays(scene, 1, jitter=False)
    assert _finite_everywhere(scene, paths, rays, SINGLE) > 0
    # The disk drops the exactly axial photons (their half-plane is undefined).
    prims = get_technique("ss-disk").create(paths, PassContext(scene, blockers_of(scene)))
    made = set(prims.photon.tolist())
    assert made >= {2, 3, 4, 5, 6, 7} and not {0, 1} & made
    # Area light: w = n_L exactly and nearly tangent to the light (c -> 0).
    sa = make_scene([TOP_AREA])
    pa = trace(sa, 6, np.random.default_rng(3))
    n = TOP_AREA.normal
    wa = np.array([n, unit(n + [0.0, 0, 1e-9]), unit([1.0, -1e-12, 0.0]),
                   unit([0.0, -1e-7, 1.0]), unit([1.0, -1.0, 1.0]), unit([0.2, -1.0, 0.0])])
    pa = dataclasses.replace(pa, w=wa[:, None, :].copy())
    assert _finite_everywhere(sa, pa, camera_rays(sa, 1, jitter=False), ALL) > 0


def test_spheres_with_vanishing_radius_stay_finite():
    for scene in (make_scene([POINT]), make_scene([TOP_AREA]), make_scene([MESH])):
        paths = trace(scene, 7, np.random.default_rng(4))
        t = np.array([[0.0], [1e-300], [1e-160], [1e-12], [1e-6], [0.3], [1.0]])
        paths = dataclasses.replace(paths, t=t)
        # Rays through the light points themselves (where a tiny sphere can be hit).
        o = np.array([0.0, 0.0, -4.0])
        rays = _rays(scene, o, paths.x[:, 0] - o)
        _finite_everywhere(scene, paths, rays, ["ss-sphere", "ss-cone", "ss-plane-uv"])


def test_rays_parallel_to_translated_light_and_strips():
    """psi in the plane of the translated light ([u,v]) or of a strip ([u,t], [v,t])."""
    scene = make_scene([TOP_AREA])
    paths = trace(scene, 8, np.random.default_rng(5))
    w = np.tile(unit([0.3, -1.0, 0.2]), (8, 1))
    t = np.linspace(0.2, 1.5, 8)[:, None]
    paths = dataclasses.replace(paths, w=w[:, None, :], t=t)
    y = paths.x[:, 0, 1] + t[:, 0] * w[:, 1]  # heights of the translated lights
    o = np.stack([np.full(8, -0.1), y, np.full(8, -4.0)], axis=1)
    d = np.array([[0.0, 0.0, 1.0], [0.0, 1e-13, 1.0], [0.0, -1e-17, 1.0]])
    o_all, d_all = np.repeat(o, 3, axis=0), np.tile(d, (8, 1))
    # Rays lying in the strips' planes: along e_u (resp. e_v) and w.
    ou = paths.x[:, 0] - 4.0 * unit(TOP_AREA.edge_u)
    o_all = np.concatenate([o_all, ou, ou, paths.x[:, 0] + 0.1 * w - 4.0 * unit(TOP_AREA.edge_v)])
    d_all = np.concatenate([d_all, np.tile(unit(TOP_AREA.edge_u), (8, 1)),
                            np.tile(unit(TOP_AREA.edge_u + 1e-14 * w[0]), (8, 1)),
                            np.tile(unit(TOP_AREA.edge_v), (8, 1))])
    rays = Rays(o_all, d_all, np.zeros(len(d_all)), np.full(len(d_all), 10.0),
                np.zeros(len(d_all), np.int64), 1)
    _finite_everywhere(scene, paths, rays, ALL)
    uv = hits_of(scene, "ss-plane-uv", paths=paths, rays=rays)[2]
    assert not np.isin(uv.ray, np.arange(0, 24, 3)).any()  # exactly parallel: no hit
