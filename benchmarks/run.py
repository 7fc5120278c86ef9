"""Throughput of each stage per estimator family, scaling tables, peak memory; ``out/bench.json``.

Usage: ``python benchmarks/run.py [--scene scenes/area.toml] [--photons N] [--estimators a,b]
[--scaling a:N,b:N] [--memory-photons N] [--quick]`` (``make bench``, ``make bench-quick``).
Nothing here is a test: numbers depend on the machine and on whatever else runs on it (the
JSON keeps the command line; compare runs made back to back, as ratios).

What is measured (one process: ``planes``' compiled kernel on numba's threads, the rest on
one core; every rate names its own numerator and clock):

* **stages of one pass** (the loop of :func:`psurf_core.render.photon_pass`, timed stage by
  stage): photon vertices traced/s (``trace``), primitives created/s (``create``), candidate
  ray-primitive pairs found/s (``binning``) and tested/s (``intersect``), hits evaluated/s
  (``evaluate``), MIS weights/s (``mis``). A technique with a fused path
  (``Technique.fused_pass``, which ``photon_pass`` uses wherever it applies, MIS groups
  included) is timed as one ``fused`` stage (binning + intersect + evaluate). Its candidate
  pairs are those of ``binning.candidate_pairs`` (the kernel walks the same spans), counted
  untimed, and its pairs found/tested per second divide them by the whole fused time.
* ``photon_vertices_per_second`` (the ``trace:`` line): ``trace`` alone on ``4 PHOTON_BATCH``
  photons (or ``--photons``) in render's batches, median of ``--trace-passes`` warm passes
  (:func:`trace_rate`; the first pass and the range in ``trace``). Each estimator's
  ``photon_vertices_per_second`` is the rate inside its own pass above.
* ``hits_per_second``: *evaluated hits* (pairs with a valid root whose contribution, shadow
  tests included, was computed) divided by the whole time spent finding and evaluating them:
  binning + intersect + evaluate + MIS weights + fused.
* ``pass_hits_per_second``: the same hits over the wall time of a real
  :func:`psurf_core.render.render_pass` (tracing, creation and camera rays included; hits
  counted through its ``tally`` hook).
* ``planes_threads``: ``planes`` find+eval hits/s on one thread and on numba's threads
  (median of ``--planes-reps`` passes, interleaved): the fused kernel shares large chunks
  among threads with the same hits in the same order, on the cores other processes leave
  idle (``fused_threads.thread_count``), so on a busy machine both rows are one thread's.
* ``two_process``: wall time of the same passes with :func:`psurf_core.parallel.render_parallel`
  on two (warmed-up) worker processes, one thread each, against one process on numba's
  threads and on one thread (images checked bit-identical); ``planes`` at >= 10^4 photons per
  pass, so that a pass outweighs its round trip to a worker. On a machine whose cores are
  busy with other work the speed-up cannot reach 2. Also the evaluated hits of those passes
  per wall second (whole passes: tracing, creation, camera rays included) on 2 processes and on
  1 thread: what the machine delivers with both cores.
* ``scaling``: each rate at 1x, 2x, 4x the photon count and at 1x, 2x, 4x the image side.
* ``peak_memory_bytes``: peak resident set size (``ru_maxrss``) of fresh subprocesses that
  render one pass of ``planes`` at 256x192: ``--memory-photons`` photons (every 32nd row's
  rays: the photons are traced, and their primitives created and binned, as for the whole
  image), and 1/50 of them over the whole image (full chunks of ray-primitive pairs); the
  larger of the two.
"""

from __future__ import annotations

import argparse
import json
import platform
import subprocess
import sys
import textwrap
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from psurf_core.binning import candidate_pairs  # noqa: E402
from psurf_core.camera import camera_rays  # noqa: E402
from psurf_core.estimators import parse_estimator  # noqa: E402
from psurf_core.geometry import blockers_of  # noqa: E402
from psurf_core.mis import mis_weights  # noqa: E402
from psurf_core.render import (  # noqa: E402
    PHOTON_BATCH,
    RenderSettings,
    kernel_radius,
    pass_generators,
    render_pass,
)
from psurf_core.scene_io import load_scene  # noqa: E402
from psurf_core.techniques.base import PassContext  # noqa: E402
from psurf_core.trace import trace  # noqa: E402

