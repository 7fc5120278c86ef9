"""Fused photon-plane gather: row spans -> pixels' rays -> plane solve -> contribution, in
compiled loops (numba).

The stage path (``binning.candidate_pairs`` -> ``PhotonPlane.intersect`` ->
``PhotonPlane.evaluate``) materialises every candidate pair and every intermediate as numpy
arrays, about 1 us per hit. Here :func:`_clip_project` and :func:`_row_spans` compute the
per-row pixel spans binning computes (each hull polygon clipped to the medium box and the near
plane, projected, within the primitive's screen rectangle), and :func:`_span_hits` walks
them: a span's rays are one contiguous run of the pixel-sorted ray table
(:func:`_ray_table`), then the plane solve, and the contribution with the sphere / box /
emitter-quad shadow tests inline, writing only the hits. A shadow segment whose box meets a
triangle mesh's box is handed back (status ``_DEFER``) and tested by
:meth:`Blockers.occluded` (Embree plus the exact float64 re-test). The results equal the
stage path's: the same hits (spans are padded by ``_SPAN_MARGIN`` pixels, so rounding in
them changes only which misses are tried), values equal to rounding
(``tests/test_fused_planes.py``).

Threads: a large chunk is cut into pieces that threads count, then fill from their offsets
(:func:`_plane_hits`), and the hull spans are computed by pieces of primitives, so the hits,
their order and hence the image are the same for any thread count. How many: numba's
(``numba.set_num_threads``, ``NUMBA_NUM_THREADS``; 1 in pass-pool workers, which already fill
the cores), at most the cores other processes leave idle (:func:`_threads`). The kernels
write into reused buffers (:class:`_HitBuffers`). They are compiled once per clone
(``cache=True``, in ``__pycache__``)."""

from __future__ import annotations

import os
import threading
import time
import weakref
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from numba import get_num_threads, njit

from ..binning import _NEAR, _SPAN_MARGIN, _chunk_bounds, _spans, screen_rects
from ..constants import PARALLEL_EPS, SHADOW_EPS
from ..geometry import _BOUNDS_PAD
from ..sampling import INV_4PI
from .base import Hits

#: Shadow-segment status written by the kernel.
_CLEAR, _BLOCKED, _DEFER = 0, 1, 2

#: Blocker kinds in :func:`_blocker_arrays` (order of ``Blockers.bounds``).
_SPHERE, _BOX, _QUAD, _MESH = 0, 1, 2, 3


@njit(cache=True, error_model="numpy")
def _slab(o, d, lo, hi):  # pragma: no cover - compiled
    """Entry and exit of one axis's slab (``geometry.ray_box``)."""
    inv = 1.0 / (PARALLEL_EPS if abs(d) < PARALLEL_EPS else d)
    ta = (lo - o) * inv
    tb = (hi - o) * inv
    return min(ta, tb), max(ta, tb)


@njit(cache=True, error_model="numpy", inline="always")
def _occluded(a0, a1, a2, b0, b1, b2, blk):  # pragma: no cover - compiled
    """Status of the open segment ``a -> b``: ``_CLEAR``, ``_BLOCKED`` or ``_DEFER`` (a mesh's
    box meets it: the caller runs the exact test). Mirrors :meth:`Blockers.occluded`: the
    per-blocker box (and quad plane) reject, then the first-hit tests of ``first_hit`` in
    ``(SHADOW_EPS, |b - a| - SHADOW_EPS)``. ``blk``: rows of :func:`_blocker_table`."""
    nbl = blk.shape[0]
    lo0, hi0 = min(a0, b0), max(a0, b0)
    lo1, hi1 = min(a1, b1), max(a1, b1)
    lo2, hi2 = min(a2, b2), max(a2, b2)
    near = False
    mesh = False
    for k in range(nbl):
        meet = (lo0 <= blk[k, 4] + _BOUNDS_PAD and hi0 >= blk[k, 1] - _BOUNDS_PAD
                and lo1 <= blk[k, 5] + _BOUNDS_PAD and hi1 >= blk[k, 2] - _BOUNDS_PAD
                and lo2 <= blk[k, 6] + _BOUNDS_PAD and hi2 >= blk[k, 3] - _BOUNDS_PAD)
        if meet and blk[k, 0] == _QUAD:
            # geometry._crosses_plane
            da = a0 * blk[k, 7] + a1 * blk[k, 8] + a2 * blk[k, 9] - blk[k, 10]
            db = b0 * blk[k, 7] + b1 * blk[k, 8] + b2 * blk[k, 9] - blk[k, 10]
            meet = da * db <= 0.0
            if meet:  # only then the distance (a square root and a division)
                ln = np.sqrt((b0 - a0) ** 2 + (b1 - a1) ** 2 + (b2 - a2) ** 2)
                t = da / (da - db) * ln
                meet = t >= 0.5 * SHADOW_EPS and t <= ln - 0.5 * SHADOW_EPS
        if meet:
            near = True
            if blk[k, 0] == _MESH:
                mesh = True
    if not near:
        return _CLEAR
    if mesh:
        return _DEFER
    v0, v1, v2 = b0 - a0, b1 - a1, b2 - a2
    length = np.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    nrm = length if length > 0 else 1.0
    d0, d1, d2 = v0 / nrm, v1 / nrm, v2 / nrm
    t_min = SHADOW_EPS
    t_max = length - SHADOW_EPS
    for k in range(nbl):
        if blk[k, 0] == _SPHERE:  # geometry.ray_sphere
            o0, o1, o2 = a0 - blk[k, 11], a1 - blk[k, 12], a2 - blk[k, 13]
            bb = o0 * d0 + o1 * d1 + o2 * d2
            cc = o0 * o0 + o1 * o1 + o2 * o2 - blk[k, 14] * blk[k, 14]
            disc = bb * bb - cc
            if disc >= 0.0:
                sq = np.sqrt(disc)
                tn, tf = -bb - sq, -bb + sq
                t = tn if tn > t_min else tf
                if np.isfinite(t) and t > t_min and t < t_max:
                    return _BLOCKED
        elif blk[k, 0] == _BOX:  # geometry.ray_box
            te0, tx0 = _slab(a0, d0, blk[k, 11], blk[k, 14])
            te1, tx1 = _slab(a1, d1, blk[k, 12], blk[k, 15])
            te2, tx2 = _slab(a2, d2, blk[k, 13], blk[k, 16])
            te, tx = max(te0, te1, te2), min(tx0, tx1, tx2)
            if te < tx:
                t = te if te > t_min else tx
                if np.isfinite(t) and t > t_min and t < t_max:
                    return _BLOCKED
        elif blk[k, 0] == _QUAD:  # geometry.ray_parallelogram
            denom = d0 * blk[k, 20] + d1 * blk[k, 21] + d2 * blk[k, 22]
            t = ((blk[k, 11] - a0) * blk[k, 20] + (blk[k, 12] - a1) * blk[k, 21]
                 + (blk[k, 13] - a2) * blk[k, 22]) / denom
            p0 = a0 + t * d0 - blk[k, 11]
            p1 = a1 + t * d1 - blk[k, 12]
            p2 = a2 + t * d2 - blk[k, 13]
            r0 = p0 * blk[k, 14] + p1 * blk[k, 15] + p2 * blk[k, 16]
            r1 = p0 * blk[k, 17] + p1 * blk[k, 18] + p2 * blk[k, 19]
            u = r0 * blk[k, 23] + r1 * blk[k, 24]
            w = r0 * blk[k, 25] + r1 * blk[k, 26]
            if (abs(denom) > PARALLEL_EPS and u >= 0.0 and u <= 1.0 and w >= 0.0
                    and w <= 1.0 and np.isfinite(t) and t > t_min and t < t_max):
                return _BLOCKED
    return _CLEAR


