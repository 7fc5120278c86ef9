"""Compiled screen footprints of primitives: the candidate pixel spans that
``binning`` computes (``screen_rects`` + ``_spans``), in compiled loops.

:func:`hull_spans` clips each primitive's hull polygon to the medium box and the near plane
(:func:`_clip_project`), projects it, and writes its per-row column spans ``[c0, c1)`` within
the primitive's screen rectangle (:func:`_screen_rects`, :func:`_row_spans_into`), padded by
``binning._SPAN_MARGIN`` pixels, so rounding changes only which misses are tried. Many
primitives are cut into pieces for threads (:mod:`.threads`); the spans are the same for any
thread count. The walkers (:mod:`.walk`) visit these spans.

The camera is passed as a :class:`~.projection.CameraRow` record."""

from __future__ import annotations

import numpy as np

from ..binning import _NEAR, _SPAN_MARGIN, screen_rects
from ..memo import memo
from .buffers import HitBuffers
from .cloud_spans import cloud_project, hull_width, max_points
from .jit import inline, kernel, scalar
from .projection import _project, _row_range, camera_row
from .threads import PIECES_PER_THREAD, guided_cut, on_threads, thread_count


@scalar
def _clip_int(v, hi):  # pragma: no cover - compiled
    """``np.clip(np.nan_to_num(v), 0, hi).astype(int64)`` of one value."""
    if np.isnan(v):
        return 0
    return int(min(max(v, 0.0), hi))


@scalar
def _corner(lo, hi, upper):  # pragma: no cover - compiled
    """One coordinate of a box corner; a non-finite bound stands for -+1e30."""
    if upper:
        return hi if np.isfinite(hi) else 1e30
    return lo if np.isfinite(lo) else -1e30


@kernel(nogil=True)
def _screen_rects(lo, hi, cam):  # pragma: no cover - compiled
    """``binning.screen_rects`` (conservative pixel rectangles of finite boxes
    ``[lo, hi]``)."""
    m = lo.shape[0]
    w, h = cam.width, cam.height
    x0 = np.zeros(m, np.int64)
    x1 = np.zeros(m, np.int64)
    y0 = np.zeros(m, np.int64)
    y1 = np.zeros(m, np.int64)
    for i in range(m):
        empty = False
        for ax in range(3):
            if not (lo[i, ax] <= hi[i, ax]):
                empty = True
        behind, all_behind = False, True
        xmin, xmax, ymin, ymax = np.nan, np.nan, np.nan, np.nan
        for corner in range(8):
            cx = _corner(lo[i, 0], hi[i, 0], (corner >> 2) & 1)
            cy = _corner(lo[i, 1], hi[i, 1], (corner >> 1) & 1)
            cz = _corner(lo[i, 2], hi[i, 2], corner & 1)
            px, py, depth = _project(cx, cy, cz, cam)
            if depth <= 1e-9:
                behind = True
            else:
                all_behind = False
            # nanmin / nanmax
            if not np.isnan(px):
                xmin = px if np.isnan(xmin) else min(xmin, px)
                xmax = px if np.isnan(xmax) else max(xmax, px)
            if not np.isnan(py):
                ymin = py if np.isnan(ymin) else min(ymin, py)
                ymax = py if np.isnan(ymax) else max(ymax, py)
        if behind:
            xmin, xmax, ymin, ymax = 0.0, w, 0.0, h
        x0[i] = _clip_int(np.floor(xmin) - 1, w)
        x1[i] = _clip_int(np.ceil(xmax) + 1, w)
        y0[i] = _clip_int(np.floor(ymin) - 1, h)
        y1[i] = _clip_int(np.ceil(ymax) + 1, h)
        if empty or all_behind:
            x1[i] = x0[i]
    return x0, x1, y0, y1


