"""What an MIS set's weights cost each member's walk: the walker with its weight, with only
the reconstructed path kept (the weight a constant that reads it), and with no MIS at all.

Usage::

    python benchmarks/mis_cost.py [SCENE.toml] [--spec paper-multi] [--photons 625]
        [--rounds 8] [--threads 1]
    python benchmarks/mis_cost.py scenes/area.toml --spec paper-multi

One batch of photons is traced and its primitives created once (``pass_breakdown.prepare``);
every round then runs each variant's compiled pass of the set (the order rotated each round,
so load drift hits every variant alike; variants are built by replacing
``kernels.fused.weight_of``, and compile in the first round). Per member it prints the
walker's CPU ns a hit (medians of the rounds after the first two): the full weight, the
reconstruction alone ("full - reconstruct only" is the densities and the heuristic) and no MIS
("reconstruct only - no MIS" is rebuilding the hit's path and its pdfs). The hits are the same
in every variant. Not a test: the times move with the machine's load.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import numba  # noqa: E402

from benchmarks import pass_breakdown as pb  # noqa: E402
from psurf_core.kernels import fused  # noqa: E402
from psurf_core.kernels import mis as kmis  # noqa: E402
from psurf_core.kernels import walk as kwalk  # noqa: E402
from psurf_core.kernels.jit import inline  # noqa: E402
from psurf_core.scene_io import load_scene  # noqa: E402

VARIANTS = ("full", "reconstruct only", "no MIS")


@inline
def _row_only(row, params, shares):  # pragma: no cover - compiled
    # 1, but read from every length and flight / direction pdf of the reconstructed path, so
    # that LLVM drops none of its rebuilding. (Until 2026-12-07 it read t1, t2, pdf.t1 and
    # pdf.w2 only: a cylinder hit's new pdf.t2, one exponential, was dropped, and its
    # "reconstruct only" read 1.9 ns above "no MIS" against a cone's 9.6.)
    # A comparison, not 0 * the sum: the fields beyond the light are NaN where K = 2.
    p = row.pdf
    x = (row.t1 + row.t2 + row.t3 + p.e1 + p.e2 + p.e3 + p.t1 + p.t2 + p.t3 + p.w1 + p.w2
         + p.c1)
    return 2.0 if x == -1.2345e300 else 1.0


def weight_variant(kind: str, real=fused.weight_of):
    """``fused.weight_of`` for variant ``kind`` of :data:`VARIANTS` (keys of their own, so
    every variant's walkers are built once)."""
    def weight_of(group, me, weighting):
        w, key = real(group, me, weighting)
        if kind == "full" or w is None:
            return w, key
        if kind == "no MIS":
            return kmis.Weight(kwalk._no_shares, kwalk._unweighted), (key, kind)
        return kmis.Weight(w.shares, _row_only), (key, kind)
    return weight_of


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scene", nargs="?", default="scenes/area.toml")
    ap.add_argument("--spec", default="paper-multi")
    ap.add_argument("--photons", type=int, default=625)
    ap.add_argument("--rounds", type=int, default=8)
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args(argv)
    numba.set_num_threads(args.threads)
    jobs = pb.prepare(load_scene(args.scene), args.spec, args.photons)
    cpu: dict = {}
    hits: dict = {}
    real = fused.weight_of
    try:
        with pb.instrumented():
            for r in range(max(args.rounds, 3)):
                for kind in VARIANTS[r % 3:] + VARIANTS[:r % 3]:
                    fused.weight_of = weight_variant(kind, real)
                    for t, v in pb.run_pass(jobs).items():
                        cpu.setdefault((t, kind), []).append(v["walker_cpu"])
                        hits[t] = v["hits"]
    finally:
        fused.weight_of = real
    print(f"# python benchmarks/mis_cost.py {' '.join(sys.argv[1:])}")
    print(f"# {args.scene}, {args.spec}, {args.photons} photons, numba on {args.threads} "
          "thread(s); walker CPU ns a hit, medians of rounds 3..")
    print(f"{'member':16s}" + "".join(f"{k:>18s}" for k in VARIANTS))
    for t in hits:
        vals = [1e9 * statistics.median(cpu[(t, k)][2:]) / max(hits[t], 1) for k in VARIANTS]
        print(f"{t:16s}" + "".join(f"{v:18.1f}" for v in vals))
    return 0


if __name__ == "__main__":
    sys.exit(main())