#: Columns of the per-primitive table (:func:`_prim_table`): plane origin ``x2``, directions
#: ``w2``, ``w1``, flights ``T2``, ``T1``, throughput ``beta``, the pinhole plane solve's rows
#: ``m`` (row-major) and ``sdet`` (``planes._plane_solver``), and ``own`` (1.0: ``x2 -> x1`` is
#: known clear for ``t2 < T2``).
_PX2, _PW2, _PW1, _PT2, _PT1, _PBETA, _PM, _PSDET, _POWN, _PCOLS = (0, 3, 6, 9, 10, 11, 14,
                                                                    23, 24, 25)

#: Columns of the pixel-sorted ray table (:func:`_ray_table`): direction, ``s_min``,
#: ``s_max``, origin.
_RD, _RSMIN, _RSMAX, _RO, _RCOLS = 0, 3, 4, 5, 8

@njit(cache=True, error_model="numpy", inline="always")
def _solver_rows(a0, a1, a2, v0, v1, v2, u0, u1, u2, o0, o1, o2):  # pragma: no cover
    """``planes._plane_solver`` for one pair: rows ``w1 x w2``, ``w1 x b``, ``b x w2`` and
    ``sdet = w2 . (w1 x b)``, ``b = o - x2`` (``a = x2``, ``v = w2``, ``u = w1``)."""
    b0, b1, b2 = o0 - a0, o1 - a1, o2 - a2
    m00, m01, m02 = u1 * v2 - u2 * v1, u2 * v0 - u0 * v2, u0 * v1 - u1 * v0
    m10, m11, m12 = u1 * b2 - u2 * b1, u2 * b0 - u0 * b2, u0 * b1 - u1 * b0
    m20, m21, m22 = b1 * v2 - b2 * v1, b2 * v0 - b0 * v2, b0 * v1 - b1 * v0
    sd = v0 * m10 + v1 * m11 + v2 * m12
    return m00, m01, m02, m10, m11, m12, m20, m21, m22, sd


@njit(cache=True, error_model="numpy", inline="always")
def _root(m00, m01, m02, m10, m11, m12, m20, m21, m22, sd, q0, q1, q2, s_min, s_max, short,
          T2, T1):  # pragma: no cover - compiled
    """The plane solve of one pair (Cramer's rule, ``PhotonPlane.intersect``) and whether it
    is a hit. The count and the fill phases both call this, so they agree on every pair.

    Returns
    -------
    hit : bool
    det, t2, t1, s : float
        ``(w1 x w2) . psi``, plane coordinates and ray distance (scene units).
    """
    det = m00 * q0 + m01 * q1 + m02 * q2
    inv = 1.0 / det
    t2 = (m10 * q0 + m11 * q1 + m12 * q2) * inv
    t1 = (m20 * q0 + m21 * q1 + m22 * q2) * inv
    s = sd * inv
    # Bitwise, not short-circuit: no branch per comparison (hits and misses interleave).
    hit = np.isfinite(inv) & (t2 > 0) & (t1 > 0) & (s > s_min) & (s < s_max)
    hit = hit & ((not short) | ((t2 < T2) & (t1 < T1)))
    return hit, det, t2, t1, s


@njit(cache=True, error_model="numpy", nogil=True)
def _span_count(i0, i1, s_prim, s_row, s_c0, s_c1, width, cs, rt, pinhole, short, pt,
                p0):  # pragma: no cover - compiled
    """Hits of spans ``i0 .. i1 - 1`` (the plane solve only; arguments as
    :func:`_span_hits`)."""
    n = 0
    m00 = m01 = m02 = m10 = m11 = m12 = m20 = m21 = m22 = sd = 0.0
    for i in range(i0, i1):
        p = s_prim[i]
        r = p - p0  # its row of pt
        T2p, T1p = pt[r, _PT2], pt[r, _PT1]
        if pinhole:
            m00, m01, m02 = pt[r, _PM], pt[r, _PM + 1], pt[r, _PM + 2]
            m10, m11, m12 = pt[r, _PM + 3], pt[r, _PM + 4], pt[r, _PM + 5]
            m20, m21, m22 = pt[r, _PM + 6], pt[r, _PM + 7], pt[r, _PM + 8]
            sd = pt[r, _PSDET]
        base = s_row[i] * width
        for k in range(cs[base + s_c0[i]], cs[base + s_c1[i]]):
            if not pinhole:
                m00, m01, m02, m10, m11, m12, m20, m21, m22, sd = _solver_rows(
                    pt[r, _PX2], pt[r, _PX2 + 1], pt[r, _PX2 + 2],
                    pt[r, _PW2], pt[r, _PW2 + 1], pt[r, _PW2 + 2],
                    pt[r, _PW1], pt[r, _PW1 + 1], pt[r, _PW1 + 2],
                    rt[k, _RO], rt[k, _RO + 1], rt[k, _RO + 2])
            n += _root(m00, m01, m02, m10, m11, m12, m20, m21, m22, sd,
                       rt[k, _RD], rt[k, _RD + 1], rt[k, _RD + 2], rt[k, _RSMIN],
                       rt[k, _RSMAX], short, T2p, T1p)[0]
    return n


