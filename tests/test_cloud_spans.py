"""Screen footprints of the curved families' solids clipped to the medium box
(``psurf_core.kernels.cloud_spans``): conservative (every pixel where a point of the surface
inside the box projects is a candidate), tighter than the unclipped solid, exact where the
solid lies inside the box, empty where it misses it.

The walkers' hits against the stage path's (rectangles) on every scene are
``test_walkers.py``'s; these tests draw cones and cylinders at random about a bundled scene's
box (apexes inside and outside it, half-angles from 0.5 to 89 degrees, lengths from a tenth
of the box to beyond it) and check the surfaces point by point.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from psurf_core.camera import project
from psurf_core.kernels.spans import hull_spans
from psurf_core.scene_io import load_scene
from psurf_core.techniques.surface_common import frame, ring

SCENES = Path(__file__).resolve().parent.parent / "scenes"


def _scene(name="study_medium.toml", width=96, height=72):
    scene = load_scene(SCENES / name)
    return replace(scene, camera=replace(scene.camera, width=width, height=height))


def _box(scene):
    return (np.asarray(scene.medium.bounds_min, float), np.asarray(scene.medium.bounds_max,
                                                                   float))


def _random_solids(scene, m, kind, rng):
    """``m`` random cones (``kind`` "cone": apex, axis, half-angle, slant length) or
    cylinders ("cylinder": first ring's centre, axis, radius, length) about the box, with
    their footprint clouds built as the families build them."""
    lo, hi = _box(scene)
    size = hi - lo
    apex = lo + rng.uniform(-0.3, 1.3, (m, 3)) * size
    axis = rng.normal(size=(m, 3))
    axis /= np.linalg.norm(axis, axis=1)[:, None]
    length = np.exp(rng.uniform(np.log(0.1), np.log(3.0), m)) * np.linalg.norm(size)
    if kind == "cone":
        th = np.radians(rng.uniform(0.5, 89.0, m))
        c, s = np.cos(th), np.sin(th)
        cloud = np.concatenate([apex[:, None], ring(apex + (length * c)[:, None] * axis, axis,
                                                    length * s)], axis=1)
        return cloud, (apex, axis, c, s, length)
    radius = np.exp(rng.uniform(np.log(0.01), np.log(1.0), m)) * np.linalg.norm(size)
    cloud = np.concatenate([ring(apex, axis, radius),
                            ring(apex + length[:, None] * axis, axis, radius)], axis=1)
    return cloud, (apex, axis, radius, length)


def _surface_points(kind, params, i, n, rng):
    """(n, 3) points of solid ``i``'s surface (the cone's nappe, the cylinder's side)."""
    e1, e2 = frame(params[1][i:i + 1])
    ph = rng.uniform(0.0, 2.0 * np.pi, n)
    radial = np.cos(ph)[:, None] * e1 + np.sin(ph)[:, None] * e2
    if kind == "cone":
        apex, axis, c, s, length = (p[i] for p in params)
        t = length * rng.uniform(0.0, 1.0, n)
        return apex + t[:, None] * (c * axis + s * radial)
    centre, axis, radius, length = (p[i] for p in params)
    h = length * rng.uniform(0.0, 1.0, n)
    return centre + h[:, None] * axis + radius * radial


def _bounds(cloud):
    return cloud.min(axis=1), cloud.max(axis=1)


def _pixels(scene, cloud, box):
    """Per primitive, the set of candidate pixels ``row * width + col`` of its spans."""
    lo, hi = _bounds(cloud)
    lo, hi = np.maximum(lo, box[0]), np.minimum(hi, box[1])
    prim, row, c0, c1 = hull_spans(scene.camera, lo, hi, cloud, box, cloud=True)
    out = [set() for _ in range(cloud.shape[0])]
    w = scene.camera.width
    for p, r, a, b in zip(prim, row, c0, c1, strict=True):
        out[p].update(range(r * w + a, r * w + b))
    return out


@pytest.mark.parametrize("kind", ["cone", "cylinder"])
def test_every_surface_point_inside_the_box_projects_into_the_spans(kind):
    scene = _scene()
    rng = np.random.default_rng(11)
    cloud, params = _random_solids(scene, 300, kind, rng)
    box = _box(scene)
    got = _pixels(scene, cloud, box)
    big = (box[0] - 1e3, box[1] + 1e3)  # a box holding every solid: the unclipped hulls
    unclipped = _pixels(scene, cloud, big)
    cam = scene.camera
    checked = tighter = 0
    for i in range(cloud.shape[0]):
        x = _surface_points(kind, params, i, 4000, rng)
        x = x[np.all((x >= box[0]) & (x <= box[1]), axis=1)]
        px, py, depth = project(cam, x)
        keep = (depth > 0) & (px >= 0) & (px < cam.width) & (py >= 0) & (py < cam.height)
        pix = set((py[keep].astype(int) * cam.width + px[keep].astype(int)).tolist())
        assert pix <= got[i], (kind, i, len(pix - got[i]))
        assert got[i] <= unclipped[i], (kind, i)
        checked += bool(pix)
        tighter += len(got[i]) < len(unclipped[i])
    assert checked > 50 and tighter > 50, (checked, tighter)


def test_a_solid_inside_the_box_keeps_its_whole_footprint():
    scene = _scene()
    lo, hi = _box(scene)
    mid, size = (lo + hi) / 2, (hi - lo).min()
    axis = np.array([[0.3, 0.5, -0.8]]) / np.linalg.norm([0.3, 0.5, -0.8])
    apex = mid[None] - 0.2 * size * axis
    cloud = np.concatenate([apex[:, None], ring(apex + 0.3 * size * axis, axis,
                                                np.array([0.15 * size]))], axis=1)
    assert np.all((cloud >= lo) & (cloud <= hi))
    assert _pixels(scene, cloud, (lo, hi)) == _pixels(scene, cloud, (lo - 1e3, hi + 1e3))


def test_a_solid_that_misses_the_box_has_no_spans_and_one_holding_it_the_boxs():
    scene = _scene()
    lo, hi = _box(scene)
    size = np.linalg.norm(hi - lo)
    axis = np.array([[0.0, 0.0, 1.0]])
    # Beside the box (its bounds overlap the box's on two axes only): no spans.
    apex = np.array([[hi[0] + 0.2 * size, (lo[1] + hi[1]) / 2, lo[2]]])
    thin = np.concatenate([apex[:, None], ring(apex + size * axis, axis,
                                               np.array([0.05 * size]))], axis=1)
    prim, *_ = hull_spans(scene.camera, *_bounds(thin), thin, (lo, hi), cloud=True)
    assert prim.size == 0
    # A wide cone whose solid holds the whole box: the box's own footprint.
    apex = ((lo + hi) / 2 - np.array([0.0, 0.0, 2.0 * size]))[None]
    wide = np.concatenate([apex[:, None], ring(apex + 5 * size * axis, axis,
                                               np.array([5 * size]))], axis=1)
    got = _pixels(scene, wide, (lo, hi))[0]
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                        for z in (lo[2], hi[2])])
    px, py, _ = project(scene.camera, corners)
    cols = {p % scene.camera.width for p in got}
    rows = {p // scene.camera.width for p in got}
    # the box's projected rectangle, give or take the span margin (a pixel)
    assert min(cols) >= np.floor(px.min()) - 2 and max(cols) <= np.ceil(px.max()) + 1
    assert min(rows) >= np.floor(py.min()) - 2 and max(rows) <= np.ceil(py.max()) + 1
    assert len(got) < len(_pixels(scene, wide, (lo - 1e3, hi + 1e3))[0])  # the whole image


def test_a_degenerate_ring_falls_back_to_the_solids_own_points():
    """A ring of radius zero (a cone of half-angle 0, a cylinder of radius 0) has no lateral
    faces to clip the box's edges with: the spans are those of the unclipped points."""
    scene = _scene()
    lo, hi = _box(scene)
    mid = (lo + hi) / 2
    axis = np.array([[1.0, 0.0, 0.0]])
    apex = (mid - 0.3 * (hi - lo))[None]
    cloud = np.concatenate([apex[:, None], ring(apex + 0.2 * axis, axis, np.zeros(1))], axis=1)
    got = _pixels(scene, cloud, (lo, hi))[0]
    assert got == _pixels(scene, cloud, (lo - 1e3, hi + 1e3))[0]
    assert got  # the segment is inside the box: not empty


def test_a_hull_wider_than_its_row_falls_back_to_the_rectangle():
    """``cloud_project`` keeps hulls of up to ``width`` vertices (a bound on its outputs'
    memory): a wider one takes its rectangle's rows, as a non-finite one does."""
    from psurf_core.kernels.cloud_spans import cloud_project, hull_width, max_points
    from psurf_core.kernels.spans import _clip_planes, _screen_rects, camera_row

    scene = _scene()
    cloud, _ = _random_solids(scene, 50, "cone", np.random.default_rng(3))
    box = np.array(_box(scene))
    lo, hi = _bounds(cloud)
    lo, hi = np.maximum(lo, box[0]), np.minimum(hi, box[1])
    cam = camera_row(scene.camera)
    x0, x1, y0, y1 = _screen_rects(lo, hi, cam)
    live = (x1 > x0) & (y1 > y0)
    near = np.ascontiguousarray(_clip_planes(scene.camera, box)[0, -1])
    v = cloud.shape[1]
    args = (np.ascontiguousarray(cloud), 1, live, near, box, cam, x0, x1, y0, y1,
            max_points(v, 1))
    full = cloud_project(*args, hull_width(v))
    narrow = cloud_project(*args, 4)
    wide = full[2] > 4
    assert wide.sum() > 10 and np.all(full[2] <= hull_width(v))
    np.testing.assert_array_equal(narrow[2][wide], -1)
    np.testing.assert_array_equal(narrow[4][wide], (y1 - y0)[wide])
    np.testing.assert_array_equal(narrow[2][~wide], full[2][~wide])
