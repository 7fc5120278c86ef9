"""Numba compile time of one estimator's kernels on two checkouts, interleaved, fresh caches.

Usage::

    python benchmarks/compile_time.py OLD_TREE NEW_TREE [--estimator mis:cone+cylinder]
        [--scene scenes/area.toml] [--scatter 2,3] [--rounds 4] [--new-env KEY=VALUE ...]

Each round runs one child process per tree (alternating which goes first), each with an
empty ``NUMBA_CACHE_DIR``: the child compiles ``planes`` first (the kernels every estimator
shares: Trace, spans, the shadow test), then times the CPU seconds of
:func:`psurf_core.render.warm_up` for ``--estimator``, i.e. what its own walkers cost to
compile. The machine's speed drifts within minutes, so compare the two trees' rounds side by
side, never against another run. ``OLD_TREE``: ``git worktree add /tmp/old COMMIT``.
``--new-env`` sets environment variables in the new tree's children only: the same tree
twice with ``--new-env NUMBA_OPT=1`` measures LLVM's optimisation level.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

_CHILD = r"""
import sys, time
tree, scene_path, spec, k0, k1 = sys.argv[1:6]
sys.path.insert(0, tree)
import psurf_core
assert psurf_core.__file__.startswith(tree), psurf_core.__file__
from psurf_core import render
from psurf_core.estimators import parse_estimator
from psurf_core.scene_io import load_scene
scene = load_scene(scene_path).with_scatter(int(k0), int(k1))
st = render.RenderSettings()
render.warm_up(scene, parse_estimator("planes", scene), st)
t = time.process_time()
render.warm_up(scene, parse_estimator(spec, scene), st)
print(time.process_time() - t)
"""


def _run(tree: Path, scene: Path, spec: str, scatter: tuple[int, int],
         extra: dict[str, str]) -> float:
    with tempfile.TemporaryDirectory(prefix="psurf_numba_") as cache:
        env = dict(os.environ, **extra, NUMBA_CACHE_DIR=cache)
        out = subprocess.run([sys.executable, "-c", _CHILD, str(tree), str(scene), spec,
                              str(scatter[0]), str(scatter[1])],
                             cwd=tree, env=env, capture_output=True, text=True)
    if out.returncode:
        raise SystemExit(f"{tree}: {spec} failed:\n{out.stderr[-3000:]}")
    return float(out.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("old", type=Path)
    ap.add_argument("new", type=Path)
    ap.add_argument("--estimator", default="mis:cone+cylinder")
    ap.add_argument("--scene", default="scenes/area.toml")
    ap.add_argument("--scatter", default="2,3", help="min,max scatter count")
    ap.add_argument("--rounds", type=int, default=4)
    ap.add_argument("--new-env", action="append", default=[], metavar="KEY=VALUE",
                    help="an environment variable of the new tree's children (repeatable)")
    a = ap.parse_args(argv)
    if any("=" not in kv for kv in a.new_env):
        ap.error("--new-env takes KEY=VALUE")
    extra = {"old": {}, "new": dict(kv.split("=", 1) for kv in a.new_env)}
    trees = {"old": a.old.resolve(), "new": a.new.resolve()}
    scene = Path(a.scene).resolve()
    k0, k1 = (int(v) for v in a.scatter.split(","))
    print(f"# {' '.join(sys.argv)}; load average {os.getloadavg()[0]:.2f}", flush=True)
    per: dict[str, list[float]] = {k: [] for k in trees}
    for r in range(a.rounds):
        for k in ("old", "new") if r % 2 == 0 else ("new", "old"):
            per[k].append(_run(trees[k], scene, a.estimator, (k0, k1), extra[k]))
            print(f"round {r + 1} {k}: {per[k][-1]:.1f} s CPU", flush=True)
    mean = {k: statistics.mean(v) for k, v in per.items()}
    print(f"{a.estimator}: old {mean['old']:.1f} s, new {mean['new']:.1f} s (means of "
          f"{a.rounds}), new/old {mean['new'] / mean['old']:.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