@njit(cache=True, error_model="numpy", nogil=True)
def _span_hits(i0, i1, s_prim, s_row, s_c0, s_c1, width, cs, rt, rid, pinhole, short, pt, p0,
               sigma_t, sigma_s, g, bmin, bmax, blk,
               o_ray, o_prim, o_s, o_t1, o_t2, o_ndp, o_val, o_st, n, lim):  # pragma: no cover
    """Every hit of spans ``i0 .. i1 - 1`` with its contribution, in span, pixel, ray order,
    written to rows ``n .. lim - 1`` of the outputs.

    Parameters
    ----------
    s_prim, s_row, s_c0, s_c1 : (S,) int64
        Spans: primitive ``s_prim`` covers pixels ``s_c0 <= c < s_c1`` of image row
        ``s_row``.
    width : int
        Image width in pixels.
    cs : (n_pixels + 1,) int64
        Pixel ``q``'s rays are rows ``cs[q] .. cs[q + 1] - 1`` of ``rt`` (:func:`_ray_table`),
        so a span's rays are one contiguous run of rows.
    rt : (U, 8) float64
        Rays with medium, pixel-sorted: direction, ``s_min``, ``s_max``, origin.
    rid : (U,) int64
        Index of each ``rt`` row in the pass's ``Rays``.
    pinhole : bool
        One ray origin: the plane solve's ``m``/``sdet`` columns of ``pt`` are used.
    short : bool
        ``t2 < T2, t1 < T1`` and no ``exp(-st (t1 + t2))`` (``planes``).
    pt : (P, 25) float64
        Per-primitive table (columns ``_PX2`` ...) of primitives ``p0 .. p0 + P - 1``.
    p0 : int
        Primitive of ``pt``'s first row.
    sigma_t, sigma_s, g : float
        Medium coefficients (1 / scene units) and the Henyey-Greenstein ``g``.
    bmin, bmax : (3,) float64
        Medium box.
    blk : (N, 27) float64
        :func:`_blocker_table`.
    o_ray, o_prim : (H,) int64
    o_s, o_t1, o_t2, o_ndp : (H,) float64
        Ray distance, plane coordinates (scene units) and ``|(w1 x w2) . psi|``.
    o_val : (H, 3) float64
        Per-photon contribution; 0 where a shadow test failed; unmasked where a status is
        ``_DEFER``.
    o_st : (H, 2) int8
        Status of the shadow segments ``x2 -> x1`` and ``x1 -> x0``.
    n, lim : int
        First output row to write and the end of the rows this call may write (hits past
        it are counted, not written).

    Returns
    -------
    n : int
        ``n`` plus the hits found.
    n_defer : int
        Hits with a ``_DEFER`` status.
    """
    n_defer = 0
    nbl = blk.shape[0]
    eps = 1e-9  # geometry.inside_box tolerance
    m00 = m01 = m02 = m10 = m11 = m12 = m20 = m21 = m22 = sd = 0.0
    for i in range(i0, i1):
        p = s_prim[i]
        r = p - p0  # its row of pt
        # Per-primitive constants, loaded once per span (a span is ~6 pairs).
        a0, a1, a2 = pt[r, _PX2], pt[r, _PX2 + 1], pt[r, _PX2 + 2]
        v0, v1, v2 = pt[r, _PW2], pt[r, _PW2 + 1], pt[r, _PW2 + 2]
        u0, u1, u2 = pt[r, _PW1], pt[r, _PW1 + 1], pt[r, _PW1 + 2]
        T2p, T1p = pt[r, _PT2], pt[r, _PT1]
        own = pt[r, _POWN] != 0.0
        if pinhole:
            m00, m01, m02 = pt[r, _PM], pt[r, _PM + 1], pt[r, _PM + 2]
            m10, m11, m12 = pt[r, _PM + 3], pt[r, _PM + 4], pt[r, _PM + 5]
            m20, m21, m22 = pt[r, _PM + 6], pt[r, _PM + 7], pt[r, _PM + 8]
            sd = pt[r, _PSDET]
        base = s_row[i] * width
        for k in range(cs[base + s_c0[i]], cs[base + s_c1[i]]):
            q0, q1, q2 = rt[k, _RD], rt[k, _RD + 1], rt[k, _RD + 2]
            if not pinhole:
                m00, m01, m02, m10, m11, m12, m20, m21, m22, sd = _solver_rows(
                    a0, a1, a2, v0, v1, v2, u0, u1, u2, rt[k, _RO], rt[k, _RO + 1],
                    rt[k, _RO + 2])
            s_min = rt[k, _RSMIN]
            hit, det, t2, t1, s = _root(m00, m01, m02, m10, m11, m12, m20, m21, m22, sd,
                                        q0, q1, q2, s_min, rt[k, _RSMAX], short, T2p, T1p)
            if not hit:
                continue
            if n >= lim:  # more hits than counted: the caller raises
                n += 1
                continue
            # Evaluate (PhotonPlane.evaluate): x2 -> x1 along the photon, x1 -> x0.
            x10 = a0 + t2 * v0
            x11 = a1 + t2 * v1
            x12 = a2 + t2 * v2
            # Status of x2 -> x1 (st1) and x1 -> x0 (st2); -1: still to test. One call
            # site of the (inlined) shadow test keeps the compiled code small.
            if own and t2 < T2p:
                st1 = _CLEAR
            elif not (bmin[0] - eps <= x10 <= bmax[0] + eps
                      and bmin[1] - eps <= x11 <= bmax[1] + eps
                      and bmin[2] - eps <= x12 <= bmax[2] + eps):
                st1 = _BLOCKED
            else:
                st1 = _CLEAR if nbl == 0 else -1
            st2 = _CLEAR if nbl == 0 else (_BLOCKED if st1 == _BLOCKED else -1)
            for seg in range(2):
                if seg == 0:
                    if st1 >= 0:
                        continue
                    e0, e1, e2 = a0, a1, a2
                    f0, f1, f2 = x10, x11, x12
                else:
                    if st2 >= 0:
                        continue
                    e0, e1, e2 = x10, x11, x12
                    f0 = rt[k, _RO] + s * q0
                    f1 = rt[k, _RO + 1] + s * q1
                    f2 = rt[k, _RO + 2] + s * q2
                res = _occluded(e0, e1, e2, f0, f1, f2, blk)
                if seg == 0:
                    st1 = res
                    if res == _BLOCKED:
                        st2 = _BLOCKED
                else:
                    st2 = res
            ndp = abs(det)
            if st1 == _BLOCKED or st2 == _BLOCKED:
                scal = 0.0
            else:
                if g == 0.0:
                    rho0 = INV_4PI
                else:  # sampling.phase_value
                    mu = -(u0 * q0 + u1 * q1 + u2 * q2)
                    mu = min(max(mu, -1.0), 1.0)
                    if g > 0.0:
                        den = (1.0 - g) ** 2 + 2.0 * g * (1.0 - mu)
                    else:
                        den = (1.0 + g) ** 2 - 2.0 * g * (1.0 + mu)
                    rho0 = INV_4PI * ((1.0 - g) * (1.0 + g)) / (den * np.sqrt(den))
                scal = sigma_t * sigma_s * rho0 * np.exp(-sigma_t * (s - s_min))
                if not short:
                    scal = scal * np.exp(-sigma_t * (t1 + t2))
                scal = scal / ndp
            o_ray[n] = rid[k]
            o_prim[n] = p
            o_s[n] = s
            o_t1[n] = t1
            o_t2[n] = t2
            o_ndp[n] = ndp
            o_val[n, 0] = pt[r, _PBETA] * scal
            o_val[n, 1] = pt[r, _PBETA + 1] * scal
            o_val[n, 2] = pt[r, _PBETA + 2] * scal
            o_st[n, 0] = st1
            o_st[n, 1] = st2
            if st1 == _DEFER or st2 == _DEFER:
                n_defer += 1
            n += 1
    return n, n_defer


