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
from ..memo import memo

#: A point this close to a quad's plane (times the scene's scale, :func:`_scale`) lies on it.
TOUCH = 1e-13
#: Points this far on one side of a plane (times the scale) are strictly on that side.
SIDE = 1e-4
#: A direction leaves a plane when the cosine of its angle to the normal is at least this.
LEAVE_COS = 1e-5


def _scale(scene) -> float:
    """The medium box's diagonal or its largest coordinate, whichever is larger (rounding
    grows with the coordinates)."""
    lo, hi = np.asarray(scene.medium.bounds_min), np.asarray(scene.medium.bounds_max)
    return float(max(np.linalg.norm(hi - lo), np.abs(lo).max(), np.abs(hi).max()))


def misses(blockers, points) -> np.ndarray:
    """(M, N) bool: the box of ``points`` (a sequence of (M, 3) arrays: each primitive's
    region is their hull), padded by ``BOUNDS_PAD``, misses blocker ``j``'s box padded by
    ``BOUNDS_PAD`` (``Blockers.bounds``)."""
    lo = np.minimum.reduce(points) - BOUNDS_PAD
    hi = np.maximum.reduce(points) + BOUNDS_PAD
    blo = blockers.bounds[:, 0] - BOUNDS_PAD
    bhi = blockers.bounds[:, 1] + BOUNDS_PAD
    out = np.zeros((lo.shape[0], blo.shape[0]), dtype=bool)
    for k in range(3):  # (a loop over 3 axes: no (M, N, 3) temporaries)
        out |= (lo[:, k, None] > bhi[None, :, k]) | (hi[:, k, None] < blo[None, :, k])
    return out


