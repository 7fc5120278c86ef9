"""Shared pieces of the multiple-scattering photon surfaces (spec 3.1 and 3.3).

Every technique of the family follows the same recipe (see ``planes.py``): pick the photons
and scatter counts ``K`` whose sampled prefix it keeps is valid, gather the last segments in
the spec's notation ``x3 -> x2 -> x1 -> x0``, bound the swept surface, solve for the camera
ray's roots, and evaluate ``f / (q |n . psi|)`` with the bounded-scene rules of spec section 4.

Photon weights (tracer layout, ``trace.py``): ``paths.beta[p, K-2]`` is ``beta_2`` (leaving
``x2`` along ``w2``) and ``paths.beta[p, K-1]`` is the weight leaving ``x1``; the tracer
multiplies by the albedo when it scatters at ``x1`` (and divides by the roulette survival
decided at ``x1``), so ``paths.beta[p, K-1] = beta_2 ss/st / q_rr(x1)``. That is exactly the
spec's ``beta_1^-`` (weight arriving at and scattering at ``x1``) times the roulette factor
that every technique of this family needs, because each of them uses at least one dimension
sampled at ``x1`` and so only sees photons that survived roulette there. Every
contribution is therefore written in terms of :func:`beta1`.
"""

from __future__ import annotations

import math

import numpy as np

from ..geometry import inside_box
from ..kernels.jit import twin
from ..kernels.shadow import BLOCKED, CLEAR, status
from ..kernels.vec import norm, sub
from ..path_record import PathRecord, Pdfs
from ..sampling import phase_value
from .base import PassContext, Technique, cross, dot

#: ``|n . psi|`` at or below this is a measure-zero grazing hit: dropped, so that no division
#: by zero (or an overflow to inf) can reach the image.
NDP_MIN = 1e-150

#: Photons whose ``sin th1`` is at or below this have no azimuth frame (``th1 = 0`` or ``pi``,
#: probability zero); techniques that need ``e_r`` skip them.
SIN_MIN = 1e-12


# ------------------------------------------------------------------------- photons
def select_photons(tech: Technique, paths, ctx: PassContext, back: int):
    """Photons and scatter counts a technique makes primitives for.

    A primitive for ``(p, K)`` needs segment ``K`` sampled (``alive[:, K-1]``: survived
    roulette at ``x1``) and the photon's own prefix valid up to the deepest sampled vertex the
    technique keeps, ``x_back`` = tracer vertex ``K - back`` (spec section 4).

    Returns
    -------
    photon, K : (M,) int
    """
    scene = ctx.scene
    lmask = tech.light_mask(paths, scene)
    photon, kk = [], []
    for k in tech.k_range(scene, paths.depth):
        ok = lmask & paths.alive[:, k - 1] & paths.prefix_ok[:, k - back]
        idx = np.flatnonzero(ok)
        photon.append(idx)
        kk.append(np.full(idx.size, k))
    photon = np.concatenate(photon) if photon else np.zeros(0, np.int64)
    K = np.concatenate(kk) if kk else np.zeros(0, np.int64)
    return photon, K


def gather(paths, photon: np.ndarray, K: np.ndarray) -> dict:
    """The photon's last three segments in spec notation (tracer vertex ``j`` = ``x_{K-j}``).

    Returns
    -------
    dict with ``x3, x2, x1 : (M, 3)``, ``w3, w2, w1 : (M, 3)``, ``T3, T2, T1 : (M,)`` and
    ``A3 : (M, 3)`` (``w3``, or the light axis / normal when ``x2`` is the light). Entries
    beyond the light (``K < 3`` for the ``3`` ones) hold arbitrary finite values.
    """
    j3 = np.maximum(K - 3, 0)
    first = (K == 2)[:, None]
    w3 = paths.w[photon, j3]
    return dict(
        x3=paths.x[photon, j3], x2=paths.x[photon, K - 2], x1=paths.x[photon, K - 1],
        w3=w3, w2=paths.w[photon, K - 2], w1=paths.w[photon, K - 1],
        T3=paths.t[photon, j3], T2=paths.t[photon, K - 2], T1=paths.t[photon, K - 1],
        A3=np.where(first, paths.light_normal[photon], w3),
    )


