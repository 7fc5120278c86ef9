"""Compiled Intersect + Evaluate of the cone, the cylinder and the generalized planes (numba).

One kernel per family walks candidate pixel spans (``spans`` rows ``(prim, row, c0, c1)``,
primitive-major) and each pixel's rays, solves the camera ray against the primitive, and for
every root the stage path keeps (the same tests in the same floating-point operations as
``intersect``) computes the per-photon contribution of ``evaluate``: visibility with the
sphere / box / emitter-quad shadow tests of ``fused_shadow.occluded`` (one compiled copy,
:func:`_status`), a segment whose box meets a triangle mesh's box left ``DEFER`` for
:meth:`Blockers.occluded`. Driven by :mod:`.surfaces_fused`, which builds the tables below and
resolves the deferred segments.

numba compiles ``occluded`` into these kernels and its cache (``cache=True``) only watches
this file: after changing ``fused_shadow.occluded``, touch this file (or clear
``__pycache__``) so that the kernels recompile.

Tables (one array per role: every array argument of a compiled call costs reference counting)

``order`` (U,) int64, ``pix`` (n_pixels, 2) int64
    Ray indices of the rays that see medium, pixel-major, and each pixel's ``(start, count)``
    in ``order`` (``binning._pixel_ray_table``).
``rt`` (R, 8) float64
    Rays: origin, unit direction ``psi``, ``s_min``, ``s_max``.
``pt`` (M, F) float64
    Primitives: the family's columns (``_CONE_COLS``, ``_CYL_COLS``, ``_GPLANE_COLS``).
``med`` (9,) float64
    ``sigma_t, sigma_s, g``, medium box min, box max.
``blk`` (N, 27) float64
    Blockers (``fused_shadow.blocker_table``).

Each kernel returns ``n, n_defer`` (hits, hits with a ``DEFER`` status) and arrays of
``cap`` rows whose first ``n`` are the hits: ``ray, prim`` (int64), ``s``, the roots
(quadrics: ``t`` and ``w1`` (cap, 3); planes: ``t3, tv``), ``n_dot_psi``, ``value`` (cap, 3)
and ``status`` (cap, 3) int8 (shadow status of up to three segments, in the stage path's
order; unused ones ``CLEAR``). A value is 0 where a test said blocked and unmasked where a
status is ``DEFER``. Separate arrays, not one table: the hits' fields are then contiguous
slices, no copies. Single-threaded: the output order is span, pixel, ray, root.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..sampling import INV_4PI
from .fused_shadow import BLOCKED, CLEAR, DEFER, occluded
from .surface_common import NDP_MIN

#: Column layout of ``pt`` per family (start column of each field).
_CONE_COLS = dict(x1=0, w2=3, c1=6, T1=7, beta=8, width=11)
_CYL_COLS = dict(x2=0, w2=3, c1=6, s1=7, T1=8, T2=9, own=10, beta=11, width=14)
_GPLANE_COLS = dict(origin=0, w3=3, v=6, x3=9, w2=12, w1=15, Tu=18, Tv=19, T2=20, own=21,
                    beta=22, vxu=25, width=28)

_TWO_PI = 2.0 * np.pi
_EPS_BOX = 1e-9  # geometry.inside_box tolerance


@njit(cache=True, error_model="numpy", inline="always")
def _dot3(a0, a1, a2, b0, b1, b2):  # pragma: no cover - compiled
    """``base.dot`` of two 3-vectors, summed in the order numpy's ``einsum`` sums them
    (``(a0 b0 + a2 b2) + a1 b1``, its two-way unrolled loop; measured): the stage path's
    roots are ill-conditioned near grazing and near the axis, where another order changes
    values by far more than 1e-12."""
    return (a0 * b0 + a2 * b2) + a1 * b1


@njit(cache=True, error_model="numpy", inline="always")
def _roots(a, h, c):  # pragma: no cover - compiled
    """``surface_common.quadratic_roots`` of one pair: both roots of ``a x^2 + 2 h x + c``,
    NaN where missing (``a = 0`` leaves the linear root in the second slot)."""
    disc = h * h - a * c
    if not disc >= 0.0:  # a miss (most candidate pairs): no square root, no divisions
        return np.nan, np.nan
    q = -(h + math.copysign(np.sqrt(disc), h))
    r0 = q / a
    r1 = c / q
    if not np.isfinite(r0):
        r0 = np.nan
    if not np.isfinite(r1):
        r1 = np.nan
    return r0, r1


@njit(cache=True, error_model="numpy", inline="always")
def _camera_vertex(mu, s, s_min, extra, med):  # pragma: no cover - compiled
    """``surface_common.camera_vertex`` times ``E(extra)``: ``ss rho(mu) E(s - s_min + extra)``,
    ``mu = -w1 . psi``. The long variants' transmittance along the photon joins the camera's
    in one ``exp`` (a sixth of a hit's cost; equal to the stage path's product to ~1e-15)."""
    g = med[2]
    if g == 0.0:
        rho0 = INV_4PI
    else:  # sampling.phase_value
        mu = min(max(mu, -1.0), 1.0)
        if g > 0.0:
            den = (1.0 - g) ** 2 + 2.0 * g * (1.0 - mu)
        else:
            den = (1.0 + g) ** 2 - 2.0 * g * (1.0 + mu)
        rho0 = INV_4PI * ((1.0 - g) * (1.0 + g)) / (den * np.sqrt(den))
    return med[1] * rho0 * np.exp(-med[0] * ((s - s_min) + extra))


@njit(cache=True, error_model="numpy", inline="always")
def _in_box(x0, x1, x2, med):  # pragma: no cover - compiled
    """``geometry.inside_box`` of one point against the medium box in ``med``."""
    return (med[3] - _EPS_BOX <= x0 <= med[6] + _EPS_BOX
            and med[4] - _EPS_BOX <= x1 <= med[7] + _EPS_BOX
            and med[5] - _EPS_BOX <= x2 <= med[8] + _EPS_BOX)


@njit(cache=True, error_model="numpy")
def _status(a0, a1, a2, b0, b1, b2, blk):  # pragma: no cover - compiled
    """Shadow status of ``a -> b``; no blockers: clear. Not inlined: ``occluded`` is, once
    here, and the kernels' several call sites stay calls (a copy per site tripled the
    compile time)."""
    if blk.shape[0] == 0:
        return CLEAR
    return occluded(a0, a1, a2, b0, b1, b2, blk)


@njit(cache=True, error_model="numpy", inline="always")
def _emit(o_ray, o_prim, o_val, o_st, n, r, p, scal, pt, cb, st0, st1, st2):  # pragma: no cover
    """Row ``n``: ray and primitive, value ``beta * scal`` (``beta``: columns ``cb..cb+2`` of
    ``pt``), statuses; returns 1 if a status is ``DEFER``."""
    o_ray[n] = r
    o_prim[n] = p
    o_val[n, 0] = pt[p, cb] * scal
    o_val[n, 1] = pt[p, cb + 1] * scal
    o_val[n, 2] = pt[p, cb + 2] * scal
    o_st[n, 0] = st0
    o_st[n, 1] = st1
    o_st[n, 2] = st2
    return 1 if (st0 == DEFER or st1 == DEFER or st2 == DEFER) else 0


@njit(cache=True, error_model="numpy", inline="always")
def _emit_axis(o_s, o_t, o_w, o_ndp, n, s, t, w0, w1, w2, ndp):  # pragma: no cover - compiled
    """Row ``n`` of a cone / cylinder hit's geometry: ``s``, the swept length ``t``, the
    reconstructed direction ``w`` and ``|n . psi|`` (the stage path's ``data`` fields)."""
    o_s[n] = s
    o_t[n] = t
    o_w[n, 0] = w0
    o_w[n, 1] = w1
    o_w[n, 2] = w2
    o_ndp[n] = ndp


@njit(cache=True, error_model="numpy")
def _cone_kernel(spans, width, order, pix, rt, pt, med, blk, short,
                 cap):  # pragma: no cover - compiled
    """Hits and values of ``PhotonCone.intersect`` + ``evaluate`` (see the module docstring):
    ``t = t1``, status of ``x1 -> x0``."""
    o_ray, o_prim = np.empty(cap, np.int64), np.empty(cap, np.int64)
    o_s, o_t, o_ndp = np.empty(cap), np.empty(cap), np.empty(cap)
    o_w, o_val, o_st = np.empty((cap, 3)), np.empty((cap, 3)), np.empty((cap, 3), np.int8)
    n = 0
    n_defer = 0
    for i in range(spans.shape[0]):
        p = spans[i, 0]
        a0, a1, a2 = pt[p, 0], pt[p, 1], pt[p, 2]  # apex x1
        ax0, ax1, ax2 = pt[p, 3], pt[p, 4], pt[p, 5]  # axis w2
        c1 = pt[p, 6]
        T1 = pt[p, 7]
        cc = c1 * c1
        base = spans[i, 1] * width
        for col in range(spans[i, 2], spans[i, 3]):
            px = base + col
            for j in range(pix[px, 1]):
                r = order[pix[px, 0] + j]
                o0, o1, o2 = rt[r, 0], rt[r, 1], rt[r, 2]
                q0, q1, q2 = rt[r, 3], rt[r, 4], rt[r, 5]
                # closest_shift, then the cone equation in s - sc (well conditioned).
                sc = _dot3(a0 - o0, a1 - o1, a2 - o2, q0, q1, q2)
                b0 = o0 + sc * q0 - a0
                b1 = o1 + sc * q1 - a1
                b2 = o2 + sc * q2 - a2
                bw = _dot3(b0, b1, b2, ax0, ax1, ax2)
                pw = _dot3(q0, q1, q2, ax0, ax1, ax2)
                r0, r1 = _roots(pw * pw - cc, bw * pw - cc * _dot3(b0, b1, b2, q0, q1, q2),
                                bw * bw - cc * _dot3(b0, b1, b2, b0, b1, b2))
                for slot in range(2):
                    s = (r0 if slot == 0 else r1) + sc
                    if not (np.isfinite(s) and s > rt[r, 6] and s < rt[r, 7]):
                        continue
                    y0, y1, y2 = o0 + s * q0, o1 + s * q1, o2 + s * q2
                    v0, v1, v2 = y0 - a0, y1 - a1, y2 - a2
                    t1 = np.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
                    nrm = t1 if t1 > 0.0 else 1.0
                    e0, e1, e2 = v0 / nrm, v1 / nrm, v2 / nrm  # w1*
                    cw = _dot3(e0, e1, e2, ax0, ax1, ax2)
                    # The squared equation also holds on the mirror nappe: keep the photon's.
                    if not (t1 > 0.0 and cw * c1 > 0.0):
                        continue
                    if short and not t1 < T1:
                        continue
                    ndp = abs(_dot3(t1 * (ax0 - cw * e0), t1 * (ax1 - cw * e1),
                                    t1 * (ax2 - cw * e2), q0, q1, q2))
                    if not ndp > NDP_MIN:
                        continue
                    st0 = _status(a0, a1, a2, y0, y1, y2, blk)
                    if st0 == BLOCKED:
                        scal = 0.0
                    else:
                        scal = _camera_vertex(-_dot3(e0, e1, e2, q0, q1, q2), s, rt[r, 6],
                                              0.0 if short else t1, med) / _TWO_PI
                        scal = scal / ndp
                    n_defer += _emit(o_ray, o_prim, o_val, o_st, n, r, p, scal, pt, 8, st0,
                                     CLEAR, CLEAR)
                    _emit_axis(o_s, o_t, o_w, o_ndp, n, s, t1, e0, e1, e2, ndp)
                    n += 1
    return n, n_defer, o_ray, o_prim, o_s, o_t, o_w, o_ndp, o_val, o_st


@njit(cache=True, error_model="numpy")
def _cylinder_kernel(spans, width, order, pix, rt, pt, med, blk, short,
                     cap):  # pragma: no cover - compiled
    """Hits and values of ``PhotonCylinder.intersect`` + ``evaluate``: ``t = t2``, statuses of
    ``x2 -> x1`` and ``x1 -> x0``."""
    o_ray, o_prim = np.empty(cap, np.int64), np.empty(cap, np.int64)
    o_s, o_t, o_ndp = np.empty(cap), np.empty(cap), np.empty(cap)
    o_w, o_val, o_st = np.empty((cap, 3)), np.empty((cap, 3)), np.empty((cap, 3), np.int8)
    n = 0
    n_defer = 0
    for i in range(spans.shape[0]):
        p = spans[i, 0]
        a0, a1, a2 = pt[p, 0], pt[p, 1], pt[p, 2]  # x2
        ax0, ax1, ax2 = pt[p, 3], pt[p, 4], pt[p, 5]  # axis w2
        c1, s1, T1, T2 = pt[p, 6], pt[p, 7], pt[p, 8], pt[p, 9]
        own = pt[p, 10] != 0.0
        rad = T1 * s1
        base = spans[i, 1] * width
        for col in range(spans[i, 2], spans[i, 3]):
            px = base + col
            for j in range(pix[px, 1]):
                r = order[pix[px, 0] + j]
                o0, o1, o2 = rt[r, 0], rt[r, 1], rt[r, 2]
                q0, q1, q2 = rt[r, 3], rt[r, 4], rt[r, 5]
                sc = _dot3(a0 - o0, a1 - o1, a2 - o2, q0, q1, q2)
                b0 = o0 + sc * q0 - a0
                b1 = o1 + sc * q1 - a1
                b2 = o2 + sc * q2 - a2
                bw = _dot3(b0, b1, b2, ax0, ax1, ax2)
                p0, p1, p2 = b0 - bw * ax0, b1 - bw * ax1, b2 - bw * ax2  # b without axis
                pw = _dot3(q0, q1, q2, ax0, ax1, ax2)
                u0, u1, u2 = q0 - pw * ax0, q1 - pw * ax1, q2 - pw * ax2  # psi without axis
                r0, r1 = _roots(_dot3(u0, u1, u2, u0, u1, u2), _dot3(p0, p1, p2, u0, u1, u2),
                                _dot3(p0, p1, p2, p0, p1, p2) - rad * rad)
                for slot in range(2):
                    s = (r0 if slot == 0 else r1) + sc
                    if not (np.isfinite(s) and s > rt[r, 6] and s < rt[r, 7]):
                        continue
                    y0, y1, y2 = o0 + s * q0, o1 + s * q1, o2 + s * q2
                    v0, v1, v2 = y0 - a0, y1 - a1, y2 - a2
                    h = _dot3(v0, v1, v2, ax0, ax1, ax2)
                    t2 = h - T1 * c1
                    if not t2 > 0.0:  # before x1 on the axis: rejected before normalizing
                        continue
                    if short and not t2 < T2:
                        continue
                    e0, e1, e2 = v0 - h * ax0, v1 - h * ax1, v2 - h * ax2
                    ne = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
                    nrm = ne if ne > 0.0 else 1.0
                    e0, e1, e2 = e0 / nrm, e1 / nrm, e2 / nrm  # e_r*
                    ndp = T1 * s1 * abs(_dot3(e0, e1, e2, q0, q1, q2))
                    if not ndp > NDP_MIN:
                        continue
                    m0, m1, m2 = c1 * ax0 + s1 * e0, c1 * ax1 + s1 * e1, c1 * ax2 + s1 * e2
                    # on_own_segment / clear_from: x2 -> x1 needs no test on the photon's
                    # own segment; otherwise x1 must lie in the box.
                    x0_, x1_, x2_ = a0 + t2 * ax0, a1 + t2 * ax1, a2 + t2 * ax2
                    st1 = CLEAR
                    if own and t2 < T2:
                        st0 = CLEAR
                    elif not _in_box(x0_, x1_, x2_, med):
                        st0 = BLOCKED
                    else:
                        st0 = _status(a0, a1, a2, x0_, x1_, x2_, blk)
                    if st0 != BLOCKED:
                        st1 = _status(x0_, x1_, x2_, y0, y1, y2, blk)
                    if st0 == BLOCKED or st1 == BLOCKED:
                        scal = 0.0
                    else:
                        scal = _camera_vertex(-_dot3(m0, m1, m2, q0, q1, q2), s, rt[r, 6],
                                              0.0 if short else t2, med) / _TWO_PI
                        scal = scal / ndp
                    n_defer += _emit(o_ray, o_prim, o_val, o_st, n, r, p, scal, pt, 11, st0,
                                     st1, CLEAR)
                    _emit_axis(o_s, o_t, o_w, o_ndp, n, s, t2, m0, m1, m2, ndp)
                    n += 1
    return n, n_defer, o_ray, o_prim, o_s, o_t, o_w, o_ndp, o_val, o_st


@njit(cache=True, error_model="numpy")
def _gplane_kernel(spans, width, order, pix, rt, pt, med, blk, short, t1t3,
                   cap):  # pragma: no cover - compiled
    """Hits and values of ``GeneralizedPlane.intersect`` + ``evaluate`` (``t1t3``: the
    ``[t1, t3]`` plane, else ``[t2, t3]``): statuses of ``x3 -> x2``, ``x2 -> x1``,
    ``x1 -> x0``."""
    o_ray, o_prim = np.empty(cap, np.int64), np.empty(cap, np.int64)
    o_s, o_t3, o_tv, o_ndp = np.empty(cap), np.empty(cap), np.empty(cap), np.empty(cap)
    o_val, o_st = np.empty((cap, 3)), np.empty((cap, 3), np.int8)
    n = 0
    n_defer = 0
    sig_t = med[0]
    for i in range(spans.shape[0]):
        p = spans[i, 0]
        g0, g1, g2 = pt[p, 0], pt[p, 1], pt[p, 2]  # plane origin
        u0, u1, u2 = pt[p, 3], pt[p, 4], pt[p, 5]  # w3
        v0, v1, v2 = pt[p, 6], pt[p, 7], pt[p, 8]  # the other direction
        n0, n1, n2 = pt[p, 25], pt[p, 26], pt[p, 27]  # v x u
        Tu, Tv = pt[p, 18], pt[p, 19]
        base = spans[i, 1] * width
        for col in range(spans[i, 2], spans[i, 3]):
            px = base + col
            for j in range(pix[px, 1]):
                r = order[pix[px, 0] + j]
                q0, q1, q2 = rt[r, 3], rt[r, 4], rt[r, 5]
                # surface_common.plane_solve (Cramer's rule), same operations.
                det = _dot3(n0, n1, n2, q0, q1, q2)
                ndp = abs(det)
                if not ndp > NDP_MIN:
                    continue
                inv = 1.0 / det
                d0, d1, d2 = rt[r, 0] - g0, rt[r, 1] - g1, rt[r, 2] - g2
                s = _dot3(u0, u1, u2, v1 * d2 - v2 * d1, v2 * d0 - v0 * d2, v0 * d1 - v1 * d0) * inv
                if not (s > rt[r, 6] and s < rt[r, 7]):
                    continue
                m0, m1, m2 = -q0, -q1, -q2
                t3 = _dot3(d0, d1, d2, v1 * m2 - v2 * m1, v2 * m0 - v0 * m2,
                           v0 * m1 - v1 * m0) * inv
                tv = _dot3(u0, u1, u2, d1 * m2 - d2 * m1, d2 * m0 - d0 * m2,
                           d0 * m1 - d1 * m0) * inv
                if not (t3 > 0.0 and tv > 0.0):
                    continue
                if short and not (t3 < Tu and tv < Tv):
                    continue
                # Evaluate: rebuilt x2* = x3 + t3 w3, x1* = x2* + (T2 | tv) w2, x0 = y(s).
                x20 = pt[p, 9] + t3 * u0
                x21 = pt[p, 10] + t3 * u1
                x22 = pt[p, 11] + t3 * u2
                step = pt[p, 20] if t1t3 else tv
                x10 = x20 + step * pt[p, 12]
                x11 = x21 + step * pt[p, 13]
                x12 = x22 + step * pt[p, 14]
                y0, y1, y2 = rt[r, 0] + s * q0, rt[r, 1] + s * q1, rt[r, 2] + s * q2
                st1 = CLEAR
                st2 = CLEAR
                if pt[p, 21] != 0.0 and t3 < Tu:
                    st0 = CLEAR
                elif not _in_box(x20, x21, x22, med):
                    st0 = BLOCKED
                else:
                    st0 = _status(pt[p, 9], pt[p, 10], pt[p, 11], x20, x21, x22, blk)
                if st0 != BLOCKED and not _in_box(x10, x11, x12, med):
                    st1 = BLOCKED
                if st0 != BLOCKED and st1 != BLOCKED:
                    st1 = _status(x20, x21, x22, x10, x11, x12, blk)
                if st0 != BLOCKED and st1 != BLOCKED:
                    st2 = _status(x10, x11, x12, y0, y1, y2, blk)
                if st0 == BLOCKED or st1 == BLOCKED or st2 == BLOCKED:
                    scal = 0.0
                else:
                    mu = -_dot3(pt[p, 15], pt[p, 16], pt[p, 17], q0, q1, q2)
                    scal = sig_t * _camera_vertex(mu, s, rt[r, 6], 0.0 if short else t3 + tv, med)
                    scal = scal / ndp
                n_defer += _emit(o_ray, o_prim, o_val, o_st, n, r, p, scal, pt, 22, st0, st1,
                                 st2)
                o_s[n] = s
                o_t3[n] = t3
                o_tv[n] = tv
                o_ndp[n] = ndp
                n += 1
    return n, n_defer, o_ray, o_prim, o_s, o_t3, o_tv, o_ndp, o_val, o_st
