"""Wall and CPU time of whole passes, and the cores they keep busy (docs/study.md).

``render_pass`` (the path ``compare`` takes) timed ``--passes`` times after three warm passes,
per estimator at its own photon count (e.g. the pass sizes a ``compare`` run chose), medians.

Usage::

    python benchmarks/pass_wall_cpu.py SCENE.toml KMIN KMAX SPEC:PHOTONS [SPEC:PHOTONS ...]
    python benchmarks/pass_wall_cpu.py scenes/study_medium.toml 2 3 planes:652 fast-multi:1404
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from benchmarks.scene_args import add_scene_args, scene_of  # noqa: E402
from psurf_core.estimators import parse_estimator  # noqa: E402
from psurf_core.render import RenderSettings, render_pass  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_scene_args(ap)
    ap.add_argument("specs", nargs="+", help="SPEC:PHOTONS")
    ap.add_argument("--passes", type=int, default=40)
    ap.add_argument("--rounds", type=int, default=2, help="each spec this many times, in turn")
    a = ap.parse_args()
    scene = scene_of(a)
    print("# python benchmarks/pass_wall_cpu.py " + " ".join(sys.argv[1:]))
    for _ in range(a.rounds):
        for item in a.specs:
            spec, n = item.rsplit(":", 1)
            est, st = parse_estimator(spec, scene), RenderSettings(photons=int(n), spp=1)
            for i in range(3):
                render_pass(scene, est, i, 1, st)
            wall, cpu = [], []
            for i in range(a.passes):
                t0, c0 = time.perf_counter(), time.process_time()
                render_pass(scene, est, 100 + i, 1, st)
                wall.append(time.perf_counter() - t0)
                cpu.append(time.process_time() - c0)
            w, c = float(np.median(wall)), float(np.median(cpu))
            print(f"{spec:>24} {int(n):6d} photons: wall {w * 1e3:7.2f} ms, CPU {c * 1e3:7.2f} ms,"
                  f" {c / w:.2f} cores, {w / int(n) * 1e6:6.1f} us of wall a photon")


if __name__ == "__main__":
    main()
