"""What one pass costs, stage by stage and technique by technique (used by ``run.py``).

Every rate names its numerator and its clock:

* ``trace``: photon vertices traced per second (wall);
* per technique: primitives created, candidate ray-primitive pairs walked and hits
  evaluated (shaded, shadow tests and MIS weight included) by its compiled walker
  (:func:`psurf_core.kernels.fused.fused_pass`, the path ``render_pass`` takes), with the wall
  and the CPU time (``time.process_time``: every thread of this process) of the walk; a
  technique without a compiled path runs the numpy stages (binning, intersect, evaluate,
  numpy MIS weights), timed the same way;
* ``hits_per_second``: evaluated hits over the wall time of finding and evaluating them
  (every walk of the pass), ``cpu_ns_per_hit``: the CPU time of the same per hit.
"""

from __future__ import annotations

import time

import numpy as np

from psurf_core.binning import candidate_pairs
from psurf_core.camera import camera_rays
from psurf_core.estimators import parse_estimator
from psurf_core.geometry import blockers_of
from psurf_core.kernels.fused import MisSet, fused_pass
from psurf_core.mis import mis_weights
from psurf_core.render import PHOTON_BATCH, RenderSettings, kernel_radius, pass_generators
from psurf_core.techniques.base import PassContext
from psurf_core.trace import trace


class Clock:
    """Wall and CPU seconds of a block, added to ``acc[key]`` and ``acc[key + '_cpu']``."""

    def __init__(self, acc: dict, key: str):
        self.acc, self.key = acc, key

    def __enter__(self):
        self.t = (time.perf_counter(), time.process_time())

    def __exit__(self, *exc):
        w, c = self.t
        self.acc[self.key] = self.acc.get(self.key, 0.0) + time.perf_counter() - w
        k = self.key + "_cpu"
        self.acc[k] = self.acc.get(k, 0.0) + time.process_time() - c


def _numpy_stages(tech, group, est, prims, paths, rays, ctx, mis, pt):
    """The numpy stage path of a technique without a compiled walker, timed."""
    it = candidate_pairs(ctx.scene.camera, rays, prims.lo, prims.hi, ctx.max_pairs, prims.hull,
                         prims.clip_box(ctx.scene))
    while True:
        with Clock(pt, "walk"):
            pair = next(it, None)
            if pair is None:
                break
            ray, prim = pair
            hits = tech.intersect(prims, rays, ray, prim, ctx)
            if len(hits):
                tech.evaluate(hits, prims, paths, rays, ctx)
                if mis is not None:
                    mis_weights(tech, mis.full_group, est.weighting, hits, prims, paths, rays,
                                ctx, mis.shares)
        pt["candidates"] += len(ray)
        pt["hits"] += len(hits)