STAGES = ("trace", "create", "binning", "intersect", "evaluate", "mis", "fused")


def with_resolution(scene, width: int, height: int):
    """``scene`` with its camera at ``width x height`` pixels."""
    return replace(scene, camera=replace(scene.camera, width=int(width), height=int(height)))


def _timed_iter(it, acc: dict, key: str):
    """Yield from ``it``, adding the time spent inside ``next`` to ``acc[key]``."""
    while True:
        a = time.perf_counter()
        try:
            item = next(it)
        except StopIteration:
            acc[key] += time.perf_counter() - a
            return
        acc[key] += time.perf_counter() - a
        yield item


def _fused(tech, group, est, prims, paths, rays, ctx):
    """``(Hits, values)`` chunks of ``tech``'s compiled walker (MIS weights computed in it
    are timed with it), or None."""
    from psurf_core.kernels.fused import MisSet, fused_pass

    mis = MisSet(group, group, est.weighting) if len(group) > 1 else None
    run = fused_pass(tech, prims, paths, rays, ctx, mis, emit=True)
    return None if run is None else ((h, v) for h, v, _ in run)


def stage_pass(scene, spec: str, photons: int, seed: int = 0) -> dict:
    """Pass 0 of ``spec``, stage by stage (the loop of ``photon_pass``, with timers)."""
    est = parse_estimator(spec, scene)
    settings = RenderSettings(photons=photons)
    blockers = blockers_of(scene)
    ray_rng, photon_ss = pass_generators(seed, 0)
    rays = camera_rays(scene, settings.spp, ray_rng, blockers=blockers)
    t = dict.fromkeys(STAGES, 0.0)
    n = {"vertices": 0, "prims": 0, "pairs": 0, "hits": 0}
    per_tech: dict[str, dict] = {}
    n_batches = -(-photons // PHOTON_BATCH)
    for b, ss in enumerate(photon_ss.spawn(n_batches)):
        nb = min(PHOTON_BATCH, photons - b * PHOTON_BATCH)
        a = time.perf_counter()
        paths = trace(scene, nb, np.random.default_rng(ss), blockers=blockers)
        t["trace"] += time.perf_counter() - a
        n["vertices"] += int(paths.alive.sum())
        for group in est.groups:
            for tech in group:
                pt = per_tech.setdefault(tech.name, {"prims": 0, "pairs": 0, "hits": 0,
                                                     **dict.fromkeys(STAGES[1:], 0.0)})
                ctx = PassContext(scene, blockers, kernel_radius(tech, scene, settings, 0), 0,
                                  settings.max_pairs)
                a = time.perf_counter()
                prims = tech.create(paths, ctx)
                pt["create"] += time.perf_counter() - a
                pt["prims"] += len(prims)
                fused = _fused(tech, group, est, prims, paths, rays, ctx)
                pairs = candidate_pairs(scene.camera, rays, prims.lo, prims.hi,
                                        settings.max_pairs, prims.hull,
                                        (scene.medium.bounds_min, scene.medium.bounds_max))
                if fused is not None:
                    # As photon_pass runs it: binning, intersect and evaluate in one compiled
                    # step, then the MIS weights. The kernel walks binning's spans (padded by
                    # a pixel) without materialising pairs, so its candidates are counted
                    # apart, untimed, from binning's.
                    for hits, _ in _timed_iter(iter(fused), pt, "fused"):
                        pt["hits"] += len(hits)
                        if len(group) > 1:
                            a = time.perf_counter()
                            mis_weights(tech, group, est.weighting, hits, prims, paths, rays,
                                        ctx)
                            pt["mis"] += time.perf_counter() - a
                    pt["pairs"] += sum(ray.size for ray, _ in pairs)
                    continue
                for ray, prim in _timed_iter(pairs, pt, "binning"):
                    pt["pairs"] += ray.size
                    a = time.perf_counter()
                    hits = tech.intersect(prims, rays, ray, prim, ctx)
                    pt["intersect"] += time.perf_counter() - a
                    if len(hits) == 0:
                        continue
                    pt["hits"] += len(hits)
                    a = time.perf_counter()
                    tech.evaluate(hits, prims, paths, rays, ctx)
                    pt["evaluate"] += time.perf_counter() - a
                    if len(group) > 1:
                        a = time.perf_counter()
                        mis_weights(tech, group, est.weighting, hits, prims, paths, rays, ctx)
                        pt["mis"] += time.perf_counter() - a
    for pt in per_tech.values():
        for k in STAGES[1:]:
            t[k] += pt[k]
        for k in ("prims", "pairs", "hits"):
            n[k] += pt[k]
    find_eval = t["binning"] + t["intersect"] + t["evaluate"] + t["mis"] + t["fused"]
    return {
        "photons": photons,
        "pixels": scene.camera.n_pixels,
        **n,
        "seconds": t,
        "photon_vertices_per_second": n["vertices"] / max(t["trace"], 1e-9),
        "primitives_per_second": n["prims"] / max(t["create"], 1e-9),
        # A fused technique finds, tests and evaluates its pairs in one timed step: its pairs
        # count against that whole time (a lower bound on its find and test rates).
        "pairs_found_per_second": n["pairs"] / max(t["binning"] + t["fused"], 1e-9),
        "pairs_tested_per_second": n["pairs"] / max(t["intersect"] + t["fused"], 1e-9),
        "hits_evaluated_per_second": n["hits"] / max(t["evaluate"] + t["mis"] + t["fused"],
                                                     1e-9),
        "hits_per_second": n["hits"] / max(find_eval, 1e-9),
        "hit_fraction": n["hits"] / n["pairs"] if n["pairs"] else None,
        "techniques": per_tech,
    }


def whole_pass(scene, spec: str, photons: int, seed: int = 0) -> dict:
    """Wall time of one real ``render_pass`` and the hits it evaluated (tally hook)."""
    est = parse_estimator(spec, scene)
    count = [0]

    def tally(tech, hits, prims, rays, raw, val):
        count[0] += len(hits)

    a = time.perf_counter()
    render_pass(scene, est, 0, seed, RenderSettings(photons=photons), tally=tally)
    sec = time.perf_counter() - a
    return {"pass_seconds": sec, "pass_hits": count[0], "pass_hits_per_second": count[0] / sec}


def two_process(scene, spec: str, photons: int, passes: int) -> dict:
    """Passes/s of 2 worker processes vs 1 process (same passes; images bit-identical).

    The pool is started and warmed up (both workers have imported psurf) before the clock
    starts: start-up is paid once per render command, not per pass. The single process runs
    its compiled kernels on numba's threads (``planes`` shares large chunks among them; pool
    workers use one thread each), so it is also timed on one thread: ``seconds_1t``.
    """
    import numba

    from psurf_core.parallel import pass_pool, render_parallel
    from psurf_core.render import render

    est = parse_estimator(spec, scene)
    settings = RenderSettings(photons=photons)
    with pass_pool(2) as pool:
        render_parallel(scene, spec, RenderSettings(photons=64), passes=4, seed=1, pool=pool)
        a = time.perf_counter()
        two = render_parallel(scene, spec, settings, passes=passes, seed=0, pool=pool)
        t2 = time.perf_counter() - a
    threads = numba.get_num_threads()
    a = time.perf_counter()
    one = render(scene, est, settings, passes=passes, seed=0)
    t1 = time.perf_counter() - a
    numba.set_num_threads(1)
    try:
        a = time.perf_counter()
        one_t = render(scene, est, settings, passes=passes, seed=0)
        t1t = time.perf_counter() - a
    finally:
        numba.set_num_threads(threads)
    # The evaluated hits of those passes (counted untimed, through render_pass's tally hook):
    # what the machine delivers per wall second with both cores, whole passes included.
    count = [0]

    def tally(tech, hits, prims, rays, raw, val):
        count[0] += len(hits)

    for i in range(passes):
        render_pass(scene, est, i, 0, settings, tally=tally)
    return {"passes": passes, "photons": photons, "threads": threads, "seconds_1": t1,
            "seconds_1t": t1t, "seconds_2": t2, "speedup": t1 / t2, "speedup_vs_1t": t1t / t2,
            "hits": count[0], "pass_hits_per_second_2": count[0] / t2,
            "pass_hits_per_second_1t": count[0] / t1t,
            "threads_speedup": t1t / t1,
            "bit_identical": bool(all(np.array_equal(o.mean, two.mean)
                                      and np.array_equal(o.var, two.var)
                                      for o in (one, one_t)))}


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


def planes_threads(scene, photons: int, reps: int) -> dict:
    """``planes`` find+eval hits/s (as :func:`stage_pass` counts and times them) on one
    thread and on all of numba's threads, the median of ``reps`` passes each (the two
    interleaved, so other load on the machine hits both alike)."""
    import numba

    threads = numba.get_num_threads()
    rates: dict[int, list] = {1: [], threads: []}
    try:
        for _ in range(reps):
            for th in rates:
                numba.set_num_threads(th)
                rates[th].append(stage_pass(scene, "planes", photons)["hits_per_second"])
    finally:
        numba.set_num_threads(threads)
    return {"photons": photons, "passes": reps, "threads": threads,
            "hits_per_second_1_thread": float(np.median(rates[1])),
            "hits_per_second": float(np.median(rates[threads]))}


_RATES = ("photon_vertices_per_second", "primitives_per_second", "pairs_tested_per_second",
          "hits_evaluated_per_second", "hits_per_second")


def _percent(x) -> str:
    return "n/a" if x is None else f"{100 * x:.0f}%"


def scaling(scene, spec: str, photons: int) -> dict:
    """Rates at 1x/2x/4x photons (scene resolution) and 1x/2x/4x image side (``photons``)."""
    cam = scene.camera
    rows = {"photons": [], "resolution": []}
    for f in (1, 2, 4):
        r = stage_pass(scene, spec, photons * f)
        rows["photons"].append({"factor": f, "photons": photons * f, "pixels": r["pixels"],
                                "pairs": r["pairs"], "hits": r["hits"],
                                **{k: r[k] for k in _RATES}})
        s = with_resolution(scene, cam.width * f, cam.height * f)
        r = stage_pass(s, spec, photons)
        rows["resolution"].append({"factor": f, "photons": photons, "pixels": r["pixels"],
                                   "pairs": r["pairs"], "hits": r["hits"],
                                   **{k: r[k] for k in _RATES}})
    return rows


_MEMORY_SCRIPT = """
import json, resource, sys, time
from dataclasses import replace
sys.path.insert(0, {root!r})
from psurf_core.estimators import parse_estimator
from psurf_core.render import RenderSettings, render_pass
from psurf_core.scene_io import load_scene
scene = load_scene({scene!r})
scene = replace(scene, camera=replace(scene.camera, width=256, height=192))
est = parse_estimator({spec!r}, scene)
import numpy as np
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
count = [0]
def tally(tech, hits, prims, rays, raw, val):
    count[0] += len(hits)
rows = np.arange(0, 192, {row_step})
pixels = (rows[:, None] * 256 + np.arange(256)[None]).ravel()
a = time.perf_counter()
render_pass(scene, est, 0, 0, RenderSettings(photons={photons}), tally=tally, pixels=pixels)
sec = time.perf_counter() - a
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
print(json.dumps(dict(peak=peak, before=before, seconds=sec, hits=count[0])))
"""


def peak_memory(scene_path: str, spec: str, photons: int, row_step: int = 1) -> dict:
    """Peak RSS of a fresh process rendering one pass of ``spec`` at 256x192 (every
    ``row_step``-th image row only: the photons are traced and their primitives created and
    binned exactly as for the whole image, but only those rows' rays are tested)."""
    code = textwrap.dedent(_MEMORY_SCRIPT).format(root=str(ROOT), scene=scene_path, spec=spec,
                                                  photons=photons, row_step=row_step)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    r = json.loads(out.stdout.strip().splitlines()[-1])
    return {"estimator": spec, "photons": photons, "resolution": [256, 192],
            "rows_rendered": len(range(0, 192, row_step)),
            "peak_rss_bytes": r["peak"], "rss_after_imports_bytes": r["before"],
            "seconds": r["seconds"], "hits": r["hits"],
            "pass_hits_per_second": r["hits"] / r["seconds"]}


def _print_scaling(spec: str, rows: dict) -> None:
    for axis in ("photons", "resolution"):
        print(f"  {spec} vs {axis} (x1, x2, x4 {'photons' if axis == 'photons' else 'side'}):")
        print("    factor  pixels   photons      pairs       hits  verts/s  prims/s  "
              "pairs/s   eval/s   hits/s")
        for r in rows[axis]:
            print(f"    {r['factor']:>6} {r['pixels']:>7} {r['photons']:>9} {r['pairs']:>10} "
                  f"{r['hits']:>10} " + " ".join(f"{r[k]:8.2e}" for k in _RATES))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="scenes/area.toml")
    ap.add_argument("--photons", type=int, default=5000)
    ap.add_argument("--estimators",
                    default="planes,plane-t1t2,plane-t1t3,cone,cylinder,points,bre,beams,"
                            "paper-multi")
    ap.add_argument("--scaling", default="planes:2000,paper-multi:400",
                    help="ESTIMATOR:PHOTONS,... for the doubling tables ('' for none)")
    ap.add_argument("--memory-photons", type=int, default=1_000_000,
                    help="photons of the peak-memory pass at 256x192 (0 skips it)")
    ap.add_argument("--parallel-estimators", default="planes,paper-multi",
                    help="estimators of the 1-vs-2-process comparison")
    ap.add_argument("--memory-row-step", type=int, default=32,
                    help="the 10^6-photon memory pass renders every N-th row")
    ap.add_argument("--trace-passes", type=int, default=5,
                    help="warm passes of the trace row (median)")
    ap.add_argument("--planes-reps", type=int, default=5,
                    help="passes of the planes threads comparison (median)")
    ap.add_argument("--parallel-passes", type=int, default=8,
                    help="passes of the 1-vs-2-process comparison (0 skips it)")
    ap.add_argument("--quick", action="store_true",
                    help="small sizes: 2000 photons, 10^5 memory photons, no scaling")
    ap.add_argument("--out", default="out/bench.json")
    args = ap.parse_args(argv)
    if args.quick:
        args.photons, args.memory_photons, args.scaling = 2000, 100_000, ""
    scene = load_scene(args.scene)
    cmd = "python benchmarks/run.py " + " ".join(sys.argv[1:] if argv is None else argv)
    print(f"# {cmd}\n# {args.scene}: {scene.camera.width}x{scene.camera.height}, "
          f"{args.photons} photons, one pass, one process")
    results = {}
    for spec in args.estimators.split(","):
        # Warm-up: compiled kernels (numba) load from their cache on first use.
        stage_pass(scene, spec, 64)
        r = stage_pass(scene, spec, args.photons)
        r.update(whole_pass(scene, spec, args.photons))
        results[spec] = r
        s = r["seconds"]
        print(f"{spec:>12}: {r['hits_per_second']:9.3g} hits/s (find+eval), "
              f"{r['pass_hits_per_second']:9.3g} hits/s (whole pass) | "
              f"{r['pairs']:>9} pairs -> {r['hits']:>9} hits "
              f"({_percent(r['hit_fraction'])}) | s: " + " ".join(
                  f"{k} {s[k]:.2f}" for k in STAGES) + f" | pass {r['pass_seconds']:.2f}")
        for name, pt in r["techniques"].items():
            if len(r["techniques"]) > 1:
                print(f"{'':>14}{name:>16}: {pt['pairs']:>9} pairs {pt['hits']:>9} hits | "
                      + " ".join(f"{k} {pt[k]:.2f}" for k in STAGES[1:]))
    vert = trace_rate(scene, max(args.photons, 4 * PHOTON_BATCH), args.trace_passes)
    lo, hi = vert["photon_vertices_per_second_range"]
    print(f"trace: {vert['photon_vertices_per_second']:.3g} vertices/s (median of "
          f"{vert['passes']} warm passes x {vert['photons']} photons, {lo:.3g}-{hi:.3g}; "
          f"first pass {vert['photon_vertices_per_second_first_pass']:.3g}; "
          f"{vert['vertices_per_pass']} vertices per pass)")
    out = {
        "command": cmd,
        "machine": {"cpus": __import__("os").cpu_count(), "python": platform.python_version(),
                    "numpy": np.__version__},
        "scene": args.scene,
        "photons": args.photons,
        "hits_per_second": {k: v["hits_per_second"] for k, v in results.items()},
        "pass_hits_per_second": {k: v["pass_hits_per_second"] for k, v in results.items()},
        "photon_vertices_per_second": vert["photon_vertices_per_second"],
        "trace": vert,
        "estimators": results,
    }
    if "planes" in args.estimators.split(","):
        # One pass is a single noisy sample on a shared machine: the median of several, and
        # what the threads bring.
        pt = out["planes_threads"] = planes_threads(scene, args.photons, args.planes_reps)
        print(f"planes find+eval, median of {pt['passes']} passes x {pt['photons']} photons: "
              f"{pt['hits_per_second']:.3g} hits/s with numba's {pt['threads']} threads (used "
              f"where other processes leave cores idle), {pt['hits_per_second_1_thread']:.3g} "
              f"on 1")
    if args.parallel_passes:
        out["two_process"] = {}
        for spec in filter(None, args.parallel_estimators.split(",")):
            # paper-multi passes are ~8x longer: fewer photons keep this step short. planes
            # passes of a few thousand photons take ~0.1 s, the scale of a task's round trip
            # to a worker: 10^4 photons or more, so that the passes' own work is timed.
            n = (max(args.photons, 10_000) if spec == "planes"
                 else max(args.photons // 8, 1))
            tp = out["two_process"][spec] = two_process(scene, spec, n, args.parallel_passes)
            print(f"2 processes vs 1, {spec}, {tp['passes']} passes x {n} photons: "
                  f"{tp['speedup']:.2f}x vs 1 process on {tp['threads']} threads, "
                  f"{tp['speedup_vs_1t']:.2f}x vs 1 thread ({tp['seconds_1']:.1f} s, "
                  f"{tp['seconds_1t']:.1f} s -> {tp['seconds_2']:.1f} s; "
                  f"bit-identical: {tp['bit_identical']}); whole passes: "
                  f"{tp['pass_hits_per_second_2']:.3g} hits/s on 2 processes, "
                  f"{tp['pass_hits_per_second_1t']:.3g} on 1 thread")
    out["scaling"] = {}
    for item in filter(None, args.scaling.split(",")):
        spec, _, n = item.partition(":")
        out["scaling"][spec] = scaling(scene, spec, int(n or 2000))
        _print_scaling(spec, out["scaling"][spec])
    if args.memory_photons:
        # A whole 10^6-photon pass at 256x192 evaluates ~2e9 plane hits (too long for a
        # benchmark): the photon side (tracing, creation, binning of every primitive) runs
        # in full with every 32nd row's rays; the pair side (chunks of max_pairs) runs in full
        # over the whole image with 1/50 of the photons. Peak = the larger of the two.
        runs = [peak_memory(args.scene, "planes", args.memory_photons, args.memory_row_step),
                peak_memory(args.scene, "planes", max(args.memory_photons // 50, 1), 1)]
        out["memory"] = runs
        out["peak_memory_bytes"] = max(m["peak_rss_bytes"] for m in runs)
        for m in runs:
            print(f"peak RSS {m['peak_rss_bytes'] / 2**20:.0f} MiB: one planes pass, "
                  f"{m['photons']} photons, 256x192, {m['rows_rendered']} rows rendered "
                  f"({m['seconds']:.1f} s, {m['hits']} hits, "
                  f"{m['pass_hits_per_second']:.3g} hits/s)")
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=2))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