def _planes(blockers):
    """Unit normals (N, 3) and offsets (N,) of the blockers' planes (NaN: not a quad), built
    once per ``blockers``."""
    def build():
        pl = blockers.planes
        n = np.linalg.norm(pl[:, :3], axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            return pl[:, :3] / n[:, None], pl[:, 3] / n

    return memo(blockers, "unit planes", build)


def _sides(blockers, points, tol):
    """(M, N) bool each: every point (a sequence of (M, 3) arrays) at a signed distance of
    at least ``tol`` above, or at least ``tol`` below, quad ``j``'s plane (False for other
    blockers)."""
    unit, off = _planes(blockers)
    up = down = None
    with np.errstate(invalid="ignore"):
        for x in points:
            h = x @ unit.T - off
            u, d = h >= tol, h <= -tol
            up, down = (u, d) if up is None else (up & u, down & d)
    return up, down


def leaves(blockers, scene, start, direction: np.ndarray) -> np.ndarray:
    """(M, N) bool: segments starting in the hull of ``start`` (a sequence of (M, 3) arrays)
    along the fixed ``direction`` (M, 3) cannot be blocked by quad ``j``: every start point
    is on one closed side of its plane (within ``TOUCH``) and the direction moves away from
    it (cosine at least ``LEAVE_COS``). False for blockers that are not quads."""
    up, down = _sides(blockers, start, -TOUCH * _scale(scene))
    unit, _ = _planes(blockers)
    with np.errstate(invalid="ignore"):
        cos = direction @ unit.T  # (M, N)
        return (up & (cos >= LEAVE_COS)) | (down & (cos <= -LEAVE_COS))


def away(blockers, scene, start, end) -> np.ndarray:
    """(M, N) bool: segments from the hull of ``start`` to the hull of ``end`` (sequences of
    (M, 3) arrays) cannot be blocked by quad ``j``: every start point is on one closed side
    of its plane (within ``TOUCH``) and every end point strictly (``SIDE``) on the same side,
    so a segment can cross the plane only within ``TOUCH / SIDE`` of its length from its
    start. False for blockers that are not quads."""
    L = _scale(scene)
    su, sd = _sides(blockers, start, -TOUCH * L)
    eu, ed = _sides(blockers, end, SIDE * L)
    return (su & eu) | (sd & ed)


def clear(*reasons: np.ndarray) -> np.ndarray:
    """(M,) float, 1.0 where, for every blocker, one of ``reasons`` ((M, N) bool each) says it
    cannot block: the segment needs no test; 0.0 elsewhere (1.0 with no blocker at all)."""
    ok = np.zeros_like(reasons[0], dtype=bool)
    for r in reasons:
        ok |= r
    return np.all(ok, axis=1).astype(float)


def _untested(blockers) -> bool:
    """No blocker boxes or planes to cull with (every flag 0: every segment is tested)."""
    return blockers.bounds is None or blockers.planes is None


def hull_clear(blockers, scene, points) -> np.ndarray:
    """(M,) float: 1.0 where no blocker can block a segment between two points of the hull of
    ``points`` (a sequence of (M, 3) arrays): every blocker's box is apart, or its plane has
    them all strictly on one side (cylinders: points holding their surface and their axis)."""
    if _untested(blockers):
        return np.zeros(points[0].shape[0])
    return clear(misses(blockers, points), away(blockers, scene, points, points))


def box_clear(blockers, scene, lo, hi) -> np.ndarray:
    """:func:`hull_clear` of the boxes ``[lo, hi]`` ((M, 3) each): 1.0 where no blocker can
    block a segment between two points of a primitive's box (photon spheres and disks: the
    vertex ``x1`` and every hit ``x0`` lie in their clipped bounds)."""
    corners = [np.where(np.array([(i >> k) & 1 for k in range(3)], bool), hi, lo)
               for i in range(8)]
    return hull_clear(blockers, scene, corners)


def swept_clear(blockers, scene, region, direction, reach) -> np.ndarray:
    """(M,) float: 1.0 where no blocker can block a segment that starts in the hull of
    ``region`` (a sequence of (M, 3) arrays) and runs along the fixed unit ``direction``
    (M, 3) for at most ``reach`` (M,): the hull of the starts and their ends is apart from
    every blocker's box, or leaves a quad's plane, or lies strictly on one side of it."""
    if _untested(blockers):
        return np.zeros(region[0].shape[0])
    hull = list(region) + [r + reach[:, None] * direction for r in region]
    return clear(misses(blockers, hull), leaves(blockers, scene, region, direction),
                 away(blockers, scene, region, hull))


def line_clear(blockers, scene, start, direction, reach) -> np.ndarray:
    """(M,) float: 1.0 where no blocker can block ``start -> start + t direction`` for any
    ``0 < t <= reach``: the rebuilt segment from a photon's kept vertex along its kept
    direction to a vertex found by the hit (photon planes' ``x2 -> x1*``, generalized planes'
    ``x3 -> x2*``), tested per hit only where the photon's own segment does not cover it."""
    return swept_clear(blockers, scene, [start], direction, reach)


def plane_clear(blockers, scene, x2, w2, w1, reach2, reach1) -> np.ndarray:
    """The ``clear`` flag of photon planes (:mod:`.planes`): (M,) float, 1.0 where no blocker
    can block the segment ``x1* -> x0`` of any of a plane's hits. ``x1*`` lies on the edge
    ``x2 + [0, reach2] w2``, and the segment runs from it along the fixed ``w1`` (out to
    ``reach1``), inside the parallelogram the two span."""
    return swept_clear(blockers, scene, [x2, x2 + reach2[:, None] * w2], w1, reach1)


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
    if _untested(blockers):
        return (np.zeros(m),) * 3
    edge = [start, start + amax[:, None] * A]

    def swept(e, reach):
        return e + [x + reach[:, None] * wK for x in e]

    P = swept(edge, reach_p)
    P1, S = [x + d2 for x in P], swept([x + R for x in edge], reach_s)
    c0 = clear(misses(blockers, P), leaves(blockers, scene, edge, wK))
    c1 = clear(misses(blockers, P + P1), leaves(blockers, scene, P, w2),
               away(blockers, scene, P, P1))
    c2 = clear(misses(blockers, P1 + S), away(blockers, scene, P1, S))
    return c0, np.where(k3, c1, c0), c2
