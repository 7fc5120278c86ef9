"""``benchmarks/cone_misses.py`` on a small pass: its classification agrees with the walker
(a pair it calls a hit has one in the compiled pass, and the hit count matches), and every
hit's ray meets the footprint solid."""

from __future__ import annotations

import numpy as np
from benchmark_support import ROOT, load_benchmark

from psurf_core.estimators import parse_estimator
from psurf_core.kernels.fused import fused_pass
from psurf_core.scene_io import load_scene

cone_misses = load_benchmark("cone_misses")


def test_classification_counts_the_walkers_hits():
    scene = load_scene(ROOT / "scenes" / "study_medium.toml").with_scatter(2, 3)
    tech = parse_estimator("cone-short", scene).sets[0][0][0]
    prims, rays, p, pix, paths, ctx = cone_misses.candidates(scene, tech, 60, 0)
    why = cone_misses.classify(prims, rays, p, pix, tech.short)
    stats: dict = {}
    out = np.zeros((len(rays), 3))
    list(fused_pass(tech, prims, paths, rays, ctx, None, emit=False, out=out, stats=stats))
    assert int((why == 0).sum()) == stats["hits"] > 100
    assert stats["candidates"] <= p.size  # (the walker skips rays that miss the medium)
    hit = (why == 0).any(axis=1)
    meets = cone_misses.meets_solid(prims.cloud[p], rays.o[pix], rays.d[pix], rays.s_min[pix],
                                    rays.s_max[pix])
    assert not np.any(hit & ~meets)
    assert np.mean(hit) > 0.5  # the footprint clipped to the box: most pairs hit
