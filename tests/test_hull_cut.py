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


def test_tube_holds_box_leaves_no_surface_point_in_the_box():
    """``tube_holds_box``: on tubes it says hold the (grown) box, no point of a dense sampling
    of the tube's surface lies in the medium box; it holds for some tubes and not for others,
    and not where a corner lies farther from the axis than the radius."""
    from psurf_core.techniques.bounds import tube_holds_box

    scene = load_scene(ROOT / "scenes" / "area.toml")
    lo, hi = scene.medium.bounds_min, scene.medium.bounds_max
    rng = np.random.default_rng(12)
    m = 600
    x = rng.uniform(-1.5, 1.5, (m, 3))
    w = rng.normal(size=(m, 3))
    w /= np.linalg.norm(w, axis=1)[:, None]
    r = rng.uniform(0.2, 4.0, m)
    holds = tube_holds_box(scene, x, w, r)
    assert 0.1 < holds.mean() < 0.9, holds.mean()
    # The surface x + h w + r (cos a e1 + sin a e2), sampled densely over the box's reach.
    e1 = np.cross(w, [0.3, 0.5, 0.81])
    e1 /= np.linalg.norm(e1, axis=1)[:, None]
    e2 = np.cross(w, e1)
    h = np.linspace(-6.0, 6.0, 241)
    a = np.linspace(0.0, 2.0 * np.pi, 181)
    ring = np.cos(a)[:, None, None] * e1[None] + np.sin(a)[:, None, None] * e2[None]
    inside_any = np.zeros(m, bool)
    for hk in h:
        p = x[None] + hk * w[None] + r[None, :, None] * ring  # (angles, m, 3)
        inside_any |= np.all((p > lo) & (p < hi), axis=2).any(axis=0)
    assert not np.any(holds & inside_any)
    assert np.any(~holds & inside_any)  # the sampling finds the surface in the box elsewhere
    corners = np.array([[(lo, hi)[(c >> k) & 1][k] for k in range(3)] for c in range(8)])
    d = corners[None] - x[:, None]
    dist = np.linalg.norm(d - np.einsum("mcj,mj->mc", d, w)[..., None] * w[:, None], axis=2)
    assert not np.any(holds & (dist.max(axis=1) > r))


def test_ball_holds_box_is_every_corner_within_the_radius():
    """``ball_holds_box`` against the corners' distances (grown box: a ball through a corner
    does not hold it)."""
    from psurf_core.techniques.bounds import ball_holds_box

    scene = load_scene(ROOT / "scenes" / "area.toml")
    lo, hi = scene.medium.bounds_min, scene.medium.bounds_max
    rng = np.random.default_rng(14)
    c = rng.uniform(-1.5, 1.5, (2000, 3))
    r = rng.uniform(0.5, 4.5, 2000)
    corners = np.array([[(lo, hi)[(k >> a) & 1][a] for a in range(3)] for k in range(8)])
    far = np.linalg.norm(corners[None] - c[:, None], axis=2).max(axis=1)
    holds = ball_holds_box(scene, c, r)
    assert 0.1 < holds.mean() < 0.9
    np.testing.assert_array_equal(holds[np.abs(far - r) > 1e-6], (far < r)[np.abs(far - r) > 1e-6])
    assert not ball_holds_box(scene, corners[:1] * 0.0, np.array([np.linalg.norm(hi - lo) / 2]))


def _held(name, scene, G):
    from psurf_core.techniques.bounds import ball_holds_box, tube_holds_box

    if name.startswith("cylinder"):
        return tube_holds_box(scene, G.x2, G.w2, G.T1 * G.s1)
    return ball_holds_box(scene, G.x1, G.T1)


@pytest.mark.parametrize("scene_name, kmin, kmax, name", [
    *((sc, 2, 3, n) for sc in ("area", "study_medium")
      for n in ("cylinder", "cylinder-short", "sphere")),
    ("point", 1, 1, "ss-sphere"), ("area", 1, 1, "ss-sphere")])
def test_surfaces_that_hold_the_box_have_no_candidates_and_no_hits(scene_name, kmin, kmax,
                                                                   name):
    """A cylinder whose tube, or a (single-scattering) sphere whose ball, holds the box gets
    empty bounds (no candidate pair); brute force finds no hit on it, and the walk and
    binning lose no hit."""
    tech = get_technique(name)
    scene, rays, paths, ctx = small_pass(
        load_scene(ROOT / "scenes" / f"{scene_name}.toml").with_scatter(kmin, kmax), 13, 300)
    prims = tech.create(paths, ctx)
    held = _held(name, scene, prims.data)
    assert held.sum() >= 5, held.sum()
    assert np.all(prims.lo[held] > prims.hi[held])
    every, counted = brute_hits(tech, prims, rays, ctx)
    assert every.size > 100
    assert not np.any(np.isin(every % (1 << 32), np.flatnonzero(held)))
    b_every, b_counted, _ = binned_hits(tech, prims, scene, rays, ctx)
    w_every, w_counted, _ = walked_hits(tech, prims, paths, rays, ctx)
    np.testing.assert_array_equal(b_every, every)
    np.testing.assert_array_equal(w_every, every)
    np.testing.assert_array_equal(w_counted, counted)
