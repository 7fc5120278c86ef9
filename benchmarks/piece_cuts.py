"""Equal pieces against large-pieces-first, in one process: how a pass's shared jobs are cut
between the two threads (``kernels.threads.guided_cut``, ``kernels.fused.CHUNK_CUT``).

Each round runs one ``stages.stage_pass`` (as ``make bench`` times it) under each cut, the
order alternating, so that the machine's drift hits both alike; it prints per cut the
medians of hits a wall second and of CPU ns a hit, and with ``--paired`` the CPU-per-hit
ratio of ``paper-multi`` over ``planes`` from passes back to back (``make bench``'s ratio).
The cuts: ``equal`` (a walk chunk in 8 equal pieces, every other job in equal pieces: the
code before 2026-12-07) and ``guided`` (the code's own).

Usage::

    python benchmarks/piece_cuts.py [--spec planes] [--photons 5000] [--rounds 30]
        [--threads 2] [--paired] [--scene scenes/area.toml]
    python benchmarks/piece_cuts.py --spec paper-multi --rounds 10
    python benchmarks/piece_cuts.py --paired --rounds 16

Not a test: the times move with the machine's load (docs/study.md, "Large pieces first").
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
from contextlib import contextmanager

import numba
import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from benchmarks.stages import stage_pass, warm_up  # noqa: E402
from psurf_core.kernels import fused, threads  # noqa: E402
from psurf_core.scene_io import load_scene  # noqa: E402

#: Per cut: (``threads.GUIDED_RATIO``, ``fused.CHUNK_CUT``).
CUTS = {"equal": (1.0, np.linspace(0.0, 1.0, 9)),
        "guided": (threads.GUIDED_RATIO, fused.CHUNK_CUT)}


@contextmanager
def cut(name: str):
    """The code runs with cut ``name`` of :data:`CUTS` inside the block."""
    old = threads.GUIDED_RATIO, fused.CHUNK_CUT
    threads.GUIDED_RATIO, fused.CHUNK_CUT = CUTS[name]
    try:
        yield
    finally:
        threads.GUIDED_RATIO, fused.CHUNK_CUT = old


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default="scenes/area.toml")
    ap.add_argument("--spec", default="planes")
    ap.add_argument("--photons", type=int, default=5000)
    ap.add_argument("--rounds", type=int, default=30)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--paired", action="store_true",
                    help="paper-multi / planes CPU per hit, passes back to back")
    args = ap.parse_args(argv)
    numba.set_num_threads(args.threads)
    scene = load_scene(args.scene)
    specs = ("planes", "paper-multi") if args.paired else (args.spec,)
    for spec in specs:
        warm_up(scene, spec, args.photons)
    got = {c: {s: {"hits_per_second": [], "cpu_ns_per_hit": []} for s in specs} for c in CUTS}
    for r in range(args.rounds):
        for c in (list(CUTS) if r % 2 == 0 else list(CUTS)[::-1]):
            with cut(c):
                for s in (specs if r % 2 == 0 else specs[::-1]):
                    res = stage_pass(scene, s, args.photons, seed=r)
                    for k in ("hits_per_second", "cpu_ns_per_hit"):
                        got[c][s][k].append(res[k])
    print(f"# python benchmarks/piece_cuts.py {' '.join(sys.argv[1:] if argv is None else argv)}")
    med = statistics.median
    for s in specs:
        for c in CUTS:
            g = got[c][s]
            print(f"{s:>12} {c:>7}: {med(g['hits_per_second']):.4g} hits/s, "
                  f"{med(g['cpu_ns_per_hit']):.2f} CPU ns a hit (medians of {args.rounds})")
        h = {c: med(got[c][s]["hits_per_second"]) for c in CUTS}
        print(f"{s:>12} guided / equal hits/s: {h['guided'] / h['equal']:.3f}x")
    if args.paired:
        for c in CUTS:
            ratios = [m / p for m, p in zip(got[c]["paper-multi"]["cpu_ns_per_hit"],
                                            got[c]["planes"]["cpu_ns_per_hit"], strict=True)]
            print(f"CPU per hit, paper-multi / planes, {c}: {med(ratios):.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