@kernel(nogil=True)
def _clip_project(hull, live, planes, cam, x0, x1, y0, y1):  # pragma: no cover - compiled
    """Per primitive: the hull polygon clipped to ``planes`` ((P, 7, 4): rows ``(n, offset)``,
    keep ``x . n >= offset``; one set for all (P = 1) or one per primitive; Sutherland-Hodgman
    as ``binning.clip_polygons``), projected to pixels, and its first candidate row and row
    count (as ``binning._polygon_spans``).
    A primitive not ``live`` (its rectangle is empty) gets no rows; one whose hull is not
    finite gets its rectangle's rows and ``count = -1``.

    Returns
    -------
    px, py : (M, V + 7) float
    count : (M,) int64
    r0, nr : (M,) int64
    """
    m, v = hull.shape[0], hull.shape[1]
    vmax = v + planes.shape[1]
    px = np.zeros((m, vmax))
    py = np.zeros((m, vmax))
    count = np.zeros(m, np.int64)
    r0 = np.zeros(m, np.int64)
    nr = np.zeros(m, np.int64)
    a = np.empty((vmax, 3))
    b = np.empty((vmax, 3))
    one_set = planes.shape[0] == 1
    for i in range(m):
        if not live[i]:
            continue
        # Element by element, into the scratch: ``np.isfinite(hull[i])`` made an array a
        # primitive and a plane set's view cost reference counts (~0.1 us a primitive).
        finite = True
        for j in range(v):
            for c in range(3):
                a[j, c] = hull[i, j, c]
                finite &= np.isfinite(a[j, c])
        if not finite:
            count[i] = -1
            r0[i] = y0[i]
            nr[i] = y1[i] - y0[i]
            continue
        n = v
        q = 0 if one_set else i
        for k in range(planes.shape[1]):
            n0, n1, n2, off = planes[q, k, 0], planes[q, k, 1], planes[q, k, 2], planes[q, k, 3]
            inside = True
            for j in range(n):
                if (a[j, 0] * n0 + a[j, 1] * n1 + a[j, 2] * n2 - off) < 0:
                    inside = False
            if inside:  # the usual case: nothing to clip
                continue
            out = 0
            for j in range(n):
                jn = j + 1 if j + 1 < n else 0
                dj = a[j, 0] * n0 + a[j, 1] * n1 + a[j, 2] * n2 - off
                dn = a[jn, 0] * n0 + a[jn, 1] * n1 + a[jn, 2] * n2 - off
                if dj >= 0:
                    for c in range(3):
                        b[out, c] = a[j, c]
                    out += 1
                if (dj >= 0) != (dn >= 0):
                    f = dj / (dj - dn)
                    for c in range(3):
                        b[out, c] = a[j, c] + f * (a[jn, c] - a[j, c])
                    out += 1
            n = out
            for j in range(n):
                for c in range(3):
                    a[j, c] = b[j, c]
            if n == 0:
                break
        count[i] = n
        if n == 0:
            continue
        ymin, ymax = np.inf, -np.inf
        for j in range(n):
            px[i, j], py[i, j], _ = _project(a[j, 0], a[j, 1], a[j, 2], cam)
            ymin = min(ymin, py[i, j])
            ymax = max(ymax, py[i, j])
        r0[i], nr[i] = _row_range(ymin, ymax, y0[i], y1[i])
    return px, py, count, r0, nr


@inline
def _put(o_prim, o_row, o_c0, o_c1, n, prim, row, c0, c1):  # pragma: no cover - compiled
    """Span ``(prim, row, c0, c1)`` written at entry ``n``; returns ``n + 1``."""
    o_prim[n], o_row[n], o_c0[n], o_c1[n] = prim, row, c0, c1
    return n + 1


@inline
def _pairs_of(cs, width, row, c0, c1):  # pragma: no cover - compiled
    """The candidate pairs of span ``(row, c0, c1)``: the rays of its pixels."""
    p = row * width
    return cs[p + c1] - cs[p + c0]


