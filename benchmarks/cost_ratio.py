"""``make bench``'s CPU-per-hit ratio (``paper-multi`` over ``planes``) in several checkouts,
run alternately, so that a change's effect on the ratio is told from the machine's drift.

Usage::

    python benchmarks/cost_ratio.py TREE [TREE ...] [--scene scenes/area.toml]
        [--photons 5000] [--rounds 5] [--alternations 2]
    git worktree add /tmp/old 8a94a85
    python benchmarks/cost_ratio.py /tmp/old .

Each alternation runs one child process per tree, in turn; a child puts its tree first on
``sys.path`` and calls that tree's :func:`benchmarks.stages.paired_cost_ratio` with
``run.py``'s arguments (numba on 2 threads), so each checkout is measured by its own code.
It prints the ratio (the median of the rounds), each round's, and the CPU ns a hit of both.
Not a test: the figures move with the machine's load; compare the trees of one run.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

_CHILD = r"""
import sys, os, json
tree = sys.argv[1]
sys.path.insert(0, tree)
os.chdir(tree)
import numba
numba.set_num_threads(2)
from benchmarks.stages import paired_cost_ratio
from psurf_core.scene_io import load_scene
r = paired_cost_ratio(load_scene(sys.argv[2]), "planes", "paper-multi", int(sys.argv[3]),
                      int(sys.argv[4]))
print(json.dumps(r))
"""


def measure(tree: str, scene: str, photons: int, rounds: int) -> dict:
    """One child's :func:`~benchmarks.stages.paired_cost_ratio` in checkout ``tree``."""
    out = subprocess.run([sys.executable, "-c", _CHILD, os.path.abspath(tree), scene,
                          str(photons), str(rounds)], capture_output=True, text=True,
                         check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("trees", nargs="+")
    ap.add_argument("--scene", default="scenes/area.toml")
    ap.add_argument("--photons", type=int, default=5000)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--alternations", type=int, default=2)
    args = ap.parse_args(argv)
    print(f"# python benchmarks/cost_ratio.py {' '.join(sys.argv[1:])}")
    for _ in range(args.alternations):
        for tree in args.trees:
            r = measure(tree, args.scene, args.photons, args.rounds)
            ns = r["cpu_ns_per_hit"]
            print(f"{tree}: ratio {r['ratio']:.3f} (rounds "
                  + ", ".join(f"{x:.2f}" for x in r["each_ratio"]) + "); CPU ns a hit: planes "
                  + ", ".join(f"{x:.1f}" for x in ns["planes"]) + "; paper-multi "
                  + ", ".join(f"{x:.1f}" for x in ns["paper-multi"]), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
