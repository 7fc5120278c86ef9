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

``c0, c1`` come from timed passes of two sizes (:func:`pass_cost`). ``Vj, Vp`` come from
*split* passes (:func:`split_terms`): one set of camera rays, two independent sets of ``n``
photons each. The halves' difference holds the photons' variance alone (the rays' jitter is
common to both and cancels): ``E[(a - b)^2] / 2 = Vp / n``; their mean has the variance
``Vj + Vp / (2 n)`` across passes. (Taking ``Vj, Vp`` from the variances of two pass sizes
instead, as this module did until 2026-12-05, read heavy tails as pixel variance: a photon
plane's rare huge contributions are seen more often in larger passes, so their variance fell
slower than ``1 / N`` and the fit called the rest ``Vj``. ``planes`` then got ~640 photons a
pass on ``study_medium`` at K = 2..3 where ~3600 gave 0.7x its variance at equal time,
docs/study.md.)
"""

from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np

from .accumulate import Welford
from .camera import camera_rays
from .geometry import blockers_of
from .render import RenderSettings, pass_generators, pass_image, photon_pass, render_pass, warm_up

#: Fewest passes a time budget should hold (a per-pixel variance estimate needs many).
MIN_PASSES = 48

#: Photons of the two timed pilot pass sizes, and pilot passes of each.
PILOT_PHOTONS = (128, 1024)
PILOT_PASSES = 6

#: Split pilot passes (:func:`split_terms`), each with two halves of up to
#: ``PILOT_PHOTONS[1]`` photons. ``Vj`` is their least certain number: for ``fast-multi`` on
#: ``study_medium`` at K = 2..3 it is a third of the halves' mean's variance.
SPLIT_PASSES = 10

#: A split pass's two halves take at most about this (s, by the timed passes' ``c0, c1``):
#: a slow estimator's halves are smaller (``paper-full`` on ``showcase.toml``, ~0.8 ms a
#: photon, would otherwise spend ~16 s on them), down to ``PHOTON_RANGE[0]`` photons.
SPLIT_PASS_SECONDS = 0.2

#: A pass's photons cost at most this many times its fixed part (see :func:`best_photons`).
OVERHEAD_CAP = 8.0

#: The fixed part of a pass is taken as at least this (s): a noisy pilot can measure ~0.
MIN_PASS_SECONDS = 1e-3

#: The range a chosen count is kept in.
PHOTON_RANGE = (64, 1 << 20)

#: First seed of the pilot passes (no render uses seeds this large).
PILOT_SEED = 1 << 30


def pass_cost(sizes, seconds) -> tuple[float, float]:
    """``(c0, c1)`` of ``seconds = c0 + c1 N`` from the median seconds of two pass sizes;
    ``c0`` clipped at 0 and ``c1`` at a tiny positive value (timings are noisy)."""
    (na, nb), (ta, tb) = sizes, seconds
    c1 = max((tb - ta) / (nb - na), 1e-12)
    return max(ta - c1 * na, 0.0), c1


def split_terms(n: int, mean_variance: float, half_difference: float) -> tuple[float, float]:
    """``(Vj, Vp)`` from split passes of ``n`` photons a half (module docstring).

    Parameters
    ----------
    n : int
        Photons of each half.
    mean_variance : float
        Pixel mean of the per-pixel sample variance, across passes, of the halves' mean
        ``(a + b) / 2``: an estimate of ``Vj + Vp / (2 n)``.
    half_difference : float
        Pixel and pass mean of ``(a - b)^2 / 2``: an estimate of ``Vp / n``.

    ``Vp`` is clipped at a tiny positive value and ``Vj`` at 0 (estimates are noisy)."""
    vp = max(half_difference * n, 1e-300)
    return max(mean_variance - vp / (2.0 * n), 0.0), vp


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
    """``(c0, c1, Vj, Vp)`` measured: :data:`PILOT_PASSES` timed passes of each of
    :data:`PILOT_PHOTONS` (wall seconds, median; :func:`pass_cost`), then
    :data:`SPLIT_PASSES` split passes (:func:`split_variances`) with halves of
    ``PILOT_PHOTONS[1]`` photons or fewer (:data:`SPLIT_PASS_SECONDS`)."""
    c0, c1 = timed_cost(scene, estimator, settings, PILOT_PHOTONS, PILOT_PASSES, PILOT_SEED)
    half = replace(settings, photons=split_photons(c0, c1))
    return (c0, c1, *split_variances(scene, estimator, half))


def timed_cost(scene, estimator, settings: RenderSettings, sizes, passes: int,
               seed: int) -> tuple[float, float]:
    """``(c0, c1)`` of :func:`pass_cost` from ``passes`` timed passes (wall seconds, median)
    of each of the two photon counts ``sizes``, size ``k`` with seed ``seed + k``."""
    times = [[] for _ in sizes]
    # The sizes alternate, so that a change in the machine's load reaches both alike.
    for i in range(passes):
        for k, n in enumerate(sizes):
            a = time.perf_counter()
            render_pass(scene, estimator, i, seed + k, replace(settings, photons=n))
            times[k].append(time.perf_counter() - a)
    return pass_cost(sizes, [float(np.median(t)) for t in times])


def split_photons(c0: float, c1: float) -> int:
    """Photons of each half of a split pass: ``PILOT_PHOTONS[1]``, or fewer where two halves
    would take more than :data:`SPLIT_PASS_SECONDS` (at least ``PHOTON_RANGE[0]``)."""
    n = (SPLIT_PASS_SECONDS / 2.0 - c0) / max(c1, 1e-12)
    return int(min(max(n, PHOTON_RANGE[0]), PILOT_PHOTONS[1]))


def split_variances(scene, estimator, settings: RenderSettings, weight=None,
                    passes: int = SPLIT_PASSES,
                    seed: int = PILOT_SEED + len(PILOT_PHOTONS)) -> tuple[float, float]:
    """``(Vj, Vp)`` of :func:`split_terms` from ``passes`` split passes of
    ``settings.photons`` photons a half: each pass's camera rays (``pass_generators``'s ray
    generator) shared by two photon sets spawned from its photon seed.

    ``weight`` (H, W, 3) or None: each pixel's weight in the pixel means (e.g. one over the
    squared reference: relative variances, as a relMSE weighs them); None, all alike."""
    cam, n, blockers = scene.camera, settings.photons, blockers_of(scene)
    w = 1.0 if weight is None else weight
    acc = Welford.empty((cam.height, cam.width, 3))
    half_difference = 0.0
    for i in range(passes):
        ray_rng, photon_ss = pass_generators(seed, i)
        rays = camera_rays(scene, settings.spp, ray_rng, blockers=blockers)
        a, b = (np.nan_to_num(pass_image(cam, rays, photon_pass(
                    scene, estimator, rays, ss, settings, i, blockers) / n, settings.spp),
                    nan=0.0, posinf=0.0, neginf=0.0)
                for ss in photon_ss.spawn(2))
        acc.add(0.5 * (a + b))
        half_difference += float(np.mean(w * 0.5 * (a - b) ** 2)) / passes
    return split_terms(n, float(np.mean(w * acc.variance)), half_difference)


def auto_photons(scene, estimator, settings: RenderSettings, budget: float) -> int:
    """Photons per pass for a render of ``estimator`` lasting ``budget`` seconds (``N*`` of
    the module docstring, measured by :func:`pilot`); the path tracer has no photons:
    ``settings.photons`` is returned."""
    chosen = auto_pass_model(scene, estimator, settings, budget)
    return settings.photons if chosen is None else chosen["photons"]


def auto_pass_model(scene, estimator, settings: RenderSettings, budget: float) -> dict | None:
    """What :func:`auto_photons` measured and chose, for the record (``compare.json``):
    ``{"photons", "c0", "c1", "vj", "vp", "pilot_seconds"}`` (seconds, seconds a photon,
    per-pass pixel variances as in the module docstring, the pilot's wall seconds); None for
    the path tracer. With ``settings.pixel_sampler`` ``"r2"`` the choice ignores ``Vj``."""
    if estimator.reference:
        return None
    warm_up(scene, estimator, settings)
    t = time.perf_counter()
    c0, c1, vj, vp = pilot(scene, estimator, settings)
    # The r2 pixel sampler covers each pixel evenly over the passes: its part of the mean's
    # variance falls much faster than 1 / P (pixel_jitter), so only the fixed cost limits
    # the pass size (the overhead cap). Vj is still measured (independent split passes) and
    # kept for the record.
    return {"photons": best_photons(c0, c1, vj if settings.pixel_sampler == "independent"
                                    else 0.0, vp, budget),
            "c0": c0, "c1": c1, "vj": vj, "vp": vp,
            "pilot_seconds": time.perf_counter() - t}
