"""The MIS weight in compiled code, composed from the members' own ``density`` twins.

:func:`weight_of` turns an MIS set into inline functions (:class:`Weight`): the
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

from collections.abc import Callable
from typing import NamedTuple

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
    """``(share, q)`` of a member: ``share(row, n)`` is its share ``n`` where it can produce
    the path of ``row`` (its scatter count ``K`` and light kind), else 0, and ``q(row, n,
    short)`` is ``(n Q)^b`` on ``row`` for that share and its shortness (``nan_to_num(|Q|)``
    as :func:`psurf_core.mis.member_densities`; with ``ratio``, ``density`` is the member's
    ``short_ratio(row)`` and ``Q`` that). ``K`` and the light kind are the photon's, the same
    for every hit of a primitive: the walker calls ``share`` once a primitive and ``q`` at
    every hit (with the checks at every hit, ``fast-multi``'s walk took 1.1x as long:
    docs/study.md, "The MIS weight's checks once a primitive"). ``Q`` is made finite before
    ``n`` multiplies it, so a member that is off or cannot produce the path (``n = 0``) adds
    exactly 0 even where its density of this path is NaN. :func:`~.jit.scalar` functions,
    built once per member kind (:func:`member_key`) and heuristic and shared by every set and
    walker they appear in: numba types them once, where inlined copies were typed again in
    each of a set's walkers; LLVM inlines them all the same."""
    key = (density, min_k, max_k, mask, power, ratio)
    if key not in _TERMS:

        @scalar(weight=True)
        def share(row, n):
            if row.K < min_k or (max_k >= 0 and row.K > max_k) or (mask >> row.kind) & 1 == 0:
                return 0.0
            return n

        @scalar(weight=True)
        def q(row, n, short):
            v = abs(density(row) if ratio else density(row, short))
            if not v < np.inf:  # NaN and inf count as 0
                v = 0.0
            v = n * v
            return v * v if power else v

        _TERMS[key] = (share, q)
    return _TERMS[key]


#: Member terms by (density, K range, light mask, power) (:func:`_member`).
_TERMS: dict = {}


def _term(member, j):
    """Member ``j``'s ``(share, q)`` (:func:`_member`) with its share and shortness read
    from ``params`` (the share once a primitive: ``shares[j]``)."""
    share, q = member

    @inline
    def s(row, params):
        return share(row, params[j, 0])

    @inline
    def t(row, params, shares):
        return q(row, shares[j], params[j, 1] != 0.0)

    return s, t


def _shares(gates):
    """``(row, params) -> (n_0, ..., n_{J-1})``: every member's share on the path of
    ``row`` (0 where it cannot produce it)."""
    head = gates[0]
    if len(gates) == 1:

        @inline
        def one(row, params):
            return (head(row, params),)

        return one
    rest = _shares(gates[1:])

    @inline
    def all_(row, params):
        return (head(row, params),) + rest(row, params)

    return all_


@inline
def _nothing(row, params, shares):
    return 0.0


def _sum(terms):
    if len(terms) == 1:
        return terms[0]
    head, rest = terms[0], _sum(terms[1:])

    @inline
    def total(row, params, shares):
        return head(row, params, shares) + rest(row, params, shares)

    return total


class Weight(NamedTuple):
    """A member's composed MIS weight, in two inline functions: ``shares(row, params)`` once
    a primitive (on the photon's path row: every member's share where it can produce the
    path, else 0) and ``w(row, params, shares)`` at every hit (the factor of the hit's
    per-photon value, already divided by ``n_me``)."""

    shares: Callable
    w: Callable


def weight_of(group, me: int, weighting: str | None):
    """``(weight, key)``: the :class:`Weight` of member ``me`` of ``group`` (a tuple of
    techniques) and the key naming it, or ``(None, None)`` when a member has no compiled
    density."""
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
    members = [_term(_member(f.short_ratio if ratio else f.density, *keys[j][3:], power, ratio),
                     j) for j, f in enumerate(fams)]
    shares = _shares([s for s, _ in members])
    terms = [t for _, t in members]
    # The member's own term once, for the numerator and in the denominator with the others'
    # (summed over every member, the own term was written twice; LLVM may have merged them:
    # paper-multi's CPU a hit read 0.99x in one process, alternating; docs/study.md, "Spans
    # counted as they are written").
    mine = terms[me]
    others = [t for j, t in enumerate(terms) if j != me]
    rest = _sum(others) if others else _nothing

    @inline
    def w(row, params, shares):
        m = mine(row, params, shares)
        den = m + rest(row, params, shares)
        return m / (den * params[me, 0]) if den > 0.0 else 0.0

    return Weight(shares, w)
