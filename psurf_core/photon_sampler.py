"""Photon samplers: where a batch of photons takes its random numbers.

Trace draws every number through :func:`uniforms`: ``k`` numbers for each of ``m`` photons
(one call per stage: the light choice, a light's emission, a segment's flight, phase cosine
and azimuth, a roulette), laid out as the stage reads them.

* ``independent`` (the default): the batch's numpy generator, ``rng.random(k * m)``: the same
  calls and bits as ever (``tests/test_trace_identity.py``);
* ``sobol``: each photon is one point of a scrambled Sobol set drawn for the batch
  (:class:`SobolDraws`; ``scipy.stats.qmc``, linear matrix scrambling and a digital shift,
  seeded by the batch's generator), each call taking the set's next ``k`` dimensions for
  the photons that draw: each photon's numbers are the coordinates of its own point, also
  where a stage draws for fewer photons than the batch (a light's photons; the survivors of
  a segment), so a photon's whole path is a function of its point. Every point is uniform
  on the unit cube, so each photon's path is distributed as with ``independent`` numbers and
  every pass stays unbiased. (Until 2026-12-06 a stage of ``m < n`` photons took the first
  ``m`` points' dimensions, which kept each photon uniform but cut its later segments loose
  from its first.) The batch's photons together cover the cube
  evenly, so a photon-surface estimate, smooth in the photon's first dimensions (its light
  point and emission direction), varies less from pass to pass: on ``study_medium``, K = 2..3,
  ``fast-multi``'s per-photon variance was 0.77x at 64x48 and 0.57x at 256x192 while photon
  planes' did not move beyond their tail's noise (docs/study.md, "Sobol photons"). Passes
  stay independent (each batch is scrambled afresh), so per-pass error bars hold.
* ``sobol-seq``: one scrambled Sobol *sequence* over a render's passes, as the ``r2`` pixel
  sampler is one sequence over them (:mod:`psurf_core.pixel_jitter`): pass ``i`` of ``N``
  photons takes the sequence's points ``i N`` to ``(i + 1) N - 1`` (:func:`sequence_start`),
  so the first ``P`` passes together are the sequence's first ``P N`` points, which cover
  the cube more evenly than ``P`` sets scrambled apart. Each point is uniform (the scrambling,
  :func:`sequence_points`, is drawn once per seed and epoch: ``SeedSequence([seed,
  SEQUENCE_KEY, epoch])``), so every pass stays unbiased; passes are no longer independent
  (negatively correlated where the estimate is smooth in the photons), so a per-pass
  variance over-states the mean's: error bars are conservative. Where a pass is rendered
  without its seed (the pass-size pilot's split passes), it falls back to ``sobol``.

Determinism: the scrambling comes from the batch's generator (``SeedSequence([seed, i])``
spawned per batch; ``sobol-seq``: the seed's), so the same seed gives the same image
anywhere.
"""

from __future__ import annotations

import threading
import warnings

import numpy as np

#: The photon samplers, the default first.
PHOTON_SAMPLERS = ("independent", "sobol", "sobol-seq")

#: The second entry of a ``sobol-seq`` scrambling's SeedSequence: 2^32 - 2, a pass index no
#: render reaches (``pixel_jitter.ROTATION_KEY`` is 2^32 - 1).
SEQUENCE_KEY = 0xFFFFFFFE

#: ``sobol-seq`` scrambles its sequence afresh every 2^EPOCH_BITS points: scipy's engine
#: reaches point ``k`` by stepping through the ones before it (40 ms for 2^22 points of 14
#: dimensions here), so a worker that starts at a late pass never steps through more than
#: an epoch. An epoch holds a 30 s study's photons many times over.
EPOCH_BITS = 22


def check_photon_sampler(name: str) -> str:
    """``name`` if it is a photon sampler, else a ValueError naming the choices."""
    if name not in PHOTON_SAMPLERS:
        raise ValueError(f"unknown photon sampler {name!r} "
                         f"(choose from {', '.join(PHOTON_SAMPLERS)})")
    return name


