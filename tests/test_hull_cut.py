"""Hulls cut to where a hit counts (``techniques.bounds``): a short photon plane's to the part
whose rebuilt ``x1*`` lies in the box, a light strip's to the box moved by the photon's later
segments (``Primitives.box``, which both span paths clip it to). The cut must lose no hit
that has a value, and must cut: both are checked against brute force (every camera ray with
every primitive) on the numpy stage path and on the compiled walker's, and the helpers
against direct tests."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from footprint_support import binned_hits, brute_hits, small_pass, walked_hits

from psurf_core.binning import _spans, screen_rects
from psurf_core.kernels.spans import hull_spans
from psurf_core.scene_io import load_scene
from psurf_core.techniques import get_technique
from psurf_core.techniques.bounds import box_span, hit_boxes

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.parametrize("scene_name, kmin, kmax", [("study_medium", 2, 3), ("area", 2, 3),
                                                    ("area_occluder", 2, 3)])
@pytest.mark.parametrize("name", ["planes", "plane-ut-short", "plane-ut", "plane-vt-short"])
def test_cut_hull_keeps_every_hit_with_a_value(scene_name, kmin, kmax, name):
    scene, rays, paths, ctx = small_pass(
        load_scene(ROOT / "scenes" / f"{scene_name}.toml").with_scatter(kmin, kmax), 11, 300)
    tech = get_technique(name)
    prims = tech.create(paths, ctx)
    every, counted = brute_hits(tech, prims, rays, ctx)
    assert counted.size > 100
    blocked = np.setdiff1d(every, counted)
    for b_every, b_counted, _ in (binned_hits(tech, prims, scene, rays, ctx, prims.hull,
                                              prims.clip_box(scene)),
                                  walked_hits(tech, prims, paths, rays, ctx)):
        np.testing.assert_array_equal(b_counted, counted)
        # the cut bites: of the hits without a value, the spans leave at most half
        if name != "plane-vt-short" and scene_name == "study_medium":
            b_blocked = np.setdiff1d(b_every, b_counted)
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


@pytest.mark.parametrize("inside", [False, True])
def test_spans_with_a_box_per_primitive_are_the_numpy_ones(inside):
    """Random parallelograms, each with its own box: the compiled spans (``hull_spans``) are
    binning's (numpy), and within those of the medium box alone (fewer in all)."""
    scene = load_scene(ROOT / "scenes" / "study_medium.toml")
    cam = replace(scene.camera, width=48, height=36)
    if inside:
        cam = replace(cam, position=np.array([0.3, -0.2, -0.6]))
    rng = np.random.default_rng(9)
    m = 400
    org = rng.uniform(-1.5, 1.5, (m, 3))
    a, b = rng.normal(size=(m, 3)), rng.normal(size=(m, 3))
    hull = np.stack([org, org + a, org + a + b, org + b], axis=1)
    lo0, hi0 = hull.min(axis=1), hull.max(axis=1)
    med = (scene.medium.bounds_min, scene.medium.bounds_max)
    lo0, hi0 = np.maximum(lo0, med[0]), np.minimum(hi0, med[1])
    blo = rng.uniform(-1.0, 0.3, (m, 3))
    box, lo, hi = hit_boxes(scene, blo, np.minimum(blo + rng.uniform(0.1, 1.5, (m, 3)), 1.0),
                            lo0, hi0)
    per = (box[:, 0], box[:, 1])
    got = hull_spans(cam, lo, hi, hull, per)
    want = _spans(cam, *screen_rects(cam, lo, hi), hull, per, 1 << 20)
    for g, w in zip(got, want, strict=True):
        np.testing.assert_array_equal(g, w)

    def pixels(spans):
        p, r, c0, c1 = spans
        n = c1 - c0
        step = np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)  # 0 .. n - 1 per span
        return set(zip(np.repeat(p, n).tolist(),
                       (np.repeat(r * cam.width + c0, n) + step).tolist(), strict=True))

    shared = hull_spans(cam, lo0, hi0, hull, med)
    for g, w in zip(shared, _spans(cam, *screen_rects(cam, lo0, hi0), hull, med, 1 << 20),
                    strict=True):
        np.testing.assert_array_equal(g, w)
    whole = pixels(shared)
    cut = pixels(got)
    assert cut <= whole and len(cut) < 0.8 * len(whole)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_a_hull_not_finite_gets_its_rectangle(bad):
    """Some parallelograms with a vertex coordinate not finite (the rest finite): the compiled
    spans are binning's, and each such primitive's spans are its whole screen rectangle's
    rows, while the others keep their polygon's (fewer pixels than their rectangles)."""
    scene = load_scene(ROOT / "scenes" / "study_medium.toml")
    cam = replace(scene.camera, width=48, height=36)
    rng = np.random.default_rng(4)
    m = 300
    org = rng.uniform(-0.9, 0.9, (m, 3))
    a, b = 0.5 * rng.normal(size=(m, 3)), 0.5 * rng.normal(size=(m, 3))
    hull = np.stack([org, org + a, org + a + b, org + b], axis=1)
    med = (scene.medium.bounds_min, scene.medium.bounds_max)
    lo, hi = np.maximum(hull.min(axis=1), med[0]), np.minimum(hull.max(axis=1), med[1])
    odd = np.arange(0, m, 7)
    hull[odd, rng.integers(0, 4, odd.size), rng.integers(0, 3, odd.size)] = bad
    got = hull_spans(cam, lo, hi, hull, med)
    x0, x1, y0, y1 = screen_rects(cam, lo, hi)
    for g, w in zip(got, _spans(cam, x0, x1, y0, y1, hull, med, 1 << 20), strict=True):
        np.testing.assert_array_equal(g, w)
    prim, row, c0, c1 = got
    live = odd[(x1[odd] > x0[odd]) & (y1[odd] > y0[odd])]
    assert live.size > 20
    for i in live:
        k = prim == i
        np.testing.assert_array_equal(row[k], np.arange(y0[i], y1[i]))
        assert (c0[k] == x0[i]).all() and (c1[k] == x1[i]).all()
    rest = np.setdiff1d(np.arange(m), odd)
    area = ((x1 - x0) * (y1 - y0))[rest].sum()
    assert (c1 - c0)[np.isin(prim, rest)].sum() < 0.8 * area


