"""What an MIS set's members cost per hit alone and inside the set: the price of the MIS weight.

For an MIS preset (e.g. ``fast-multi``) and each of its members run alone, one pass at a time
in alternating rounds in one process (:func:`benchmarks.stages.stage_pass`, numba on one
thread, so CPU time is the walk's own), prints per member: hits per swept photon, the walk's
CPU ns per hit alone and inside the set (the difference is what its MIS weight costs: the
path row at the hit and every member's ``density``), and the set's walk CPU per photon with
the members' sample counts (``@share``) applied, against the first member alone. Medians over
the rounds after the first (the first pass of a process pays for cold buffers).

Usage::

    python benchmarks/member_cost.py SCENE.toml KMIN KMAX SPEC [--photons 2000] [--rounds 4]
    python benchmarks/member_cost.py scenes/study_medium.toml 2 3 fast-multi

Not a test: CPU time still moves with the machine's load (shared caches); compare within
one run.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import numba  # noqa: E402

from benchmarks.scene_args import add_scene_args, scene_of  # noqa: E402
from benchmarks.stages import stage_pass  # noqa: E402
from psurf_core.estimators import parse_estimator  # noqa: E402


def _walk(res: dict, name: str) -> tuple[float, int]:
    t = res["techniques"][name]
    return t.get("walk_cpu", 0.0), t["hits"]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_scene_args(ap)
    ap.add_argument("spec", help="an MIS set or preset with one group")
    ap.add_argument("--photons", type=int, default=2000)
    ap.add_argument("--rounds", type=int, default=4)
    args = ap.parse_args(argv)
    numba.set_num_threads(1)
    scene = scene_of(args)
    est = parse_estimator(args.spec, scene)
    (group, full), = est.sets
    shares = {m.name: float(getattr(m, "share", 1.0)) for m in group}
    names = [m.name for m in group]
    alone = {n: {"ns": [], "hits": 0} for n in names}
    inset = {n: {"ns": [], "hits": 0} for n in names}
    for spec in [args.spec, *names]:
        stage_pass(scene, spec, 200)  # kernels loaded, buffers allocated
    for r in range(args.rounds):
        res = stage_pass(scene, args.spec, args.photons, seed=r)
        for n in names:
            cpu, hits = _walk(res, n)
            if r:
                inset[n]["ns"].append(1e9 * cpu / max(hits, 1))
            inset[n]["hits"] = hits
        for n in names:
            cpu, hits = _walk(stage_pass(scene, n, args.photons, seed=r), n)
            if r:
                alone[n]["ns"].append(1e9 * cpu / max(hits, 1))
            alone[n]["hits"] = hits
    print(f"# {args.scene} K={args.kmin}..{args.kmax}, {args.spec}, {args.photons} photons a "
          f"pass, medians of rounds 2..{args.rounds}, numba on 1 thread, CPU time")
    print(f"{'member':<22} {'share':>5} {'hits/photon':>11} {'ns/hit alone':>12} "
          f"{'ns/hit in set':>13} {'MIS weight ns':>13}")
    per_photon_set = per_photon_alone = 0.0
    for n in names:
        h = alone[n]["hits"] / args.photons
        a, s = statistics.median(alone[n]["ns"]), statistics.median(inset[n]["ns"])
        print(f"{n:<22} {shares[n]:5.2f} {h:11.1f} {a:12.1f} {s:13.1f} {s - a:13.1f}")
        per_photon_set += shares[n] * h * s
        per_photon_alone += shares[n] * h * a
    first = names[0]
    base = alone[first]["hits"] / args.photons * statistics.median(alone[first]["ns"])
    print(f"walk CPU per photon: the set {per_photon_set / 1e3:.2f} us "
          f"({per_photon_set / base:.2f}x {first} alone; {per_photon_alone / base:.2f}x "
          f"with its members' hits unweighted)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
