"""Which camera rays can hit which primitive: screen-space binning (Tungsten's FrustumBinner idea).

Each primitive's world bounds (already clipped to the medium box) are projected to the image;
only the rays of the pixels inside that rectangle become candidates. Candidate pairs are
produced in chunks of at most ``max_pairs`` so memory stays bounded, and never as a full
``rays x primitives`` array.
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
    cam: Camera, rays: Rays, lo: np.ndarray, hi: np.ndarray, max_pairs: int
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
    """
    if lo.shape[0] == 0 or len(rays) == 0:
        return
    order, start, counts = _pixel_ray_table(rays, cam.n_pixels)
    x0, x1, y0, y1 = screen_rects(cam, lo, hi)
    w = np.maximum(x1 - x0, 0)
    h = np.maximum(y1 - y0, 0)
    area = w * h
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
    spp = max(int(rays.spp), 1)
    prim_ids = np.flatnonzero(area > 0)
    if prim_ids.size == 0:
        return
    # Chunk primitives so that pixel pairs x spp stays under max_pairs.
    cum = np.cumsum(area[prim_ids] * spp)
    bounds = [0]
    while bounds[-1] < prim_ids.size:
        base = cum[bounds[-1] - 1] if bounds[-1] > 0 else 0
        nxt = int(np.searchsorted(cum, base + max_pairs, side="right"))
        bounds.append(max(nxt, bounds[-1] + 1))
    for a, b in zip(bounds[:-1], bounds[1:], strict=True):
        ids = prim_ids[a:b]
        n_pix = area[ids]
        prim = np.repeat(ids, n_pix)
        k = np.arange(int(n_pix.sum())) - np.repeat(np.cumsum(n_pix) - n_pix, n_pix)
        ww = w[prim]
        pixel = (y0[prim] + k // ww) * cam.width + x0[prim] + k % ww
        out = _expand_rays(prim, pixel, order, start, counts)
        if out is not None:
            yield out


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
