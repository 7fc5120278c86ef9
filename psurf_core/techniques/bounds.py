"""Bounds of primitives: the hull binning uses for a wedge of a plane (:func:`wedge_hull`),
the axis-aligned bounds of segments or rays (:func:`ray_bounds`), the parts of hulls where a
hit can count (:func:`box_span`, :func:`hit_boxes`; for surfaces that bound a convex solid:
:mod:`.outside_box`), and all of these for a light strip (:func:`strip_bounds`).

A hit whose rebuilt vertex leaves the medium box is blocked (its value is 0) but costs the
walker its roots, acceptance and shadow status all the same: on ``study_medium`` at K = 2..3
(256x192) that was 7.7 % of ``plane-t1t2-short``'s hits and 13.3 % of ``plane-ut-short``'s
(docs/study.md, "Hulls cut to where a hit counts"). Cutting a hull to the region where its
rebuilt vertices stay in the box (a short plane's shorter side; a light strip's box,
:attr:`Primitives.box`, that the spans clip its hull to in place of the medium's) removes
those candidates and changes no value."""

from __future__ import annotations

import numpy as np

from ..scene import Scene
from .base import clip_bounds, dot
from .single import sweep_bounds
from .surface_common import box_reach

__all__ = ["box_span", "hit_boxes", "ray_bounds", "strip_bounds", "wedge_hull"]

#: Growth of a box a hull is cut to, as a share of the medium box's largest side: the
#: walker's own tests (``inside_box`` of a rebuilt vertex, exact in float64) decide every
#: hit, so a cut never drops a hit they would keep for rounding.
CLIP_SLACK = 1e-7


def slack(scene: Scene) -> float:
    """:data:`CLIP_SLACK` of the medium box's largest side (scene units)."""
    med = scene.medium
    return CLIP_SLACK * float(np.max(np.asarray(med.bounds_max) - np.asarray(med.bounds_min)))


def box_span(scene: Scene, origin: np.ndarray, direction: np.ndarray):
    """``(t_in, t_out)``, each (M,): the parameters ``t`` of the lines ``origin + t
    direction`` inside the medium box grown by :data:`CLIP_SLACK` (``t_in > t_out``: the line
    misses it; a zero direction component: inside for every ``t`` or none)."""
    med = scene.medium
    e = slack(scene)
    lo = np.asarray(med.bounds_min, float) - e
    hi = np.asarray(med.bounds_max, float) + e
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / direction
        ta, tb = (lo - origin) * inv, (hi - origin) * inv
    flat = direction == 0.0
    inside = (origin >= lo) & (origin <= hi)
    near = np.where(flat, np.where(inside, -np.inf, np.inf), np.minimum(ta, tb))
    far = np.where(flat, np.where(inside, np.inf, -np.inf), np.maximum(ta, tb))
    return near.max(axis=1), far.min(axis=1)


def hit_boxes(scene: Scene, box_lo: np.ndarray, box_hi: np.ndarray, lo: np.ndarray,
              hi: np.ndarray):
    """Per-primitive boxes where hits can count, grown by :data:`CLIP_SLACK`, as
    :attr:`Primitives.box` takes them, and the bounds ``[lo, hi]`` cut to them.

    Parameters
    ----------
    box_lo, box_hi : (M, 3) float
        Each primitive's box (inside the medium box).
    lo, hi : (M, 3) float
        The primitives' bounds.

    Returns
    -------
    box : (M, 2, 3) float
    lo, hi : (M, 3) float
        ``lo > hi`` (an empty rectangle) where the box is empty.
    """
    e = slack(scene)
    box_lo, box_hi = box_lo - e, box_hi + e
    return np.stack([box_lo, box_hi], axis=1), np.maximum(lo, box_lo), np.minimum(hi, box_hi)


