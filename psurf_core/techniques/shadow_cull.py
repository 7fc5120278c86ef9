"""Shadow tests a primitive's hits can skip, decided once per primitive (numpy, at Create).

A technique tests each of its hits' shadow segments against every blocker
(:meth:`~psurf_core.geometry.Blockers.occluded`, :func:`~psurf_core.kernels.shadow.status`).
Where every segment of one kind, over all of a primitive's hits, lies in a region known at
Create, a blocker that cannot block any segment in that region need not be tested. Two
reasons are exact here:

* **boxes apart**: the region's box misses the blocker's box padded by ``BOUNDS_PAD`` (the
  test's own first reject, on each segment's box, a subset of the region's);
* **a plane left behind** (quads: emitters): the segment starts in a region on one closed side
  of the quad's plane and runs along a fixed direction away from it (:func:`leaves`), or it
  runs from a region on one closed side to one strictly on that side (:func:`away`). A
  segment that crosses the plane only at its start (within rounding) is not blocked by the
  quad: the test looks at ``(SHADOW_EPS, |b - a| - SHADOW_EPS)`` only.

A segment whose every blocker can be skipped is clear without a test. The tolerances keep
that verdict the test's own in floating point: a start at most ``TOUCH`` (times the scene's
scale, :func:`_scale`) behind the plane, moving away at a slope of at least ``LEAVE_COS``, is
past it within ``TOUCH / LEAVE_COS`` = 1e-8 scales of its start, inside the
``SHADOW_EPS / 2`` = 5e-7 the test ignores for scenes up to 50 units; and the starts the
walkers rebuild on a light (the one case that touches a plane) are off it by their rounding,
~1e-16 scales, not ``TOUCH``.
"""

from __future__ import annotations

import numpy as np

from ..constants import BOUNDS_PAD

#: A point this close to a quad's plane (times the medium box's diagonal) lies on it.
TOUCH = 1e-13
#: Points this far on one side of a plane (times the diagonal) are strictly on that side.
SIDE = 1e-4
#: A direction leaves a plane when the cosine of its angle to the normal is at least this.
LEAVE_COS = 1e-5


def _scale(scene) -> float:
    """The medium box's diagonal or its largest coordinate, whichever is larger (rounding
    grows with the coordinates)."""
    lo, hi = np.asarray(scene.medium.bounds_min), np.asarray(scene.medium.bounds_max)
    return float(max(np.linalg.norm(hi - lo), np.abs(lo).max(), np.abs(hi).max()))


def misses(blockers, points: np.ndarray) -> np.ndarray:
    """(M, N) bool: the box of ``points`` (M, V, 3), padded by ``BOUNDS_PAD``, misses blocker
    ``j``'s box padded by ``BOUNDS_PAD`` (``Blockers.bounds``)."""
    lo = points.min(axis=1) - BOUNDS_PAD
    hi = points.max(axis=1) + BOUNDS_PAD
    blo = blockers.bounds[:, 0] - BOUNDS_PAD
    bhi = blockers.bounds[:, 1] + BOUNDS_PAD
    meet = np.all((lo[:, None] <= bhi[None]) & (hi[:, None] >= blo[None]), axis=2)
    return ~meet


