"""Surfaces of revolution about the axis ``(x2, A3)`` (spec 3.3; K >= 2).

Both integrate the azimuth ``ph2`` of ``w2`` about ``A3`` (``w3``, or the light's axis / normal
when ``x2`` is the light): rotating ``w2`` about ``A3`` leaves ``rho(w3 . w2)`` (or the emission
term) unchanged, and the azimuth frame of ``ph1`` (spec 1) turns with it, so the rest of the
photon's subpath ``x2 -> x1 -> x0`` is revolved rigidly by the rotation ``R`` that takes it
onto the hit. ``x2`` (tracer vertex ``K-2``) is kept and ``x1* = x2 + T2 R w2`` is rebuilt.

* ``hyperboloid`` ``[t1, ph2]``: the ray ``x1 + t w1`` revolved; ``n = w1* x (A3 x d2)``,
  ``d2 = x0 - x2``. ``X = beta_1^- (1/2pi) E(t1*) ss rho0 E(s*) / |n . psi|`` (the spec's
  ``beta_2 (1/2pi)(ss/st) ...``); short: ``t1* < T1``, drop ``E(t1*)``.
* ``torus`` ``[cos th1, ph2]``: the meridian half-circle ``x1 + T1 (c1 w2 + s1 e_r)``
  revolved, a quartic in ``s``; ``n = T1 (w2* - c1 w1*) / s1^2 x (A3 x d2)``.
  ``X = beta_1^- (1/st) ss rho(c1*) rho0 E(s*) / |n . psi|``. Long only (no distance is
  integrated).
"""

from __future__ import annotations

import numpy as np

from ..path_record import Pdfs, photon_record
from ..sampling import phase_value
from .base import Hits, Primitives, Technique, clip_bounds, dot, in_medium, on_ray, segments_clear
from .surface_common import (
    NDP_MIN,
    SIN_MIN,
    beta1,
    camera_vertex,
    closest_shift,
    expand,
    finish,
    gather,
    q_to_w2,
    quadratic_roots,
    quartic_real_roots,
    radial,
    revolve,
    select_photons,
    square_quadratic,
    transmittance,
)

#: A reconstructed subpath must land on the hit within this fraction of its size; rejects the
#: squared equations' spurious branches and rotations about a (near-)zero radial offset.
RESIDUAL_TOL = 1e-7


def hyperboloid_normal(w1: np.ndarray, A3: np.ndarray, d2: np.ndarray) -> np.ndarray:
    """(H, 3) ``dx0/dt1 x dx0/dph2 = w1 x (A3 x d2)`` (up to sign)."""
    return np.cross(w1, np.cross(A3, d2))


def torus_normal(w2, w1, t1, A3, d2) -> np.ndarray:
    """(H, 3) ``dx0/dc1 x dx0/dph2 = t1 (w2 - c1 w1) / s1^2 x (A3 x d2)`` (up to sign)."""
    c1 = dot(w1, w2)
    # Infinite at th1 = 0, pi (probability zero); MIS maps a non-finite density to 0.
    with np.errstate(divide="ignore", invalid="ignore"):
        radial_dc = (t1 / (1.0 - c1 * c1))[:, None] * (w2 - c1[:, None] * w1)
        return np.cross(radial_dc, np.cross(A3, d2))


