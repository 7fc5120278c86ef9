"""Single-scattering footprints: the compiled walk visits the pixels of an ``ss-cone``'s
footprint solid (``Primitives.cloud``, the multiple-scattering cone's) and of a
single-scattering plane patch's or strip's polygon (``Primitives.hull``), not their whole
screen rectangles. Each must keep every hit and must cut: both checked against brute force
(every camera ray with every primitive) on the compiled walk and, for the hulls, on the
numpy stage path (which uses hulls but not clouds), on a parallelogram light and on a mesh
light's triangles."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from psurf_core.binning import candidate_pairs
from psurf_core.camera import camera_rays
from psurf_core.geometry import blockers_of
from psurf_core.kernels.fused import fused_pass
from psurf_core.scene_io import load_scene
from psurf_core.techniques import get_technique
from psurf_core.techniques.base import PassContext
from psurf_core.trace import trace

ROOT = Path(__file__).resolve().parent.parent


def _keys(tech, prims, rays, ctx, ray, prim) -> np.ndarray:
    """Sorted ``ray << 32 | prim`` of the hits among the pairs ``(ray, prim)``."""
    h = tech.intersect(prims, rays, ray, prim, ctx)
    return np.sort(h.ray.astype(np.int64) * (1 << 32) + h.prim)


def _binned(tech, prims, scene, rays, ctx) -> tuple[np.ndarray, int]:
    keys, pairs = [], 0
    for ray, prim in candidate_pairs(scene.camera, rays, prims.lo, prims.hi, 1 << 16,
                                     prims.hull, prims.clip_box(scene)):
        keys.append(_keys(tech, prims, rays, ctx, ray, prim))
        pairs += ray.size
    return np.sort(np.concatenate(keys)), pairs


def _walked(tech, prims, paths, rays, ctx) -> tuple[np.ndarray, int]:
    keys, stats = [], {}
    for hits, _, _ in fused_pass(tech, prims, paths, rays, ctx, stats=stats):
        keys.append(hits.ray.astype(np.int64) * (1 << 32) + hits.prim)
    return np.sort(np.concatenate(keys)), stats["candidates"]


@pytest.mark.parametrize("scene_name", ["area", "mesh_light"])
@pytest.mark.parametrize("name", ["ss-cone", "ss-cone-short", "ss-plane-uv", "ss-plane-ut",
                                  "ss-plane-ut-short", "ss-plane-vt"])
def test_footprint_keeps_every_hit_and_cuts(scene_name, name):
    scene = load_scene(ROOT / "scenes" / f"{scene_name}.toml").with_scatter(1, 1)
    scene = replace(scene, camera=replace(scene.camera, width=32, height=24))
    blockers = blockers_of(scene)
    rng = np.random.default_rng(5)
    rays = camera_rays(scene, 1, rng, blockers=blockers)
    paths = trace(scene, 400, rng, blockers=blockers)
    tech = get_technique(name)
    ctx = PassContext(scene, blockers, 0.0, 0, 1 << 16)
    prims = tech.create(paths, ctx)
    assert (prims.cloud if name.startswith("ss-cone") else prims.hull) is not None
    # brute force: every ray that sees the medium with every primitive
    seen = np.flatnonzero(rays.s_max > rays.s_min)
    every = _keys(tech, prims, rays, ctx, np.repeat(seen, len(prims)),
                  np.tile(np.arange(len(prims)), seen.size))
    assert every.size > 10  # (ss-plane-uv on mesh_light: small triangles, ~15 hits)
    walked, pairs = _walked(tech, prims, paths, rays, ctx)
    np.testing.assert_array_equal(walked, every)
    # the cut bites: the walk tries fewer pairs than the screen rectangles hold
    rect = sum(r.size for r, _ in candidate_pairs(scene.camera, rays, prims.lo, prims.hi,
                                                  1 << 16))
    assert pairs < 0.9 * rect, (pairs, rect)
    if prims.hull is not None:
        binned, b_pairs = _binned(tech, prims, scene, rays, ctx)
        np.testing.assert_array_equal(binned, every)
        assert b_pairs < 0.9 * rect, (b_pairs, rect)
