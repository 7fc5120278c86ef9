"""What the surfaces of revolution about the axis ``(x2, A3)`` share (spec 3.3; K >= 2):
the hyperboloid (:mod:`.hyperboloids`) and the torus (:mod:`.tori`).

Both integrate the azimuth ``ph2`` of ``w2`` about ``A3`` (``w3``, or the light's axis / normal
when ``x2`` is the light): rotating ``w2`` about ``A3`` leaves ``rho(w3 . w2)`` (or the emission
term) unchanged, and the azimuth frame of ``ph1`` (spec 1) turns with it, so the rest of the
photon's subpath ``x2 -> x1 -> x0`` is revolved rigidly by the rotation ``R`` that takes it
onto the hit (:func:`revolved`). ``x2`` (tracer vertex ``K-2``) is kept and
``x1* = x2 + T2 R w2`` is rebuilt, so both share their hit record (:class:`RevolutionHit`),
their shadow segments and their Reconstruct.

Each numpy function has its compiled twin (``@twin``) beneath it; see :mod:`.cones`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..kernels.jit import twin
from ..kernels.shadow import BLOCKED, CLEAR, status
from ..kernels.vec import add, madd, norm, scale, sub
from ..path_record import with_t1, with_w1, with_w2
from ..records import Vec
from ..records import replace as set_field
from .base import cross, dot, segments_clear
from .surface_common import rebuilt_clear, unit

#: A reconstructed subpath must land on the hit within this fraction of its size; rejects the
#: squared equations' spurious branches and rotations about a (near-)zero radial offset.
RESIDUAL_TOL = 1e-7


class RevolutionHit(NamedTuple):
    """One hit of a surface of revolution (a row of its ``Hits.data``)."""

    t1: float  # distance x1* -> x0 (the torus: the photon's own T1)
    w2: Vec  # the photon's w2 revolved: x1* = x2 + T2 w2
    w1: Vec  # the photon's w1 revolved (the torus: rebuilt at c1*, then revolved)
    n_dot_psi: float  # |n . psi|


# ------------------------------------------------------------------------- Intersect
def revolved(A, T2, w2, w1, t1, P):
    """The rotation about unit ``A`` taking the radial part of ``T2 w2 + t1 w1`` onto that of
    ``P = x0 - x2``, applied to ``w2`` and ``w1``.

    Returns
    -------
    ok : (H,) bool
        Both radial parts are non-zero (else the rotation is undefined) and the revolved
        subpath lands on ``P`` within :data:`RESIDUAL_TOL` of its length ``T2 + t1``.
    w2, w1 : (H, 3) float
        The revolved directions.
    """
    src = T2[:, None] * w2 + t1[:, None] * w1
    e1, ne = unit(src - dot(src, A)[:, None] * A)
    f1, nf = unit(P - dot(P, A)[:, None] * A)
    e2, f2 = cross(A, e1), cross(A, f1)

    def rotate(v):
        return dot(v, A)[:, None] * A + dot(v, e1)[:, None] * f1 + dot(v, e2)[:, None] * f2

    w2r, w1r = rotate(w2), rotate(w1)
    with np.errstate(invalid="ignore"):
        res = np.linalg.norm(T2[:, None] * w2r + t1[:, None] * w1r - P, axis=1)
        ok = (ne > 0) & (nf > 0) & (res <= RESIDUAL_TOL * (T2 + t1))
    return ok, w2r, w1r


@twin(revolved)
def _revolved(A, T2, w2, w1, t1, P):
    src = add(scale(T2, w2), scale(t1, w1))
    e1, ne = unit(sub(src, scale(dot(src, A), A)))
    f1, nf = unit(sub(P, scale(dot(P, A), A)))
    e2, f2 = cross(A, e1), cross(A, f1)
    w2r = add(add(scale(dot(w2, A), A), scale(dot(w2, e1), f1)), scale(dot(w2, e2), f2))
    w1r = add(add(scale(dot(w1, A), A), scale(dot(w1, e1), f1)), scale(dot(w1, e2), f2))
    res = norm(sub(add(scale(T2, w2r), scale(t1, w1r)), P))
    return ne > 0.0 and nf > 0.0 and res <= RESIDUAL_TOL * (T2 + t1), w2r, w1r


# ------------------------------------------------------------------------- Evaluate
def segments(G, x0, hit):
    """The reconstructed path's segments: ``x2 -> x1*``, ``x1* -> x0``."""
    x1 = G.x2 + G.T2[:, None] * hit.w2
    return [(G.x2, x1), (x1, x0)]


def visibility(G, x0, hit, medium, blockers):
    """(H,) bool: the rebuilt ``x1*`` is in the box, ``x2 -> x1*`` and ``x1* -> x0`` are
    unoccluded (``x1*`` is never on the photon's own segment: ``w2`` is revolved)."""
    x1 = G.x2 + G.T2[:, None] * hit.w2
    known = np.zeros(x1.shape[0], dtype=bool)
    return segments_clear(blockers, (x1, x0),
                          ok=rebuilt_clear(G.x2, x1, known, False, medium, blockers))


@twin(visibility)
def _visibility(G, x0, hit, medium, blockers):
    x1 = madd(G.x2, G.T2, hit.w2)
    st0 = rebuilt_clear(G.x2, x1, False, False, medium, blockers)
    st1 = CLEAR if st0 == BLOCKED else status(x1, x0, blockers)
    return st0, st1, CLEAR


# ------------------------------------------------------------------------- MIS
def reconstruct(rec, G, hit):
    """The hit's full path: ``t1*``, the revolved ``w2*, w1*`` and ``x1* = x2 + t2 w2*``."""
    return rec.with_(t1=hit.t1, w2=hit.w2, w1=hit.w1, x1=rec.x2 + rec.t2[:, None] * hit.w2)


@twin(reconstruct)
def _reconstruct(rec, G, hit):
    row = with_w1(with_w2(with_t1(rec, hit.t1), hit.w2), hit.w1)  # w1's pdf is about w2
    return set_field(row, "x1", madd(row.x2, row.t2, hit.w2))