class _Revolution(Technique):
    """What the two revolution surfaces share: finishing hits, Evaluate and Reconstruct."""

    min_k = 2
    family = "revolutions"

    def _hits(self, ray, prim, s, ok, rays, x2, A3, T2, rot, w2, w1, t1):
        """Finish candidate roots: revolve the photon's ``w2, w1`` (with the hit's ``t1``)
        by ``rot``, keep those that land on ``y(s)`` and have a usable ``|n . psi|``."""
        P = rays.o[ray] + s[:, None] * rays.d[ray] - x2
        w2r, w1r = rot(w2), rot(w1)
        with np.errstate(invalid="ignore"):
            res = np.linalg.norm(T2[:, None] * w2r + t1[:, None] * w1r - P, axis=1)
            ok = ok & (res <= RESIDUAL_TOL * (T2 + t1))
        ndp = np.abs(dot(self._normal(w2r, w1r, t1, A3, P), rays.d[ray]))
        keep = ok & (ndp > NDP_MIN) & np.isfinite(ndp)
        return Hits(ray[keep], prim[keep], s[keep],
                    dict(t1=t1[keep], w2=w2r[keep], w1=w1r[keep], n_dot_psi=ndp[keep]))

    # ------------------------------------------------------------------ Evaluate
    def evaluate(self, hits, prims, paths, rays, ctx) -> np.ndarray:
        scene = ctx.scene
        p = hits.prim
        d = prims.data
        x2 = d["x2"][p]
        x1 = x2 + d["T2"][p][:, None] * hits.data["w2"]
        x0 = rays.o[hits.ray] + hits.s[:, None] * rays.d[hits.ray]
        valid = in_medium(scene, x1) & segments_clear(ctx.blockers, (x2, x1), (x1, x0))
        scal = self._factor(hits, prims, ctx) * camera_vertex(scene, rays, hits, hits.data["w1"])
        return finish(beta1(paths, prims.photon[p], prims.K[p]), scal, valid,
                      hits.data["n_dot_psi"])

    # ------------------------------------------------------------------ Reconstruct
    def reconstruct(self, hits, prims, paths, rays, ctx):
        p = hits.prim
        rec = photon_record(paths, prims.photon[p], prims.K[p], ctx.scene, rays, hits.ray, hits.s)
        w2 = hits.data["w2"]
        return rec.with_(t1=hits.data["t1"], w2=w2, w1=hits.data["w1"],
                         x1=rec.x2 + rec.t2[:, None] * w2)


class Hyperboloid(_Revolution):
    """The hyperboloid ``[t1, ph2]``; ``short`` restricts ``t1* < T1``."""

    def __init__(self, short: bool):
        self.short = short
        self.name = "hyperboloid-short" if short else "hyperboloid"

    def _normal(self, w2, w1, t1, A3, d2):
        return hyperboloid_normal(w1, A3, d2)

    # ------------------------------------------------------------------ Create
    def create(self, paths, ctx) -> Primitives:
        photon, K = select_photons(self, paths, ctx, back=2)
        g = gather(paths, photon, K)
        x2, q0 = g["x2"], g["T2"][:, None] * g["w2"]
        if self.short:  # every point is within max(|q0|, |q0 + T1 w1|) of x2 (convexity)
            r = np.maximum(g["T2"], np.linalg.norm(q0 + g["T1"][:, None] * g["w1"], axis=1))
            lo, hi = x2 - r[:, None], x2 + r[:, None]
        else:  # unbounded: the whole box
            lo, hi = np.full_like(x2, -np.inf), np.full_like(x2, np.inf)
        lo, hi = clip_bounds(ctx.scene, lo, hi)
        return Primitives(self.name, photon, K, lo, hi,
                          dict(x2=x2, A3=g["A3"], w2=g["w2"], w1=g["w1"], T2=g["T2"],
                               T1=g["T1"]))

    # ------------------------------------------------------------------ Intersect
    def intersect(self, prims, rays, ray, prim, ctx) -> Hits:
        d = prims.data
        x2, A, w1 = d["x2"][prim], d["A3"][prim], d["w1"][prim]
        q = d["T2"][prim][:, None] * d["w2"][prim]
        o, psi = rays.o[ray], rays.d[ray]
        sc = closest_shift(o, psi, x2)
        b = o + sc[:, None] * psi - x2  # P(u) = b + u psi, s = sc + u

        def perp(v):
            return v - dot(v, A)[:, None] * A

        bA, pA, qA, dA = dot(b, A), dot(psi, A), dot(q, A), dot(w1, A)
        bp, pp, qp, dp = perp(b), perp(psi), perp(q), perp(w1)
        # Equal heights fix one unknown linearly in the other; equal radii then give a
        # quadratic. Divide by the larger height rate (spec 3.3: better conditioned).
        by_s = np.abs(dA) >= np.abs(pA)
        with np.errstate(divide="ignore", invalid="ignore"):
            al, ga = (bA - qA) / dA, pA / dA  # t = al + ga u
            m, n = qp + al[:, None] * dp, ga[:, None] * dp
            r_u = quadratic_roots(dot(pp, pp) - dot(n, n), dot(bp, pp) - dot(m, n),
                                  dot(bp, bp) - dot(m, m))
            al2, ga2 = (qA - bA) / pA, dA / pA  # u = al2 + ga2 t
            m2, n2 = bp + al2[:, None] * pp, ga2[:, None] * pp
            r_t = quadratic_roots(dot(n2, n2) - dot(dp, dp), dot(m2, n2) - dot(qp, dp),
                                  dot(m2, m2) - dot(qp, qp))
            u = np.where(by_s, r_u, al2 + ga2 * r_t)
            t = np.where(by_s, al + ga * r_u, r_t)
        ray, prim, u, _ = expand(ray, prim, u)
        t, sc = t.reshape(-1), np.tile(sc, 2)
        s = sc + u
        with np.errstate(invalid="ignore"):
            ok = np.isfinite(s) & np.isfinite(t) & (t > 0) & on_ray(rays, ray, s)
        if self.short:
            ok &= t < d["T1"][prim]
        ray, prim, s, t = ray[ok], prim[ok], s[ok], t[ok]
        x2, A, w2, w1 = d["x2"][prim], d["A3"][prim], d["w2"][prim], d["w1"][prim]
        P = rays.o[ray] + s[:, None] * rays.d[ray] - x2
        rot, good = revolve(A, d["T2"][prim][:, None] * w2 + t[:, None] * w1, P)
        return self._hits(ray, prim, s, good, rays, x2, A, d["T2"][prim], rot, w2, w1, t)

    def _factor(self, hits, prims, ctx):
        """``(1/2pi) [E(t1*)]``: ``p(ph2)`` is not in ``q`` and ``E(T2)/p(T2) ss`` makes
        ``beta_1^-``."""
        f = np.full(len(hits), 1.0 / (2.0 * np.pi))
        return f if self.short else f * transmittance(ctx, hits.data["t1"])

    def density(self, rec, ctx):
        """Relative ``Q = q_{<=w2} 2pi p(t2) p(w1) |n . psi|`` (``p(c2) = 2pi p(w2)``: the
        azimuth ``ph2`` is integrated); short: ``* E(t1)``."""
        pdf = Pdfs(rec, ctx.scene)
        n = hyperboloid_normal(rec.w1, rec.A3, rec.x0 - rec.x2)
        q = q_to_w2(rec, pdf) * 2.0 * np.pi * pdf.t2 * pdf.w1 * np.abs(dot(n, rec.psi))
        if self.short:
            q = q * transmittance(ctx, rec.t1)
        return q


