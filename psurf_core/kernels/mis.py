"""The MIS weight in compiled code, composed from the members' own ``density`` twins.

:func:`weight_of` turns an MIS set into one inline function ``w(row, shares)``: the
balance (``b = 1``) or power (``b = 2``) heuristic with sample counts,
``(n_me Q_me)^b / sum_j (n_j Q_j)^b / n_me``, over the members that can produce the hit's
path (its scatter count ``K`` and light kind, as ``Technique.can_produce``), each ``Q_j`` the
member family's compiled ``density`` on the reconstructed path ``row``
(:class:`~psurf_core.path_record.PathRow`) and ``n_j`` the share of the pass's photons member
``j`` swept (``shares``; see :func:`psurf_core.mis.weights_from_densities`). The members are
unrolled at compile time (a chain of closures, one per member), so the compiler inlines
every density into the walker and computes a factor the members share (a pdf, a cross
product, an exponential) once.

The shares and whether each member is short are a run-time array (:func:`member_params`):
a share of 0 switches a member off, so an estimator ``SPEC~A`` (the window's member toggles)
runs the kernels compiled for ``SPEC``; allocations (``cone@0.25``) and short or long members
compile nothing new either. Members whose family has no compiled
density make :func:`weight_of` return None (the numpy weights of :mod:`psurf_core.mis` run
instead).
"""

from __future__ import annotations

import numpy as np

from ..pdfs import KIND_CODE
from .jit import inline


def member_key(tech) -> tuple:
    """What of member ``tech`` the compiled weight depends on (its share and whether it is
    short are run-time values: see :func:`member_params`)."""
    mask = sum(1 << KIND_CODE[k] for k in tech.lights)
    return (type(tech).__module__, type(tech).__qualname__, getattr(tech, "which", None),
            int(tech.min_k), -1 if tech.max_k is None else int(tech.max_k), mask)


def member_params(full_group, shares) -> np.ndarray:
    """(J, 2) float: per member of ``full_group``, its share of the photons (0: off) and
    1.0 if it is short: the run-time half of the composed weight."""
    return np.ascontiguousarray(np.column_stack(
        [np.asarray(shares, dtype=float), [float(bool(m.short)) for m in full_group]]))


def _member(density, j, min_k, max_k, mask, power):
    """``(n_j Q_j)^b`` of member ``j`` on ``row`` (0 where it is off or cannot produce the
    path; ``nan_to_num(|Q|)`` as :func:`psurf_core.mis.member_densities`)."""

    @inline
    def q(row, params):
        n = params[j, 0]
        if n == 0.0:
            return 0.0
        if row.K < min_k or (max_k >= 0 and row.K > max_k) or (mask >> row.kind) & 1 == 0:
            return 0.0
        v = abs(density(row, params[j, 1] != 0.0))
        if not v < np.inf:  # NaN and inf count as 0
            v = 0.0
        v = n * v
        return v * v if power else v

    return q


def _sum(terms):
    if len(terms) == 1:
        return terms[0]
    head, rest = terms[0], _sum(terms[1:])

    @inline
    def total(row, params):
        return head(row, params) + rest(row, params)

    return total


def weight_of(group, me: int, weighting: str | None):
    """``(w, key)``: the inline weight ``w(row, shares)`` of member ``me`` of ``group`` (a
    tuple of techniques) and the key naming it, or ``(None, None)`` when a member has no
    compiled density. ``w`` is the factor of the hit's per-photon value (already divided by
    ``n_me``)."""
    fams = [getattr(m, "compiled", None) for m in group]
    if any(f is None or f.density is None for f in fams):
        return None, None
    power = weighting == "power"
    keys = tuple(member_key(m) for m in group)
    terms = [_member(f.density, j, *keys[j][3:], power) for j, f in enumerate(fams)]
    total, mine = _sum(terms), terms[me]

    @inline
    def w(row, params):
        den = total(row, params)
        return mine(row, params) / den / params[me, 0] if den > 0.0 else 0.0

    return w, (keys, me, power)
