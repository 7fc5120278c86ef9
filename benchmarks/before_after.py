"""Time whole passes of the same estimators on two checkouts, interleaved, and compare images.

Usage::

    python benchmarks/before_after.py OLD_TREE NEW_TREE [--scene scenes/area.toml]
        [--estimators planes,paper-single,paper-multi] [--photons 5000] [--passes 5]
        [--rounds 3] [--out out/before_after.json]

``OLD_TREE`` and ``NEW_TREE`` are checkouts (``git worktree add /tmp/old COMMIT``). Each
round runs one child process per tree and estimator, alternating old and new, so the two
trees see the same machine load. A child imports ``psurf_core`` from its tree only (the tree
first on ``sys.path``), renders one warm-up pass (numba compiles, buffers are allocated),
then times ``--passes`` passes of :func:`psurf_core.render.render_pass` (wall clock; also
the CPU time of the process and its minor page faults, ``getrusage``) and returns them with
the images. It uses only the API both checkouts share (``load_scene``, ``parse_estimator``,
``RenderSettings``, ``render_pass``), so the same harness measures both: unlike each
checkout's own ``make bench``, whose definitions changed with the restructure.

The images of both trees are compared too (the largest relative difference of a pixel over
the passes), since "nothing got slower" means little if the work changed.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

_CHILD = r"""
import sys, time, json, io, resource
import numpy as np
tree, scene_path, spec = sys.argv[1:4]
photons, passes = int(sys.argv[4]), int(sys.argv[5])
sys.path.insert(0, tree)
import psurf_core
assert psurf_core.__file__.startswith(tree), psurf_core.__file__
from psurf_core.scene_io import load_scene
from psurf_core.estimators import parse_estimator
from psurf_core.render import RenderSettings, render_pass
scene = load_scene(scene_path)
est = parse_estimator(spec, scene)
st = RenderSettings(photons=photons)
render_pass(scene, est, 10_000, 7, st)          # warm-up: compile, allocate
times, cpu, faults, imgs = [], [], [], []
for i in range(passes):
    f0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    t0, c0 = time.perf_counter(), time.process_time()
    img = render_pass(scene, est, i, 7, st)
    times.append(time.perf_counter() - t0)
    cpu.append(time.process_time() - c0)
    faults.append(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - f0)
    imgs.append(img)
buf = io.BytesIO()
np.save(buf, np.stack(imgs))
sys.stdout.write(json.dumps({"times": times, "cpu": cpu, "faults": faults}) + "\n")
sys.stdout.flush()
with open(sys.argv[6], "wb") as f:
    f.write(buf.getvalue())
"""


def _run(tree: Path, scene: Path, spec: str, photons: int, passes: int, npy: Path) -> dict:
    env = dict(os.environ, NUMBA_NUM_THREADS=os.environ.get("NUMBA_NUM_THREADS", "2"))
    out = subprocess.run(
        [sys.executable, "-c", _CHILD, str(tree), str(scene), spec, str(photons), str(passes),
         str(npy)],
        cwd=tree, env=env, capture_output=True, text=True)
    if out.returncode:
        raise SystemExit(f"{tree}: {spec} failed:\n{out.stderr[-3000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("old", type=Path)
    ap.add_argument("new", type=Path)
    ap.add_argument("--scene", default="scenes/area.toml")
    ap.add_argument("--estimators", default="planes,paper-single,paper-multi")
    ap.add_argument("--photons", type=int, default=5000)
    ap.add_argument("--passes", type=int, default=5)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--out", type=Path, default=Path("out/before_after.json"))
    a = ap.parse_args(argv)
    import numpy as np

    a.out = a.out.resolve()
    a.out.parent.mkdir(parents=True, exist_ok=True)
    trees = {"old": a.old.resolve(), "new": a.new.resolve()}
    scene = Path(a.scene).resolve()
    res: dict = {"command": " ".join(sys.argv), "started": time.strftime("%Y-%m-%d %H:%M:%S UTC",
                 time.gmtime()), "load_before": os.getloadavg(), "estimators": {}}
    for spec in a.estimators.split(","):
        per = {k: [] for k in trees}
        cpu = {k: [] for k in trees}
        faults = {k: [] for k in trees}
        for r in range(a.rounds):
            order = ("old", "new") if r % 2 == 0 else ("new", "old")
            for k in order:
                npy = a.out.parent / f"before_after_{k}.npy"
                got = _run(trees[k], scene, spec, a.photons, a.passes, npy)
                per[k].extend(got["times"])
                # (a checkout whose child predates these keys reports none)
                cpu[k].extend(got.get("cpu", []))
                faults[k].extend(got.get("faults", []))
        imgs = {k: np.load(a.out.parent / f"before_after_{k}.npy") for k in trees}
        scale = max(float(np.abs(imgs["old"]).max()), 1e-300)
        diff = float(np.abs(imgs["old"] - imgs["new"]).max()) / scale
        med = {k: statistics.median(v) for k, v in per.items()}
        med_cpu = {k: statistics.median(v) if v else None for k, v in cpu.items()}
        med_faults = {k: statistics.median(v) if v else None for k, v in faults.items()}
        res["estimators"][spec] = {
            "median_pass_seconds": med, "new_over_old": med["new"] / med["old"],
            "pass_seconds": per, "median_pass_cpu_seconds": med_cpu, "pass_cpu_seconds": cpu,
            "median_pass_page_faults": med_faults, "pass_page_faults": faults,
            "max_pixel_difference_relative_to_peak": diff,
            "bit_identical": bool(np.array_equal(imgs["old"], imgs["new"]))}
        extra = ""
        if med_cpu["old"] and med_cpu["new"]:
            extra = (f"; CPU new/old {med_cpu['new'] / med_cpu['old']:.3f}, page faults a pass "
                     f"old {med_faults['old']:.0f}, new {med_faults['new']:.0f}")
        print(f"{spec:>14}: old {med['old']*1e3:8.1f} ms/pass, new {med['new']*1e3:8.1f} "
              f"ms/pass, new/old {med['new']/med['old']:.3f}{extra}; images: max diff "
              f"{diff:.2e} of the peak, bit-identical {res['estimators'][spec]['bit_identical']}",
              flush=True)
    res["load_after"] = os.getloadavg()
    a.out.write_text(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
