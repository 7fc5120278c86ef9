"""Which camera rays can hit which primitive: screen-space binning (Tungsten's FrustumBinner idea).

Each primitive's world bounds (already clipped to the medium box) are projected to the image
as a pixel rectangle. Planar families also give a convex hull polygon
(:attr:`~psurf_core.techniques.base.Primitives.hull`: the parallelogram, or a triangle
holding the wedge's part in the box); it is clipped to the box and the camera's near plane,
projected, and only the pixels of its per-row spans (within the rectangle) become candidates,
so the pairs tested follow the primitive's true footprint. Candidate pairs are produced in
chunks of at most ``max_pairs`` so memory stays bounded, and never as a full
``rays x primitives`` array.

Curved families (cones, cylinders, ...) keep the rectangle: bounding them by a clipped
circumscribed prism or pyramid halves their pairs, but in numpy the polytope clipping and
per-row spans cost more than the intersections they save (measured; see ``benchmarks/``).
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from .camera import Rays, project
from .scene import Camera

_CORNERS = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], dtype=float)


def screen_rects(cam: Camera, lo: np.ndarray, hi: np.ndarray):
    """Conservative pixel rectangles covered by boxes ``[lo, hi]`` (M, 3).

    Returns
    -------
    x0, x1, y0, y1 : (M,) int
        Columns ``x0 <= c < x1`` and rows ``y0 <= r < y1``; empty when ``x0 >= x1``.
        A box reaching behind the camera plane gets the whole image.
    """
    m = lo.shape[0]
    empty = np.any(~(lo <= hi), axis=1)  # also catches NaN
    lo_f = np.where(np.isfinite(lo), lo, -1e30)
    hi_f = np.where(np.isfinite(hi), hi, 1e30)
    corners = lo_f[:, None, :] + _CORNERS[None] * (hi_f - lo_f)[:, None, :]
    px, py, depth = project(cam, corners.reshape(-1, 3))
    px, py, depth = (a.reshape(m, 8) for a in (px, py, depth))
    behind = np.any(depth <= 1e-9, axis=1)
    all_behind = np.all(depth <= 1e-9, axis=1)
    with np.errstate(invalid="ignore"):
        x0 = np.floor(np.nanmin(np.where(behind[:, None], 0, px), axis=1)) - 1
        x1 = np.ceil(np.nanmax(np.where(behind[:, None], cam.width, px), axis=1)) + 1
        y0 = np.floor(np.nanmin(np.where(behind[:, None], 0, py), axis=1)) - 1
        y1 = np.ceil(np.nanmax(np.where(behind[:, None], cam.height, py), axis=1)) + 1
    x0 = np.clip(np.nan_to_num(x0), 0, cam.width).astype(np.int64)
    x1 = np.clip(np.nan_to_num(x1), 0, cam.width).astype(np.int64)
    y0 = np.clip(np.nan_to_num(y0), 0, cam.height).astype(np.int64)
    y1 = np.clip(np.nan_to_num(y1), 0, cam.height).astype(np.int64)
    dead = empty | all_behind
    x1[dead] = x0[dead]
    return x0, x1, y0, y1


def _pixel_ray_table(rays: Rays, n_pixels: int):
    """Start index and count of the (pixel-sorted) rays of every pixel with medium."""
    useful = rays.s_max > rays.s_min
    counts = np.bincount(rays.pixel[useful], minlength=n_pixels)
    # Rays are pixel-major; useless rays are skipped through an index list.
    order = np.flatnonzero(useful)
    start = np.concatenate([[0], np.cumsum(counts)[:-1]])
    return order, start, counts


def candidate_pairs(
    cam: Camera, rays: Rays, lo: np.ndarray, hi: np.ndarray, max_pairs: int,
    hull: np.ndarray | None = None, box: tuple[np.ndarray, np.ndarray] | None = None,
) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Yield chunks ``(ray_idx, prim_idx)`` of candidate pairs, each at most ~``max_pairs``.

    Parameters
    ----------
    cam : Camera
    rays : Rays
        Pixel-major rays (any subset of pixels).
    lo, hi : (M, 3) float
        Primitive bounds.
    max_pairs : int
    hull : (M, V, 3) float, optional
        A convex planar polygon containing each primitive (:attr:`Primitives.hull`); rows with
        a non-finite vertex fall back to the rectangle of ``[lo, hi]``. With ``box`` (the
        medium's ``(bounds_min, bounds_max)``), candidates are the pixels the polygon clipped
        to the box covers (per-row spans) instead of the whole rectangle.
    box : (lo, hi), optional
        The medium's bounds, (3,) each, or a box per primitive, (M, 3) each
        (:meth:`Primitives.clip_box`).
    """
    if lo.shape[0] == 0 or len(rays) == 0:
        return
    order, start, counts = _pixel_ray_table(rays, cam.n_pixels)
    x0, x1, y0, y1 = screen_rects(cam, lo, hi)
    pix = np.flatnonzero(counts > 0)
    if pix.size <= 64:
        # A few pixels (one-pixel inspection): test each primitive's rectangle directly.
        pr, pc = np.divmod(pix, cam.width)
        step = max(1, max_pairs // max(pix.size, 1))
        for a in range(0, lo.shape[0], step):
            sl = slice(a, a + step)
            inside = ((pc[None] >= x0[sl, None]) & (pc[None] < x1[sl, None])
                      & (pr[None] >= y0[sl, None]) & (pr[None] < y1[sl, None]))
            pi, qi = np.nonzero(inside)
            out = _expand_rays(pi + a, pix[qi], order, start, counts)
            if out is not None:
                yield out
        return
    table = _ray_table(rays, counts, order, start)
    spans = _spans(cam, x0, x1, y0, y1, hull, box, max_pairs)
    if spans is None:
        return
    s_prim, s_row, s_c0, s_c1 = spans
    n_pix = (s_c1 - s_c0).astype(np.int64)
    spp = max(int(rays.spp), 1)
    # Chunk spans so that pixel pairs x spp stays under max_pairs.
    bounds = _chunk_bounds(n_pix * spp, max_pairs)
    for a, b in zip(bounds[:-1], bounds[1:], strict=True):
        npx = n_pix[a:b]
        prim = np.repeat(s_prim[a:b], npx)
        k = np.arange(prim.size) - np.repeat(np.cumsum(npx) - npx, npx)
        pixel = np.repeat(s_row[a:b] * cam.width + s_c0[a:b], npx) + k
        out = _pairs_from_table(prim, pixel, table)
        if out is not None:
            yield out


def _chunk_bounds(sizes: np.ndarray, budget: int) -> list[int]:
    """Boundaries ``[0, ..., len(sizes)]`` of consecutive runs whose ``sizes`` sum to at most
    ``budget`` (a single larger item makes a run of its own)."""
    return chunk_bounds_cum(np.cumsum(sizes), budget)


def chunk_bounds_cum(cum: np.ndarray, budget: int) -> list[int]:
    """:func:`_chunk_bounds` from the running sums ``cum = np.cumsum(sizes)``."""
    bounds = [0]
    while bounds[-1] < cum.size:
        base = cum[bounds[-1] - 1] if bounds[-1] > 0 else 0
        nxt = int(np.searchsorted(cum, base + budget, side="right"))
        bounds.append(max(nxt, bounds[-1] + 1))
    return bounds


def _ray_table(rays: Rays, counts: np.ndarray, order, start) -> np.ndarray:
    """(n_pixels, C) ray indices of every pixel (``C`` = most rays in a pixel), -1 padded."""
    c_max = int(counts.max()) if counts.size else 0
    table = np.full((counts.size, max(c_max, 1)), -1, dtype=np.int64)
    pix = np.repeat(np.arange(counts.size), counts)
    j = np.arange(pix.size) - np.repeat(start, counts)
    table[pix, j] = order
    return table


def _pairs_from_table(prim: np.ndarray, pixel: np.ndarray, table: np.ndarray):
    """(ray, prim) pairs of every (primitive, pixel) pair over the pixel's rays, in pixel
    order then ray order (the order :func:`_expand_rays` gives)."""
    r = table[pixel]  # (P, C)
    if r.shape[1] == 1:
        keep = np.flatnonzero(r[:, 0] >= 0)
        if keep.size == 0:
            return None
        return r[keep, 0], prim[keep]
    ok = r >= 0
    if not ok.any():
        return None
    return r[ok], np.broadcast_to(prim[:, None], r.shape)[ok]


def _spans(cam: Camera, x0, x1, y0, y1, hull, box, max_pairs: int):
    """Candidate pixel spans ``(prim, row, c0, c1)`` (columns ``c0 <= c < c1``) of every
    primitive: its rectangle's rows, or the rows and spans of its clipped hull polygon."""
    w = np.maximum(x1 - x0, 0)
    h = np.maximum(y1 - y0, 0)
    live = (w > 0) & (h > 0)
    use_hull = np.zeros(live.shape, dtype=bool)
    if hull is not None and box is not None:
        use_hull = live & np.all(np.isfinite(hull), axis=(1, 2))
    parts = []
    rect = np.flatnonzero(live & ~use_hull)
    if rect.size:
        prim = np.repeat(rect, h[rect])
        row = y0[prim] + np.arange(prim.size) - np.repeat(np.cumsum(h[rect]) - h[rect], h[rect])
        parts.append((prim, row, x0[prim], x1[prim]))
    poly = np.flatnonzero(use_hull)
    if poly.size:
        # Chunk primitives so that (primitive, row, edge) work stays under max_pairs.
        v_max = hull.shape[1] + len(_CLIP_PLANES)
        bounds = _chunk_bounds(h[poly] * v_max, max_pairs)
        for a, b in zip(bounds[:-1], bounds[1:], strict=True):
            ids = poly[a:b]
            parts.append(_polygon_spans(cam, hull[ids], ids, x0[ids], x1[ids], y0[ids],
                                        y1[ids], box))
    if not parts:
        return None
    prim, row, c0, c1 = (np.concatenate(p) for p in zip(*parts, strict=True))
    ok = c1 > c0
    # Primitive-major order (then row), as the rectangle binning yields its pairs.
    order = np.lexsort((row[ok], prim[ok]))
    return prim[ok][order], row[ok][order], c0[ok][order], c1[ok][order]


#: Clip planes of the hull polygons: the medium box's six faces and the camera's near plane.
_CLIP_PLANES = tuple(range(7))

#: Pixels added on every side of a hull's projected spans: covers rounding in the projection
#: (hits are exact float64 tests; a pixel too many only costs a failed test).
_SPAN_MARGIN = 1e-3

#: Points closer to the camera plane than this are clipped away (no hit can lie there:
#: camera rays start at the camera).
_NEAR = 1e-9


def clip_polygons(poly: np.ndarray, count: np.ndarray, normal: np.ndarray, offset: np.ndarray):
    """Sutherland-Hodgman clip of convex polygons to the half-spaces ``x . normal >= offset``.

    Parameters
    ----------
    poly : (M, V, 3) float
        Vertices; slots ``>= count`` are ignored.
    count : (M,) int
    normal : (3,) float
    offset : float or (M,) float
        One offset for every polygon, or one each (a box per primitive,
        :attr:`~psurf_core.techniques.base.Primitives.box`).

    Returns
    -------
    poly : (M, V + 1, 3) float
    count : (M,) int
    """
    m, v, _ = poly.shape
    j = np.arange(v)
    valid = j[None] < count[:, None]
    offset = np.asarray(offset, dtype=float)
    d = poly @ normal - (offset[:, None] if offset.ndim else offset)
    cut = np.flatnonzero(np.any(valid & (d < 0), axis=1))
    if cut.size < m:
        # Most polygons lie inside most planes: clip only those that reach outside.
        out = np.zeros((m, v + 1, 3))
        out[:, :v] = poly
        n_out = count.copy()
        if cut.size:
            out[cut], n_out[cut] = clip_polygons(poly[cut], count[cut], normal,
                                                 offset[cut] if offset.ndim else offset)
        return out, n_out
    nxt = np.where(j[None] + 1 < count[:, None], j[None] + 1, 0)
    d_n = np.take_along_axis(d, nxt, axis=1)
    p_n = np.take_along_axis(poly, nxt[:, :, None], axis=1)
    inside = valid & (d >= 0)
    cross = valid & ((d >= 0) != (d_n >= 0))
    with np.errstate(divide="ignore", invalid="ignore"):
        f = np.where(cross, d / (d - d_n), 0.0)
    ip = poly + f[:, :, None] * (p_n - poly)
    emit = inside.astype(np.int64) + cross
    off = np.cumsum(emit, axis=1) - emit
    out = np.zeros((m, v + 1, 3))
    rows = np.broadcast_to(np.arange(m)[:, None], (m, v))
    out[rows[inside], off[inside]] = poly[inside]
    slot = off + inside
    out[rows[cross], slot[cross]] = ip[cross]
    return out, emit.sum(axis=1)


def _polygon_spans(cam: Camera, hull, ids, x0, x1, y0, y1, box):
    """Per-row pixel spans of hull polygons clipped to the box and to the near plane."""
    m = hull.shape[0]
    poly, count = hull, np.full(m, hull.shape[1])
    bmin, bmax = (b[ids] if np.ndim(b) == 2 else b for b in box)
    for axis in range(3):
        e = np.zeros(3)
        e[axis] = 1.0
        poly, count = clip_polygons(poly, count, e, bmin[..., axis])
        poly, count = clip_polygons(poly, count, -e, -bmax[..., axis])
    poly, count = clip_polygons(poly, count, np.asarray(cam.forward, float),
                                float(np.dot(cam.forward, cam.position)) + _NEAR)
    v = max(int(count.max()), 1)
    poly = poly[:, :v]
    px, py, _ = project(cam, poly.reshape(-1, 3))
    px, py = px.reshape(m, v), py.reshape(m, v)
    j = np.arange(v)
    valid = j[None] < count[:, None]
    big = np.float64(1e30)
    ymin = np.where(valid, py, big).min(axis=1)
    ymax = np.where(valid, py, -big).max(axis=1)
    r0 = np.maximum(np.floor(ymin - _SPAN_MARGIN), y0)
    r1 = np.minimum(np.floor(ymax + _SPAN_MARGIN) + 1, y1)
    r0 = np.where(count > 0, r0, 0).astype(np.int64)
    nr = np.maximum(np.where(count > 0, r1, 0).astype(np.int64) - r0, 0)
    k = np.repeat(np.arange(m), nr)
    row = r0[k] + np.arange(k.size) - np.repeat(np.cumsum(nr) - nr, nr)
    # Edge a -> b of each polygon, clipped to the row's strip [row - margin, row + 1 + margin].
    nxt = np.where(j[None] + 1 < count[:, None], j[None] + 1, 0)
    xa, ya = px[k], py[k]
    xb = np.take_along_axis(px, nxt, axis=1)[k]
    yb = np.take_along_axis(py, nxt, axis=1)[k]
    lo_y = (row - _SPAN_MARGIN)[:, None]
    hi_y = (row + 1 + _SPAN_MARGIN)[:, None]
    dy = yb - ya
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / dy
        ta = (lo_y - ya) * inv
        tb = (hi_y - ya) * inv
    flat = dy == 0
    t_lo = np.where(flat, 0.0, np.maximum(np.minimum(ta, tb), 0.0))
    t_hi = np.where(flat, 1.0, np.minimum(np.maximum(ta, tb), 1.0))
    hit = valid[k] & (t_lo <= t_hi) & np.where(flat, (ya >= lo_y) & (ya <= hi_y), True)
    xl = xa + t_lo * (xb - xa)
    xh = xa + t_hi * (xb - xa)
    xmin = np.where(hit, np.minimum(xl, xh), big).min(axis=1)
    xmax = np.where(hit, np.maximum(xl, xh), -big).max(axis=1)
    c0 = np.maximum(np.floor(xmin - _SPAN_MARGIN), x0[k])
    c1 = np.minimum(np.floor(xmax + _SPAN_MARGIN) + 1, x1[k])
    c1 = np.where(xmin <= xmax, c1, c0)
    return ids[k], row, c0.astype(np.int64), c1.astype(np.int64)


def _expand_rays(prim, pixel, order, start, counts):
    """Turn (primitive, pixel) pairs into (ray, primitive) pairs over each pixel's rays."""
    c = counts[pixel]
    keep = c > 0
    prim, pixel, c = prim[keep], pixel[keep], c[keep]
    if prim.size == 0:
        return None
    total = int(c.sum())
    j = np.arange(total) - np.repeat(np.cumsum(c) - c, c)
    ray = order[np.repeat(start[pixel], c) + j]
    return ray, np.repeat(prim, c)
