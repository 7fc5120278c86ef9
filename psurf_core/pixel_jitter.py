"""Where each pass's camera rays go inside their pixels: the pixel sampler.

SCENES.md's box filter makes a pixel's value the average over its area, so every pass draws
a point of each pixel (the ray's *jitter*) and every pass's estimate is unbiased as long as
that point is uniform over the pixel. Two samplers:

``independent``
    A fresh uniform point every pass (``rng``, pass ``i``'s ray generator). The passes are
    independent: the per-pass variance over the passes is the variance of the mean image
    (:mod:`psurf_core.study`'s ``mean_variance``). The pixel-area part of it, ``Vj`` in
    :mod:`psurf_core.pass_size`, then falls as ``1 / P`` like the photons' part.
``r2``
    Pass ``i`` takes point ``i`` of the R2 low-discrepancy sequence (Roberts 2018: the
    additive recurrence on the plastic number) shifted by a uniform random offset per pixel
    (a Cranley-Patterson rotation, drawn once per seed from ``SeedSequence([seed,
    ROTATION_KEY])``: the one random draw every pass of a seed shares). Each pass's point is
    uniform over the pixel (a uniform shift of any point is), so each pass stays unbiased; the
    passes' points together cover each pixel evenly, so the pixel-area part of the mean's
    variance falls much faster than ``1 / P``. What is left is the photons' part: an estimator
    whose photons are cheap in variance (photon surfaces) gains most. The passes are no longer
    independent: per-pass variance over ``P`` overstates the mean's variance (by the ``Vj``
    it counts); the variance across independent runs (different seeds) does not.

Both are deterministic in ``(seed, pass index)``: the same seed gives the same image
anywhere, on any worker, after any resume.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

#: The samplers :func:`pass_jitter` knows.
SAMPLERS = ("independent", "r2")

#: The second entry of the SeedSequence of a seed's per-pixel rotation: 2^32 - 1, a pass
#: index no render reaches, so no pass's own sequence ``[seed, i]`` is the rotation's.
ROTATION_KEY = 0xFFFFFFFF

#: R2's step: ``(1 / g, 1 / g^2)`` with ``g`` the plastic number (``g^3 = g + 1``).
_G = 1.32471795724474602596
R2_STEP = np.array([1.0 / _G, 1.0 / _G**2])


def check_sampler(name: str) -> str:
    """``name`` if it is a sampler, else a ValueError naming the choices."""
    if name not in SAMPLERS:
        raise ValueError(f"unknown pixel sampler {name!r} (choose from {', '.join(SAMPLERS)})")
    return name


@lru_cache(maxsize=8)
def rotation(seed: int, n: int) -> np.ndarray:
    """(n, 2) float in [0, 1): the per-ray-slot offsets of seed ``seed`` (read-only; cached:
    every pass of a render reads the same ones)."""
    rot = np.random.default_rng(np.random.SeedSequence([int(seed), ROTATION_KEY])).random((n, 2))
    rot.setflags(write=False)
    return rot


def r2_points(index: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """(n, 2): point ``index`` of R2 shifted by ``rot`` (n, 2), modulo 1."""
    return (np.outer(np.asarray(index, dtype=float) + 1.0, R2_STEP) + rot) % 1.0


def independent_jitter(n: int, rng: np.random.Generator):
    """``(jx, jy)``, each (n,): fresh uniform points from ``rng`` (x drawn first, then y: the
    order every image so far was rendered with)."""
    return rng.random(n), rng.random(n)


def pass_jitter(sampler: str, n_pixels: int, spp: int, seed: int, pass_index: int,
                rng: np.random.Generator):
    """``(jx, jy)``, each (n_pixels * spp,) in [0, 1): pass ``pass_index``'s point in every
    pixel (pixel-major, ``spp`` per pixel), for :func:`~psurf_core.camera.camera_rays`.

    ``independent`` draws them from ``rng`` (as ``camera_rays`` always did: the same bits);
    ``r2`` gives ray slot ``q`` (pixel ``q // spp``, ray ``j = q % spp``) point
    ``pass_index * spp + j`` of R2 shifted by the seed's rotation of slot ``q``.
    """
    n = n_pixels * spp
    if sampler == "independent":
        return independent_jitter(n, rng)
    check_sampler(sampler)
    idx = pass_index * spp + np.tile(np.arange(spp), n_pixels)
    pts = r2_points(idx, rotation(int(seed), n))
    return pts[:, 0], pts[:, 1]
