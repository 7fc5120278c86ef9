"""Screen-space binning: the tight (hull polygon) footprints are conservative.

Every hit that the rectangle binning (the primitive's box projected to the screen) finds must
also be found when only the pixels of the primitive's clipped hull polygon are tested, for
short and long planar primitives, with the camera outside and inside the medium box (the
near-plane clip), and at 2 rays per pixel.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from footprint_support import binned_hits, small_pass

from psurf_core.binning import clip_polygons
from psurf_core.camera import camera_rays
from psurf_core.geometry import blockers_of
from psurf_core.scene_io import load_scene
from psurf_core.techniques import get_technique
from psurf_core.techniques.base import PassContext

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.parametrize("camera", ["outside", "inside"])
@pytest.mark.parametrize("name", ["planes", "plane-t1t2", "plane-t1t3", "plane-t2t3-short"])
def test_hull_binning_finds_every_rectangle_hit(name, camera):
    inside = {"position": np.array([0.2, 0.1, -0.5])} if camera == "inside" else {}
    scene, rays, paths, ctx = small_pass(load_scene(ROOT / "scenes" / "area.toml"), 7, 150,
                                         spp=2, width=40, height=30, max_pairs=1 << 15,
                                         **inside)
    tech = get_technique(name)
    prims = tech.create(paths, ctx)
    assert prims.hull is not None
    box = (scene.medium.bounds_min, scene.medium.bounds_max)
    every_rect, rect, rect_pairs = binned_hits(tech, prims, scene, rays, ctx, None, box)
    every_tight, tight, tight_pairs = binned_hits(tech, prims, scene, rays, ctx, prims.hull,
                                                  box)
    assert rect.size > 100
    np.testing.assert_array_equal(tight, rect)
    assert tight_pairs < rect_pairs
    # and every hit the hull finds, the rectangle finds
    assert np.isin(every_tight, every_rect).all()


def test_random_parallelograms_conservative():
    """Random parallelograms anywhere around the box (partly outside it, crossing the
    camera plane): the hull binning loses no hit of the rectangle binning."""
    scene = load_scene(ROOT / "scenes" / "area.toml")
    scene = replace(scene, camera=replace(scene.camera, width=32, height=24,
                                          position=np.array([0.3, -0.2, -1.3])))
    blockers = blockers_of(scene)
    rng = np.random.default_rng(3)
    rays = camera_rays(scene, 1, rng, blockers=blockers)
    tech = get_technique("planes")
    m = 400
    w2 = rng.normal(size=(m, 3))
    w1 = rng.normal(size=(m, 3))
    w2 /= np.linalg.norm(w2, axis=1, keepdims=True)
    w1 /= np.linalg.norm(w1, axis=1, keepdims=True)
    x2 = rng.uniform(-1.5, 1.5, size=(m, 3))
    T2, T1 = rng.exponential(1.0, m), rng.exponential(1.0, m)
    from psurf_core.techniques.base import Primitives, clip_bounds
    from psurf_core.techniques.bounds import wedge_hull

    c = [x2, x2 + T2[:, None] * w2, x2 + T1[:, None] * w1,
         x2 + T2[:, None] * w2 + T1[:, None] * w1]
    lo, hi = clip_bounds(scene, np.minimum.reduce(c), np.maximum.reduce(c))
    from psurf_core.records import table
    from psurf_core.techniques.planes import PlaneGeometry
    from psurf_core.techniques.surface_common import solve_columns

    data = table(PlaneGeometry, x2=x2, w2=w2, w1=w1, T2=T2, T1=T1, own=0.0, beta=1.0,
                 clear=0.0, line=0.0,
                 **solve_columns(scene, x2, w2, w1))
    prims = Primitives("planes", np.zeros(m, np.int64), np.full(m, 2), lo, hi, data,
                       hull=wedge_hull(scene, x2, w2, w1, T2, T1))
    ctx = PassContext(scene, blockers, 0.0, 0, 1 << 15)
    box = (scene.medium.bounds_min, scene.medium.bounds_max)
    rect = binned_hits(tech, prims, scene, rays, ctx, None, box, valued=False)[0]
    tight = binned_hits(tech, prims, scene, rays, ctx, prims.hull, box,
                        valued=False)[0]
    assert rect.size > 100
    np.testing.assert_array_equal(tight, rect)


def test_clip_polygons_square():
    """The unit square clipped to ``x >= 0.25`` keeps 4 vertices spanning x in [0.25, 1]."""
    sq = np.array([[[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]], dtype=float)
    poly, n = clip_polygons(sq, np.array([4]), np.array([1.0, 0, 0]), 0.25)
    assert n[0] == 4
    v = poly[0, : n[0]]
    assert v[:, 0].min() == pytest.approx(0.25) and v[:, 0].max() == 1.0
    poly, n = clip_polygons(sq, np.array([4]), np.array([1.0, 0, 0]), 2.0)
    assert n[0] == 0