@kernel(nogil=True)
def _row_spans_into(px, py, count, r0, nr, x0, x1, p_off, o_prim, o_row, o_c0, o_c1,
                    n, cs, width, before):  # pragma: no cover - compiled
    """Per-row column spans ``[c0, c1)`` of the projected polygons of :func:`_clip_project`
    (each polygon edge clipped to the row's strip widened by ``_SPAN_MARGIN``, as
    ``binning._polygon_spans``), primitive-major then by row, written to the given arrays
    from entry ``n`` (empty spans are dropped), primitive ``i`` named ``p_off + i``.

    With a non-empty ``before`` ((n_spans + 1,) int64), ``before[e + 1]`` is the candidate
    pairs of the spans written up to entry ``e`` (running from this call's first entry; a
    span's pairs are the rays of its pixels, ``cs`` the pixels' running ray counts of an
    image ``width`` pixels wide): counted as each span is written, where the walk's cuts
    need them (counted after the spans in one loop, ~0.34 ms of a 15 ms ``planes`` pass on
    one core, docs/study.md, "Spans counted as they are written").

    Returns
    -------
    n : int
        The entry after the last one written.
    pairs, columns : int
        With ``before``: the written spans' candidate pairs and pixels (``sum(c1 - c0)``;
        binning's chunk size is ``columns * per_pix``); else 0, 0.

    Edge by edge: each polygon edge is clipped to the strips of the rows its ``y`` range
    can reach (one row more each side), not to every row of the primitive, and widens those
    rows' ``[xmin, xmax]``. The clip of an edge to a row's strip is the same expression as
    row by row, and a row the edge cannot reach is one whose clip is empty (the sign of
    ``hi_y - y`` or ``y - lo_y`` decides it exactly), so the spans are the same; a cone's
    footprint of ~9 edges over ~26 rows is clipped ~2-3 times a row, not 9."""
    big = 1e30
    counted = before.shape[0] > 0
    pairs = columns = 0
    most = 0
    for i in range(px.shape[0]):
        most = max(most, nr[i])
    xmin = np.empty(most)
    xmax = np.empty(most)
    for i in range(px.shape[0]):
        cnt, ra, m = count[i], r0[i], nr[i]
        if m <= 0:
            continue
        if cnt < 0:  # no finite hull: the rectangle
            if x1[i] > x0[i]:
                for row in range(ra, ra + m):
                    n = _put(o_prim, o_row, o_c0, o_c1, n, p_off + i, row, x0[i], x1[i])
                    if counted:
                        pairs += _pairs_of(cs, width, row, x0[i], x1[i])
                        columns += x1[i] - x0[i]
                        before[n] = pairs
            continue
        for r in range(m):
            xmin[r], xmax[r] = big, -big
        for j in range(cnt):
            jn = j + 1 if j + 1 < cnt else 0
            xa, ya, xb, yb = px[i, j], py[i, j], px[i, jn], py[i, jn]
            dy = yb - ya
            inv_dy = 1.0 / dy if dy != 0 else 0.0
            # Rows whose strip [row - margin, row + 1 + margin] can meet [min y, max y], one
            # more each side, within the primitive's rows.
            lo_f = max(np.floor(min(ya, yb) - 1.0 - _SPAN_MARGIN) - 1.0, float(ra))
            hi_f = min(np.floor(max(ya, yb) + _SPAN_MARGIN) + 1.0, float(ra + m - 1))
            if not lo_f <= hi_f:
                continue
            for row in range(int(lo_f), int(hi_f) + 1):
                lo_y = row - _SPAN_MARGIN
                hi_y = row + 1 + _SPAN_MARGIN
                if dy == 0:
                    t_lo, t_hi = 0.0, 1.0
                    hit = ya >= lo_y and ya <= hi_y
                else:
                    ta = (lo_y - ya) * inv_dy
                    tb = (hi_y - ya) * inv_dy
                    t_lo = max(min(ta, tb), 0.0)
                    t_hi = min(max(ta, tb), 1.0)
                    hit = t_lo <= t_hi
                if hit:
                    xl = xa + t_lo * (xb - xa)
                    xh = xa + t_hi * (xb - xa)
                    r = row - ra
                    xmin[r] = min(xmin[r], xl, xh)
                    xmax[r] = max(xmax[r], xl, xh)
        for r in range(m):
            if xmin[r] > xmax[r]:
                continue
            c0 = int(max(np.floor(xmin[r] - _SPAN_MARGIN), x0[i]))
            c1 = int(min(np.floor(xmax[r] + _SPAN_MARGIN) + 1, x1[i]))
            if c1 > c0:
                n = _put(o_prim, o_row, o_c0, o_c1, n, p_off + i, ra + r, c0, c1)
                if counted:  # (a running sum: ~1.4 ns a span, one core)
                    pairs += _pairs_of(cs, width, ra + r, c0, c1)
                    columns += c1 - c0
                    before[n] = pairs
    return n, pairs, columns


