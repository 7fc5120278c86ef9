"""Hulls cut to where a hit counts (``techniques.bounds``): a short photon plane's to the part
whose rebuilt ``x1*`` lies in the box, a light strip's to the box moved by the photon's later
segments. The cut must lose no hit that has a value, and must cut: both are checked against
brute force (every camera ray with every primitive), and the helpers against direct tests."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from psurf_core.binning import candidate_pairs
from psurf_core.camera import camera_rays
from psurf_core.geometry import blockers_of
from psurf_core.scene_io import load_scene
from psurf_core.techniques import get_technique
from psurf_core.techniques.base import PassContext
from psurf_core.techniques.bounds import box_span, hull_in_boxes
from psurf_core.trace import trace

ROOT = Path(__file__).resolve().parent.parent


def _keys(tech, prims, rays, ctx, ray, prim):
    """Sorted keys of the hits among pairs ``(ray, prim)``, all and those with a value."""
    h = tech.intersect(prims, rays, ray, prim, ctx)
    val = np.any(tech.evaluate(h, prims, None, rays, ctx) != 0.0, axis=1)
    key = h.ray.astype(np.int64) * (1 << 32) + h.prim
    return np.sort(key), np.sort(key[val])


def _binned(tech, prims, scene, rays, ctx):
    box = (scene.medium.bounds_min, scene.medium.bounds_max)
    every, counted = [], []
    for ray, prim in candidate_pairs(scene.camera, rays, prims.lo, prims.hi, 1 << 16,
                                     prims.hull, box):
        a, b = _keys(tech, prims, rays, ctx, ray, prim)
        every.append(a)
        counted.append(b)
    return np.sort(np.concatenate(every)), np.sort(np.concatenate(counted))


@pytest.mark.parametrize("scene_name, kmin, kmax", [("study_medium", 2, 3), ("area", 2, 3),
                                                    ("area_occluder", 2, 3)])
@pytest.mark.parametrize("name", ["planes", "plane-ut-short", "plane-ut", "plane-vt-short"])
def test_cut_hull_keeps_every_hit_with_a_value(scene_name, kmin, kmax, name):
    scene = load_scene(ROOT / "scenes" / f"{scene_name}.toml").with_scatter(kmin, kmax)
    scene = replace(scene, camera=replace(scene.camera, width=32, height=24))
    blockers = blockers_of(scene)
    rng = np.random.default_rng(11)
    rays = camera_rays(scene, 1, rng, blockers=blockers)
    paths = trace(scene, 300, rng, blockers=blockers)
    tech = get_technique(name)
    ctx = PassContext(scene, blockers, 0.0, 0, 1 << 16)
    prims = tech.create(paths, ctx)
    # brute force: every ray that sees the medium with every primitive
    seen = np.flatnonzero(rays.s_max > rays.s_min)
    ray = np.repeat(seen, len(prims))
    prim = np.tile(np.arange(len(prims)), seen.size)
    every, counted = _keys(tech, prims, rays, ctx, ray, prim)
    b_every, b_counted = _binned(tech, prims, scene, rays, ctx)
    assert counted.size > 100
    np.testing.assert_array_equal(b_counted, counted)
    # the cut bites: of the hits without a value, the binning tries at most half
    blocked = np.setdiff1d(every, counted)
    b_blocked = np.setdiff1d(b_every, b_counted)
    if name != "plane-vt-short" and scene_name == "study_medium":
        assert blocked.size > 0.05 * every.size, (blocked.size, every.size)
        assert b_blocked.size < 0.5 * blocked.size, (b_blocked.size, blocked.size)


def test_box_span_is_the_lines_part_in_the_box():
    scene = load_scene(ROOT / "scenes" / "study_medium.toml")
    rng = np.random.default_rng(5)
    o = rng.uniform(-2.0, 2.0, (400, 3))
    d = rng.normal(size=(400, 3))
    d[:40, rng.integers(0, 3, 40)] = 0.0  # lines parallel to a face
    t_in, t_out = box_span(scene, o, d)
    t = np.linspace(-6.0, 6.0, 2001)
    p = o[:, None] + t[None, :, None] * d[:, None]
    lo, hi = scene.medium.bounds_min, scene.medium.bounds_max
    inside = np.all((p >= lo) & (p <= hi), axis=2)
    within = (t[None] >= t_in[:, None]) & (t[None] <= t_out[:, None])
    assert inside.any()
    assert not (inside & ~within).any()  # conservative
    # and tight: a parameter inside the span but 1e-3 of the box's side from its ends is in
    near = (t[None] >= t_in[:, None] + 1e-3) & (t[None] <= t_out[:, None] - 1e-3)
    assert not (near & ~inside).any()


def test_hull_in_boxes_is_the_polygons_part_in_the_box():
    scene = load_scene(ROOT / "scenes" / "study_medium.toml")
    rng = np.random.default_rng(9)
    m = 300
    org = rng.uniform(-1.5, 1.5, (m, 3))
    a, b = rng.normal(size=(m, 3)), rng.normal(size=(m, 3))
    hull = np.stack([org, org + a, org + a + b, org + b], axis=1)
    lo, hi = hull.min(axis=1), hull.max(axis=1)
    box_lo = rng.uniform(-1.0, 0.0, (m, 3))
    box_hi = box_lo + rng.uniform(0.2, 1.5, (m, 3))
    hull[:5, 2] = np.nan  # a row that falls back to its rectangle is kept as it is
    cut, clo, chi = hull_in_boxes(scene, hull, lo.copy(), hi.copy(), box_lo, box_hi)
    assert cut.shape[1] > 4
    assert np.isnan(cut[:5]).any(axis=(1, 2)).all()
    # sample points of each parallelogram; those in the box lie in the cut polygon
    u, v = rng.uniform(size=(2, 200))
    pts = org[:, None] + u[None, :, None] * a[:, None] + v[None, :, None] * b[:, None]
    inb = np.all((pts >= box_lo[:, None]) & (pts <= box_hi[:, None]), axis=2)
    n = np.cross(a, b)
    kept = 0
    for i in range(5, m):
        poly = cut[i]
        # inside the convex polygon: on the inner side of every (non-degenerate) edge
        e = np.roll(poly, -1, axis=0) - poly
        side = np.einsum("ej,pej->pe", n[i][None].repeat(len(poly), 0),
                         np.cross(e[None], pts[i][:, None] - poly[None]))
        ok = np.where(np.linalg.norm(e, axis=1)[None] > 1e-12, side >= -1e-9, True).all(axis=1)
        assert ok[inb[i]].all(), i
        kept += int(inb[i].sum())
        if inb[i].any():
            assert (clo[i] <= chi[i]).all()
    assert kept > 1000
