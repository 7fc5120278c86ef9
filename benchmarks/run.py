"""Throughput of every stage per estimator, the headline rates, and the slower tables;
writes ``out/bench.json``.

Usage: ``python benchmarks/run.py [--scene scenes/area.toml] [--photons N] [--estimators a,b]
[--reps R] [--quick]`` (``make bench``, ``make bench-quick``). Nothing here is a test: numbers
depend on the machine and on whatever else runs on it (the JSON keeps the command line and
the load average; compare runs made back to back, as ratios).

Headline (``out/bench.json`` key ``headline``), each the **median of ``--reps`` warm passes**
(compiled kernels loaded, buffers allocated; :func:`benchmarks.stages.steady`), in one process
whose compiled walkers run on numba's threads (on the cores other processes leave idle):

* ``hits_per_second.<spec>``: evaluated hits (shaded, shadow tests and MIS weights included)
  per wall second of finding and evaluating them;
* ``cpu_ns_per_hit.<spec>``: CPU nanoseconds (all threads) per evaluated hit, the same
  work; ``hit_cost_ratio``: ``paper-multi``'s over ``planes``', the median of rounds that
  run one pass of each back to back (:func:`benchmarks.stages.paired_cost_ratio`; the ratio
  of the two steady medians is ``hit_cost_ratio_separate_runs``);
* ``photon_vertices_per_second``: Trace alone in render's batches
  (:func:`benchmarks.stages.trace_rate`; its range and first pass in ``trace``).

Beside them, ``machine.units``: :func:`benchmarks.machine_probe.units_reading` before and
after the headline, whether the two vCPUs shared one core's units then (a slower thread at
~1.3x / 2x / 2x on the three loops, against ~1.0x on two cores of their own); and
``machine.walker_by_cpu``: a one-thread ``planes`` pass on each CPU alone
(:func:`walker_by_cpu`), whether one vCPU runs the walker slower than the other.

Also per technique (:func:`benchmarks.stages.stage_pass`), 1 vs 2 processes, tables per
doubling of photons and image side, and the peak RSS of a 10^6-photon pass at 256x192
(:mod:`benchmarks.extras`).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from benchmarks import bench_compare, extras, machine_probe, pass_breakdown  # noqa: E402
from benchmarks.stages import paired_cost_ratio, steady, trace_rate  # noqa: E402
from psurf_core.render import PHOTON_BATCH  # noqa: E402
from psurf_core.scene_io import load_scene  # noqa: E402

#: The issue's targets (12): hits/s per estimator, vertices/s, CPU cost ratio per hit.
TARGETS = {"planes": 4e7, "paper-multi": 2e7, "paper-single": 1e7}
TRACE_TARGET, RATIO_TARGET = 1e7, 1.5


def _print_run(spec: str, r: dict) -> None:
    last = r["last"]
    print(f"{spec:>14}: {r['hits_per_second']:9.3g} hits/s, {r['cpu_ns_per_hit']:6.1f} CPU "
          f"ns/hit (median of {r['passes']}; each: "
          + ", ".join(f"{x:.3g}" for x in r["each"]["hits_per_second"]) + ")")
    for name, pt in last["techniques"].items():
        frac = "" if pt["hit_fraction"] is None else f" ({100 * pt['hit_fraction']:.0f}%)"
        print(f"{'':>16}{name:>18}: {'compiled' if pt['compiled'] else 'numpy   '} "
              f"{pt['prims']:>7} prims {pt['candidates']:>10} pairs -> {pt['hits']:>9} hits"
              f"{frac}, {pt['cpu_ns_per_hit']:6.1f} CPU ns/hit")


def walker_by_cpu(jobs) -> dict:
    """:func:`benchmarks.machine_probe.cpu_speeds` of one compiled pass of ``jobs``
    (``pass_breakdown.prepare``'s: photons traced and created once) on one thread."""
    return machine_probe.cpu_speeds(lambda: pass_breakdown.run_pass(jobs))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="scenes/area.toml")
    ap.add_argument("--photons", type=int, default=5000)
    ap.add_argument("--estimators", default="planes,plane-t1t2,plane-t1t3,cone,cylinder,beams,"
                                            "paper-single,paper-multi")
    ap.add_argument("--reps", type=int, default=5, help="warm passes per estimator (median)")
    ap.add_argument("--scaling", default="planes:2000,paper-multi:400",
                    help="ESTIMATOR:PHOTONS,... for the doubling tables ('' for none)")
    ap.add_argument("--memory-photons", type=int, default=1_000_000,
                    help="photons of the peak-memory pass at 256x192 (0 skips it)")
    ap.add_argument("--memory-row-step", type=int, default=32,
                    help="the 10^6-photon memory pass renders every N-th row")
    ap.add_argument("--parallel-estimators", default="planes,paper-multi",
                    help="estimators of the 1-vs-2-process comparison")
    ap.add_argument("--parallel-passes", type=int, default=8,
                    help="passes of the 1-vs-2-process comparison (0 skips it)")
    ap.add_argument("--quick", action="store_true",
                    help="small sizes: 2000 photons, 3 reps, 10^5 memory photons, no scaling, "
                         "no process comparison")
    ap.add_argument("--out", default="out/bench.json")
    ap.add_argument("--compare", default=None, metavar="PREVIOUS.json",
                    help="the run to compare the headline with (default: --out's file as it "
                         "was before this run, when there is one)")
    args = ap.parse_args(argv)
    previous = bench_compare.load_previous(args.compare or args.out)
    if args.compare and previous is None:
        ap.error(f"--compare {args.compare}: no such file, or not a bench.json")
    if args.quick:
        args.photons, args.reps, args.memory_photons = 2000, 3, 100_000
        args.scaling, args.parallel_passes = "", 0
    scene = load_scene(args.scene)
    cmd = "python benchmarks/run.py " + " ".join(sys.argv[1:] if argv is None else argv)
    import numba

    print(f"# {cmd}\n# {args.scene}: {scene.camera.width}x{scene.camera.height}, "
          f"{args.photons} photons per pass, one process, numba threads "
          f"{numba.get_num_threads()}, load average {os.getloadavg()[0]:.2f}")
    # Whether the two vCPUs share one core's units now (benchmarks/machine_probe.py): the
    # same code read 2.8-3.8e7 planes hits/s minutes apart on this machine, and the probe
    # read 1.0x and 2.0x within a minute. Read before and after the headline, and kept.
    units = {"before": machine_probe.units_reading()}
    print("# two threads at once / alone (machine_probe.py's units), before: "
          + machine_probe.units_line(units["before"]))
    # Each vCPU alone on a walker's pass: one often ran it 1.3x slower than the other while
    # the units read 1.0x (docs/study.md, "Large pieces first").
    planes_pass = pass_breakdown.prepare(scene, "planes", args.photons)
    cpus = {"before": walker_by_cpu(planes_pass)}
    print("# a one-thread planes pass on each CPU alone, before: "
          + machine_probe.cpu_speeds_line(cpus["before"]))
    results = {spec: steady(scene, spec, args.photons, args.reps)
               for spec in args.estimators.split(",")}
    for spec, r in results.items():
        _print_run(spec, r)
    vert = trace_rate(scene, max(args.photons, 4 * PHOTON_BATCH), args.reps)
    lo, hi = vert["photon_vertices_per_second_range"]
    print(f"trace: {vert['photon_vertices_per_second']:.3g} vertices/s (median of "
          f"{vert['passes']} warm passes x {vert['photons']} photons, {lo:.3g}-{hi:.3g}; "
          f"first pass {vert['photon_vertices_per_second_first_pass']:.3g})")
    head = {
        "hits_per_second": {k: v["hits_per_second"] for k, v in results.items()},
        "cpu_ns_per_hit": {k: v["cpu_ns_per_hit"] for k, v in results.items()},
        "photon_vertices_per_second": vert["photon_vertices_per_second"],
    }
    paired = None
    if "planes" in results and "paper-multi" in results:
        # Back to back (stages.paired_cost_ratio): the two estimators' steady medians are
        # measured tens of seconds apart, and this machine's speed moves in that time.
        paired = paired_cost_ratio(scene, "planes", "paper-multi", args.photons, args.reps)
        head["hit_cost_ratio"] = paired["ratio"]
        head["hit_cost_ratio_separate_runs"] = (results["paper-multi"]["cpu_ns_per_hit"]
                                                / results["planes"]["cpu_ns_per_hit"])
        print("CPU per hit, paper-multi / planes, passes back to back: "
              + ", ".join(f"{x:.2f}" for x in paired["each_ratio"])
              + f" (median {paired['ratio']:.2f}; from the two steady medians: "
              f"{head['hit_cost_ratio_separate_runs']:.2f})")
    units["after"] = machine_probe.units_reading()
    print("# two threads at once / alone (machine_probe.py's units), after: "
          + machine_probe.units_line(units["after"]))
    cpus["after"] = walker_by_cpu(planes_pass)
    print("# a one-thread planes pass on each CPU alone, after: "
          + machine_probe.cpu_speeds_line(cpus["after"]))
    print("\nheadline (median of warm passes)            measured     target")
    for spec, target in TARGETS.items():
        if spec in results:
            print(f"  {spec + ' hits/s':<40} {results[spec]['hits_per_second']:10.3g} "
                  f"{'>=':>4} {target:.0e}")
    print(f"  {'trace vertices/s':<40} {head['photon_vertices_per_second']:10.3g} "
          f"{'>=':>4} {TRACE_TARGET:.0e}")
    if "hit_cost_ratio" in head:
        print(f"  {'CPU per hit, paper-multi / planes':<40} {head['hit_cost_ratio']:10.2f} "
              f"{'<=':>4} {RATIO_TARGET}")
    out = {
        "command": cmd,
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version(),
                    "numpy": np.__version__, "numba_threads": numba.get_num_threads(),
                    "load_average": os.getloadavg(), "units": units,
                    "walker_by_cpu": cpus},
        "scene": args.scene, "photons": args.photons, "reps": args.reps,
        "headline": head, "targets": {"hits_per_second": TARGETS, "trace": TRACE_TARGET,
                                      "hit_cost_ratio": RATIO_TARGET},
        "trace": vert, "estimators": results, "hit_cost_ratio": paired,
    }
    if args.parallel_passes:
        out["two_process"] = {}
        for spec in filter(None, args.parallel_estimators.split(",")):
            n = max(args.photons, 10_000) if spec == "planes" else max(args.photons // 8, 1)
            tp = out["two_process"][spec] = extras.two_process(scene, spec, n,
                                                               args.parallel_passes)
            print(f"2 processes vs 1, {spec}, {tp['passes']} passes x {n} photons: "
                  f"{tp['speedup']:.2f}x vs 1 process on {tp['threads']} threads, "
                  f"{tp['speedup_vs_1t']:.2f}x vs 1 thread (bit-identical: "
                  f"{tp['bit_identical']}); whole passes: {tp['pass_hits_per_second_2']:.3g} "
                  f"hits/s on 2 processes, {tp['pass_hits_per_second_1t']:.3g} on 1 thread")
    out["scaling"] = {}
    for item in filter(None, args.scaling.split(",")):
        spec, _, n = item.partition(":")
        out["scaling"][spec] = extras.scaling(scene, spec, int(n or 2000))
        extras._print_scaling(spec, out["scaling"][spec])
    if args.memory_photons:
        runs = [extras.peak_memory(args.scene, "planes", args.memory_photons,
                                   args.memory_row_step),
                extras.peak_memory(args.scene, "planes", max(args.memory_photons // 50, 1), 1)]
        out["memory"] = runs
        out["peak_memory_bytes"] = max(m["peak_rss_bytes"] for m in runs)
        for m in runs:
            print(f"peak RSS {m['peak_rss_bytes'] / 2**20:.0f} MiB: one planes pass, "
                  f"{m['photons']} photons, 256x192, {m['rows_rendered']} rows rendered")
    if previous is not None:
        rows = bench_compare.compare(out, previous)
        print(bench_compare.report(rows, previous))
        out["against_previous"] = {"command": previous.get("command"), "rows": rows}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(args.out).with_suffix(".json.part")  # whole or not at all
    tmp.write_text(json.dumps(out, indent=2, default=float))
    tmp.replace(args.out)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