def _clip_planes(cam, box):
    """(P, 7, 4) rows ``(n, offset)`` (keep ``x . n >= offset``): the box's six faces and the
    camera's near plane; ``box`` ``(lo, hi)`` is one box ((3,) each: P = 1) or one per
    primitive ((M, 3) each: P = M)."""
    bmin, bmax = (np.asarray(b, float).reshape(-1, 3) for b in box)
    fwd = np.asarray(cam.forward, float)
    out = np.zeros((bmin.shape[0], 7, 4))
    for ax in range(3):
        out[:, 2 * ax, ax], out[:, 2 * ax, 3] = 1.0, bmin[:, ax]
        out[:, 2 * ax + 1, ax], out[:, 2 * ax + 1, 3] = -1.0, -bmax[:, ax]
    out[:, 6, :3] = fwd
    out[:, 6, 3] = float(fwd @ np.asarray(cam.position, float)) + _NEAR
    return out


#: Primitives from which :func:`hull_spans` is shared among threads (~1 us each).
_THREADED_MIN_PRIMS = 2000

#: :func:`counted_spans`' ``before``, in memory written before (:mod:`.buffers`).
_COUNTS = HitBuffers()
_BEFORE = ((np.int64, 1),)


def hull_spans(cam, lo, hi, hull, box, cloud: bool = False):
    """Candidate pixel spans ``(prim, row, c0, c1)`` of every primitive: what
    ``binning.screen_rects`` + ``binning._spans`` give (hull polygons clipped to the box and
    the near plane, within the screen rectangles of ``[lo, hi]``), in compiled loops.
    ``box`` is ``(lo, hi)`` of the medium box ((3,) each) or of a box per primitive ((M, 3)
    each: :meth:`Primitives.clip_box`; not for clouds).

    ``cloud``: ``hull`` holds footprint solids, not planar polygons (a cone: its apex and a
    ring circumscribing its base circle; a cylinder: two rings; ``Primitives.cloud``): each
    clipped to the box, its projection's convex hull gives the spans
    (:func:`.cloud_spans.cloud_project`).

    Many primitives are cut into consecutive pieces that numba's threads clip and project,
    then write the spans of, in primitive order (each primitive's spans depend on it alone):
    the same spans for any thread count."""
    return counted_spans(cam, lo, hi, hull, box, None, 0, cloud)[0]


