"""CPU seconds of one pass at a given photon count, estimators alternated in one process.

At a small photon count this is a pass's fixed cost ``c0`` (camera rays, Create, screen spans,
buffers, one walker call per technique); at two counts it gives the per-photon cost ``c1``
of the pass model (``psurf_core/pass_size.py``, docs/study.md). CPU time
(``time.process_time``, every thread), so a busy machine changes it less than wall time; to
compare commits, run it in a worktree of each (``git worktree add /tmp/old COMMIT``) in
alternation and take medians.

Usage::

    python benchmarks/pass_cost.py SCENE.toml KMIN KMAX PHOTONS ROUNDS SPEC [SPEC ...]
    python benchmarks/pass_cost.py scenes/study_medium.toml 2 3 16 4 planes fast-multi
"""

from __future__ import annotations

import os
import statistics
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from psurf_core.estimators import parse_estimator  # noqa: E402
from psurf_core.geometry import blockers_of  # noqa: E402
from psurf_core.render import RenderSettings, render_pass  # noqa: E402
from psurf_core.scene_io import load_scene  # noqa: E402

#: Passes timed together per round and estimator.
PASSES = 5


def main(argv: list[str]) -> None:
    if len(argv) < 6:
        sys.exit(__doc__)
    scene = load_scene(argv[0]).with_scatter(int(argv[1]), int(argv[2]))
    photons, rounds, specs = int(argv[3]), int(argv[4]), argv[5:]
    ests = {s: parse_estimator(s, scene) for s in specs}
    blockers = blockers_of(scene)
    settings = RenderSettings(photons=photons)
    for s in specs:  # compile or load the kernels before timing
        render_pass(scene, ests[s], 999, 7, settings, blockers=blockers)
    cpu = {s: [] for s in specs}
    i = 0
    for _ in range(rounds):
        for s in specs:
            t0 = time.process_time()
            for _ in range(PASSES):
                render_pass(scene, ests[s], i, 7, settings, blockers=blockers)
                i += 1
            cpu[s].append((time.process_time() - t0) / PASSES)
    for s in specs:
        print(f"{s:45s} N={photons}: median {statistics.median(cpu[s]) * 1e3:.2f} ms CPU/pass "
              f"(min {min(cpu[s]) * 1e3:.2f})")


if __name__ == "__main__":
    main(sys.argv[1:])
