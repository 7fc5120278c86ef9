"""Single-scattering footprints: the compiled walk visits the pixels of an ``ss-cone``'s
footprint solid (``Primitives.cloud``, the multiple-scattering cone's) and of a
single-scattering plane patch's or strip's polygon (``Primitives.hull``), not their whole
screen rectangles. Each must keep every hit and must cut: both checked against brute force
(every camera ray with every primitive) on the compiled walk and, for the hulls, on the
numpy stage path (which uses hulls but not clouds), on a parallelogram light and on a mesh
light's triangles."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from footprint_support import binned_hits, brute_hits, small_pass, walked_hits

from psurf_core.binning import candidate_pairs
from psurf_core.scene_io import load_scene
from psurf_core.techniques import get_technique

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.parametrize("scene_name", ["area", "mesh_light"])
@pytest.mark.parametrize("name", ["ss-cone", "ss-cone-short", "ss-plane-uv", "ss-plane-ut",
                                  "ss-plane-ut-short", "ss-plane-vt"])
def test_footprint_keeps_every_hit_and_cuts(scene_name, name):
    scene, rays, paths, ctx = small_pass(
        load_scene(ROOT / "scenes" / f"{scene_name}.toml").with_scatter(1, 1), 5, 400)
    tech = get_technique(name)
    prims = tech.create(paths, ctx)
    assert (prims.cloud if name.startswith("ss-cone") else prims.hull) is not None
    every, _ = brute_hits(tech, prims, rays, ctx, valued=False)
    assert every.size > 10  # (ss-plane-uv on mesh_light: small triangles, ~15 hits)
    walked, _, pairs = walked_hits(tech, prims, paths, rays, ctx)
    np.testing.assert_array_equal(walked, every)
    # the cut bites: the walk tries fewer pairs than the screen rectangles hold
    rect = sum(r.size for r, _ in candidate_pairs(scene.camera, rays, prims.lo, prims.hi,
                                                  1 << 16))
    assert pairs < 0.9 * rect, (pairs, rect)
    if prims.hull is not None:
        binned, _, b_pairs = binned_hits(tech, prims, scene, rays, ctx, prims.hull,
                                         prims.clip_box(scene), valued=False)
        np.testing.assert_array_equal(binned, every)
        assert b_pairs < 0.9 * rect, (b_pairs, rect)