def photon_dimensions(scene, depth: int) -> int:
    """The most numbers one photon of ``scene`` draws when traced ``depth`` segments that a
    Sobol set gives it: the light choice (where there are several lights), each light's
    emission (a point light 2, an area light 4, a mesh light 5:
    its triangle too), the first flight, and per later segment a roulette number, the phase
    cosine, the azimuth and the flight."""
    from .scene import AreaLight, PointLight

    per = [2 if isinstance(lt, PointLight) else 4 if isinstance(lt, AreaLight) else 5
           for lt in scene.lights]
    choice = 1 if len(scene.lights) > 1 else 0  # one light: its choice takes no dimension
    return choice + sum(per) + 1 + 4 * max(int(depth) - 1, 0)


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

    def __init__(self, rng: np.random.Generator, n: int, dims: int, points=None):
        self.rng, self.n, self.dims, self.next = rng, int(n), int(dims), 0
        if points is None:
            from scipy.stats import qmc

            with warnings.catch_warnings():
                # "balance properties ... n a power of 2": each point is uniform at any n.
                warnings.simplefilter("ignore", UserWarning)
                points = qmc.Sobol(self.dims, scramble=True, rng=rng).random(self.n)
        self.points = points

    def columns(self, k: int, m: int, pairs: bool = False,
                rows: np.ndarray | None = None, spare: bool = False) -> np.ndarray:
        """(k * m,) the set's next ``k`` dimensions of points ``rows`` ((m,) photon indices
        of the batch: each photon its own point; default the first ``m``), dimension by
        dimension (with ``pairs`` the first two interleaved, point by point); independent
        numbers where the set has no such dimensions, or for ``spare`` numbers (see
        :func:`uniforms`), which take none of the set's dimensions."""
        if spare:
            return self.rng.random(k * m)
        d0, self.next = self.next, self.next + k
        if self.next > self.dims or m > self.n:
            cols = self.rng.random((k, m))
        elif rows is None:
            cols = self.points[:m, d0:d0 + k].T
        else:
            cols = self.points[rows[:m], d0:d0 + k].T
        if not pairs:
            return np.ascontiguousarray(cols).ravel()
        return np.concatenate([cols[:2].T.ravel(), cols[2:].ravel()])


def uniforms(rng, k: int, m: int, out: np.ndarray | None = None,
             pairs: bool = False, rows: np.ndarray | None = None,
             spare: bool = False) -> np.ndarray:
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
    rows : (m,) int array, optional
        The batch indices of the ``m`` photons drawing (the survivors of a stage, a light's
        photons): a Sobol set gives each photon the dimensions of its own point, so a
        photon's whole path is one point of the set (a generator ignores them).
    spare : bool
        Numbers no estimate depends on (the light choice where the scene has one light):
        a Sobol set gives them independent numbers and keeps its first dimensions, whose
        projections are its most even, for the light point and the emission direction. A
        generator draws them as any others (the draws of every earlier version).

    Returns
    -------
    (k * m,) float
        ``out`` when given.
    """
    if isinstance(rng, SobolDraws):
        r = rng.columns(k, m, pairs, rows, spare)
        if out is None:
            return r
        out[:] = r
        return out
    return rng.random(k * m) if out is None else rng.random(out=out)


def sequence_start(pass_index: int, photons: int, batch: int, batch_size: int) -> int:
    """The index in the ``sobol-seq`` sequence of batch ``batch``'s first photon in pass
    ``pass_index`` of ``photons`` photons (batches of ``batch_size``)."""
    return int(pass_index) * int(photons) + int(batch) * int(batch_size)


_ENGINES: dict = {}
_ENGINES_LOCK = threading.Lock()


def sequence_points(seed: int, dims: int, start: int, n: int) -> np.ndarray:
    """(n, dims) float in [0, 1): points ``start`` to ``start + n - 1`` of seed ``seed``'s
    scrambled Sobol sequence of ``dims`` dimensions (the ``sobol-seq`` sampler). The same
    points whatever was asked before: a kept engine is stepped forward when ``start`` lies
    ahead of it and rebuilt otherwise (one per seed, dimension count and epoch)."""
    from scipy.stats import qmc

    epoch, local = divmod(int(start), 1 << EPOCH_BITS)
    key = (int(seed), int(dims), epoch)
    with _ENGINES_LOCK:
        eng = _ENGINES.pop(key, None)
        if eng is None or eng.num_generated > local:
            ss = np.random.SeedSequence([int(seed), SEQUENCE_KEY, epoch])
            eng = qmc.Sobol(int(dims), scramble=True, rng=np.random.default_rng(ss))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # n a power of 2: see SobolDraws
            if local > eng.num_generated:
                eng.fast_forward(local - eng.num_generated)
            pts = eng.random(int(n))
        if len(_ENGINES) >= 8:  # a render keeps one; a worker of many seeds a few
            _ENGINES.pop(next(iter(_ENGINES)))
        _ENGINES[key] = eng
    return pts


def batch_draws(sampler: str, rng: np.random.Generator, scene, n: int, depth: int,
                seed: int | None = None, start: int = 0):
    """What Trace draws from for a batch of ``n`` photons under ``sampler``: ``rng`` itself
    (``independent``) or a :class:`SobolDraws` seeded by it (``sobol``; ``sobol-seq`` with
    ``seed`` given: the points from ``start`` of the seed's sequence, :func:`sequence_points`,
    ``rng`` drawing only the dimensions beyond the sequence's)."""
    if sampler == "independent":
        return rng
    check_photon_sampler(sampler)
    dims = photon_dimensions(scene, depth)
    if sampler == "sobol-seq" and seed is not None:
        return SobolDraws(rng, n, dims, sequence_points(seed, dims, start, n))
    return SobolDraws(rng, n, dims)