@njit(cache=True, error_model="numpy")
def _candidates(i0, i1, s_row, s_c0, s_c1, width, cs):  # pragma: no cover - compiled
    """Candidate pairs (rays with medium over the spans' pixels) of spans ``i0 .. i1 - 1``:
    at most that many hits."""
    total = 0
    for i in range(i0, i1):
        base = s_row[i] * width
        total += cs[base + s_c1[i]] - cs[base + s_c0[i]]
    return total


@njit(cache=True, error_model="numpy")
def _project(x, y, z, cam):  # pragma: no cover - compiled
    """``camera.project`` of one point; ``cam`` as in :func:`_hull_spans`."""
    vx, vy, vz = x - cam[0], y - cam[1], z - cam[2]
    depth = vx * cam[3] + vy * cam[4] + vz * cam[5]
    u = (vx * cam[6] + vy * cam[7] + vz * cam[8]) / (depth * cam[12] * cam[13])
    w = (vx * cam[9] + vy * cam[10] + vz * cam[11]) / (depth * cam[12])
    return (u + 1.0) * 0.5 * cam[14], (1.0 - w) * 0.5 * cam[15], depth


@njit(cache=True, error_model="numpy")
def _clip_int(v, hi):  # pragma: no cover - compiled
    """``np.clip(np.nan_to_num(v), 0, hi).astype(int64)`` of one value."""
    if np.isnan(v):
        return 0
    return int(min(max(v, 0.0), hi))


@njit(cache=True, error_model="numpy")
def _corner(lo, hi, upper):  # pragma: no cover - compiled
    """One coordinate of a box corner; a non-finite bound stands for -+1e30."""
    if upper:
        return hi if np.isfinite(hi) else 1e30
    return lo if np.isfinite(lo) else -1e30


@njit(cache=True, error_model="numpy", nogil=True)
def _screen_rects(lo, hi, cam):  # pragma: no cover - compiled
    """``binning.screen_rects`` (conservative pixel rectangles of finite boxes
    ``[lo, hi]``)."""
    m = lo.shape[0]
    w, h = cam[14], cam[15]
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


@njit(cache=True, error_model="numpy", nogil=True)
def _clip_project(hull, live, planes, cam, x0, x1, y0, y1):  # pragma: no cover - compiled
    """Per primitive: the hull polygon clipped to ``planes`` (rows ``(n, offset)``: keep
    ``x . n >= offset``; Sutherland-Hodgman as ``binning.clip_polygons``), projected to
    pixels, and its first candidate row and row count (as ``binning._polygon_spans``).
    A primitive not ``live`` (its rectangle is empty) gets no rows; one whose hull is not
    finite gets its rectangle's rows and ``count = -1``.

    Returns
    -------
    px, py : (M, V + 7) float
    count : (M,) int64
    r0, nr : (M,) int64
    """
    m, v = hull.shape[0], hull.shape[1]
    vmax = v + planes.shape[0]
    px = np.zeros((m, vmax))
    py = np.zeros((m, vmax))
    count = np.zeros(m, np.int64)
    r0 = np.zeros(m, np.int64)
    nr = np.zeros(m, np.int64)
    a = np.empty((vmax, 3))
    b = np.empty((vmax, 3))
    for i in range(m):
        if not live[i]:
            continue
        if not np.all(np.isfinite(hull[i])):
            count[i] = -1
            r0[i] = y0[i]
            nr[i] = y1[i] - y0[i]
            continue
        n = v
        for j in range(v):
            for c in range(3):
                a[j, c] = hull[i, j, c]
        for k in range(planes.shape[0]):
            inside = True
            for j in range(n):
                if (a[j, 0] * planes[k, 0] + a[j, 1] * planes[k, 1] + a[j, 2] * planes[k, 2]
                        - planes[k, 3]) < 0:
                    inside = False
            if inside:  # the usual case: nothing to clip
                continue
            out = 0
            for j in range(n):
                jn = j + 1 if j + 1 < n else 0
                dj = (a[j, 0] * planes[k, 0] + a[j, 1] * planes[k, 1] + a[j, 2] * planes[k, 2]
                      - planes[k, 3])
                dn = (a[jn, 0] * planes[k, 0] + a[jn, 1] * planes[k, 1]
                      + a[jn, 2] * planes[k, 2] - planes[k, 3])
                if dj >= 0:
                    b[out] = a[j]
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
        lo = max(np.floor(ymin - _SPAN_MARGIN), y0[i])
        hi = min(np.floor(ymax + _SPAN_MARGIN) + 1, y1[i])
        r0[i] = int(lo)
        nr[i] = max(int(hi) - int(lo), 0)
    return px, py, count, r0, nr


@njit(cache=True, error_model="numpy", nogil=True)
def _row_spans(px, py, count, r0, nr, x0, x1, total):  # pragma: no cover - compiled
    """Per-row column spans ``[c0, c1)`` of the projected polygons of :func:`_clip_project`
    (each polygon edge clipped to the row's strip widened by ``_SPAN_MARGIN``, as
    ``binning._polygon_spans``), primitive-major then by row; empty spans are dropped.

    Returns
    -------
    n : int
    prim, row, c0, c1 : (total,) int64
        The first ``n`` entries.
    """
    o_prim = np.empty(total, np.int64)
    o_row = np.empty(total, np.int64)
    o_c0 = np.empty(total, np.int64)
    o_c1 = np.empty(total, np.int64)
    n = _row_spans_into(px, py, count, r0, nr, x0, x1, 0, o_prim, o_row, o_c0, o_c1, 0)
    return n, o_prim, o_row, o_c0, o_c1


