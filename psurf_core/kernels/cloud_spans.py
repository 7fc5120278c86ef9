"""Screen footprints of the curved families' footprint solids, clipped to the medium box.

A cone's footprint solid (:attr:`~psurf_core.techniques.base.Primitives.cloud`) is the pyramid
of its apex and a polygon ring circumscribing its base circle; a cylinder's, the right prism
of two such rings. The solid ``C`` contains the surface, but a long cone reaches far beyond
the box, and a short one beyond it on the side away from the photon's own flight: the rays
through that part of its projection meet the surface outside the medium, where nothing is
estimated (``benchmarks/cone_misses.py`` on ``cone-short`` at 256x192, ``study_medium``,
K = 2..3, before this clip: 46 % of its candidate pairs missed, 85 % of those with their
better root outside the ray's medium interval).

What can hold a hit is ``C`` clipped to the box ``B``. The vertices of the intersection of two
convex polytopes are ``C``'s vertices inside ``B``, ``C``'s edges crossing ``B``'s faces,
``B``'s edges crossing ``C``'s faces and ``B``'s corners inside ``C``; every one is an end
of one of ``C``'s edges clipped to ``B`` or of one of ``B``'s twelve edges clipped to ``C``'s
face half-spaces. The convex hull of those ends, projected (Andrew's monotone chain), is
``C`` clipped to ``B`` seen by the camera; the spans then take every pixel it touches, widened
by ``binning._SPAN_MARGIN``. The box is grown and ``C``'s faces relaxed by
:data:`CLIP_SLACK` of the scene's size, so rounding keeps a hit on the boundary inside. Where
rounding could flip a face's orientation (a ring of near-zero radius), the primitive keeps
its unclipped points (:func:`_clipped_points`).
"""

from __future__ import annotations

import numpy as np

from .jit import inline, kernel
from .projection import _cross2, _project, _row_range

#: Relative slack (of the box's and the solid's extent together) by which the box is grown
#: and the solid's faces are relaxed before clipping.
CLIP_SLACK = 1e-7


@inline
def _vertex(cloud, i, j, out):  # pragma: no cover - compiled
    for c in range(3):
        out[c] = cloud[i, j, c]


@inline
def _clip_to_box(a, b, lo, hi):  # pragma: no cover - compiled
    """Parameters ``(t0, t1)`` of segment ``a -> b`` inside the box ``[lo, hi]`` (slabs);
    ``t0 > t1``: none. Not ``mesh_bvh.slab``: that one treats a direction under
    ``PARALLEL_EPS`` (meant for unit ray directions) as ``PARALLEL_EPS``, which on these
    unnormalised edges could cut off part of an edge lying along a face within 1e-12."""
    t0, t1 = 0.0, 1.0
    for c in range(3):
        d = b[c] - a[c]
        if d == 0.0:
            if a[c] < lo[c] or a[c] > hi[c]:
                return 1.0, 0.0
            continue
        ta, tb = (lo[c] - a[c]) / d, (hi[c] - a[c]) / d
        t0 = max(t0, min(ta, tb))
        t1 = min(t1, max(ta, tb))
    return t0, t1


@inline
def _clip_to_faces(fa_k, fb_k, nf):  # pragma: no cover - compiled
    """Parameters ``(t0, t1)`` of a segment ``a -> b`` inside the half-spaces of
    :func:`_faces`, from the signed values ``fa_k[k]``, ``fb_k[k]`` of its ends at face
    ``k`` (``x . n - offset``, keep ``>= 0``; :func:`_corner_values`)."""
    t0, t1 = 0.0, 1.0
    for k in range(nf):
        fa, fb = fa_k[k], fb_k[k]
        if fa < 0.0 and fb < 0.0:
            return 1.0, 0.0
        if fa < 0.0:
            t0 = max(t0, fa / (fa - fb))
        elif fb < 0.0:
            t1 = min(t1, fa / (fa - fb))
    return t0, t1


