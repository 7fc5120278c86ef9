"""The slower benchmark tables of ``run.py``: whole passes on 1 vs 2 processes, rates per
doubling of the photon count and of the image side, and the peak memory of a large pass."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from benchmarks.stages import stage_pass
from psurf_core.estimators import parse_estimator
from psurf_core.render import RenderSettings, render_pass

ROOT = Path(__file__).resolve().parent.parent

_RATES = ("photon_vertices_per_second", "hits_per_second", "cpu_ns_per_hit")


def with_resolution(scene, width: int, height: int):
    """``scene`` with its camera at ``width x height`` pixels."""
    return replace(scene, camera=replace(scene.camera, width=int(width), height=int(height)))


def whole_pass(scene, spec: str, photons: int, seed: int = 0) -> dict:
    """Wall time of one real ``render_pass`` and the hits it evaluated (tally hook)."""
    est = parse_estimator(spec, scene)
    count = [0]

    def tally(tech, hits, prims, rays, raw, val):
        count[0] += len(hits)

    a = time.perf_counter()
    render_pass(scene, est, 0, seed, RenderSettings(photons=photons), tally=tally)
    sec = time.perf_counter() - a
    return {"pass_seconds": sec, "pass_hits": count[0], "pass_hits_per_second": count[0] / sec}


def two_process(scene, spec: str, photons: int, passes: int) -> dict:
    """Passes/s of 2 worker processes vs 1 process (same passes; images bit-identical).

    The pool is started and warmed up (both workers have imported psurf) before the clock
    starts: start-up is paid once per render command, not per pass. The single process runs
    its compiled kernels on numba's threads (``planes`` shares large chunks among them; pool
    workers use one thread each), so it is also timed on one thread: ``seconds_1t``.
    """
    import numba

    from psurf_core.parallel import pass_pool, render_parallel
    from psurf_core.render import render

    est = parse_estimator(spec, scene)
    settings = RenderSettings(photons=photons)
    with pass_pool(2) as pool:
        render_parallel(scene, spec, RenderSettings(photons=64), passes=4, seed=1, pool=pool)
        a = time.perf_counter()
        two = render_parallel(scene, spec, settings, passes=passes, seed=0, pool=pool)
        t2 = time.perf_counter() - a
    threads = numba.get_num_threads()
    a = time.perf_counter()
    one = render(scene, est, settings, passes=passes, seed=0)
    t1 = time.perf_counter() - a
    numba.set_num_threads(1)
    try:
        a = time.perf_counter()
        one_t = render(scene, est, settings, passes=passes, seed=0)
        t1t = time.perf_counter() - a
    finally:
        numba.set_num_threads(threads)
    # The evaluated hits of those passes (counted untimed, through render_pass's tally hook):
    # what the machine delivers per wall second with both cores, whole passes included.
    count = [0]

    def tally(tech, hits, prims, rays, raw, val):
        count[0] += len(hits)

    for i in range(passes):
        render_pass(scene, est, i, 0, settings, tally=tally)
    return {"passes": passes, "photons": photons, "threads": threads, "seconds_1": t1,
            "seconds_1t": t1t, "seconds_2": t2, "speedup": t1 / t2, "speedup_vs_1t": t1t / t2,
            "hits": count[0], "pass_hits_per_second_2": count[0] / t2,
            "pass_hits_per_second_1t": count[0] / t1t,
            "threads_speedup": t1t / t1,
            "bit_identical": bool(all(np.array_equal(o.mean, two.mean)
                                      and np.array_equal(o.var, two.var)
                                      for o in (one, one_t)))}


def scaling(scene, spec: str, photons: int) -> dict:
    """Rates at 1x/2x/4x photons (scene resolution) and 1x/2x/4x image side (``photons``)."""
    cam = scene.camera
    rows = {"photons": [], "resolution": []}
    for f in (1, 2, 4):
        r = stage_pass(scene, spec, photons * f)
        rows["photons"].append({"factor": f, "photons": photons * f, "pixels": r["pixels"],
                                "candidates": r["candidates"], "hits": r["hits"],
                                **{k: r[k] for k in _RATES}})
        s = with_resolution(scene, cam.width * f, cam.height * f)
        r = stage_pass(s, spec, photons)
        rows["resolution"].append({"factor": f, "photons": photons, "pixels": r["pixels"],
                                   "candidates": r["candidates"], "hits": r["hits"],
                                   **{k: r[k] for k in _RATES}})
    return rows


_MEMORY_SCRIPT = """
import json, sys, time
from dataclasses import replace
sys.path.insert(0, {root!r})
from psurf_core.peak_memory import peak_rss_bytes
from psurf_core.estimators import parse_estimator
from psurf_core.render import RenderSettings, render_pass
from psurf_core.scene_io import load_scene
scene = load_scene({scene!r})
scene = replace(scene, camera=replace(scene.camera, width=256, height=192))
est = parse_estimator({spec!r}, scene)
import numpy as np
before = peak_rss_bytes()
count = [0]
def tally(tech, hits, prims, rays, raw, val):
    count[0] += len(hits)
rows = np.arange(0, 192, {row_step})
pixels = (rows[:, None] * 256 + np.arange(256)[None]).ravel()
a = time.perf_counter()
render_pass(scene, est, 0, 0, RenderSettings(photons={photons}), tally=tally, pixels=pixels)
sec = time.perf_counter() - a
peak = peak_rss_bytes()
print(json.dumps(dict(peak=peak, before=before, seconds=sec, hits=count[0])))
"""


def peak_memory(scene_path: str, spec: str, photons: int, row_step: int = 1) -> dict:
    """Peak RSS of a fresh process rendering one pass of ``spec`` at 256x192 (every
    ``row_step``-th image row only: the photons are traced and their primitives created and
    binned exactly as for the whole image, but only those rows' rays are tested)."""
    code = textwrap.dedent(_MEMORY_SCRIPT).format(root=str(ROOT), scene=scene_path, spec=spec,
                                                  photons=photons, row_step=row_step)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    r = json.loads(out.stdout.strip().splitlines()[-1])
    return {"estimator": spec, "photons": photons, "resolution": [256, 192],
            "rows_rendered": len(range(0, 192, row_step)),
            "peak_rss_bytes": r["peak"], "rss_after_imports_bytes": r["before"],
            "seconds": r["seconds"], "hits": r["hits"],
            "pass_hits_per_second": r["hits"] / r["seconds"]}


def _print_scaling(spec: str, rows: dict) -> None:
    for axis in ("photons", "resolution"):
        print(f"  {spec} vs {axis} (x1, x2, x4 {'photons' if axis == 'photons' else 'side'}):")
        print("    factor  pixels   photons candidates      hits  verts/s   hits/s  ns/hit")
        for r in rows[axis]:
            print(f"    {r['factor']:>6} {r['pixels']:>7} {r['photons']:>9} "
                  f"{r['candidates']:>10} {r['hits']:>9} " + " ".join(f"{r[k]:8.3g}"
                                                                        for k in _RATES))