def counted_spans(cam, lo, hi, hull, box, cs, width, cloud: bool = False):
    """:func:`hull_spans` and, where ``cs`` is given (the pixels' running ray counts,
    :func:`.rays.ray_table`, of an image ``width`` pixels wide), what comes before each span,
    counted by the threads that write the spans (:func:`_row_spans_into`'s ``before``; the
    pieces' running sums are then moved past the pieces before them).

    Returns
    -------
    spans : tuple of 4 (S,) int64
        ``(prim, row, c0, c1)``.
    before : (S + 1,) int64 or None
        The candidate pairs of spans ``0 .. i - 1`` (None without ``cs``).
    columns : int
        ``sum(c1 - c0)`` (0 without ``cs``).
    """
    per = np.ndim(box[0]) == 2  # a box per primitive (Primitives.box): its planes by piece
    planes = None if per else memo(cam, ("clip planes", tuple(np.ravel(box))),
                                   lambda: _clip_planes(cam, box))
    camv = camera_row(cam)
    c = np.ascontiguousarray
    lo, hi, hull = c(lo, float), c(hi, float), c(hull, float)
    if cloud:
        if per:
            raise ValueError("hull_spans: a footprint cloud is clipped to the medium box only")
        near, corners = c(planes[0, -1]), np.array(box, float).reshape(2, 3)
        # An odd count: an apex and a ring (a cone's pyramid); even: two rings (a prism).
        v = hull.shape[1]
        na = 1 if v % 2 else v // 2
        pmax, hw = max_points(v, na), hull_width(v)

        def outline(h, live, _, camv, x0, x1, y0, y1):
            return cloud_project(h, na, live, near, corners, camv, x0, x1, y0, y1, pmax, hw)
    else:
        outline = _clip_project
    m = lo.shape[0]
    threads = thread_count() if m >= _THREADED_MIN_PRIMS else 1
    cut = guided_cut(m, threads * PIECES_PER_THREAD) if threads > 1 else [0, m]
    parts = [None] * (len(cut) - 1)

    def project(j):  # screen rectangles, clipped and projected hulls, rows per primitive
        # (in the pieces, not before them: each step on all primitives at once was ~0.05 ms
        # of a 15 ms planes pass on one core, in Python between a pass and the next)
        a, b = cut[j], cut[j + 1]
        lo_j, hi_j = lo[a:b], hi[a:b]
        # +-inf / NaN bounds: binning's rounding at its 1e30 stand-ins is not mirrored
        x0, x1, y0, y1 = (_screen_rects(lo_j, hi_j, camv)
                          if np.isfinite(lo_j).all() and np.isfinite(hi_j).all()
                          else (c(r) for r in screen_rects(cam, lo_j, hi_j)))
        live = (x1 > x0) & (y1 > y0)
        pl = _clip_planes(cam, (box[0][a:b], box[1][a:b])) if per else planes
        parts[j] = (x0, x1, *outline(hull[a:b], live, pl, camv, x0, x1, y0, y1))

    on_threads(project, len(parts), threads)
    # Each piece writes from the first row it could fill (its rows before it), then the
    # pieces close up in order: the spans of one thread, in as much memory.
    at = np.cumsum([0] + [int(pp[-1].sum()) for pp in parts])
    out = tuple(np.empty(int(at[-1]), np.int64) for _ in range(4))
    counted = cs is not None
    cs = cs if counted else np.zeros(1, np.int64)
    before = (_COUNTS.take("before", _BEFORE, int(at[-1]) + 1)[0] if counted
              else np.zeros(0, np.int64))
    end = np.zeros(len(parts), np.int64)
    sums = np.zeros((len(parts), 2), np.int64)  # per piece: candidate pairs, columns

    def fill(j):  # pairs running within the piece: the pieces before it are added below
        x0, x1, px, py, count, r0, nr = parts[j]
        end[j], sums[j, 0], sums[j, 1] = _row_spans_into(px, py, count, r0, nr, x0, x1, cut[j],
                                                         *out, at[j], cs, width, before)

    on_threads(fill, len(parts), threads)
    n = base = 0
    for j in range(len(parts)):
        k = int(end[j] - at[j])
        if at[j] != n:
            for o in out:
                o[n:n + k] = o[at[j]:at[j] + k]  # numpy copies overlapping slices safely
        if counted and (at[j] != n or base):
            np.add(before[at[j] + 1:at[j] + k + 1], base, out=before[n + 1:n + k + 1])
        n += k
        base += int(sums[j, 0])
    if not counted:
        return tuple(o[:n] for o in out), None, 0
    before[0] = 0
    return tuple(o[:n] for o in out), before[:n + 1], int(sums[:, 1].sum())
