"""Where the wall time of whole passes goes, phase by phase: the trace, each member's Create
and walk (with the members' shares applied, as ``render_pass`` runs them), and the rest; wall
and CPU time of each, and the cores it kept busy.

``render_pass`` itself runs (the path ``compare`` takes), with clocks around ``trace``, each
technique's ``create`` and the compiled walk of each (``fused_pass``'s chunks), so the phases
are the real ones, threads included. The serial phases (one core) are what a pass cannot
spread over two cores; the walks' serial addition to the image (of their compact rows,
``fused.accumulate``, or of their pieces' own images, ``fused.add_images``) is printed beside
them. Medians are not taken: the sums over ``--passes`` passes after three warm ones, per
pass.

Usage::

    python benchmarks/pass_phases.py SCENE.toml KMIN KMAX SPEC [--photons 1404] [--passes 20]
    python benchmarks/pass_phases.py scenes/study_medium.toml 2 3 fast-multi --photons 1404

Not a test: times move with the machine's load; compare within one run.
"""

from __future__ import annotations

import argparse
import collections
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import psurf_core.kernels.fused as F  # noqa: E402
import psurf_core.render as R  # noqa: E402
from benchmarks.scene_args import add_scene_args, scene_of  # noqa: E402
from psurf_core.estimators import parse_estimator  # noqa: E402


def _clocked(table, name, fn):
    """``fn`` with its wall and CPU (this process) time added to ``table[name]``."""

    def run(*a, **k):
        w, c = time.perf_counter(), time.process_time()
        try:
            return fn(*a, **k)
        finally:
            table[name][0] += time.perf_counter() - w
            table[name][1] += time.process_time() - c

    return run


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_scene_args(ap)
    ap.add_argument("spec")
    ap.add_argument("--photons", type=int, default=1404)
    ap.add_argument("--passes", type=int, default=20)
    a = ap.parse_args(argv)
    scene = scene_of(a)
    est = parse_estimator(a.spec, scene)
    phases = collections.defaultdict(lambda: [0.0, 0.0])

    R.trace = _clocked(phases, "trace", R.trace)
    fused = R.fused_pass

    def fused_pass(tech, *args, **kw):
        chunks = fused(tech, *args, **kw)
        if chunks is None:
            return None

        def walk():
            yield from _clocked(phases, f"walk {tech.name}", lambda: list(chunks))()

        return walk()

    R.fused_pass = fused_pass
    # The addition to the image of the compact rows or of the pieces' own images, one core,
    # between a chunk's walk and the next: inside the walk phases above, printed beside them.
    inner = collections.defaultdict(lambda: [0.0, 0.0])
    F.accumulate = _clocked(inner, "image addition (in the walks)", F.accumulate)
    F.add_images = _clocked(inner, "image addition (in the walks)", F.add_images)
    for group, _ in est.sets:
        for tech in group:
            tech.create = _clocked(phases, f"create {tech.name}", tech.create)

    settings = R.RenderSettings(photons=a.photons)
    for i in range(3):  # warm: compiled kernels, buffers
        R.render_pass(scene, est, i, 1, settings)
    phases.clear()
    inner.clear()
    w0, c0 = time.perf_counter(), time.process_time()
    for i in range(a.passes):
        R.render_pass(scene, est, 3 + i, 1, settings)
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    n = a.passes
    res = f" --resolution {a.resolution[0]},{a.resolution[1]}" if a.resolution else ""
    print(f"# python benchmarks/pass_phases.py {a.scene} {a.kmin} {a.kmax} {a.spec} "
          f"--photons {a.photons} --passes {a.passes}{res}")
    print(f"{a.spec}, {a.photons} photons: pass wall {wall / n * 1e3:.2f} ms, "
          f"CPU {cpu / n * 1e3:.2f} ms, {cpu / wall:.2f} cores")
    rest_w, rest_c = wall, cpu
    for name, (w, c) in phases.items():
        print(f"  {name:28s} wall {w / n * 1e3:7.2f} ms  CPU {c / n * 1e3:7.2f} ms  "
              f"{c / max(w, 1e-12):.2f} cores")
        rest_w, rest_c = rest_w - w, rest_c - c
    print(f"  {'rest (rays, MIS set, image)':28s} wall {rest_w / n * 1e3:7.2f} ms  "
          f"CPU {rest_c / n * 1e3:7.2f} ms")
    for name, (w, c) in inner.items():
        print(f"  {name:28s} wall {w / n * 1e3:7.2f} ms  CPU {c / n * 1e3:7.2f} ms")
    return 0


if __name__ == "__main__":
    sys.exit(main())
