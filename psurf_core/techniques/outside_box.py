"""The part of the medium box outside a convex solid, for surfaces that bound one.

A photon cylinder's surface is the boundary of an infinite tube and a photon sphere's of a
ball, both convex. A hit counts only inside the medium box ``B``, so every surface point that
can give one lies in ``B`` minus the solid's open interior ``C``. That set is not convex, but
its axis-aligned bounds are exact and cheap: a point of ``B \\ C`` with ``x_k = a`` exists
iff the box's cross-section at ``x_k = a`` (a rectangle) is not inside ``C``, iff one of the
rectangle's corners is not (``C`` is convex), and those corners run along the box's four
edges parallel to axis ``k``. So the largest ``x_k`` of ``B \\ C`` is the largest ``a`` at
which one of those edges is outside ``C``, read off the interval where the edge's line is
inside ``C`` (a quadratic's negative part), and likewise the smallest.

:func:`cut_to_outside` clips a primitive's bounds to them. Where ``C`` holds the whole box (a
wide tube or ball) the bounds are empty; where it holds a corner or a face, they shrink to the
rest; either way only pairs without a hit go (on ``scenes/area.toml``, ``python
benchmarks/pass_breakdown.py scenes/area.toml --spec paper-multi`` counts a cylinder's
candidate pairs 7.78M -> 5.70M and ``--spec paper-single --photons 2500`` ``ss-sphere``'s
1.97M -> 1.33M, for the same hits: docs/study.md, "Tubes and balls that hold the box").
The box is grown by ``bounds.CLIP_SLACK`` first and the bounds after, so rounding drops no
hit.
"""

from __future__ import annotations

import numpy as np

from ..scene import Scene
from .base import dot
from .bounds import slack
from .surface_common import quadratic_roots

__all__ = ["ball_edges", "cut_to_outside", "outside_bounds", "tube_edges"]


def tube_edges(x: np.ndarray, w: np.ndarray, r: np.ndarray):
    """The quadratic of the tubes of radius ``r`` (M,) about the lines ``x + h w`` ((M, 3),
    ``w`` unit) on a box edge: a function of the edge's point ``p`` (3,) and axis ``k``
    returning ``(A, B, C)`` (M,) each, the edge ``p + a e_k`` inside the tube where
    ``A a^2 + 2 B a + C < 0`` (``A >= 0``): the squared distance to the axis minus ``r^2``."""
    def quadratic(p, k):
        q = p - x
        q_perp = q - dot(q, w)[:, None] * w
        d_perp = -w[:, k, None] * w
        d_perp[:, k] += 1.0
        return dot(d_perp, d_perp), dot(q_perp, d_perp), dot(q_perp, q_perp) - r * r
    return quadratic


def ball_edges(c: np.ndarray, radius: np.ndarray):
    """:func:`tube_edges` for the balls of ``radius`` (M,) about ``c`` (M, 3)."""
    def quadratic(p, k):
        q = p - c
        return np.ones(len(c)), q[:, k], dot(q, q) - radius * radius
    return quadratic


def _inside(A, B, C):
    """(a_in, a_out) (M,) each: the open interval where ``A a^2 + 2 B a + C < 0`` (``A >=
    0``; ``a_in > a_out``: nowhere). ``A = 0`` (an edge parallel to a tube's axis): all or
    nothing, by the sign of ``C``."""
    r = quadratic_roots(np.where(A > 0.0, A, 1.0), B, C)
    a_in, a_out = np.fmin(r[0], r[1]), np.fmax(r[0], r[1])
    some = A > 0.0
    a_in = np.where(some, np.where(np.isnan(a_in), np.inf, a_in), np.where(C < 0.0, -np.inf,
                                                                        np.inf))
    a_out = np.where(some, np.where(np.isnan(a_out), -np.inf, a_out),
                     np.where(C < 0.0, np.inf, -np.inf))
    return a_in, a_out


def outside_bounds(scene: Scene, quadratic) -> tuple[np.ndarray, np.ndarray]:
    """``(lo, hi)`` (M, 3) each: the axis-aligned bounds of the medium box (grown by
    ``CLIP_SLACK``, then the bounds too) minus the open solids of ``quadratic``
    (:func:`tube_edges`, :func:`ball_edges`); ``lo > hi`` where a solid holds the box."""
    s = slack(scene)
    blo, bhi = np.asarray(scene.medium.bounds_min) - s, np.asarray(scene.medium.bounds_max) + s
    lo, hi = None, None
    for k in range(3):
        j1, j2 = (k + 1) % 3, (k + 2) % 3
        for c1 in (blo[j1], bhi[j1]):
            for c2 in (blo[j2], bhi[j2]):
                p = np.zeros(3)
                p[j1], p[j2] = c1, c2  # the edge p + a e_k, blo_k <= a <= bhi_k
                a_in, a_out = _inside(*quadratic(p, k))
                # Its largest a outside the solid: the end bhi_k, or where it enters the
                # solid (none: -inf) if bhi_k is inside; the smallest likewise.
                top = np.where((a_in < bhi[k]) & (bhi[k] < a_out),
                               np.where(a_in >= blo[k], a_in, -np.inf), bhi[k])
                bot = np.where((a_in < blo[k]) & (blo[k] < a_out),
                               np.where(a_out <= bhi[k], a_out, np.inf), blo[k])
                if lo is None:
                    lo, hi = np.full((len(top), 3), np.inf), np.full((len(top), 3), -np.inf)
                hi[:, k] = np.maximum(hi[:, k], top)
                lo[:, k] = np.minimum(lo[:, k], bot)
    return lo - s, hi + s


def cut_to_outside(scene: Scene, lo: np.ndarray, hi: np.ndarray, quadratic) -> None:
    """Clip the bounds ``lo, hi`` (M, 3) in place to :func:`outside_bounds`; where those are
    empty, the medium box's corners swapped (finite and empty, as clipping to the box keeps
    them): the spans and binning give such a primitive no candidate pair."""
    if len(lo) == 0:
        return
    olo, ohi = outside_bounds(scene, quadratic)
    np.maximum(lo, olo, out=lo)
    np.minimum(hi, ohi, out=hi)
    empty = np.any(~(lo <= hi), axis=1)
    lo[empty], hi[empty] = scene.medium.bounds_max, scene.medium.bounds_min
