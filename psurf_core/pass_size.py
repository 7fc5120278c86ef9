"""How many photons a pass should hold when the budget is time: chosen by measurement.

A pass of ``N`` photons costs ``c0 + c1 N`` seconds: ``c0`` is what every pass pays whatever
its photons (camera rays, ray tables, per-technique set-up), ``c1`` the photons' own work. Its
per-pixel variance is ``Vj + Vp / N``: ``Vp`` the photons' variance (one photon's), ``Vj`` the
pixel integration's (each pass jitters its camera rays inside the pixels, SCENES.md's box
filter; no number of photons removes it). A budget ``T`` holds ``T / (c0 + c1 N)`` passes, so
the final image's variance is ``(Vj + Vp / N) (c0 + c1 N) / T``, smallest at

    ``N* = sqrt(Vp c0 / (Vj c1))``.

When photon surfaces make ``Vp`` small, ``Vj`` is what is left and many small passes pay:
at 64x48 on ``study_medium`` (K = 1) the pixel term is ~25x the photon term of 2000 photons
of MIS(3 ss planes + cone + sphere) (docs/study.md). A fixed pass count per budget (the
previous rule, 48 passes) gave such an estimator ~10^4 photons a pass, almost all wasted.

:func:`auto_photons` measures all four numbers on pilot passes (after the warm-up that
compiles the kernels; seeds no render uses; not counted in any budget) and returns ``N*``,
kept within :data:`PHOTON_RANGE`, where a pass's photons cost at most :data:`OVERHEAD_CAP`
times its fixed part, and so that the budget still holds :data:`MIN_PASSES`.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np

from .accumulate import Welford
from .render import RenderSettings, render_pass, warm_up

#: Fewest passes a time budget should hold (a per-pixel variance estimate needs many).
MIN_PASSES = 48

#: Photons of the two pilot pass sizes, and pilot passes of each.
PILOT_PHOTONS = (128, 1024)
PILOT_PASSES = 6

#: A pass's photons cost at most this many times its fixed part (see :func:`best_photons`).
OVERHEAD_CAP = 8.0

#: The fixed part of a pass is taken as at least this (s): a noisy pilot can measure ~0.
MIN_PASS_SECONDS = 1e-3

#: The range a chosen count is kept in.
PHOTON_RANGE = (64, 1 << 20)

#: First seed of the pilot passes (no render uses seeds this large).
PILOT_SEED = 1 << 30


def pass_model(sizes, seconds, variances) -> tuple[float, float, float, float]:
    """``(c0, c1, Vj, Vp)`` from two pass sizes: their median seconds and mean per-pass
    pixel variances (``seconds = c0 + c1 N``, ``variance = Vj + Vp / N``). ``c0`` and ``Vj``
    are clipped at 0 and ``c1``, ``Vp`` at tiny positive values: timings and variance
    estimates are noisy."""
    (na, nb), (ta, tb), (va, vb) = sizes, seconds, variances
    c1 = max((tb - ta) / (nb - na), 1e-12)
    c0 = max(ta - c1 * na, 0.0)
    vp = max((va - vb) / (1.0 / na - 1.0 / nb), 1e-300)
    vj = max(vb - vp / nb, 0.0)
    return c0, c1, vj, vp


def best_photons(c0: float, c1: float, vj: float, vp: float, budget: float) -> int:
    """The pass size minimising ``(Vj + Vp / N) (c0 + c1 N)``, at most
    ``OVERHEAD_CAP c0 / c1`` (past it a larger pass gains under ``1 / OVERHEAD_CAP`` however
    small ``Vj`` is, and a pilot cannot tell a small ``Vj`` from none) and what lets
    ``budget`` seconds hold :data:`MIN_PASSES` passes, within :data:`PHOTON_RANGE`."""
    c0 = max(c0, MIN_PASS_SECONDS)
    n = min((budget / MIN_PASSES - c0) / c1, OVERHEAD_CAP * c0 / c1)
    if vj > 0.0:
        n = min(math.sqrt(vp * c0 / (vj * c1)), n)
    return int(min(max(n, PHOTON_RANGE[0]), PHOTON_RANGE[1]))


def pilot(scene, estimator, settings: RenderSettings) -> tuple[float, float, float, float]:
    """:func:`pass_model` measured: :data:`PILOT_PASSES` timed passes of each of
    :data:`PILOT_PHOTONS` (wall seconds, median) and their per-pass variance."""
    secs, var = [], []
    for k, n in enumerate(PILOT_PHOTONS):
        st = replace(settings, photons=n)
        acc = Welford.empty((scene.camera.height, scene.camera.width, 3))
        times = []
        for i in range(PILOT_PASSES):
            a = time.perf_counter()
            img = render_pass(scene, estimator, i, PILOT_SEED + k, st)
            times.append(time.perf_counter() - a)
            acc.add(np.nan_to_num(img, nan=0.0, posinf=0.0, neginf=0.0))
        secs.append(float(np.median(times)))
        var.append(float(np.mean(acc.variance)))
    return pass_model(PILOT_PHOTONS, secs, var)


def auto_photons(scene, estimator, settings: RenderSettings, budget: float) -> int:
    """Photons per pass for a render of ``estimator`` lasting ``budget`` seconds (``N*`` of
    the module docstring, measured by :func:`pilot`); the path tracer has no photons:
    ``settings.photons`` is returned."""
    if estimator.reference:
        return settings.photons
    warm_up(scene, estimator, settings)
    return best_photons(*pilot(scene, estimator, settings), budget)