@inline
def _corner_values(lo, hi, faces, nf, fc):  # pragma: no cover - compiled
    """``fc[q, k]``: face ``k``'s ``x . n - offset`` at box corner ``q`` (bit ``c`` of ``q``:
    ``hi[c]``, else ``lo[c]``). Each box edge joins two corners: computed once a corner, not
    once an edge's end (8 corners, 24 ends)."""
    for q in range(8):
        x = hi[0] if q & 1 else lo[0]
        y = hi[1] if q & 2 else lo[1]
        z = hi[2] if q & 4 else lo[2]
        for k in range(nf):
            fc[q, k] = x * faces[k, 0] + y * faces[k, 1] + z * faces[k, 2] - faces[k, 3]


@inline
def _faces(cloud, i, na, faces, slack, cen):  # pragma: no cover - compiled
    """The face half-spaces of primitive ``i``'s solid (``na`` = 1: a pyramid, apex first;
    else a prism of two rings of ``na``), each oriented to hold the points' centroid and
    relaxed by ``slack``; returns their count. Faces whose centroid distance is within
    rounding of zero are left out (and the caller keeps the solid's own points). ``cen``:
    a buffer of 3 for the centroid."""
    v = cloud.shape[1]
    nb = v - na
    for c in range(3):
        cen[c] = 0.0
        for j in range(v):
            cen[c] += cloud[i, j, c] / v
    nf = 0
    # Lateral faces (A_k, B_k, B_k+1), then the caps (B_0, B_1, B_2) and (A_0, A_1, A_2).
    for k in range(nb + (2 if na > 1 else 1)):
        if k < nb:
            p0 = k if na > 1 else 0
            p1, p2 = na + k, na + (k + 1) % nb
        elif k == nb:
            p0, p1, p2 = na, na + 1, na + 2
        else:
            p0, p1, p2 = 0, 1, 2
        ux = cloud[i, p1, 0] - cloud[i, p0, 0]
        uy = cloud[i, p1, 1] - cloud[i, p0, 1]
        uz = cloud[i, p1, 2] - cloud[i, p0, 2]
        wx = cloud[i, p2, 0] - cloud[i, p0, 0]
        wy = cloud[i, p2, 1] - cloud[i, p0, 1]
        wz = cloud[i, p2, 2] - cloud[i, p0, 2]
        nx, ny, nz = uy * wz - uz * wy, uz * wx - ux * wz, ux * wy - uy * wx
        nn = np.sqrt(nx * nx + ny * ny + nz * nz)
        if not nn > 0.0:
            continue
        nx, ny, nz = nx / nn, ny / nn, nz / nn
        off = nx * cloud[i, p0, 0] + ny * cloud[i, p0, 1] + nz * cloud[i, p0, 2]
        dc = nx * cen[0] + ny * cen[1] + nz * cen[2] - off
        if abs(dc) <= 100.0 * slack:
            continue
        if dc < 0.0:
            nx, ny, nz, off = -nx, -ny, -nz, -off
        faces[nf, 0], faces[nf, 1], faces[nf, 2] = nx, ny, nz
        faces[nf, 3] = off - slack
        nf += 1
    return nf


@inline
def _add(pts, n, a, b, t):  # pragma: no cover - compiled
    for c in range(3):
        pts[n, c] = a[c] + t * (b[c] - a[c])
    return n + 1


