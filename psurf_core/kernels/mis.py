"""The MIS weight in compiled code, composed from the members' own ``density`` twins.

:func:`weight_of` turns an MIS set into one inline function ``w(row, shares)``: the
balance (``b = 1``) or power (``b = 2``) heuristic with sample counts,
``(n_me Q_me)^b / sum_j (n_j Q_j)^b / n_me``, over the members that can produce the hit's
path (its scatter count ``K`` and light kind, as ``Technique.can_produce``), each ``Q_j`` the
member family's compiled ``density`` on the reconstructed path ``row``
(:class:`~psurf_core.path_record.PathRow`) and ``n_j`` the share of the pass's photons member
``j`` swept (``shares``; see :func:`psurf_core.mis.weights_from_densities`). The members are
unrolled at compile time (a chain of closures, one per member). Each member's term is a
:func:`~.jit.scalar` function shared by every set and walker it appears in (numba types it
once per process; inlined in numba's IR it was typed again in each of a set's walkers: a
quarter of ``paper-multi``'s compilation, 2026-12-04); LLVM inlines the terms and their
densities into the walker all the same, where a factor the members share (a pdf, a cross
product, an exponential) is computed once.

The shares and whether each member is short are a run-time array (:func:`member_params`):
a share of 0 switches a member off, so an estimator ``SPEC~A`` (the window's member toggles)
runs the kernels compiled for ``SPEC``; allocations (``cone@0.25``) compile nothing new
either, and short or long members nothing but this: where every member is short and its
family has a ``short_ratio`` (``fast-multi``'s planes, light strips and cones), the pdfs
every member shares cancel from the heuristic, and the weight takes each member's
``short_ratio`` (its Jacobian and constants: ``E(t*) / p(t*) = 1 / st`` for each short flight)
instead of its density. The two agree to rounding (``tests/test_walkers.py`` holds the
compiled weights to the numpy ones of :mod:`psurf_core.mis`, which weigh densities), and the
exponentials and phase functions of the reconstructed path go unused. Members whose family
has no compiled density make :func:`weight_of` return None (the numpy weights run instead).
"""

from __future__ import annotations

import numpy as np

from ..pdfs import KIND_CODE
from .jit import inline, scalar


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


def _member(density, min_k, max_k, mask, power, ratio=False):
    """``(n Q)^b`` of a member on ``row`` for its share ``n`` and shortness ``short`` (0
    where it is off or cannot produce the path; ``nan_to_num(|Q|)`` as
    :func:`psurf_core.mis.member_densities`; with ``ratio``, ``density`` is the member's
    ``short_ratio(row)`` and ``Q`` that). A :func:`~.jit.scalar` function, built once
    per member kind (:func:`member_key`) and heuristic and shared by every set and walker
    it appears in: numba types it once, where an inlined copy was typed again in each of
    a set's walkers; LLVM inlines it all the same."""
    key = (density, min_k, max_k, mask, power, ratio)
    if key not in _TERMS:

        @scalar
        def q(row, n, short):
            if n == 0.0:
                return 0.0
            if row.K < min_k or (max_k >= 0 and row.K > max_k) or (mask >> row.kind) & 1 == 0:
                return 0.0
            v = abs(density(row) if ratio else density(row, short))
            if not v < np.inf:  # NaN and inf count as 0
                v = 0.0
            v = n * v
            return v * v if power else v

        _TERMS[key] = q
    return _TERMS[key]


#: Member terms by (density, K range, light mask, power) (:func:`_member`).
_TERMS: dict = {}


def _term(q, j):
    """Member ``j``'s term ``q`` with its share and shortness read from ``params``."""

    @inline
    def t(row, params):
        return q(row, params[j, 0], params[j, 1] != 0.0)

    return t


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
    # Every member short: the pdfs every member shares cancel from the heuristics, and
    # what is left of each density is its ``short_ratio`` (a Jacobian and constants).
    ratio = all(m.short and f.short_ratio is not None for m, f in zip(group, fams,
                                                                      strict=True))
    key = (keys, me, power, ratio)
    # Built once per key: composing makes numba dispatchers (~0.2 ms each), which every
    # pass would otherwise pay again before the walker cache recognises the key.
    if key not in _WEIGHTS:
        _WEIGHTS[key] = _compose(fams, keys, me, power, ratio)
    return _WEIGHTS[key], key


#: Composed weights by key (:func:`weight_of`).
_WEIGHTS: dict = {}


def _compose(fams, keys, me, power, ratio):
    terms = [_term(_member(f.short_ratio if ratio else f.density, *keys[j][3:], power, ratio),
                   j) for j, f in enumerate(fams)]
    total, mine = _sum(terms), terms[me]

    @inline
    def w(row, params):
        den = total(row, params)
        return mine(row, params) / den / params[me, 0] if den > 0.0 else 0.0

    return w
