"""Bounds of primitives: the hull binning uses for a wedge of a plane (:func:`wedge_hull`),
the axis-aligned bounds of segments or rays (:func:`ray_bounds`), and the parts of hulls where
a hit can count (:func:`box_span`, :func:`hull_in_boxes`).

A hit whose rebuilt vertex leaves the medium box is blocked (its value is 0) but costs the
walker its roots, acceptance and shadow status all the same: on ``study_medium`` at K = 2..3
(256x192) that was 7.7 % of ``plane-t1t2-short``'s hits and 13.3 % of ``plane-ut-short``'s
(docs/study.md, "Hulls cut to where a hit counts"). Cutting a hull to the region where its
rebuilt vertices stay in the box removes those candidates and changes no value."""

from __future__ import annotations

import numpy as np

from ..binning import clip_polygons
from ..scene import Scene
from .base import dot

__all__ = ["box_span", "hull_in_boxes", "ray_bounds", "wedge_hull"]

#: Growth of a box a hull is cut to, as a share of the medium box's largest side: the
#: walker's own tests (``inside_box`` of a rebuilt vertex, exact in float64) decide every
#: hit, so a cut never drops a hit they would keep for rounding.
CLIP_SLACK = 1e-7


def _slack(scene: Scene) -> float:
    med = scene.medium
    return CLIP_SLACK * float(np.max(np.asarray(med.bounds_max) - np.asarray(med.bounds_min)))


def box_span(scene: Scene, origin: np.ndarray, direction: np.ndarray):
    """``(t_in, t_out)``, each (M,): the parameters ``t`` of the lines ``origin + t
    direction`` inside the medium box grown by :data:`CLIP_SLACK` (``t_in > t_out``: the line
    misses it; a zero direction component: inside for every ``t`` or none)."""
    med = scene.medium
    e = _slack(scene)
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


def hull_in_boxes(scene: Scene, hull: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                  box_lo: np.ndarray, box_hi: np.ndarray):
    """Hull polygons cut to one axis-aligned box each (grown by :data:`CLIP_SLACK`), and their
    bounds cut alike.

    Parameters
    ----------
    hull : (M, V, 3) float
        :attr:`Primitives.hull` rows (a row with a non-finite vertex is kept as it is: binning
        gives it its rectangle).
    lo, hi : (M, 3) float
        The primitives' bounds.
    box_lo, box_hi : (M, 3) float
        Each primitive's box: the points where its hits can count.

    Returns
    -------
    hull : (M, W, 3) float
        The cut polygons, ``W`` the most vertices any has (at least ``V``), each padded with
        its last vertex (a repeated vertex adds no edge that changes a span).
    lo, hi : (M, 3) float
        Bounds within the boxes; ``lo > hi`` (an empty rectangle) where nothing is left.
    """
    e = _slack(scene)
    box_lo, box_hi = box_lo - e, box_hi + e
    m, v, _ = hull.shape
    fin = np.flatnonzero(np.all(np.isfinite(hull), axis=(1, 2)))
    poly, count = hull[fin], np.full(fin.size, v)
    eye = np.eye(3)
    for ax in range(3):
        poly, count = clip_polygons(poly, count, eye[ax], box_lo[fin, ax])
        poly, count = clip_polygons(poly, count, -eye[ax], -box_hi[fin, ax])
    width = max(int(count.max(initial=0)), v)
    out = np.empty((m, width, 3))
    out[:, :v] = hull
    out[:, v:] = hull[:, -1:]
    j = np.arange(width)
    last = np.take_along_axis(poly, np.maximum(count - 1, 0)[:, None, None], axis=1)
    out[fin] = np.where((j[None] < count[:, None])[:, :, None], poly[:, :width], last)
    lo, hi = np.maximum(lo, box_lo), np.minimum(hi, box_hi)
    gone = fin[count == 0]
    lo[gone], hi[gone] = 1.0, 0.0
    return out, lo, hi


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