@inline
def _clipped_points(cloud, i, na, lo, hi, slack, faces, pts, a, b, cen, ins,
                    fc):  # pragma: no cover - compiled
    """Points whose convex hull is primitive ``i``'s solid clipped to the box ``[lo, hi]``
    (already grown): its vertices inside, its edges' ends clipped to the box where they
    cross it, and the box's edges clipped to its faces. Returns their count (0: the solid
    misses the box). Where a face was left out (:func:`_faces`), the solid's own points:
    the box's edges clipped to the remaining faces alone could cover far more. ``ins``: a
    buffer of ``V`` flags (which vertices are inside: an edge between two of them gives no
    point), ``fc``: of ``(8, V + 2)`` (:func:`_corner_values`)."""
    v = cloud.shape[1]
    nb = v - na
    n = 0
    for j in range(v):
        inside = True
        for c in range(3):
            if not (lo[c] <= cloud[i, j, c] <= hi[c]):
                inside = False
        ins[j] = inside
        if inside:
            _vertex(cloud, i, j, a)
            n = _add(pts, n, a, a, 0.0)
    if n == v:
        # The whole solid in the box: it is its own clip (the box's edges could add only
        # points of the faces' slack, outside the solid), and no face is needed.
        return n
    nf = _faces(cloud, i, na, faces, slack, cen)
    if nf < nb + (2 if na > 1 else 1):
        for j in range(v):
            for c in range(3):
                pts[j, c] = cloud[i, j, c]
        return v
    # Edges: lateral (A_k, B_k), ring B (B_k, B_k+1), ring A (prism).
    for k in range(nb * 2 + (na if na > 1 else 0)):
        if k < nb:
            e0, e1 = (k if na > 1 else 0), na + k
        elif k < 2 * nb:
            e0, e1 = na + k - nb, na + (k - nb + 1) % nb
        else:
            e0, e1 = k - 2 * nb, (k - 2 * nb + 1) % na
        if ins[e0] and ins[e1]:  # _clip_to_box gives exactly (0, 1): no point
            continue
        _vertex(cloud, i, e0, a)
        _vertex(cloud, i, e1, b)
        t0, t1 = _clip_to_box(a, b, lo, hi)
        if t0 <= t1:
            if t0 > 0.0:
                n = _add(pts, n, a, b, t0)
            if t1 < 1.0:
                n = _add(pts, n, a, b, t1)
    _corner_values(lo, hi, faces, nf, fc)
    for e in range(12):  # the box's edges: along axis e // 4 at the corner e % 4 of the others
        ax = e // 4
        c1, c2 = (ax + 1) % 3, (ax + 2) % 3
        a[ax], b[ax] = lo[ax], hi[ax]
        a[c1] = b[c1] = hi[c1] if e % 2 else lo[c1]
        a[c2] = b[c2] = hi[c2] if (e // 2) % 2 else lo[c2]
        qa = ((e % 2) << c1) | (((e // 2) % 2) << c2)  # the corners of a and b
        t0, t1 = _clip_to_faces(fc[qa], fc[qa | (1 << ax)], nf)
        if t0 <= t1:
            n = _add(pts, n, a, b, t0)
            n = _add(pts, n, a, b, t1)
    return n


@inline
def _extent(cloud, i, lo, hi):  # pragma: no cover - compiled
    """The largest coordinate extent of the box and primitive ``i``'s points together."""
    big = 0.0
    for c in range(3):
        mn, mx = lo[c], hi[c]
        for j in range(cloud.shape[1]):
            mn, mx = min(mn, cloud[i, j, c]), max(mx, cloud[i, j, c])
        big = max(big, mx - mn)
    return big


def hull_width(v: int) -> int:
    """Vertices of a projected hull that :func:`cloud_project` keeps (more: the primitive's
    rectangle): a bound on the memory its outputs take, ``M x hull_width`` twice, where the
    clipped points can be many more (:func:`max_points`)."""
    return 2 * v + 8


@inline
def _hull(pts, n, cam, qx, qy, hx, hy):  # pragma: no cover - compiled
    """The projections of ``pts[:n]`` sorted by (x, y) in ``qx, qy``, and their convex hull
    (Andrew's monotone chain, counter-clockwise) in ``hx, hy``; returns its vertex count."""
    for j in range(n):  # project, then insertion-sort by (x, y): n is small
        x, y, _ = _project(pts[j, 0], pts[j, 1], pts[j, 2], cam)
        k = j
        while k > 0 and (qx[k - 1] > x or (qx[k - 1] == x and qy[k - 1] > y)):
            qx[k], qy[k] = qx[k - 1], qy[k - 1]
            k -= 1
        qx[k], qy[k] = x, y
    h = 0
    for j in range(n):  # lower hull
        while h >= 2 and _cross2(hx[h - 2], hy[h - 2], hx[h - 1], hy[h - 1], qx[j],
                                 qy[j]) <= 0.0:
            h -= 1
        hx[h], hy[h] = qx[j], qy[j]
        h += 1
    lower = h + 1
    for j in range(n - 2, -1, -1):  # upper hull
        while h >= lower and _cross2(hx[h - 2], hy[h - 2], hx[h - 1], hy[h - 1], qx[j],
                                     qy[j]) <= 0.0:
            h -= 1
        hx[h], hy[h] = qx[j], qy[j]
        h += 1
    return max(h - 1, 1)  # the last point repeats the first


def max_points(v: int, na: int) -> int:
    """The most points :func:`_clipped_points` writes for a solid of ``v`` points (``na``
    in its first ring): each vertex, two per edge, two per box edge."""
    nb = v - na
    return v + 2 * (2 * nb + (na if na > 1 else 0)) + 24


@kernel(nogil=True)
def cloud_project(cloud, na, live, near, box, cam, x0, x1, y0, y1, pmax,
                  width):  # pragma: no cover - compiled
    """Per primitive: its footprint solid clipped to the box (module docstring), projected
    to pixels, as the convex hull (Andrew's monotone chain, counter-clockwise) of its clipped
    points, and its first candidate row and row count (as :func:`.spans._clip_project`).
    A solid with a point that is not finite, or a clipped point not in front of the near
    plane (``near``: ``(n, offset)``), or a hull of more than :func:`hull_width` vertices,
    gets its rectangle's rows and ``count = -1``; one that misses the box gets no rows.

    Parameters
    ----------
    cloud : (M, V, 3) float
        The solids' points: ``na`` = 1, an apex then a ring (a pyramid); else two rings of
        ``na`` points, in the same order (a right prism).
    box : (2, 3) float
        The medium box's corners.
    pmax, width : int
        :func:`max_points` of ``(V, na)``, :func:`hull_width` of ``V``.

    Returns
    -------
    px, py : (M, width) float
    count : (M,) int64
    r0, nr : (M,) int64
    """
    m, v = cloud.shape[0], cloud.shape[1]
    px = np.zeros((m, width))
    py = np.zeros((m, width))
    count = np.zeros(m, np.int64)
    r0 = np.zeros(m, np.int64)
    nr = np.zeros(m, np.int64)
    qx = np.empty(pmax)
    qy = np.empty(pmax)
    hx = np.empty(2 * pmax)  # Andrew's chain holds up to twice its points
    hy = np.empty(2 * pmax)
    pts = np.empty((pmax, 3))
    faces = np.empty((v + 2, 4))
    ins = np.empty(v, np.bool_)
    fc = np.empty((8, v + 2))
    a, b, cen = np.empty(3), np.empty(3), np.empty(3)
    lo, hi = np.empty(3), np.empty(3)
    for i in range(m):
        if not live[i]:
            continue
        finite, n = True, 0
        for j in range(v):
            for c in range(3):
                if not np.isfinite(cloud[i, j, c]):
                    finite = False
        if finite:
            slack = CLIP_SLACK * _extent(cloud, i, box[0], box[1])
            for c in range(3):
                lo[c], hi[c] = box[0, c] - slack, box[1, c] + slack
            n = _clipped_points(cloud, i, na, lo, hi, slack, faces, pts, a, b, cen, ins, fc)
            if n == 0:
                continue
            for j in range(n):
                d = pts[j, 0] * near[0] + pts[j, 1] * near[1] + pts[j, 2] * near[2] - near[3]
                if not d >= 0.0:
                    finite = False
        h = 0
        if finite:
            h = _hull(pts, n, cam, qx, qy, hx, hy)
        if not finite or h > width:
            count[i] = -1
            r0[i] = y0[i]
            nr[i] = y1[i] - y0[i]
            continue
        for j in range(h):
            px[i, j], py[i, j] = hx[j], hy[j]
        count[i] = h
        ymin, ymax = np.inf, -np.inf
        for j in range(h):
            ymin = min(ymin, py[i, j])
            ymax = max(ymax, py[i, j])
        r0[i], nr[i] = _row_range(ymin, ymax, y0[i], y1[i])
    return px, py, count, r0, nr