@njit(cache=True, error_model="numpy", nogil=True)
def _row_spans_into(px, py, count, r0, nr, x0, x1, p_off, o_prim, o_row, o_c0, o_c1,
                    n):  # pragma: no cover - compiled
    """:func:`_row_spans` written to the given arrays from entry ``n``, primitive ``i`` named
    ``p_off + i``; returns the entry after the last one written."""
    big = 1e30
    inv_dy = np.empty(px.shape[1])  # per edge: the same for every row of the primitive
    for i in range(px.shape[0]):
        cnt = count[i]
        for j in range(max(cnt, 0) if nr[i] > 0 else 0):
            jn = j + 1 if j + 1 < cnt else 0
            inv_dy[j] = 1.0 / (py[i, jn] - py[i, j])
        for row in range(r0[i], r0[i] + nr[i]):
            if cnt < 0:  # no finite hull: the rectangle
                c0, c1 = x0[i], x1[i]
            else:
                lo_y = row - _SPAN_MARGIN
                hi_y = row + 1 + _SPAN_MARGIN
                xmin, xmax = big, -big
                for j in range(cnt):
                    jn = j + 1 if j + 1 < cnt else 0
                    xa, ya, xb, yb = px[i, j], py[i, j], px[i, jn], py[i, jn]
                    dy = yb - ya
                    if dy == 0:
                        t_lo, t_hi = 0.0, 1.0
                        hit = ya >= lo_y and ya <= hi_y
                    else:
                        ta = (lo_y - ya) * inv_dy[j]
                        tb = (hi_y - ya) * inv_dy[j]
                        t_lo = max(min(ta, tb), 0.0)
                        t_hi = min(max(ta, tb), 1.0)
                        hit = t_lo <= t_hi
                    if hit:
                        xl = xa + t_lo * (xb - xa)
                        xh = xa + t_hi * (xb - xa)
                        xmin = min(xmin, xl, xh)
                        xmax = max(xmax, xl, xh)
                if xmin > xmax:
                    continue
                c0 = int(max(np.floor(xmin - _SPAN_MARGIN), x0[i]))
                c1 = int(min(np.floor(xmax + _SPAN_MARGIN) + 1, x1[i]))
            if c1 > c0:
                o_prim[n] = p_off + i
                o_row[n] = row
                o_c0[n] = c0
                o_c1[n] = c1
                n += 1
    return n


def _camera_vector(cam) -> np.ndarray:
    """(16,) float: position, forward, right, image-up, ``tan(fov_y / 2)``, aspect, width,
    height (what the compiled projection reads)."""
    th = float(np.tan(np.radians(cam.fov_y) / 2.0))
    return np.concatenate([np.asarray(cam.position, float), np.asarray(cam.forward, float),
                           np.asarray(cam.right, float), np.asarray(cam.image_up, float),
                           [th, cam.width / cam.height, cam.width, cam.height]])


#: Primitives from which :func:`_hull_spans` is shared among threads (~1 us each).
_THREADED_MIN_PRIMS = 2000


def _hull_spans(cam, lo, hi, hull, box):
    """Candidate pixel spans ``(prim, row, c0, c1)`` of every primitive: what
    ``binning.screen_rects`` + ``binning._spans`` give (hull polygons clipped to the box and
    the near plane, within the screen rectangles of ``[lo, hi]``), in compiled loops.

    Many primitives are cut into consecutive pieces that numba's threads clip and project,
    then write the spans of, in primitive order (each primitive's spans depend on it alone):
    the same spans for any thread count."""
    bmin, bmax = (np.asarray(b, float) for b in box)
    fwd = np.asarray(cam.forward, float)
    eye = np.eye(3)
    planes = np.array([row for ax in range(3)
                       for row in (np.append(eye[ax], bmin[ax]), np.append(-eye[ax], -bmax[ax]))]
                      + [np.append(fwd, float(fwd @ np.asarray(cam.position, float)) + _NEAR)])
    camv = _camera_vector(cam)
    c = np.ascontiguousarray
    lo, hi, hull = c(lo, float), c(hi, float), c(hull, float)
    # +-inf / NaN bounds: binning's rounding at its 1e30 stand-ins is not mirrored
    rects = None if np.isfinite(lo).all() and np.isfinite(hi).all() else screen_rects(cam, lo,
                                                                                        hi)
    m = lo.shape[0]
    threads = _threads() if m >= _THREADED_MIN_PRIMS else 1
    if threads <= 1:
        x0, x1, y0, y1 = rects if rects is not None else _screen_rects(lo, hi, camv)
        live = (x1 > x0) & (y1 > y0)
        px, py, count, r0, nr = _clip_project(hull, live, planes, camv, x0, x1, y0, y1)
        n, prim, row, c0, c1 = _row_spans(px, py, count, r0, nr, x0, x1, int(nr.sum()))
        if not _WARM:  # load the threaded path's kernel now (render.warm_up's pass)
            _row_spans_into(px[:0], py[:0], count[:0], r0[:0], nr[:0], x0[:0], x1[:0], 0,
                            prim, row, c0, c1, n)
        return prim[:n], row[:n], c0[:n], c1[:n]
    cut = np.linspace(0, m, threads * _PIECES_PER_THREAD + 1).astype(np.int64).tolist()
    parts = [None] * (len(cut) - 1)

    def project(j):  # screen rectangles, clipped and projected hulls, rows per primitive
        a, b = cut[j], cut[j + 1]
        x0, x1, y0, y1 = ((c(r[a:b]) for r in rects) if rects is not None
                          else _screen_rects(lo[a:b], hi[a:b], camv))
        live = (x1 > x0) & (y1 > y0)
        parts[j] = (x0, x1, *_clip_project(hull[a:b], live, planes, camv, x0, x1, y0, y1))

    _on_threads(project, len(parts), threads)
    # Each piece writes from the first row it could fill (its rows before it), then the
    # pieces close up in order: the spans of one thread, in as much memory.
    at = np.cumsum([0] + [int(pp[-1].sum()) for pp in parts])
    out = [np.empty(int(at[-1]), np.int64) for _ in range(4)]
    end = np.zeros(len(parts), np.int64)

    def fill(j):
        x0, x1, px, py, count, r0, nr = parts[j]
        end[j] = _row_spans_into(px, py, count, r0, nr, x0, x1, cut[j], *out, at[j])

    _on_threads(fill, len(parts), threads)
    n = 0
    for j in range(len(parts)):
        k = int(end[j] - at[j])
        if at[j] != n:
            for o in out:
                o[n:n + k] = o[at[j]:at[j] + k]  # numpy copies overlapping slices safely
        n += k
    return tuple(o[:n] for o in out)


