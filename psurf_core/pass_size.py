"""How many photons a pass should hold when the budget is time: chosen by measurement.

Each estimator is most efficient with its own pass size: large enough that what every pass
pays whatever its photons (camera rays, ray tables, per-chunk set-up) is small, and small
enough that a time budget holds many passes (the per-pixel variance is estimated across
passes). :func:`auto_photons` times one warm pass and sizes the passes so that the budget
holds about :data:`TARGET_PASSES` of them, within :data:`PHOTON_RANGE`.
"""

from __future__ import annotations

import time
from dataclasses import replace

from .render import RenderSettings, render_pass, warm_up

#: Passes a time budget should hold (enough for a per-pixel variance estimate).
TARGET_PASSES = 48

#: Photons of the pass that is timed, and the range a chosen count is kept in.
PROBE_PHOTONS = 1000
PHOTON_RANGE = (64, 1 << 20)


def auto_photons(scene, estimator, settings: RenderSettings, budget: float) -> int:
    """Photons per pass for a render of ``estimator`` lasting ``budget`` seconds: about
    ``budget / TARGET_PASSES`` seconds per pass, by a timed pass of ``PROBE_PHOTONS``
    photons (after the warm-up that compiles the kernels; the path tracer has no photons:
    ``settings.photons`` is returned)."""
    if estimator.reference:
        return settings.photons
    warm_up(scene, estimator, settings)
    probe = replace(settings, photons=PROBE_PHOTONS)
    a = time.perf_counter()
    render_pass(scene, estimator, 0, 1 << 30, probe)  # a seed no render uses
    per_photon = max(time.perf_counter() - a, 1e-6) / PROBE_PHOTONS
    n = int(budget / TARGET_PASSES / per_photon)
    return int(min(max(n, PHOTON_RANGE[0]), PHOTON_RANGE[1]))