def beta1(paths, photon: np.ndarray, K: np.ndarray) -> np.ndarray:
    """(H, 3) ``beta_1^-`` (with the roulette factor at ``x1``): see the module docstring."""
    return paths.beta[photon, K - 1]


def radial(w1: np.ndarray, w2: np.ndarray):
    """``c1 = w1 . w2``, ``s1 = sin th1`` and the unit radial ``e_r = (w1 - c1 w2) / s1``.

    Returns
    -------
    c1, s1 : (M,) float
    e_r : (M, 3) float
        Finite everywhere; meaningless where ``s1 <= SIN_MIN`` (callers skip those).
    """
    c1 = np.clip(dot(w1, w2), -1.0, 1.0)
    e = w1 - c1[:, None] * w2
    s1 = np.linalg.norm(e, axis=1)
    e_r = e / np.where(s1 > SIN_MIN, s1, 1.0)[:, None]
    return c1, s1, e_r


def unit(v: np.ndarray):
    """``(v / |v|, |v|)`` for (H, 3) ``v``; rows of zero length stay zero."""
    n = np.linalg.norm(v, axis=1)
    return v / np.where(n > 0.0, n, 1.0)[:, None], n


@twin(unit)
def _unit(v):
    n = norm(v)
    d = n if n > 0.0 else 1.0
    return (v[0] / d, v[1] / d, v[2] / d), n


def own_segment(paths, photon: np.ndarray, j: np.ndarray, start: np.ndarray,
                scene) -> np.ndarray:
    """(M,) float 0/1: the per-primitive part of ``base.on_own_segment``: the photon's own
    segment ``j`` (tracer numbering) is unoccluded with its vertices in the box, and
    (``j = 1``) its start, the light, lies in the box. A point ``start + t w`` with
    ``t < T`` of such a segment is known to be reached unoccluded inside the box."""
    pk = paths.prefix_ok
    own = pk.reshape(-1)[photon * pk.shape[1] + j].copy()
    light = np.flatnonzero(own & (j == 1))
    if light.size:
        med = scene.medium
        own[light] = inside_box(start[light], med.bounds_min, med.bounds_max)
    return own.astype(float)


def rebuilt_clear(a, b, known, line, medium, blockers):
    """(H,) bool: the segment ``a -> b`` to a rebuilt vertex ``b`` counts: ``known`` clear
    (on the photon's own segment), or ``b`` inside the box and the segment unoccluded, which
    ``line`` (bool, scalar or (H,): :func:`.shadow_cull.line_clear` said no blocker can block
    any segment from ``a`` along its direction) answers without a test."""
    ok = known.copy()
    idx = np.flatnonzero(~known)
    if idx.size:
        inb = inside_box(b[idx], medium.bounds_min, medium.bounds_max)
        res = inb & np.broadcast_to(line, known.shape)[idx]
        k = np.flatnonzero(inb & ~res)
        if k.size:
            res[k] = ~blockers.occluded(a[idx][k], b[idx][k])
        ok[idx] = res
    return ok


@twin(rebuilt_clear, inline=True)
def _rebuilt_clear(a, b, known, line, medium, blockers):
    """The segment's shadow status (``kernels.shadow``)."""
    if known:
        return CLEAR
    if not inside_box(b, medium.bounds_min, medium.bounds_max):
        return BLOCKED
    if line:
        return CLEAR
    return status(a, b, blockers)


# ------------------------------------------------------------------------- bounds
def circle_extent(axis: np.ndarray, r: np.ndarray) -> np.ndarray:
    """(M, 3) per-coordinate half-extent of circles of radius ``r`` about unit ``axis``."""
    return r[:, None] * np.sqrt(np.clip(1.0 - axis**2, 0.0, None))


def cone_bounds(apex, axis, c, s, length):
    """Bounds of ``apex + t (c axis + s e(ph))`` over every azimuth and ``0 <= t <= length``
    (``length`` None: to infinity)."""
    ext = circle_extent(axis, s)
    dmin, dmax = c[:, None] * axis - ext, c[:, None] * axis + ext
    if length is None:
        return (np.where(dmin < 0.0, -np.inf, apex), np.where(dmax > 0.0, np.inf, apex))
    return (apex + length[:, None] * np.minimum(dmin, 0.0),
            apex + length[:, None] * np.maximum(dmax, 0.0))


#: Vertices of the polygons circumscribing the circles of footprint clouds (:func:`ring`).
RING_VERTICES = 8


