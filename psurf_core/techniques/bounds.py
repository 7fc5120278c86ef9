"""Bounds of unbounded primitives: the hull binning uses for a wedge of a plane
(:func:`wedge_hull`) and the axis-aligned bounds of segments or rays (:func:`ray_bounds`)."""

from __future__ import annotations

import numpy as np

from ..scene import Scene
from .base import dot

__all__ = ["ray_bounds", "wedge_hull"]


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
