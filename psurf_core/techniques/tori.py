"""Torus ``[cos th1, ph2]`` (spec 3.3, second row; K >= 2).

The photon keeps everything up to ``x2`` (tracer vertex ``K-2``), its flights ``T2, T1`` and
the azimuth ``ph1`` of ``w1`` (the radial unit ``e_r`` about ``w2``); it integrates ``cos th1``
and the azimuth ``ph2`` of ``w2`` about ``A3``. ``x0`` sweeps the meridian half-circle
``x2 + T2 w2 + T1 (c1 w2 + s1 e_r)`` revolved about the axis ``(x2, A3)``: a generalised torus
(the circle's plane usually does not contain the axis). With ``P = y(s) - x2``, the distance
``|P|^2 = T2^2 + T1^2 + 2 T1 T2 c1`` gives ``c1(s)`` and the height ``P . A3`` then gives a
quartic in ``s`` (:mod:`.quartic`), at most four roots; the photon's subpath, rebuilt at
``c1*``, is revolved onto the hit (:mod:`.revolutions`). The scaled normal is
``n = T1 (w2* - c1 w1*) / s1^2 x (A3 x d2)``, ``d2 = x0 - x2``.

``X = beta_1^- (1/st) ss rho(c1*) rho0 E(s*) / |n . psi|`` (``rho / p(ph1) = 2pi rho``,
``p(ph2)`` is not in ``q``, ``E/p`` of ``T1`` gives ``1/st``). Long only: no distance is
integrated.

``Q = q_{<=w2} 2pi p(t2) (1/2pi) p(t1) |n . psi| = q_{<=w2} p(t2) p(t1) |n . psi|``.

Each numpy function has its compiled twin (``@twin``) beneath it; see :mod:`.cones`. The
hit record, shadow segments and Reconstruct are the revolutions' (:mod:`.revolutions`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..kernels.jit import twin
from ..kernels.vec import add, madd, scale, sub
from ..path_record import revolution_axis
from ..records import Vec, table
from ..sampling import phase_value
from . import grids
from .base import Compiled, Primitives, Technique, clip_bounds, cross, dot
from .quartic import quartic_real_roots, square_quadratic
from .revolutions import RevolutionHit, reconstruct, revolved, segments, visibility
from .surface_common import (
    NDP_MIN,
    SIN_MIN,
    beta1,
    camera_term,
    gather,
    q_to_w2,
    radial,
    select_photons,
)


class TorusGeometry(NamedTuple):
    """One torus (a row of its ``Primitives.data``)."""

    x2: Vec  # the centre: the photon's vertex x2
    A3: Vec  # the axis direction (w3, or the light's axis / normal)
    w2: Vec  # the photon's w2 (before revolving)
    e_r: Vec  # the photon's radial unit of w1 about w2: the meridian's plane
    T2: float  # the photon's flight from x2
    T1: float  # the photon's flight from x1: the meridian's radius
    beta: Vec  # beta_1^- (W)


# ------------------------------------------------------------------------- geometry
def scaled_normal(w2, w1, t1, A3, d2):
    """(H, 3) ``dx0/dc1 x dx0/dph2 = t1 (w2 - c1 w1) / s1^2 x (A3 x d2)`` (up to sign)."""
    c1 = dot(w1, w2)
    # Infinite at th1 = 0, pi (probability zero); MIS maps a non-finite density to 0.
    with np.errstate(divide="ignore", invalid="ignore"):
        radial_dc = (t1 / (1.0 - c1 * c1))[:, None] * (w2 - c1[:, None] * w1)
        return cross(radial_dc, cross(A3, d2))


@twin(scaled_normal)
def _scaled_normal(w2, w1, t1, A3, d2):
    c1 = dot(w1, w2)
    radial_dc = scale(t1 / (1.0 - c1 * c1), sub(w2, scale(c1, w1)))
    return cross(radial_dc, cross(A3, d2))


# ------------------------------------------------------------------------- Intersect
def quartic(G, b, psi, R):
    """(5, N) coefficients (highest first) of the torus equation in ``u``, for the ray points
    ``P(u) = b + R u psi`` (``b``: relative to ``x2``): ``c1(u)`` from the distance, then
    ``(P . A - T2 wA - T1 c1 wA)^2 = (T1 eA)^2 (1 - c1^2)`` from the height."""
    T2, T1 = G.T2, G.T1
    wA, eA, pA = dot(G.w2, G.A3), dot(G.e_r, G.A3), dot(psi, G.A3)
    k2 = np.stack([R * R, 2.0 * R * dot(b, psi), dot(b, b) - T2 * T2 - T1 * T1]) / \
        (2.0 * T1 * T2)
    g = -T1 * wA * k2
    g[1] += R * pA
    g[2] += dot(b, G.A3) - T2 * wA
    e2 = (T1 * eA) ** 2
    coef = square_quadratic(g) + e2 * square_quadratic(k2)
    coef[4] -= e2
    return coef


@twin(quartic)
def _quartic(G, b, psi, R):
    T2, T1 = G.T2, G.T1
    wA, eA, pA = dot(G.w2, G.A3), dot(G.e_r, G.A3), dot(psi, G.A3)
    den = 2.0 * T1 * T2
    k2 = (R * R / den, 2.0 * R * dot(b, psi) / den, (dot(b, b) - T2 * T2 - T1 * T1) / den)
    h = -T1 * wA
    g = (h * k2[0], h * k2[1] + R * pA, h * k2[2] + (dot(b, G.A3) - T2 * wA))
    e2 = (T1 * eA) ** 2
    sg, sk = square_quadratic(g), square_quadratic(k2)
    return (sg[0] + e2 * sk[0], sg[1] + e2 * sk[1], sg[2] + e2 * sk[2], sg[3] + e2 * sk[3],
            sg[4] + e2 * sk[4] - e2)


def near(G, b, psi, R):
    """(N,) bool: can the ray meet the torus? Its chord through the ball ``|P| <= R = T2 + T1``
    (which holds the torus) must exist and reach the torus's height range along ``A3``,
    ``T2 wA +- T1 sqrt(wA^2 + eA^2)`` (the whole meridian circle's): a cheap cull before
    the quartic."""
    wA, eA = dot(G.w2, G.A3), dot(G.e_r, G.A3)
    half = G.T1 * np.sqrt(wA * wA + eA * eA)
    bA = dot(b, G.A3)
    with np.errstate(invalid="ignore"):
        h = np.sqrt(R * R - dot(b, b)) * np.abs(dot(psi, G.A3))  # NaN: no chord
        return (bA - h <= G.T2 * wA + half) & (bA + h >= G.T2 * wA - half)


@twin(near)
def _near(G, b, psi, R):
    wA, eA = dot(G.w2, G.A3), dot(G.e_r, G.A3)
    half = G.T1 * np.sqrt(wA * wA + eA * eA)
    bA = dot(b, G.A3)
    h = np.sqrt(R * R - dot(b, b)) * abs(dot(psi, G.A3))
    return bA - h <= G.T2 * wA + half and bA + h >= G.T2 * wA - half


def roots(G, o, psi):
    """(4, N) ray distances of the quartic's roots (NaN: none), solved in ``u = (s - sc) / R``
    about the ray point closest to ``x2``: the torus lies in ``|u| <= 1``."""
    sc = dot(G.x2 - o, psi)
    b = o + sc[:, None] * psi - G.x2
    R = G.T2 + G.T1
    out = np.full((4, sc.shape[0]), np.nan)
    k = np.flatnonzero(near(G, b, psi, R))
    if k.size:
        out[:, k] = sc[k] + R[k] * quartic_real_roots(quartic(G[k], b[k], psi[k], R[k]))
    return out


@twin(roots)
def _roots(G, o, psi):
    sc = dot(sub(G.x2, o), psi)
    b = sub(madd(o, sc, psi), G.x2)
    R = G.T2 + G.T1
    if not near(G, b, psi, R):
        return np.nan, np.nan, np.nan, np.nan
    u0, u1, u2, u3 = quartic_real_roots(quartic(G, b, psi, R))
    return sc + R * u0, sc + R * u1, sc + R * u2, sc + R * u3


def accept(G, o, psi, s, short):
    """Hits: ``|c1*| < 1``, the photon's subpath rebuilt at ``c1*`` and revolved onto ``y(s)``
    (:func:`~.revolutions.revolved`), not grazing; their records (:class:`RevolutionHit`)."""
    P = o + s[:, None] * psi - G.x2
    T2, T1 = G.T2, G.T1
    c1 = (dot(P, P) - T2 * T2 - T1 * T1) / (2.0 * T1 * T2)
    inside = np.abs(c1) < 1.0
    c1 = np.clip(c1, -1.0, 1.0)
    s1 = np.sqrt(1.0 - c1 * c1)
    w1 = c1[:, None] * G.w2 + s1[:, None] * G.e_r
    landed, w2r, w1r = revolved(G.A3, T2, G.w2, w1, T1, P)
    ndp = np.abs(dot(scaled_normal(w2r, w1r, T1, G.A3, P), psi))
    with np.errstate(invalid="ignore"):
        ok = inside & landed & (ndp > NDP_MIN) & np.isfinite(ndp)
    return ok, table(RevolutionHit, t1=T1, w2=w2r, w1=w1r, n_dot_psi=ndp)


@twin(accept)
def _accept(G, o, psi, s, short):
    P = sub(madd(o, s, psi), G.x2)
    T2, T1 = G.T2, G.T1
    c1 = (dot(P, P) - T2 * T2 - T1 * T1) / (2.0 * T1 * T2)
    inside = abs(c1) < 1.0
    c1 = min(max(c1, -1.0), 1.0)
    s1 = np.sqrt(1.0 - c1 * c1)
    w1 = add(scale(c1, G.w2), scale(s1, G.e_r))
    landed, w2r, w1r = revolved(G.A3, T2, G.w2, w1, T1, P)
    ndp = abs(dot(scaled_normal(w2r, w1r, T1, G.A3, P), psi))
    return (inside and landed and ndp > NDP_MIN and np.isfinite(ndp),
            RevolutionHit(T1, w2r, w1r, ndp))


# ------------------------------------------------------------------------- Evaluate
def contribution(G, psi, s, s_min, hit, short, medium):
    """``rho(c1*) / st ss rho0 E(s* - s_min) / |n . psi|`` per unit photon weight."""
    rho1 = phase_value(dot(hit.w1, hit.w2), medium.g)
    return rho1 / medium.sigma_t * camera_term(-dot(hit.w1, psi), s - s_min, 0.0, medium) / \
        hit.n_dot_psi


@twin(contribution)
def _contribution(G, psi, s, s_min, hit, short, medium):
    rho1 = phase_value(dot(hit.w1, hit.w2), medium.g)
    return rho1 / medium.sigma_t * camera_term(-dot(hit.w1, psi), s - s_min, 0.0, medium) / \
        hit.n_dot_psi


# ------------------------------------------------------------------------- MIS
def density(rec, short):
    """Relative ``Q = q_{<=w2} p(t2) p(t1) |n . psi|``."""
    n = scaled_normal(rec.w2, rec.w1, rec.t1, revolution_axis(rec), rec.x0 - rec.x2)
    with np.errstate(invalid="ignore"):
        return q_to_w2(rec) * rec.pdf.t2 * rec.pdf.t1 * np.abs(dot(n, rec.psi))


@twin(density, weight=True)
def _density(rec, short):
    n = scaled_normal(rec.w2, rec.w1, rec.t1, revolution_axis(rec), sub(rec.x0, rec.x2))
    return q_to_w2(rec) * rec.pdf.t2 * rec.pdf.t1 * abs(dot(n, rec.psi))


# ------------------------------------------------------------------------- drawing
def surface_grid(G, short, far):
    """(M, 16, 36, 3) the meridian half-circle of radius ``T1`` about ``x2 + T2 w2`` revolved
    about ``(x2, A3)``: the drawing's sweep grid (:mod:`.grids`)."""
    th = np.linspace(0, np.pi, 16)
    merid = (G.T2[:, None, None] * G.w2[:, None]
             + G.T1[:, None, None] * (np.cos(th)[None, :, None] * G.w2[:, None]
                                      + np.sin(th)[None, :, None] * G.e_r[:, None]))
    return grids.revolve(G.x2, G.A3, merid)


# ------------------------------------------------------------------------- Create
class Torus(Technique):
    """The (generalised) torus ``[cos th1, ph2]`` (long only)."""

    family = "revolutions"
    min_k = 2
    compiled = Compiled(TorusGeometry, RevolutionHit, 4, roots, accept, visibility,
                        contribution, segments, reconstruct, density, staged=True)

    names = ("torus", None)
    grid = staticmethod(surface_grid)

    def create(self, paths, ctx) -> Primitives:
        photon, K = select_photons(self, paths, ctx, back=2)
        g = gather(paths, photon, K)
        c1, s1, e_r = radial(g["w1"], g["w2"])
        # th1 = 0 or pi: no meridian half-plane; T = 0: no circle (both probability zero).
        ok = (s1 > SIN_MIN) & (g["T1"] > 0) & (g["T2"] > 0)
        photon, K = photon[ok], K[ok]
        g = {k: v[ok] for k, v in g.items()}
        r = (g["T2"] + g["T1"])[:, None]  # every point is within T2 + T1 of x2
        lo, hi = clip_bounds(ctx.scene, g["x2"] - r, g["x2"] + r)
        return Primitives(self.name, photon, K, lo, hi, table(
            TorusGeometry, x2=g["x2"], A3=g["A3"], w2=g["w2"], e_r=e_r[ok], T2=g["T2"],
            T1=g["T1"], beta=beta1(paths, photon, K)))

    def scaled_normal(self, rec):
        """(H, 3) scaled normal on records ``rec`` (the inspector's)."""
        return scaled_normal(rec.w2, rec.w1, rec.t1, rec.A3, rec.x0 - rec.x2)