def frame(axis: np.ndarray):
    """(M, 3) unit vectors ``e1, e2`` with ``e1, e2, axis`` orthonormal (Duff et al. 17)."""
    z = axis
    sign = np.where(z[:, 2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + z[:, 2])
    b = z[:, 0] * z[:, 1] * a
    e1 = np.stack([1.0 + sign * z[:, 0] ** 2 * a, sign * b, -sign * z[:, 0]], axis=1)
    e2 = np.stack([b, sign + z[:, 1] ** 2 * a, -z[:, 1]], axis=1)
    return e1, e2


def ring(centre: np.ndarray, axis: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """(M, V, 3) vertices of the regular polygons circumscribing the circles of ``radius``
    about ``centre`` in the planes normal to unit ``axis`` (their convex hull contains the
    circles: vertices at ``radius / cos(pi / V)``)."""
    e1, e2 = frame(axis)
    ang = 2.0 * np.pi * np.arange(RING_VERTICES) / RING_VERTICES
    r = (np.abs(radius) / np.cos(np.pi / RING_VERTICES))[:, None, None]
    return centre[:, None] + r * (np.cos(ang)[None, :, None] * e1[:, None]
                                  + np.sin(ang)[None, :, None] * e2[:, None])


def box_reach(scene, origin: np.ndarray, axis: np.ndarray | None = None) -> np.ndarray:
    """(M,) how far the medium box reaches from ``origin``: the largest distance to a box
    corner, or (``axis`` given) the largest extent of the box along ``axis`` from ``origin``
    (what a long surface needs to be drawn to: the box clips the rest)."""
    med = scene.medium
    corners = np.array([[x, y, z] for x in (med.bounds_min[0], med.bounds_max[0])
                        for y in (med.bounds_min[1], med.bounds_max[1])
                        for z in (med.bounds_min[2], med.bounds_max[2])])
    d = corners[None] - origin[:, None]
    if axis is None:
        return np.sqrt((d**2).sum(axis=2)).max(axis=1)
    return np.einsum("mkc,mc->mk", d, axis).max(axis=1)


def sweep_bounds(lo, hi, d, length):
    """Boxes ``[lo, hi]`` swept along ``d`` for ``0..length`` (None: to infinity)."""
    if length is None:
        return np.where(d < 0.0, -np.inf, lo), np.where(d > 0.0, np.inf, hi)
    step = length[:, None] * d
    return np.minimum(lo, lo + step), np.maximum(hi, hi + step)


def half_disk_bounds(apex, a, b, length):
    """Bounds of ``apex + t (cos u a + sin u b)``, ``u`` in [0, pi], ``0 <= t <= length``
    (``a, b`` orthonormal; ``length`` None: to infinity)."""
    rad = np.sqrt(a**2 + b**2)
    dmax = np.where(b >= 0.0, rad, np.abs(a))
    dmin = np.where(b <= 0.0, -rad, -np.abs(a))
    if length is None:
        return (np.where(dmin < 0.0, -np.inf, apex), np.where(dmax > 0.0, np.inf, apex))
    return (apex + length[:, None] * np.minimum(dmin, 0.0),
            apex + length[:, None] * np.maximum(dmax, 0.0))


# ------------------------------------------------------------------------- roots
def quadratic_roots(a, h, c):
    """Both real roots of ``a x^2 + 2 h x + c = 0`` (numerically stable form).

    A vanishing ``a`` leaves the linear root in the second slot; missing roots are NaN.

    Returns
    -------
    (2, N) float
    """
    with np.errstate(all="ignore"):
        disc = h * h - a * c
        q = -(h + np.copysign(np.sqrt(np.maximum(disc, 0.0)), h))
        r = np.stack([q / a, c / q])
    return np.where((disc >= 0.0) & np.isfinite(r), r, np.nan)


@twin(quadratic_roots)
def _quadratic_roots(a, h, c):
    """``(r0, r1)``, NaN where missing."""
    disc = h * h - a * c
    if not disc >= 0.0:  # a miss (most candidate pairs): no square root, no divisions
        return np.nan, np.nan
    q = -(h + math.copysign(np.sqrt(disc), h))
    r0 = q / a
    r1 = c / q
    return (r0 if np.isfinite(r0) else np.nan), (r1 if np.isfinite(r1) else np.nan)


# ------------------------------------------------------------------------- evaluate
def camera_term(mu, ds, extra, medium):
    """``ss rho(mu) E(ds + extra)``: the scattering at ``x0 = y(s)`` towards the camera
    (``mu = -w1 . psi``), the camera segment's transmittance over ``ds = s - s_min`` and a
    long technique's transmittance over its integrated distances ``extra`` (0 for short
    ones), in one exponential."""
    return medium.sigma_s * phase_value(mu, medium.g) * np.exp(-medium.sigma_t * (ds + extra))


@twin(camera_term)
def _camera_term(mu, ds, extra, medium):
    return medium.sigma_s * phase_value(mu, medium.g) * np.exp(-medium.sigma_t * (ds + extra))


# ------------------------------------------------------------------------- densities
def q_to_w2(rec: PathRecord, pdf: Pdfs | None = None) -> np.ndarray:
    """(H,) relative ``q_{<= w2}``: ``p(t3) p(w2)`` (``K >= 3``) or the emission pdf ``p(w2)``
    (``K = 2``; the light-position pdf is shared and dropped, ``path_record``)."""
    pdf = rec.pdf if pdf is None else pdf
    return np.where(rec.K >= 3, pdf.t3, 1.0) * pdf.w2


@twin(q_to_w2)
def _q_to_w2(rec, pdf=None):
    return (rec.pdf.t3 if rec.K >= 3 else 1.0) * rec.pdf.w2




def plane_solver(x, u, v, o):
    """The solve's vectors for ``x + a u + b v = o + s psi`` and rays from ``o`` (each (3,) or
    (H, 3)): ``m0 = v x u``, ``m1 = v x r``, ``m2 = r x u`` and ``sdet = u . (v x r)``,
    ``r = o - x``. By Cramer's rule and triple-product identities every determinant is then a
    dot product with ``psi`` (:func:`cached_solve`): ``det = m0 . psi``, ``a det = m1 . psi``,
    ``b det = m2 . psi``, ``s det = sdet``. For a pinhole camera ``r`` depends on the surface
    only: Create computes the vectors once per primitive for the camera's position."""
    r = o - x
    vxr = cross(v, r)
    return cross(v, u), vxr, cross(r, u), dot(u, vxr)


@twin(plane_solver)
def _plane_solver(x, u, v, o):
    r = sub(o, x)
    vxr = cross(v, r)
    return cross(v, u), vxr, cross(r, u), dot(u, vxr)


def cached_solve(x, u, v, G, o, psi):
    """``(det, a, b, s)`` of ``x + a u + b v = o + s psi`` (inf / NaN where singular; ``|det|``
    is the Jacobian ``|(v x u) . psi|``) from :func:`plane_solver`'s vectors. The compiled twin
    reads those Create stored for rays from the camera at ``G.eye`` (``G.m0, G.m1, G.m2,
    G.sdet``, :func:`solve_columns`): three dot products and a division a ray."""
    m0, m1, m2, sdet = plane_solver(x, u, v, o)
    det = dot(m0, psi)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        return det, dot(m1, psi) * inv, dot(m2, psi) * inv, sdet * inv


@twin(cached_solve)
def _cached_solve(x, u, v, G, o, psi):
    if o[0] == G.eye[0] and o[1] == G.eye[1] and o[2] == G.eye[2]:
        m1, m2, sdet = G.m1, G.m2, G.sdet  # the camera's: computed by Create
    else:
        _, m1, m2, sdet = plane_solver(x, u, v, o)
    # m0 = v x u does not depend on the origin: read, not chosen, so that the walker's two
    # calls (roots, accept) share one division to LLVM.
    det = dot(G.m0, psi)
    inv = 1.0 / det
    return det, dot(m1, psi) * inv, dot(m2, psi) * inv, sdet * inv


def solve_columns(scene, x, u, v) -> dict:
    """The geometry columns :func:`cached_solve` reads, for ``x + a u + b v`` ((M, 3) each) and
    rays from the camera: ``eye`` and :func:`plane_solver`'s ``m0, m1, m2, sdet``."""
    eye = np.broadcast_to(np.asarray(scene.camera.position, float), np.shape(x))
    m0, m1, m2, sdet = plane_solver(x, u, v, eye)
    return dict(eye=eye, m0=m0, m1=m1, m2=m2, sdet=sdet)