def stage_pass(scene, spec: str, photons: int, seed: int = 0) -> dict:
    """Pass 0 of ``spec``, stage by stage and technique by technique (the loop of
    ``render.photon_pass``, with clocks)."""
    est = parse_estimator(spec, scene)
    settings = RenderSettings(photons=photons)
    blockers = blockers_of(scene)
    ray_rng, photon_ss = pass_generators(seed, 0)
    rays = camera_rays(scene, settings.spp, ray_rng, blockers=blockers)
    t: dict = {}
    vertices = 0
    per_tech: dict[str, dict] = {}
    n_batches = -(-photons // PHOTON_BATCH)
    for b, ss in enumerate(photon_ss.spawn(n_batches)):
        nb = min(PHOTON_BATCH, photons - b * PHOTON_BATCH)
        with Clock(t, "trace"):
            paths = trace(scene, nb, np.random.default_rng(ss), blockers=blockers)
        vertices += int(paths.alive.sum())
        for group, full in est.sets:
            mis = MisSet(group, full, est.weighting) if len(group) > 1 else None
            for tech in group:
                pt = per_tech.setdefault(tech.name, {"prims": 0, "candidates": 0, "hits": 0})
                ctx = PassContext(scene, blockers, kernel_radius(tech, scene, settings, 0), 0,
                                  settings.max_pairs)
                with Clock(pt, "create"):
                    prims = tech.create(paths, ctx)
                pt["prims"] += len(prims)
                out = np.zeros((len(rays), 3))
                with Clock(pt, "walk"):
                    run = fused_pass(tech, prims, paths, rays, ctx, mis, emit=False, out=out,
                                     stats=pt)
                    compiled = run is not None
                    if compiled:
                        list(run)
                if not compiled:
                    _numpy_stages(tech, group, est, prims, paths, rays, ctx, mis, pt)
                pt["compiled"] = compiled
    hits = sum(p["hits"] for p in per_tech.values())
    walk = sum(p.get("walk", 0.0) for p in per_tech.values())
    walk_cpu = sum(p.get("walk_cpu", 0.0) for p in per_tech.values())
    for p in per_tech.values():
        p["cpu_ns_per_hit"] = 1e9 * p.get("walk_cpu", 0.0) / max(p["hits"], 1)
        p["hit_fraction"] = p["hits"] / p["candidates"] if p["candidates"] else None
    return {
        "photons": photons, "pixels": scene.camera.n_pixels, "vertices": vertices,
        "hits": hits, "candidates": sum(p["candidates"] for p in per_tech.values()),
        "trace_seconds": t["trace"], "walk_seconds": walk, "walk_cpu_seconds": walk_cpu,
        "photon_vertices_per_second": vertices / max(t["trace"], 1e-9),
        "hits_per_second": hits / max(walk, 1e-9),
        "cpu_ns_per_hit": 1e9 * walk_cpu / max(hits, 1),
        "techniques": per_tech,
    }


def warm_up(scene, spec: str, photons: int) -> None:
    """One untimed :func:`stage_pass` of ``photons`` (seed 1000): the kernels load and the
    buffers a pass reuses (the walkers' ``psurf_core.kernels.buffers``, the tracer's
    ``psurf_core.trace_buffers``) reach the size of the timed passes. (After a 256-photon
    warm-up the first timed pass grew them: in a fresh process its ``planes`` hit cost 183
    CPU ns against 50-54 after, and the first round of ``benchmarks/cost_ratio.py`` read a
    ratio of 0.49 against 1.56-1.65, 2026-12-07.)"""
    stage_pass(scene, spec, photons, seed=1000)


def steady(scene, spec: str, photons: int, reps: int) -> dict:
    """:func:`stage_pass` ``reps`` times after a warm-up pass of the same size (compiled
    kernels loaded, the pass's buffers allocated at their full size: :func:`warm_up`): the
    median of each headline rate, and every pass's."""
    warm_up(scene, spec, photons)
    runs = [stage_pass(scene, spec, photons, seed=r) for r in range(reps)]
    keys = ("hits_per_second", "cpu_ns_per_hit", "photon_vertices_per_second")
    out = {k: float(np.median([r[k] for r in runs])) for k in keys}
    out.update({"passes": reps, "photons": photons, "hits": int(np.median([r["hits"]
                                                                           for r in runs])),
                "each": {k: [r[k] for r in runs] for k in keys}, "last": runs[-1]})
    return out


def paired_cost_ratio(scene, base: str, spec: str, photons: int, rounds: int) -> dict:
    """The CPU cost of one evaluated hit of ``spec`` over ``base``'s, from passes run back to
    back: each round one :func:`stage_pass` of each (seed ``r``, the order alternating), the
    ratio of that round's two ``cpu_ns_per_hit``; the median over the rounds. (Each estimator's
    :func:`steady` median comes from its own stretch of the run, tens of seconds apart, in
    whatever phase a shared machine is in then; a round's pair shares one.) A warm-up pass
    of each comes first (:func:`warm_up`)."""
    warm_up(scene, base, photons)
    warm_up(scene, spec, photons)
    ratios, each = [], {base: [], spec: []}
    for r in range(rounds):
        order = (base, spec) if r % 2 == 0 else (spec, base)
        got = {s: stage_pass(scene, s, photons, seed=r)["cpu_ns_per_hit"] for s in order}
        for s in (base, spec):
            each[s].append(got[s])
        ratios.append(got[spec] / got[base])
    return {"ratio": float(np.median(ratios)), "rounds": rounds, "each_ratio": ratios,
            "cpu_ns_per_hit": each}


def trace_rate(scene, photons: int, passes: int) -> dict:
    """Photon vertices traced per second by ``trace`` alone, in render's batches of
    ``PHOTON_BATCH`` (the previous batch's paths alive while the next is traced, as in a
    render): the median of ``passes`` warm passes (pass ``i`` seeded as render's pass ``i``),
    their range, and the first pass after the kernels loaded (cold memory)."""
    blockers = blockers_of(scene)
    trace(scene, 64, np.random.default_rng(0), blockers=blockers)  # kernels load from cache
    rates, verts = [], []
    for i in range(passes + 1):
        _, photon_ss = pass_generators(0, i)
        n_batches = -(-photons // PHOTON_BATCH)
        secs, nv = 0.0, 0
        for b, ss in enumerate(photon_ss.spawn(n_batches)):
            nb = min(PHOTON_BATCH, photons - b * PHOTON_BATCH)
            a = time.perf_counter()
            paths = trace(scene, nb, np.random.default_rng(ss), blockers=blockers)
            secs += time.perf_counter() - a
            nv += int(paths.alive.sum())
        rates.append(nv / secs)
        verts.append(nv)
    warm = rates[1:]
    return {"photons": photons, "passes": passes, "vertices_per_pass": int(np.median(verts)),
            "photon_vertices_per_second": float(np.median(warm)),
            "photon_vertices_per_second_range": [float(min(warm)), float(max(warm))],
            "photon_vertices_per_second_first_pass": float(rates[0])}