def heights(blockers, points: np.ndarray) -> np.ndarray:
    """(M, V, N) signed distance of each point to each blocker's plane (quads; NaN for the
    others): ``x . n / |n| - c / |n|`` for ``Blockers.planes`` rows ``(n, c)``."""
    pl = blockers.planes
    n = np.linalg.norm(pl[:, :3], axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        unit, off = pl[:, :3] / n[:, None], pl[:, 3] / n
    return points @ unit.T - off


def leaves(blockers, scene, start: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """(M, N) bool: segments starting in the hull of ``start`` (M, V, 3) along the fixed
    ``direction`` (M, 3) cannot be blocked by quad ``j``: every start point is on one closed
    side of its plane (within ``TOUCH``) and the direction moves away from it (cosine at
    least ``LEAVE_COS``). False for blockers that are not quads."""
    L = _scale(scene)
    h = heights(blockers, start)  # (M, V, N)
    pl = blockers.planes
    n = np.linalg.norm(pl[:, :3], axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        cos = direction @ (pl[:, :3] / n[:, None]).T  # (M, N)
        up = (cos >= LEAVE_COS) & np.all(h >= -TOUCH * L, axis=1)
        down = (cos <= -LEAVE_COS) & np.all(h <= TOUCH * L, axis=1)
    return up | down


def away(blockers, scene, start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """(M, N) bool: segments from the hull of ``start`` (M, V, 3) to the hull of ``end``
    (M, W, 3) cannot be blocked by quad ``j``: every start point is on one closed side of its
    plane (within ``TOUCH``) and every end point strictly (``SIDE``) on the same side, so a
    segment can cross the plane only within ``TOUCH / SIDE`` of its length from its start.
    False for blockers that are not quads."""
    L = _scale(scene)
    hs, he = heights(blockers, start), heights(blockers, end)
    with np.errstate(invalid="ignore"):
        up = np.all(hs >= -TOUCH * L, axis=1) & np.all(he >= SIDE * L, axis=1)
        down = np.all(hs <= TOUCH * L, axis=1) & np.all(he <= -SIDE * L, axis=1)
    return up | down


def clear(*reasons: np.ndarray) -> np.ndarray:
    """(M,) float, 1.0 where, for every blocker, one of ``reasons`` ((M, N) bool each) says it
    cannot block: the segment needs no test; 0.0 elsewhere (1.0 with no blocker at all)."""
    ok = np.zeros_like(reasons[0], dtype=bool)
    for r in reasons:
        ok |= r
    return np.all(ok, axis=1).astype(float)


def strip_clear(blockers, scene, start, A, amax, wK, reach_p, reach_s, k3, d2, R, w2):
    """The three ``clear`` flags of light strips (:mod:`.light_planes`): (M,) float each, 1.0
    where no blocker can block the rebuilt segments ``x_K* -> x_{K-1}*``, ``x_{K-1}* ->
    x_1*``, ``x_1* -> x0`` of any of a strip's hits, so its twins skip their tests.

    The light points ``x_K*`` lie on the edge ``start + [0, amax] A``; the first scatterings
    ``x_{K-1}*`` (inside the box) in the parallelogram ``P`` the edge sweeps along ``w_K``
    out to ``reach_p``; the ``x_1*`` in ``P + d2`` (``d2 = T2 w2``; ``P`` at K = 2); the
    ``x0`` in the strip, the edge moved by ``R`` and swept out to ``reach_s``. The first
    segment leaves the light's plane along ``w_K`` (emission faces the front), the second
    runs along ``w2`` from ``P`` to ``P + d2``, the third from ``P + d2`` to the strip. At
    K = 2 the middle pair of the strip's ``segments`` is the first again, and so is its
    flag."""
    m = start.shape[0]
    if blockers.bounds is None or blockers.planes is None:
        return (np.zeros(m),) * 3
    edge = np.stack([start, start + amax[:, None] * A], axis=1)  # (M, 2, 3)

    def swept(e, reach):
        return np.concatenate([e, e + (reach[:, None] * wK)[:, None]], axis=1)

    P = swept(edge, reach_p)
    P1, S = P + d2[:, None], swept(edge + R[:, None], reach_s)
    c0 = clear(misses(blockers, P), leaves(blockers, scene, edge, wK))
    c1 = clear(misses(blockers, np.concatenate([P, P1], axis=1)),
               leaves(blockers, scene, P, w2), away(blockers, scene, P, P1))
    c2 = clear(misses(blockers, np.concatenate([P1, S], axis=1)), away(blockers, scene, P1, S))
    return c0, np.where(k3, c1, c0), c2
