"""Photon samplers: where a batch of photons takes its random numbers.

Trace draws every number through :func:`uniforms`: ``k`` numbers for each of ``m`` photons
(one call per stage: the light choice, a light's emission, a segment's flight, phase cosine
and azimuth, a roulette), laid out as the stage reads them.

* ``independent`` (the default): the batch's numpy generator, ``rng.random(k * m)``: the same
  calls and bits as ever (``tests/test_trace_identity.py``);
* ``sobol``: each photon is one point of a scrambled Sobol set drawn for the batch
  (:class:`SobolDraws`; ``scipy.stats.qmc``, linear matrix scrambling and a digital shift,
  seeded by the batch's generator), each call taking the set's next ``k`` dimensions for
  the first ``m`` points. Every point is uniform on the unit cube and the dimensions are
  scrambled independently, so each photon's numbers are jointly uniform, as with
  ``independent``, and every pass stays unbiased; where a stage draws for ``m < n``
  photons (after roulette), photon ``i`` of the stage takes point ``i`` of its dimensions,
  which are independent of the earlier ones. The batch's photons together cover the cube
  evenly, so a photon-surface estimate, smooth in the photon's first dimensions (its light
  point and emission direction), varies less from pass to pass: on ``study_medium``, K = 2..3,
  ``fast-multi``'s per-photon variance was 0.77x at 64x48 and 0.57x at 256x192 while photon
  planes' did not move beyond their tail's noise (docs/study.md, "Sobol photons"). Passes
  stay independent (each batch is scrambled afresh), so per-pass error bars hold.

Determinism: the scrambling comes from the batch's generator (``SeedSequence([seed, i])``
spawned per batch), so the same seed gives the same image anywhere.
"""

from __future__ import annotations

import warnings

import numpy as np

#: The photon samplers, the default first.
PHOTON_SAMPLERS = ("independent", "sobol")


def check_photon_sampler(name: str) -> str:
    """``name`` if it is a photon sampler, else a ValueError naming the choices."""
    if name not in PHOTON_SAMPLERS:
        raise ValueError(f"unknown photon sampler {name!r} "
                         f"(choose from {', '.join(PHOTON_SAMPLERS)})")
    return name


def photon_dimensions(scene, depth: int) -> int:
    """The most numbers one photon of ``scene`` draws when traced ``depth`` segments: the
    light choice, each light's emission (a point light 2, an area light 4, a mesh light 5:
    its triangle too), the first flight, and per later segment a roulette number, the phase
    cosine, the azimuth and the flight."""
    from .scene import AreaLight, PointLight

    per = [2 if isinstance(lt, PointLight) else 4 if isinstance(lt, AreaLight) else 5
           for lt in scene.lights]
    return 1 + sum(per) + 1 + 4 * max(int(depth) - 1, 0)


class SobolDraws:
    """The ``sobol`` sampler's numbers for one batch of ``n`` photons (module docstring).

    Parameters
    ----------
    rng : numpy.random.Generator
        The batch's generator: it scrambles the set (and gives independent numbers to any
        dimension beyond ``dims``).
    n : int
        Photons in the batch.
    dims : int
        Dimensions of the set (:func:`photon_dimensions`).
    """

    def __init__(self, rng: np.random.Generator, n: int, dims: int):
        from scipy.stats import qmc

        self.rng, self.n, self.dims, self.next = rng, int(n), int(dims), 0
        with warnings.catch_warnings():
            # "balance properties ... n a power of 2": each point is uniform at any n.
            warnings.simplefilter("ignore", UserWarning)
            self.points = qmc.Sobol(self.dims, scramble=True, rng=rng).random(self.n)

    def columns(self, k: int, m: int, pairs: bool = False) -> np.ndarray:
        """(k * m,) the set's next ``k`` dimensions of its first ``m`` points, dimension by
        dimension (with ``pairs`` the first two interleaved, point by point); independent
        numbers where the set has no such dimensions."""
        d0, self.next = self.next, self.next + k
        if self.next > self.dims or m > self.n:
            cols = self.rng.random((k, m))
        else:
            cols = self.points[:m, d0:d0 + k].T
        if not pairs:
            return np.ascontiguousarray(cols).ravel()
        return np.concatenate([cols[:2].T.ravel(), cols[2:].ravel()])


def uniforms(rng, k: int, m: int, out: np.ndarray | None = None,
             pairs: bool = False) -> np.ndarray:
    """``k`` uniform numbers for each of ``m`` photons, as one stage of Trace reads them:
    ``k`` runs of ``m`` (with ``pairs``, the first ``2 m`` as ``(m, 2)`` rows).

    Parameters
    ----------
    rng : numpy.random.Generator or SobolDraws
        A generator gives ``rng.random(k * m)`` (into ``out`` if given): the calls every
        earlier version made, bit for bit.
    k, m : int
    out : (k * m,) float array, optional
    pairs : bool

    Returns
    -------
    (k * m,) float
        ``out`` when given.
    """
    if isinstance(rng, SobolDraws):
        r = rng.columns(k, m, pairs)
        if out is None:
            return r
        out[:] = r
        return out
    return rng.random(k * m) if out is None else rng.random(out=out)


def batch_draws(sampler: str, rng: np.random.Generator, scene, n: int, depth: int):
    """What Trace draws from for a batch of ``n`` photons under ``sampler``: ``rng`` itself
    (``independent``) or a :class:`SobolDraws` seeded by it."""
    if sampler == "independent":
        return rng
    check_photon_sampler(sampler)
    return SobolDraws(rng, n, photon_dimensions(scene, depth))
