"""What the screen-footprint tests share (``test_binning.py``, ``test_hull_cut.py``,
``test_single_footprints.py``): one small traced pass, and the hits found by brute force
(every camera ray with every primitive), by binning's candidate pairs and by the compiled
walk, as sorted keys ``ray << 32 | prim``. Helpers only: the tests hold the assertions."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from psurf_core.binning import candidate_pairs
from psurf_core.camera import camera_rays
from psurf_core.geometry import blockers_of
from psurf_core.kernels.fused import fused_pass
from psurf_core.techniques.base import PassContext
from psurf_core.trace import trace


def small_pass(scene, seed: int, photons: int, *, spp: int = 1, width: int = 32,
               height: int = 24, max_pairs: int = 1 << 16, **camera):
    """``(scene, rays, paths, ctx)`` of one pass of ``scene`` with its camera at ``width`` x
    ``height`` (and ``camera``'s other fields replaced): rays, then photons, from one
    generator seeded ``seed``."""
    scene = replace(scene, camera=replace(scene.camera, width=width, height=height, **camera))
    blockers = blockers_of(scene)
    rng = np.random.default_rng(seed)
    rays = camera_rays(scene, spp, rng, blockers=blockers)
    paths = trace(scene, photons, rng, blockers=blockers)
    return scene, rays, paths, PassContext(scene, blockers, 0.0, 0, max_pairs)


def keys_of(ray, prim) -> np.ndarray:
    """``ray << 32 | prim`` (int64) of hits or pairs."""
    return np.asarray(ray).astype(np.int64) * (1 << 32) + prim


def _sorted(parts) -> np.ndarray:
    return np.sort(np.concatenate(parts)) if parts else np.zeros(0, np.int64)


def pair_hits(tech, prims, rays, ctx, ray, prim, valued=True):
    """Sorted keys of the hits among the pairs ``(ray, prim)`` (numpy Intersect), and of those
    of them with a value (numpy Evaluate; a hull may be cut to where hits count; without
    ``valued``, not evaluated: an empty array)."""
    h = tech.intersect(prims, rays, ray, prim, ctx)
    key = keys_of(h.ray, h.prim)
    if not valued:
        return np.sort(key), np.zeros(0, np.int64)
    val = np.any(tech.evaluate(h, prims, None, rays, ctx) != 0.0, axis=1)
    return np.sort(key), np.sort(key[val])


def brute_hits(tech, prims, rays, ctx, valued=True):
    """:func:`pair_hits` of every ray that sees the medium with every primitive."""
    seen = np.flatnonzero(rays.s_max > rays.s_min)
    return pair_hits(tech, prims, rays, ctx, np.repeat(seen, len(prims)),
                     np.tile(np.arange(len(prims)), seen.size), valued)


def binned_hits(tech, prims, scene, rays, ctx, hull=None, box=None, valued=True):
    """``(every, counted, pairs)``: :func:`pair_hits` over binning's candidate pairs
    (``candidate_pairs`` with ``hull`` and clip ``box``; both None: the screen rectangles)
    and the number of pairs tried."""
    every, counted, pairs = [], [], 0
    for ray, prim in candidate_pairs(scene.camera, rays, prims.lo, prims.hi, ctx.max_pairs,
                                     hull, box):
        a, b = pair_hits(tech, prims, rays, ctx, ray, prim, valued)
        every.append(a)
        counted.append(b)
        pairs += ray.size
    return _sorted(every), _sorted(counted), pairs


def walked_hits(tech, prims, paths, rays, ctx):
    """``(every, counted, candidates)``: the hits of the compiled walk
    (:func:`~psurf_core.kernels.fused.fused_pass`), those with a value, and the candidate
    pairs it tried."""
    every, counted, stats = [], [], {}
    for hits, val, _ in fused_pass(tech, prims, paths, rays, ctx, stats=stats):
        key = keys_of(hits.ray, hits.prim)
        every.append(key)
        counted.append(key[np.any(val != 0.0, axis=1)])
    return _sorted(every), _sorted(counted), stats["candidates"]
