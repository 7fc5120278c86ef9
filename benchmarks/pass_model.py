"""The pass model of estimators on a scene: what limits them at equal time (docs/study.md).

A pass of ``N`` photons costs ``c0 + c1 N`` CPU seconds and has per-pixel variance
``Vj + Vp / N`` (``Vj`` the pixel jitter's, ``Vp`` one photon's; psurf_core/pass_size.py).
This measures the four numbers per estimator, with CPU time (``time.process_time``, every
thread) so that a busy machine changes them little:

* ``Vp`` from passes whose camera rays go through the pixel centres (no jitter: the
  variance left is the photons'), at 256 and 2048 photons (their mean ``Vp``; both printed);
* ``Vj`` from jittered passes of 2048 photons minus the unjittered ones;
* ``c0``, ``c1`` from the median CPU time of the passes at the two sizes;

and prints ``N* = sqrt(Vp c0 / (Vj c1))``, the equal-time variance ``(Vj + Vp / N*)
(c0 + c1 N*)`` and its ratio to the first estimator's.

Usage::

    python benchmarks/pass_model.py SCENE.toml KMIN KMAX PASSES SPEC [SPEC ...]
    python benchmarks/pass_model.py scenes/study_medium.toml 1 1 12 beams paper-single fast-single
"""

from __future__ import annotations

import math
import os
import sys
import time
from dataclasses import replace

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from psurf_core import SceneError  # noqa: E402
from psurf_core import render as render_mod  # noqa: E402
from psurf_core.accumulate import Welford  # noqa: E402
from psurf_core.camera import camera_rays  # noqa: E402
from psurf_core.estimators import parse_estimator  # noqa: E402
from psurf_core.metrics import var_relmse  # noqa: E402
from psurf_core.render import RenderSettings, render_pass, warm_up  # noqa: E402
from psurf_core.scene_io import load_scene  # noqa: E402
from psurf_core.study import load_reference  # noqa: E402

SIZES = (256, 2048)


def pass_variance(scene, est, photons: int, passes: int, jitter: bool, seed: int = 7,
                  settings: RenderSettings | None = None) -> tuple[np.ndarray, list[float]]:
    """(H, W, 3) per-pixel variance of ``passes`` passes (pass ``i`` of seed ``seed``;
    ``settings`` with ``photons`` photons, default :class:`RenderSettings`'s; camera rays
    through the pixel centres unless ``jitter``) and the CPU seconds of each pass."""
    settings = replace(settings or RenderSettings(), photons=photons)
    real = render_mod.camera_rays
    render_mod.camera_rays = lambda *a, **k: camera_rays(*a, jitter=jitter, **k)
    try:
        acc = Welford.empty((scene.camera.height, scene.camera.width, 3))
        cpu = []
        for i in range(passes):
            a = time.process_time()
            img = render_pass(scene, est, i, seed, settings)
            cpu.append(time.process_time() - a)
            acc.add(img)
    finally:
        render_mod.camera_rays = real
    return acc.variance, cpu


def passes_of(scene, est, photons: int, passes: int, jitter: bool,
              seed: int = 7, settings: RenderSettings | None = None,
              reference: np.ndarray | None = None) -> tuple[float, float]:
    """(mean per-pass pixel variance, median CPU seconds a pass) of :func:`pass_variance`'s
    passes. With a ``reference`` image (H, W, 3) the mean is of the variance over
    ``R^2 + EPS mean(R)^2`` (:func:`psurf_core.metrics.var_relmse`: what a relMSE against it
    sees of the noise)."""
    var, cpu = pass_variance(scene, est, photons, passes, jitter, seed, settings)
    v = float(np.mean(var)) if reference is None else var_relmse(var, reference)
    return v, float(np.median(cpu))


def reference_image(path: str, scene) -> np.ndarray:
    """The mean image (H, W, 3) of an ``app.py render`` .npz of ``scene`` (its size and
    scatter range: :func:`psurf_core.study.load_reference`'s checks, as ``compare
    --reference``); a bad file ends the benchmark with that message."""
    try:
        return load_reference(path, scene).mean
    except SceneError as e:
        raise SystemExit(str(e)) from None


def model(scene, spec: str, passes: int) -> dict:
    """``c0, c1, Vj, Vp, N*`` and the equal-time variance of ``spec`` on ``scene``."""
    est = parse_estimator(spec, scene)
    warm_up(scene, est, RenderSettings(photons=64))
    (na, nb) = SIZES
    va, ta = passes_of(scene, est, na, passes, False)
    vb, tb = passes_of(scene, est, nb, passes, False)
    vjb, _ = passes_of(scene, est, nb, passes, True)
    vp = (va * na + vb * nb) / 2
    c1 = max((tb - ta) / (nb - na), 1e-12)
    c0 = max(ta - c1 * na, 1e-4)
    vj = max(vjb - vb, 0.0)
    n_star = math.sqrt(vp * c0 / (vj * c1)) if vj > 0 else float("inf")
    n_use = min(n_star, 1 << 20)
    return {"spec": spec, "Vp": vp, "Vp_each": (va * na, vb * nb), "Vj": vj, "c0": c0,
            "c1": c1, "N*": n_star,
            "var_time": (vj + vp / n_use) * (c0 + c1 * n_use),
            "var_time_2048": (vj + vp / nb) * (c0 + c1 * nb)}


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) < 5:
        print(__doc__)
        return 2
    scene = load_scene(argv[0])
    scene = replace(scene, min_scatter=int(argv[1]), max_scatter=int(argv[2]))
    passes = int(argv[3])
    print(f"# python benchmarks/pass_model.py {' '.join(argv)}")
    first = None
    for spec in argv[4:]:
        m = model(scene, spec, passes)
        first = first or m
        print(f"{spec:50s} Vp {m['Vp']:.3g} ({m['Vp_each'][0]:.3g}, {m['Vp_each'][1]:.3g}) "
              f"Vj {m['Vj']:.3g} c0 {m['c0'] * 1e3:.1f} ms c1 {m['c1'] * 1e6:.1f} us "
              f"N* {m['N*']:.0f} var*t {m['var_time']:.3g} "
              f"ratio {m['var_time'] / first['var_time']:.3f} "
              f"(at 2048 photons: {m['var_time_2048'] / first['var_time_2048']:.3f})",
              flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
