"""Does one Sobol sequence over a render's passes beat a Sobol set scrambled per pass?
The variance of whole renders (``P`` passes of ``N`` photons), across seeds, per photon
sampler (``psurf_core.photon_sampler``: ``independent``, ``sobol``, ``sobol-seq``).

``sobol-seq``'s passes are not independent, so the per-pass variance (what
``benchmarks/photon_qmc.py`` and ``ablation.py`` measure) cannot see its gain: only renders
repeated with other seeds can. For each estimator and sampler this renders ``--seeds``
seeds (``--seed``, ``--seed + 1``, ...) of ``P`` passes each, with ``compare``'s ``r2`` pixel
sampler, and prints the relative variance of the final image across the seeds
(``psurf_core.metrics.var_relmse`` of the per-pixel variance of the mean, against
``--reference`` or else the mean of every render) and its ratio to the first sampler's;
with ``--reference``, also the median of the renders' relMSEs (a typical render's error:
``planes``' grazing tail moves the variance across seeds far more than it). Equal passes
and photons: equal cost (the sampler's own cost is in ``seconds``).

Usage::

    python benchmarks/photon_sequence.py SCENE.toml KMIN KMAX "SPEC:N:P;..." [--seeds 8]
        [--samplers sobol,sobol-seq] [--resolution W,H] [--reference REF.npz]
    python benchmarks/photon_sequence.py scenes/study_medium.toml 2 3 \\
        "fast-multi:1000:30;planes:3000:30" --resolution 256,192

Not a test: ``planes``' variance is heavy-tailed (more seeds before trusting tens of percent).
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
from psurf_core.metrics import relmse, var_relmse  # noqa: E402
from psurf_core.render import RenderSettings, render, warm_up  # noqa: E402


def spread(scene, spec: str, photons: int, passes: int, sampler: str, seeds, ref=None):
    """``(relvar, median_relmse, seconds)``: the relative variance of the mean image of
    ``passes`` passes across ``seeds`` (against ``ref``, else the renders' mean), the median
    over the seeds of each render's relMSE against ``ref`` (NaN without one: a typical
    render's error, which a heavy tail moves far less than the variance) and the wall
    seconds a render took (median)."""
    est = parse_estimator(spec, scene)
    st = RenderSettings(photons=photons, pixel_sampler="r2", photon_sampler=sampler)
    warm_up(scene, est, st)
    imgs, secs = [], []
    for s in seeds:
        t0 = time.perf_counter()
        imgs.append(render(scene, est, st, passes=passes, seed=int(s)).mean)
        secs.append(time.perf_counter() - t0)
    imgs = np.array(imgs)
    var_of_mean = imgs.var(axis=0, ddof=1)
    typical = np.nan if ref is None else float(np.median([relmse(i, ref) for i in imgs]))
    return (var_relmse(var_of_mean, imgs.mean(axis=0) if ref is None else ref), typical,
            float(np.median(secs)))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_scene_args(ap)
    ap.add_argument("specs", help='"SPEC:PHOTONS:PASSES;..."')
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--seed", type=int, default=500, help="the first seed")
    ap.add_argument("--samplers", default="sobol,sobol-seq")
    ap.add_argument("--reference", help="an .npz whose 'mean' weighs the pixels (relMSE)")
    args = ap.parse_args(argv)
    scene = scene_of(args)
    ref = None if args.reference is None else np.load(args.reference)["mean"]
    seeds = range(args.seed, args.seed + args.seeds)
    samplers = args.samplers.split(",")
    print(f"# {' '.join(sys.argv)}")
    for item in args.specs.split(";"):
        spec, n, p = item.rsplit(":", 2)
        base = None
        for sampler in samplers:
            v, typ, sec = spread(scene, spec, int(n), int(p), sampler, seeds, ref)
            base = (v, typ) if base is None else base
            med = "" if ref is None else (f"; median relMSE {typ:.4g} "
                                          f"({typ / base[1]:.3f}x)")
            print(f"{spec:>12} {sampler:>12}: relVar {v:.4g} ({v / base[0]:.3f}x "
                  f"{samplers[0]}){med}, {sec:.2f} s a render of {p} x {n}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
