"""Trace: photon subpaths from the lights, sampled as in an infinite medium (spec section 4).

The box and the blockers never stop a photon. They are recorded instead: ``prefix_ok[:, j]``
says whether the photon's own vertices ``1..j`` lie in the box and its segments ``1..j`` are
unoccluded, which every technique checks for the sampled part of a path it reconstructs.
A photon is extended only while some technique could still use its next segment (the
deepest look-back of any technique is three segments: the generalized planes rebuild
``x2, x1`` from ``x3``), so escaped photons cost a bounded amount of work and bias nothing.

Two implementations, side by side, with the same names:

* the **numpy reference**, :mod:`psurf_core.trace_numpy` (re-exported here: ``PhotonPaths``,
  the formulas and the stages) and :mod:`psurf_core.trace_emit` (emission): structs
  of arrays over the active photons, one loop over depth (``emit``, :func:`step`,
  :func:`assemble`), built from elementary formulas vectorized over photons
  (``direction_about``, :func:`phase_cosine`, :func:`free_flight`, :func:`segment_clip`, ...);
* the **compiled path**, :mod:`psurf_core.trace_compiled` and
  :mod:`psurf_core.trace_emit_compiled`, what :func:`trace` runs: per-photon numba loops of the
  same stages (``emit``, ``step``, ``assemble``, ``trace``) calling each formula's compiled
  twin, a scalar function registered under the numpy function's name
  (:func:`psurf_core.kernels.jit.twin`) with the same IEEE operations in the same order. Its
  shadow tests (:mod:`psurf_core.trace_shadow`) decide ``Blockers.occluded``'s answer from
  rounding bounds where it cannot depend on rounding, and its memory is reused between calls
  (:mod:`psurf_core.trace_buffers`).

Both draw the same random numbers from the generator (the same calls, sizes and order) and
turn them into azimuths and flights with :mod:`psurf_core.variates` (``+ - * /`` only, so
numpy and numba round alike). ``tests/test_trace_reference.py`` holds them
bit-identical on every bundled scene; ``tests/test_trace_identity.py`` holds both to the
frozen output of 2026-11-22.

Vertex numbering: ``x[:, 0]`` is the light point and ``x[:, j]`` the photon's ``j``-th
scattering vertex; segment ``j`` (stored at index ``j - 1``) goes from vertex ``j - 1`` to
vertex ``j`` along ``w[:, j-1]`` with sampled length ``t[:, j-1]``. In the spec's notation of
a K-event path, tracer vertex ``j`` is ``x_{K-j}``.
"""

from __future__ import annotations

import numpy as np

from .geometry import Blockers, blockers_of
from .kernels.jit import ctrl_c_kept
from .scene import Scene
from .trace_emit import direction_about, emit
from .trace_numpy import (  # the numpy reference and its records, re-exported
    LOOKBACK,
    PhotonPaths,
    advance,
    assemble,
    free_flight,
    phase_cosine,
    roulette_survival,
    scattered_weight,
    segment_clip,
    step,
    survives,
    trace_depth,
    trace_numpy,
)

__all__ = ["LOOKBACK", "PhotonPaths", "advance", "assemble", "direction_about", "emit",
           "free_flight", "phase_cosine", "roulette_survival", "scattered_weight",
           "segment_clip", "step", "survives", "trace", "trace_depth"]


def trace(
    scene: Scene,
    n_photons: int,
    rng: np.random.Generator,
    *,
    blockers: Blockers | None = None,
    max_depth: int | None = None,
    reference: bool = False,
) -> PhotonPaths:
    """Trace ``n_photons`` photon subpaths (spec sections 1 and 4).

    Parameters
    ----------
    scene : Scene
    n_photons : int
    rng : numpy.random.Generator
        The pass's photon generator.
    blockers : Blockers, optional
        ``blockers_of(scene)`` (built here when not given).
    max_depth : int, optional
        Segments to trace (default :func:`trace_depth`).
    reference : bool
        Run the numpy reference (:func:`psurf_core.trace_numpy.trace_numpy`) instead of the
        compiled path (``trace_compiled.trace``); the result and the generator's state are the same.

    Returns
    -------
    PhotonPaths
    """
    blockers = blockers_of(scene) if blockers is None else blockers
    depth = trace_depth(scene) if max_depth is None else int(max_depth)
    if not reference:
        from . import trace_compiled  # numba: imported on first use, not with psurf_core

        with ctrl_c_kept():
            return trace_compiled.trace(scene, n_photons, rng, blockers, depth)
    return trace_numpy(scene, n_photons, rng, blockers, depth)