def _blocker_table(blockers):
    """The kernel's view of :class:`~psurf_core.geometry.Blockers`: (N, 27) float64, one row
    per entry of ``blockers.bounds`` (spheres, boxes, quads, meshes: ``first_hit``'s order),
    or ``None`` when the blockers carry no bounds (then the stage path runs).

    Columns: 0 kind (``_SPHERE``, ...); 1-3 / 4-6 box ``lo`` / ``hi``; 7-10 plane ``(n, n .
    p)`` (quads); from 11: sphere centre, radius | box min, max | quad corner, ``eu``, ``ev``,
    ``eu x ev``, inverse Gram matrix (row-major). One array, not one per field: every array
    argument of a compiled call costs reference counting.
    """
    if blockers.bounds is None or blockers.planes is None:
        return None
    n_all = blockers.bounds.shape[0]
    blk = np.zeros((0 if blockers.empty else n_all, 27))
    if blk.shape[0] == 0:
        return blk
    blk[:, 0] = _MESH
    blk[:, 1:4] = blockers.bounds[:, 0]
    blk[:, 4:7] = blockers.bounds[:, 1]
    blk[:, 7:11] = np.nan_to_num(blockers.planes)
    k = 0
    for c, r in zip(blockers.sphere_c, blockers.sphere_r, strict=True):
        blk[k, 0], blk[k, 11:14], blk[k, 14] = _SPHERE, c, r
        k += 1
    for lo, hi in zip(blockers.box_min, blockers.box_max, strict=True):
        blk[k, 0], blk[k, 11:14], blk[k, 14:17] = _BOX, lo, hi
        k += 1
    for corner, eu, ev in blockers.quads:
        g = np.linalg.inv(np.array([[eu @ eu, eu @ ev], [eu @ ev, ev @ ev]]))
        blk[k, 0] = _QUAD
        blk[k, 11:23] = np.concatenate([corner, eu, ev, np.cross(eu, ev)])
        blk[k, 23:27] = g.ravel()
        k += 1
    return blk


def _ray_table(rays, n_pixels: int):
    """The rays with medium (``s_max > s_min``) in pixel order, one row each.

    Returns
    -------
    cs : (n_pixels + 1,) int64
        Pixel ``q``'s rays are rows ``cs[q] .. cs[q + 1] - 1`` (rays are pixel-major).
    rt : (U, 8) float64
        Direction, ``s_min``, ``s_max`` (scene units), origin: what the kernel reads of a
        ray, in one contiguous row.
    rid : (U,) int64
        Index of each row in ``rays``.
    """
    rid = np.flatnonzero(rays.s_max > rays.s_min)
    cs = np.zeros(n_pixels + 1, np.int64)
    np.cumsum(np.bincount(rays.pixel[rid], minlength=n_pixels), out=cs[1:])
    rt = np.empty((rid.size, _RCOLS))
    rt[:, _RD:_RD + 3] = rays.d[rid]
    rt[:, _RSMIN] = rays.s_min[rid]
    rt[:, _RSMAX] = rays.s_max[rid]
    rt[:, _RO:_RO + 3] = rays.o[rid]
    return cs, rt, rid


def _prim_table(prims, paths, rays, med, p0: int, p1: int) -> np.ndarray:
    """(p1 - p0, 25) float64: the constants of photon planes ``p0 .. p1 - 1``, one row each
    (columns ``_PX2`` ...), so a span loads a few neighbouring cache lines instead of one
    from each of nine arrays. Built per chunk (its spans are primitive-major: one range), so
    it never holds more than a chunk's planes."""
    d = prims.data
    pinhole = rays.origin is not None  # then the pair's solve is three dot products
    c = np.ascontiguousarray
    return _fill_prim_table(
        p0, p1, c(d["x2"], float), c(d["w2"], float), c(d["w1"], float), c(d["T2"], float),
        c(d["T1"], float), c(prims.photon, np.int64), c(prims.K, np.int64),
        c(paths.beta, float), c(paths.prefix_ok, np.bool_), pinhole,
        c(d["m"], float) if pinhole else np.zeros((0, 3, 3)),
        c(d["sdet"], float) if pinhole else np.zeros(0),
        c(med.bounds_min, float), c(med.bounds_max, float))


@njit(cache=True, error_model="numpy", nogil=True)
def _fill_prim_table(p0, p1, x2, w2, w1, T2, T1, photon, K, beta, prefix_ok, pinhole, m, sdet,
                     bmin, bmax):  # pragma: no cover - compiled
    """:func:`_prim_table`'s rows (the same values numpy's indexing gives: copies).

    ``own`` is ``on_own_segment``'s shortcut: ``x2 -> x1`` is known clear (no test) when the
    photon's own segment ``K - 1`` is (``prefix_ok``) and, for ``K = 2``, ``x2`` (the light)
    lies in the box (within 1e-9); the kernel adds ``t2 < T2`` per hit.
    """
    pt = np.zeros((p1 - p0, _PCOLS))
    eps = 1e-9
    for r in range(p1 - p0):
        p = p0 + r
        for c in range(3):
            pt[r, _PX2 + c] = x2[p, c]
            pt[r, _PW2 + c] = w2[p, c]
            pt[r, _PW1 + c] = w1[p, c]
            pt[r, _PBETA + c] = beta[photon[p], K[p] - 1, c]
        pt[r, _PT2] = T2[p]
        pt[r, _PT1] = T1[p]
        if pinhole:
            for a in range(3):
                for c in range(3):
                    pt[r, _PM + 3 * a + c] = m[p, a, c]
            pt[r, _PSDET] = sdet[p]
        own = prefix_ok[photon[p], K[p] - 1]
        if own and K[p] == 2:
            for c in range(3):
                if not (x2[p, c] >= bmin[c] - eps and x2[p, c] <= bmax[c] + eps):
                    own = False
        pt[r, _POWN] = 1.0 if own else 0.0
    return pt


#: Candidate pairs from which a chunk is shared among threads (below, handing the work
#: out costs more than it saves: ~20k pairs are ~2 ms of work).
_THREADED_MIN_PAIRS = 20_000

#: Pieces per thread a shared chunk is cut into (equal candidate pairs each), handed out in
#: order to whichever thread is free: a thread that loses its core to another process does
#: not hold the others back by more than one piece.
_PIECES_PER_THREAD = 4


#: The kernels' outputs per hit: ray, prim (int64); s, t1, t2, ndp (float64); val (3 float64);
#: status (2 int8), in this order in one buffer.
_HIT_FIELDS = ((np.int64, 1), (np.int64, 1), (np.float64, 1), (np.float64, 1),
               (np.float64, 1), (np.float64, 1), (np.float64, 3), (np.int8, 2))
_HIT_BYTES = sum(np.dtype(t).itemsize * k for t, k in _HIT_FIELDS)


class _Storage(np.ndarray):
    """Memory of :class:`_HitBuffers`. Its own type matters: numpy collapses a view's
    ``base`` through plain-ndarray views but stops at a change of type, so every view of a
    lease (a plain view of this) keeps that lease alive."""


