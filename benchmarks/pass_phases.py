"""The phases of one compiled pass per technique: the jobs it hands to the threads (the
spans' ``project`` and ``fill``, the walk's ``piece``: :func:`psurf_core.kernels.threads.on_threads`
calls, named by the function handed out) and the stretches between them, where one thread
runs Python (``serial``), in wall ms.

The pass is :func:`benchmarks.pass_breakdown.run_pass` on the inputs of
:func:`benchmarks.pass_breakdown.prepare` (pass 0 of seed 0, traced and created once), run
``--rounds`` times per technique; each phase's figure is its median over the rounds after
the first. The serial stretches are what a second core cannot shorten (docs/study.md,
"Spans counted as they are written").

Usage::

    python benchmarks/pass_phases.py SCENE.toml [--spec planes] [--photons 5000]
        [--rounds 40] [--threads 2] [--json PATH]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import numba  # noqa: E402

from benchmarks.pass_breakdown import (  # noqa: E402
    BenchError,
    check_args,
    prepare,
    run_pass,
    write_json,
)
from psurf_core.kernels import fused, spans  # noqa: E402
from psurf_core.scene import SceneError  # noqa: E402
from psurf_core.scene_io import load_scene  # noqa: E402
from psurf_core.techniques import UnknownTechnique  # noqa: E402

#: The modules whose ``on_threads`` a pass calls (each imported it by name).
_CALLERS = (fused, spans)


def phases(job, rounds: int) -> list[tuple[str, float]]:
    """``[(name, median wall ms), ...]`` of one technique's pass in order: ``serial`` before,
    between and after the thread jobs, each job by its function's name."""
    marks: list = []
    originals = [m.on_threads for m in _CALLERS]

    def timed(fn, n, threads, _run=originals[0]):
        marks.append((fn.__name__, time.perf_counter()))
        _run(fn, n, threads)
        marks.append(("serial", time.perf_counter()))

    per_round = []
    try:
        for m in _CALLERS:
            m.on_threads = timed
        for _ in range(rounds):
            marks.clear()
            t0 = time.perf_counter()
            run_pass([job])
            t1 = time.perf_counter()
            points = [("serial", t0), *marks, ("end", t1)]
            per_round.append([(name, 1e3 * (b - a))
                              for (name, a), (_, b) in zip(points[:-1], points[1:], strict=True)])
    finally:
        for m, f in zip(_CALLERS, originals, strict=True):
            m.on_threads = f
    warm = per_round[1:]
    if any([n for n, _ in r] != [n for n, _ in warm[0]] for r in warm):
        raise BenchError("the pass handed out different jobs from round to round")
    return [(name, statistics.median(r[i][1] for r in warm))
            for i, (name, _) in enumerate(warm[0])]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scene")
    ap.add_argument("--spec", default="planes")
    ap.add_argument("--photons", type=int, default=5000)
    ap.add_argument("--rounds", type=int, default=40)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--json", metavar="PATH")
    args = ap.parse_args(argv)
    before = numba.get_num_threads()
    try:
        check_args(args)
        numba.set_num_threads(args.threads)
        jobs = prepare(load_scene(args.scene), args.spec, args.photons)
        res = {job[0].name: phases(job, args.rounds) for job in jobs}
    except (BenchError, SceneError, UnknownTechnique, OSError) as e:
        print(f"pass_phases: {e}", file=sys.stderr)
        return 2
    finally:
        numba.set_num_threads(before)
    print(f"# {args.scene}, {args.spec}, {args.photons} photons, {args.threads} thread(s); "
          f"wall ms, medians of rounds 2..{args.rounds}")
    for name, row in res.items():
        serial = sum(ms for n, ms in row if n == "serial")
        print(f"{name:20s} " + "  ".join(f"{n} {ms:.3f}" for n, ms in row)
              + f"  | serial {serial:.3f} of {sum(ms for _, ms in row):.3f}")
    return write_json(args.json, res, "pass_phases")


if __name__ == "__main__":
    sys.exit(main())
