"""Throughput of each stage per estimator family; writes ``out/bench.json``.

Usage: ``python benchmarks/run.py [--scene scenes/area.toml] [--photons N] [--estimators a,b]``
(``make bench``). Measures, on one core, one pass per estimator:
photon vertices traced per second, primitives created per second, candidate ray-primitive
pairs tested per second, hits evaluated per second, and the peak traced memory (tracemalloc
of numpy allocations). Numbers depend on the machine; nothing here is a test.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from psurf_core.binning import candidate_pairs  # noqa: E402
from psurf_core.camera import camera_rays  # noqa: E402
from psurf_core.estimators import parse_estimator  # noqa: E402
from psurf_core.geometry import blockers_of  # noqa: E402
from psurf_core.render import RenderSettings, kernel_radius  # noqa: E402
from psurf_core.scene_io import load_scene  # noqa: E402
from psurf_core.techniques.base import PassContext  # noqa: E402
from psurf_core.trace import trace  # noqa: E402


def bench_estimator(scene, spec, photons, seed=0):
    """Time the stages of one pass of ``spec``; returns a dict of rates."""
    est = parse_estimator(spec, scene)
    settings = RenderSettings(photons=photons)
    blockers = blockers_of(scene)
    rng = np.random.default_rng(seed)
    rays = camera_rays(scene, 1, rng, blockers=blockers)
    t = {"create": 0.0, "intersect": 0.0, "evaluate": 0.0}
    n = {"prims": 0, "pairs": 0, "hits": 0}
    t0 = time.perf_counter()
    paths = trace(scene, photons, rng, blockers=blockers)
    t_trace = time.perf_counter() - t0
    vertices = int(paths.alive.sum())
    for tech in est.techniques:
        ctx = PassContext(scene, blockers, kernel_radius(tech, scene, settings, 0), 0,
                          settings.max_pairs)
        a = time.perf_counter()
        prims = tech.create(paths, ctx)
        t["create"] += time.perf_counter() - a
        n["prims"] += len(prims)
        for ray, prim in candidate_pairs(scene.camera, rays, prims.lo, prims.hi,
                                         settings.max_pairs):
            a = time.perf_counter()
            hits = tech.intersect(prims, rays, ray, prim, ctx)
            b = time.perf_counter()
            if len(hits):
                tech.evaluate(hits, prims, paths, rays, ctx)
            t["intersect"] += b - a
            t["evaluate"] += time.perf_counter() - b
            n["pairs"] += ray.size
            n["hits"] += len(hits)
    return {
        "photon_vertices": vertices,
        "photon_vertices_per_second": vertices / t_trace,
        "primitives_per_second": n["prims"] / max(t["create"], 1e-9),
        "pairs_tested_per_second": n["pairs"] / max(t["intersect"], 1e-9),
        "hits_evaluated_per_second": n["hits"] / max(t["evaluate"], 1e-9),
        "hits": n["hits"],
        "seconds": {"trace": t_trace, **t},
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="scenes/area.toml")
    ap.add_argument("--photons", type=int, default=20_000)
    ap.add_argument("--estimators", default="planes,plane-t1t2,points,bre,beams,beams-long")
    ap.add_argument("--out", default="out/bench.json")
    args = ap.parse_args(argv)
    scene = load_scene(args.scene)
    results = {}
    tracemalloc.start()
    for spec in args.estimators.split(","):
        results[spec] = bench_estimator(scene, spec, args.photons)
        r = results[spec]
        print(f"{spec:>14}: {r['photon_vertices_per_second']:.3g} vertices/s, "
              f"{r['pairs_tested_per_second']:.3g} pairs/s, "
              f"{r['hits_evaluated_per_second']:.3g} hits evaluated/s ({r['hits']} hits)")
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    out = {
        "scene": args.scene,
        "photons": args.photons,
        "hits_per_second": {k: v["hits_evaluated_per_second"] for k, v in results.items()},
        "photon_vertices_per_second": float(np.mean(
            [v["photon_vertices_per_second"] for v in results.values()])),
        "peak_memory_bytes": peak,
        "estimators": results,
    }
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=2))
    print(f"peak traced memory {peak / 2**20:.1f} MiB; wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
