"""Fused photon-plane gather: row spans -> pixels' rays -> plane solve -> contribution, in
compiled loops (numba).

The stage path (``binning.candidate_pairs`` -> ``PhotonPlane.intersect`` ->
``PhotonPlane.evaluate``) materialises every candidate pair and every intermediate as numpy
arrays, about 1 us per hit. Here the per-row pixel spans binning computes come from
:func:`.fused_spans.hull_spans`, and :func:`_span_hits` walks them: a span's rays are one
contiguous run of the pixel-sorted ray table (:func:`_ray_table`), then the plane solve, and
the contribution with the sphere / box / emitter-quad shadow tests of
:func:`.fused_shadow.occluded` inline, writing only the hits. A shadow segment whose box meets
a triangle mesh's box is handed back (status ``DEFER``) and tested by
:meth:`Blockers.occluded` (Embree plus the exact float64 re-test). The results equal the
stage path's: the same hits (spans are padded by ``_SPAN_MARGIN`` pixels, so rounding in
them changes only which misses are tried), values equal to rounding
(``tests/test_fused_planes.py``).

Threads: a large chunk is cut into pieces that threads count, then fill from their offsets
(:func:`_plane_hits`), and the hull spans are computed by pieces of primitives, so the hits,
their order and hence the image are the same for any thread count. How many:
:func:`.fused_threads.thread_count`. The kernels write into reused buffers
(:class:`_HitBuffers`). They are compiled once per clone (``cache=True``, in
``__pycache__``); numba compiles ``occluded`` into :func:`_span_hits` and its cache only
watches this file: after changing ``fused_shadow.occluded``, touch this file (or clear
``__pycache__``) so that the kernel recompiles."""

from __future__ import annotations

import threading
import weakref
from collections.abc import Iterator

import numpy as np
from numba import njit

from ..binning import _chunk_bounds, _spans, screen_rects
from ..compiled import ctrl_c_kept
from ..sampling import INV_4PI
from .base import Hits
from .fused_shadow import BLOCKED, CLEAR, DEFER, blocker_table, occluded
from .fused_spans import hull_spans
from .fused_threads import PIECES_PER_THREAD, on_threads, thread_count

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
        :func:`.fused_shadow.blocker_table`.
    o_ray, o_prim : (H,) int64
    o_s, o_t1, o_t2, o_ndp : (H,) float64
        Ray distance, plane coordinates (scene units) and ``|(w1 x w2) . psi|``.
    o_val : (H, 3) float64
        Per-photon contribution; 0 where a shadow test failed; unmasked where a status is
        ``DEFER``.
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
        Hits with a ``DEFER`` status.
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
                st1 = CLEAR
            elif not (bmin[0] - eps <= x10 <= bmax[0] + eps
                      and bmin[1] - eps <= x11 <= bmax[1] + eps
                      and bmin[2] - eps <= x12 <= bmax[2] + eps):
                st1 = BLOCKED
            else:
                st1 = CLEAR if nbl == 0 else -1
            st2 = CLEAR if nbl == 0 else (BLOCKED if st1 == BLOCKED else -1)
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
                res = occluded(e0, e1, e2, f0, f1, f2, blk)
                if seg == 0:
                    st1 = res
                    if res == BLOCKED:
                        st2 = BLOCKED
                else:
                    st2 = res
            ndp = abs(det)
            if st1 == BLOCKED or st2 == BLOCKED:
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
            if st1 == DEFER or st2 == DEFER:
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
    k = threads * PIECES_PER_THREAD
    cut = np.unique(np.concatenate([[a], a + np.searchsorted(cum, cum[-1] * np.arange(1, k) / k),
                                    [b]]))
    pieces = list(zip(cut[:-1].tolist(), cut[1:].tolist(), strict=True))
    hits = np.zeros(len(pieces) + 1, np.int64)

    def count(j):
        hits[j + 1] = _span_count(*pieces[j], *spans, width, cs, rt, pinhole, short, pt, p0)

    on_threads(count, len(pieces), threads)
    off = np.cumsum(hits)
    out = _BUFFERS.take(int(off[-1]))
    ends, defer = np.zeros(len(pieces), np.int64), np.zeros(len(pieces), np.int64)

    def fill(j):
        ends[j], defer[j] = _span_hits(*pieces[j], *const, *out, off[j], off[j + 1])

    on_threads(fill, len(pieces), threads)
    if not np.array_equal(ends, off[1:]):
        raise RuntimeError("planes_fused: the count and fill phases disagree")
    return (int(defer.sum()), *out)


#: Non-empty once the threaded path's kernel (:func:`_span_count`) is loaded in this
#: process.
_WARM: list = []


def plane_chunks(tech, prims, paths, rays, ctx) -> Iterator[tuple[Hits, np.ndarray]] | None:
    """All hits of photon planes ``prims`` with ``rays`` and their per-photon contributions,
    as ``(Hits, values (H, 3))`` chunks of at most ~``ctx.max_pairs`` candidate pairs.

    Hits and values equal those of ``tech.intersect`` + ``tech.evaluate`` over
    ``binning.candidate_pairs`` (hit order: primitive, row, pixel, ray), whatever the number
    of threads numba runs (``numba.set_num_threads``). Returns ``None`` where the fused path
    does not apply (a few pixels only: binning's per-pixel branch; or blockers without
    bounds), so the caller runs the stage path.
    """
    bl = blocker_table(ctx.blockers)
    if bl is None:
        return None
    if np.count_nonzero(np.bincount(rays.pixel[rays.s_max > rays.s_min],
                                    minlength=ctx.scene.camera.n_pixels)) <= 64:
        return None
    return _chunks(tech, prims, paths, rays, ctx, bl)


def _chunks(tech, prims, paths, rays, ctx, bl):
    """:func:`_fused_chunks`, with Ctrl-C kept a KeyboardInterrupt
    (:func:`~psurf_core.compiled.ctrl_c_kept`: a SIGINT handled while numba boxes a result
    surfaces as a SystemError caused by it; ``render --checkpoint`` must see the Ctrl-C)."""
    with ctrl_c_kept():
        yield from _fused_chunks(tech, prims, paths, rays, ctx, bl)


def _fused_chunks(tech, prims, paths, rays, ctx, bl):
    scene = ctx.scene
    cam = scene.camera
    med = scene.medium
    if len(prims) == 0 or len(rays) == 0:
        return
    box = (med.bounds_min, med.bounds_max)
    if prims.hull is not None:
        s_prim, s_row, s_c0, s_c1 = hull_spans(cam, prims.lo, prims.hi, prims.hull, box)
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
    threads = thread_count()
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
            defer = np.flatnonzero(np.any(st == DEFER, axis=1))
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
    ok = st[:, 0] != BLOCKED
    ok &= st[:, 1] != BLOCKED
    for k, (a, b) in enumerate(((x2, x1), (x1, x0))):
        idx = np.flatnonzero(ok & (st[:, k] == DEFER))
        if idx.size:
            ok[idx] = ~blockers.occluded(a[idx], b[idx])
    val[rows[~ok]] = 0.0