class Torus(_Revolution):
    """The (generalised) torus ``[cos th1, ph2]`` (long only)."""

    def __init__(self, short: bool = False):
        if short:
            raise ValueError("the torus has no short variant")
        self.short = False
        self.name = "torus"

    def _normal(self, w2, w1, t1, A3, d2):
        return torus_normal(w2, w1, t1, A3, d2)

    # ------------------------------------------------------------------ Create
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
        return Primitives(self.name, photon, K, lo, hi,
                          dict(x2=g["x2"], A3=g["A3"], w2=g["w2"], e_r=e_r[ok], T2=g["T2"],
                               T1=g["T1"]))

    # ------------------------------------------------------------------ Intersect
    def intersect(self, prims, rays, ray, prim, ctx) -> Hits:
        d = prims.data
        keep = _torus_candidates(rays, ray, d, prim)
        ray, prim = ray[keep], prim[keep]
        T2, T1 = d["T2"][prim], d["T1"][prim]
        x2, A, w2, e_r = d["x2"][prim], d["A3"][prim], d["w2"][prim], d["e_r"][prim]
        s_lo, s_hi = rays.s_min[ray], rays.s_max[ray]
        # s = s0 + sig u with u in (-1, 1) on the ray's interval (keeps the quartic scaled).
        s0, sig = 0.5 * (s_lo + s_hi), 0.5 * (s_hi - s_lo)
        psi = rays.d[ray]
        B = rays.o[ray] + s0[:, None] * psi - x2
        # |P|^2 = |L|^2 = T2^2 + T1^2 + 2 T1 T2 c1 gives c1(u); heights give g(u) = T1 s1 eA.
        bp = dot(B, psi)
        k2 = np.stack([sig * sig, 2.0 * sig * bp, dot(B, B) - T2 * T2 - T1 * T1])
        k2 = k2 / (2.0 * T1 * T2)
        wA, eA = dot(w2, A), dot(e_r, A)
        g = -T1 * wA * k2
        g[1] += sig * dot(psi, A)
        g[2] += dot(B, A) - T2 * wA
        e2 = (T1 * eA) ** 2
        coef = square_quadratic(g) + e2 * square_quadratic(k2)
        coef[4] -= e2
        u = quartic_real_roots(coef)
        ray, prim, u, _ = expand(ray, prim, u)
        s = np.tile(s0, 4) + np.tile(sig, 4) * u
        with np.errstate(invalid="ignore"):
            ok = np.isfinite(s) & on_ray(rays, ray, s)
        ray, prim, s = ray[ok], prim[ok], s[ok]
        x2, A, w2, e_r = d["x2"][prim], d["A3"][prim], d["w2"][prim], d["e_r"][prim]
        T2, T1 = d["T2"][prim], d["T1"][prim]
        P = rays.o[ray] + s[:, None] * rays.d[ray] - x2
        c1 = (dot(P, P) - T2 * T2 - T1 * T1) / (2.0 * T1 * T2)
        inside = np.abs(c1) < 1.0
        c1 = np.clip(c1, -1.0, 1.0)
        s1 = np.sqrt(1.0 - c1 * c1)
        w1 = c1[:, None] * w2 + s1[:, None] * e_r
        rot, good = revolve(A, T2[:, None] * w2 + T1[:, None] * w1, P)
        return self._hits(ray, prim, s, good & inside, rays, x2, A, T2, rot, w2, w1, T1)

    def _factor(self, hits, prims, ctx):
        """``rho(c1*) / st``: ``rho/p(ph1) = 2pi rho``, ``p(ph2)`` not in ``q``, ``E/p`` of
        ``T1`` gives ``1/st`` (``beta_1^-`` has that of ``T2``)."""
        med = ctx.scene.medium
        c1 = dot(hits.data["w1"], hits.data["w2"])
        return phase_value(c1, med.phase.g) / med.sigma_t

    def density(self, rec, ctx):
        """Relative ``Q = q_{<=w2} 2pi p(t2) (1/2pi) p(t1) |n . psi| = q_{<=w2} p(t2) p(t1)
        |n . psi|``."""
        pdf = Pdfs(rec, ctx.scene)
        n = torus_normal(rec.w2, rec.w1, rec.t1, rec.A3, rec.x0 - rec.x2)
        with np.errstate(invalid="ignore"):
            return q_to_w2(rec, pdf) * pdf.t2 * pdf.t1 * np.abs(dot(n, rec.psi))