def wedge_hull(scene: Scene, origin: np.ndarray, u: np.ndarray, v: np.ndarray,
               lu: np.ndarray | None = None, lv: np.ndarray | None = None) -> np.ndarray:
    """(M, 4, 3) convex hulls of the parallelograms ``origin + a u + b v``, ``0 <= a <= lu``,
    ``0 <= b <= lv`` (``lu, lv`` given), or of the part inside the medium box of the wedges
    ``a, b >= 0`` (``None``).

    For unit ``u, v`` with ``c = u . v``, ``|a u + b v|^2 >= (a + b)^2 (1 + c) / 2`` on the
    wedge, so its points within distance ``D`` of ``origin`` (``D``: the farthest box corner)
    have ``a + b <= L = D sqrt(2 / (1 + c))``: the triangle ``origin, origin + L u,
    origin + L v`` (returned with its last vertex repeated) contains them. ``L`` is inf for a
    degenerate wedge (``c = -1``): binning then uses the rectangle.
    """
    if lu is not None:
        a, b = lu[:, None] * u, lv[:, None] * v
        return np.stack([origin, origin + a, origin + a + b, origin + b], axis=1)
    med = scene.medium
    corners = np.array([[x, y, z] for x in (med.bounds_min[0], med.bounds_max[0])
                        for y in (med.bounds_min[1], med.bounds_max[1])
                        for z in (med.bounds_min[2], med.bounds_max[2])])
    far = np.sqrt(((origin[:, None, :] - corners[None]) ** 2).sum(axis=2).max(axis=1))
    c = np.clip(dot(u, v), -1.0, 1.0)
    with np.errstate(divide="ignore"):
        big = far * np.sqrt(2.0 / (1.0 + c)) * (1.0 + 1e-9)
    # Past ~1e3 box sizes the clipped vertices would lose precision: use the rectangle.
    big = np.where(big <= 1e3 * far, big, np.inf)
    with np.errstate(invalid="ignore"):  # inf x 0: NaN, which also falls back
        a, b = big[:, None] * u, big[:, None] * v
    return np.stack([origin, origin + a, origin + b, origin + b], axis=1)


def ray_bounds(origin: np.ndarray, direction: np.ndarray, length: np.ndarray | None):
    """Bounds of segments (``length`` given) or of rays to infinity (``length`` None)."""
    if length is not None:
        end = origin + length[:, None] * direction
        return np.minimum(origin, end), np.maximum(origin, end)
    inf = np.full_like(origin, np.inf)
    lo = np.where(direction < 0, -inf, origin)
    hi = np.where(direction > 0, inf, origin)
    return lo, hi


def strip_bounds(scene: Scene, org: np.ndarray, A: np.ndarray, amax: np.ndarray,
                 w: np.ndarray, length: np.ndarray | None, edge: np.ndarray, moves):
    """Where the light strips ``org + a A + b w`` (``0 <= a <= amax``, ``0 < b``, ``b <
    length`` if short; (M, 3) and (M,) each, ``length`` None: long) can be hit.

    ``edge`` (M,) is each strip's edge length ``amax |A|``; ``moves`` the offsets ``x0 - x*``
    ((M, 3) each: ``R`` and ``T1 w1``) from a hit to the rebuilt vertices that must stay in the
    box. Returns ``(lo, hi, hull, box, reach)``: the bounds (clipped to the box, then to the
    per-strip box), the hull (``wedge_hull``) of the strip out to ``reach`` (``length``, or the
    box's reach from ``org`` plus the edge for a long strip: the points of a long strip inside
    the box lie that close), and the box ``box ∩ (box + m)`` over ``moves`` that the spans
    clip the hull to (:func:`hit_boxes`)."""
    end = org + amax[:, None] * A
    lo, _ = sweep_bounds(np.minimum(org, end), w, w, length)
    _, hi = sweep_bounds(np.maximum(org, end), w, w, length)
    lo, hi = clip_bounds(scene, lo, hi)
    reach = length if length is not None else box_reach(scene, org) + edge
    hull = wedge_hull(scene, org, A, w, amax, reach)
    bmin, bmax = (np.asarray(b, float) for b in (scene.medium.bounds_min,
                                                 scene.medium.bounds_max))
    full = np.broadcast_to(bmin, org.shape), np.broadcast_to(bmax, org.shape)
    box, lo, hi = hit_boxes(scene, np.maximum.reduce([full[0], *(bmin + m for m in moves)]),
                            np.minimum.reduce([full[1], *(bmax + m for m in moves)]), lo, hi)
    return lo, hi, hull, box, reach