def _box_samples(scene, rng, n):
    lo, hi = scene.medium.bounds_min, scene.medium.bounds_max
    return lo + (hi - lo) * rng.random((n, 3))


@pytest.mark.parametrize("solid", ["tube", "ball"])
def test_outside_bounds_are_the_bounds_of_the_box_outside_the_solid(solid):
    """``outside_box.outside_bounds``: every sampled point of the box outside the solid (and
    every sampled point of its surface in the box) lies within them, and they are exact: the
    sampled points reach them within the sampling's reach; some are empty (a solid that holds
    the box), some cut, some the whole box."""
    from psurf_core.techniques.outside_box import ball_edges, outside_bounds, tube_edges

    scene = load_scene(ROOT / "scenes" / "area.toml")
    blo, bhi = scene.medium.bounds_min, scene.medium.bounds_max
    rng = np.random.default_rng(12 if solid == "tube" else 13)
    m = 300
    x = rng.uniform(-2.5, 2.5, (m, 3))
    w = rng.normal(size=(m, 3))
    w /= np.linalg.norm(w, axis=1)[:, None]
    r = rng.uniform(0.3, 4.0, m)
    quadratic = tube_edges(x, w, r) if solid == "tube" else ball_edges(x, r)
    lo, hi = outside_bounds(scene, quadratic)
    pts = _box_samples(scene, rng, 40000)
    # Plus the box's edges and faces densely: the extremes of the outside part lie there.
    t = np.linspace(0.0, 1.0, 201)
    for k in range(3):
        for a in (blo, bhi):
            face = _box_samples(scene, rng, 4000)
            face[:, k] = a[k]
            pts = np.concatenate([pts, face])
        j1, j2 = (k + 1) % 3, (k + 2) % 3
        for c in range(4):  # the four edges along axis k
            e = np.tile(blo, (t.size, 1))
            e[:, j1] = (blo, bhi)[c & 1][j1]
            e[:, j2] = (blo, bhi)[c >> 1][j2]
            e[:, k] = blo[k] + t * (bhi[k] - blo[k])
            pts = np.concatenate([pts, e])
    empty = cut = whole = 0
    for i in range(m):
        q = pts - x[i]
        d2 = np.sum(q * q, 1) - (np.sum(q * w[i], 1) ** 2 if solid == "tube" else 0.0)
        out = pts[d2 >= r[i] ** 2]
        if out.size == 0:
            assert np.any(lo[i] > hi[i]), i
            empty += 1
            continue
        assert np.all(out >= lo[i]) and np.all(out <= hi[i]), i
        np.testing.assert_allclose(out.min(0), lo[i], atol=0.03)
        np.testing.assert_allclose(out.max(0), hi[i], atol=0.03)
        if np.all(lo[i] <= blo) and np.all(hi[i] >= bhi):
            whole += 1
        else:
            cut += 1
    assert empty >= 10 and cut >= 10 and whole >= 10, (empty, cut, whole)


@pytest.mark.parametrize("scene_name, kmin, kmax, name", [
    *((sc, 2, 3, n) for sc in ("area", "study_medium")
      for n in ("cylinder", "cylinder-short", "sphere")),
    ("point", 1, 1, "ss-sphere"), ("area", 1, 1, "ss-sphere")])
def test_bounds_cut_to_the_box_outside_the_solid_lose_no_hit(scene_name, kmin, kmax, name):
    """Cylinders and (single-scattering) spheres have bounds cut to the box outside their
    tube or ball: some are empty, some cut; every brute-force hit lies within its
    primitive's bounds (none on an empty one), and the walk and binning find every
    brute-force hit."""
    tech = get_technique(name)
    scene, rays, paths, ctx = small_pass(
        load_scene(ROOT / "scenes" / f"{scene_name}.toml").with_scatter(kmin, kmax), 13, 300)
    prims = tech.create(paths, ctx)
    empty = np.any(prims.lo > prims.hi, axis=1)
    blo, bhi = scene.medium.bounds_min, scene.medium.bounds_max
    cut = ~empty & np.any((prims.lo > blo + 1e-3) | (prims.hi < bhi - 1e-3), axis=1)
    assert empty.sum() >= 5 and cut.sum() >= 5, (empty.sum(), cut.sum())
    every, counted = brute_hits(tech, prims, rays, ctx)
    assert every.size > 100
    ray, prim = every >> 32, every % (1 << 32)
    assert not np.any(empty[prim])
    hits = tech.intersect(prims, rays, ray, prim, ctx)
    x0 = rays.o[hits.ray] + hits.s[:, None] * rays.d[hits.ray]
    assert np.all(x0 >= prims.lo[hits.prim] - 1e-12) and np.all(x0 <= prims.hi[hits.prim] + 1e-12)
    b_every, b_counted, _ = binned_hits(tech, prims, scene, rays, ctx)
    w_every, w_counted, _ = walked_hits(tech, prims, paths, rays, ctx)
    np.testing.assert_array_equal(b_every, every)
    np.testing.assert_array_equal(w_every, every)
    np.testing.assert_array_equal(w_counted, counted)