class _HitBuffers(threading.local):
    """Two reusable output buffers per thread, so a pass's kernel writes to memory it has
    written before.

    Fresh memory costs a page fault per 4 KiB on first write (the allocator hands large
    blocks back to the system when they are freed); on this kind of virtual machine that was
    ~30% of the kernel's time. A buffer is handed out as a *lease* (a plain view of its
    storage) and reused only when the lease is gone: every array made from the hits, views
    included, references it, so memory someone still reads is never overwritten. While a
    consumer keeps both (``PassRecord`` keeps every chunk) the hits get fresh memory.
    """

    def __init__(self):
        self.storage = [None, None]
        self.leases = [None, None]  # weakref.ref of the lease last handed out

    def take(self, rows: int) -> tuple[np.ndarray, ...]:
        """Output arrays of ``rows`` rows (``_HIT_FIELDS``)."""
        need = max(rows, 1) * _HIT_BYTES
        for i in range(2):
            lease = self.leases[i]
            if lease is not None and lease() is not None:
                continue  # hits of an earlier chunk are still referenced
            if self.storage[i] is None or self.storage[i].size < need:
                self.storage[i] = None  # free the smaller one first
                self.storage[i] = _Storage(shape=(need + need // 4,), dtype=np.uint8)
            lease = self.storage[i].view(np.ndarray)
            self.leases[i] = weakref.ref(lease)
            return _split(lease, rows)
        return _split(np.empty(need, np.uint8), rows)


def _split(buf: np.ndarray, rows: int) -> tuple[np.ndarray, ...]:
    """``buf`` (uint8) cut into the ``_HIT_FIELDS`` arrays of ``rows`` rows (views)."""
    out, at = [], 0
    for t, k in _HIT_FIELDS:
        size = rows * k * np.dtype(t).itemsize
        a = buf[at:at + size].view(t)
        out.append(a.reshape(rows, k) if k > 1 else a)
        at += size
    return tuple(out)


_BUFFERS = _HitBuffers()


def _plane_hits(a, b, spans, width, cs, rt, rid, pinhole, short, pt, p0, sigma_t, sigma_s, g,
                bmin, bmax, blk, threads):
    """Every hit of spans ``a .. b - 1`` and its contribution (:func:`_span_hits`).

    ``spans`` is the tuple ``(prim, row, c0, c1)`` of (S,) arrays. With ``threads > 1`` the
    spans are cut into pieces of equal candidate pairs; the threads count each piece's hits
    (:func:`_span_count`), and after an exclusive prefix sum write each piece's hits from its
    offset, so the rows equal the single-threaded ones whichever thread ran which piece.
    Counting costs ~15% more work in all; the kernels release the GIL, and a thread that
    waits sleeps (no spinning on a busy machine).

    Returns
    -------
    n_defer : int
    ray, prim, s, t1, t2, ndp, val, status : arrays of ``n`` rows (the hits)
    """
    const = (*spans, width, cs, rt, rid, pinhole, short, pt, p0, sigma_t, sigma_s, g, bmin,
             bmax, blk)
    if threads <= 1:
        out = _BUFFERS.take(_candidates(a, b, *spans[1:], width, cs))
        n, n_defer = _span_hits(a, b, *const, *out, 0, out[0].size)
        return (n_defer, *(x[:n] for x in out))
    s_prim, s_row, s_c0, s_c1 = spans
    base = s_row[a:b] * width
    cum = np.cumsum(cs[base + s_c1[a:b]] - cs[base + s_c0[a:b]])
    k = threads * _PIECES_PER_THREAD
    cut = np.unique(np.concatenate([[a], a + np.searchsorted(cum, cum[-1] * np.arange(1, k) / k),
                                    [b]]))
    pieces = list(zip(cut[:-1].tolist(), cut[1:].tolist(), strict=True))
    hits = np.zeros(len(pieces) + 1, np.int64)

    def count(j):
        hits[j + 1] = _span_count(*pieces[j], *spans, width, cs, rt, pinhole, short, pt, p0)

    _on_threads(count, len(pieces), threads)
    off = np.cumsum(hits)
    out = _BUFFERS.take(int(off[-1]))
    ends, defer = np.zeros(len(pieces), np.int64), np.zeros(len(pieces), np.int64)

    def fill(j):
        ends[j], defer[j] = _span_hits(*pieces[j], *const, *out, off[j], off[j + 1])

    _on_threads(fill, len(pieces), threads)
    if not np.array_equal(ends, off[1:]):
        raise RuntimeError("planes_fused: the count and fill phases disagree")
    return (int(defer.sum()), *out)


class _OtherLoad:
    """Cores that other processes kept busy lately (Linux ``/proc/stat``, minus this process's
    own CPU time), so that threads are used only where a core is free.

    On a machine whose cores are taken by other work a second thread cannot gain: it waits in
    the run queue while holding a piece the first thread then waits for (measured on a
    2-core machine with three other busy processes: 2 threads 20% slower than 1). The
    estimate is refreshed at most every ``_LOAD_REFRESH`` seconds; where ``/proc/stat`` is
    missing it is 0 (all of numba's threads are used). It only chooses the thread count,
    which changes no result.
    """

    def __init__(self):
        self.last = None  # (monotonic s, all CPUs' busy s, this process's CPU s)
        self.others = 0.0
        self.lock = threading.Lock()

    def __call__(self) -> float:
        now = time.monotonic()
        with self.lock:
            if self.last is not None and now - self.last[0] < _LOAD_REFRESH:
                return self.others
            try:
                with open("/proc/stat") as f:
                    ticks = [int(x) for x in f.readline().split()[1:]]
            except (OSError, ValueError):
                return 0.0
            # user nice system idle iowait irq softirq steal: all but idle and iowait are
            # taken (steal: by other virtual machines).
            busy = (sum(ticks[:8]) - ticks[3] - ticks[4]) / os.sysconf("SC_CLK_TCK")
            t = os.times()
            own = t.user + t.system
            if self.last is not None:
                dt = now - self.last[0]
                self.others = max(0.0, (busy - self.last[1] - (own - self.last[2])) / dt)
            self.last = (now, busy, own)
            return self.others


#: Seconds between two readings of :class:`_OtherLoad`.
_LOAD_REFRESH = 0.5

_OTHER_LOAD = _OtherLoad()

#: Non-empty once the threaded path's kernels are loaded in this process.
_WARM: list = []


def _threads() -> int:
    """Threads for a large chunk: numba's thread count (``numba.set_num_threads``,
    ``NUMBA_NUM_THREADS``), at most the cores other processes leave free (at least 1)."""
    n = get_num_threads()
    if n > 1:
        free = (os.cpu_count() or 1) - _OTHER_LOAD()
        n = max(1, min(n, int(free + 0.5)))
    return n


#: Helper threads of :func:`_on_threads` (started on first use, shared by all callers).
_HELPERS: dict[int, ThreadPoolExecutor] = {}
# A forked child has none of the parent's threads: its pools would never run a task.
if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_HELPERS.clear)


def _on_threads(fn, n: int, threads: int) -> None:
    """``fn(j)`` for ``j = 0 .. n - 1`` on ``threads`` threads (this one and ``threads - 1``
    helpers), each taking the next ``j`` when free. An exception (Ctrl-C included) stops the
    handing out; the helpers finish the item they hold, then it is re-raised."""
    if threads <= 1:
        for j in range(n):
            fn(j)
        return
    pool = _HELPERS.get(threads - 1)
    if pool is None:
        pool = _HELPERS[threads - 1] = ThreadPoolExecutor(threads - 1, "psurf-planes")
    items = iter(range(n))
    lock = threading.Lock()
    stop = []

    def work():
        while not stop:
            with lock:
                j = next(items, None)
            if j is None:
                return
            fn(j)

    helpers = [pool.submit(work) for _ in range(threads - 1)]
    try:
        work()
    except BaseException:
        stop.append(True)
        raise
    finally:
        for f in helpers:
            f.result()


def plane_chunks(tech, prims, paths, rays, ctx) -> Iterator[tuple[Hits, np.ndarray]] | None:
    """All hits of photon planes ``prims`` with ``rays`` and their per-photon contributions,
    as ``(Hits, values (H, 3))`` chunks of at most ~``ctx.max_pairs`` candidate pairs.

    Hits and values equal those of ``tech.intersect`` + ``tech.evaluate`` over
    ``binning.candidate_pairs`` (hit order: primitive, row, pixel, ray), whatever the number
    of threads numba runs (``numba.set_num_threads``). Returns ``None`` where the fused path
    does not apply (a few pixels only: binning's per-pixel branch; or blockers without
    bounds), so the caller runs the stage path.
    """
    bl = _blocker_table(ctx.blockers)
    if bl is None:
        return None
    if np.count_nonzero(np.bincount(rays.pixel[rays.s_max > rays.s_min],
                                    minlength=ctx.scene.camera.n_pixels)) <= 64:
        return None
    return _chunks(tech, prims, paths, rays, ctx, bl)


def _interrupted(e: BaseException) -> bool:
    """Was ``e`` caused (at any depth) by a KeyboardInterrupt?"""
    seen = set()
    while e is not None and id(e) not in seen:
        if isinstance(e, KeyboardInterrupt):
            return True
        seen.add(id(e))
        e = e.__cause__ or e.__context__
    return False


def _chunks(tech, prims, paths, rays, ctx, bl):
    """:func:`_fused_chunks`, with Ctrl-C kept a KeyboardInterrupt.

    A SIGINT whose Python handler runs while a compiled function returns (numba boxing its
    result) surfaces as ``SystemError: ... returned a result with an exception set``, caused
    by the KeyboardInterrupt; callers (``render --checkpoint``: save and exit 130) must see
    the Ctrl-C itself.
    """
    try:
        yield from _fused_chunks(tech, prims, paths, rays, ctx, bl)
    except SystemError as e:
        if _interrupted(e):
            raise KeyboardInterrupt from None
        raise


def _fused_chunks(tech, prims, paths, rays, ctx, bl):
    scene = ctx.scene
    cam = scene.camera
    med = scene.medium
    if len(prims) == 0 or len(rays) == 0:
        return
    box = (med.bounds_min, med.bounds_max)
    if prims.hull is not None:
        s_prim, s_row, s_c0, s_c1 = _hull_spans(cam, prims.lo, prims.hi, prims.hull, box)
    else:
        x0, x1, y0, y1 = screen_rects(cam, prims.lo, prims.hi)
        spans = _spans(cam, x0, x1, y0, y1, None, box, ctx.max_pairs)
        if spans is None:
            return
        s_prim, s_row, s_c0, s_c1 = spans
    if s_prim.size == 0:
        return
    cs, rt, rid = _ray_table(rays, cam.n_pixels)
    spans = (s_prim, s_row, s_c0, s_c1)
    if rays.origin is not None and "m" not in prims.data:
        from .planes import _plane_solver

        d = prims.data
        d.update(_plane_solver(d["x2"], d["w2"], d["w1"], rays.origin))
    # Chunks as binning's (pixels x the most rays in a pixel, within max_pairs): the same
    # chunks, hence the same per-chunk sums in the image, as before the kernel was threaded.
    per_pix = max(int(np.diff(cs).max()), 1)
    bounds = _chunk_bounds((s_c1 - s_c0).astype(np.int64) * per_pix, ctx.max_pairs)
    medium = (float(med.sigma_t), float(med.sigma_s), float(med.phase.g),
              np.ascontiguousarray(med.bounds_min, float),
              np.ascontiguousarray(med.bounds_max, float), bl)
    threads = _threads()
    width = int(cam.width)
    for a, b in zip(bounds[:-1], bounds[1:], strict=True):
        p0, p1 = int(s_prim[a]), int(s_prim[b - 1]) + 1
        pt = _prim_table(prims, paths, rays, med, p0, p1)
        if not _WARM:
            # Compile or load the threaded path's kernel in the first (warm-up) pass, which
            # is too small to use it: a time budget must not pay for it later.
            _span_count(a, a, *spans, width, cs, rt, rays.origin is not None,
                        bool(tech.short), pt, p0)
            _WARM.append(True)
        big = _candidates(a, b, s_row, s_c0, s_c1, width, cs) >= _THREADED_MIN_PAIRS
        th = threads if big else 1
        n_defer, ray, prim, s, t1, t2, ndp, val, st = _plane_hits(
            a, b, spans, width, cs, rt, rid, rays.origin is not None, bool(tech.short), pt, p0,
            *medium, th)
        if ray.size == 0:
            continue
        if n_defer:
            defer = np.flatnonzero(np.any(st == _DEFER, axis=1))
            _resolve(ctx.blockers, rays, prims, ray[defer], prim[defer], s[defer], t2[defer],
                     st[defer], val, defer)
        yield Hits(ray, prim, s, dict(t2=t2, t1=t1, n_dot_psi=ndp)), val


def _resolve(blockers, rays, prims, ray, prim, s, t2, st, val, rows):
    """Exact shadow tests (:meth:`Blockers.occluded`) of the deferred segments; zero the
    values of the rows (``rows`` of ``val``) found blocked."""
    d = prims.data
    x2 = d["x2"][prim]
    x1 = x2 + t2[:, None] * d["w2"][prim]
    x0 = rays.o[ray] + s[:, None] * rays.d[ray]
    ok = st[:, 0] != _BLOCKED
    ok &= st[:, 1] != _BLOCKED
    for k, (a, b) in enumerate(((x2, x1), (x1, x0))):
        idx = np.flatnonzero(ok & (st[:, k] == _DEFER))
        if idx.size:
            ok[idx] = ~blockers.occluded(a[idx], b[idx])
    val[rows[~ok]] = 0.0