def _torus_candidates(rays, ray, d, prim) -> np.ndarray:
    """(N,) bool: pairs whose ray interval can meet the torus (cheap cull before the quartic).

    The torus lies in the shell ``|T2 - T1| <= |p - x2| <= T2 + T1`` and, along ``A3``, within
    ``T2 wA +- T1 sqrt(wA^2 + eA^2)`` of ``x2`` (the whole meridian circle's height range).
    """
    x2, A = d["x2"][prim], d["A3"][prim]
    T2, T1 = d["T2"][prim], d["T1"][prim]
    o, psi = rays.o[ray] - x2, rays.d[ray]
    s_lo, s_hi = rays.s_min[ray], rays.s_max[ray]
    a, b = o + s_lo[:, None] * psi, o + s_hi[:, None] * psi
    sc = np.clip(-dot(o, psi), s_lo, s_hi)
    near = np.linalg.norm(o + sc[:, None] * psi, axis=1)
    far = np.maximum(np.linalg.norm(a, axis=1), np.linalg.norm(b, axis=1))
    wA, eA = dot(d["w2"][prim], A), dot(d["e_r"][prim], A)
    half = T1 * np.sqrt(wA * wA + eA * eA)
    ha, hb = dot(a, A), dot(b, A)
    return ((near <= T2 + T1) & (far >= np.abs(T2 - T1)) & (s_hi > s_lo)
            & (np.minimum(ha, hb) <= T2 * wA + half) & (np.maximum(ha, hb) >= T2 * wA - half))
