"""Photon cone ``[t1, ph1]`` (spec 3.1, cone row; K >= 2).

The photon keeps everything up to ``x1`` (tracer vertex ``K-1``) and the polar cosine
``c1 = w1 . w2`` of its last direction; the azimuth ``ph1`` and the distance ``t1`` are
integrated. ``x0 = x1 + t1 w1(ph1)`` sweeps one nappe of the cone with apex ``x1``, axis
``w2`` and half-angle ``th1``: ``((p - x1) . w2)^2 = c1^2 |p - x1|^2`` with
``sign((p - x1) . w2) = sign(c1)``, at most two roots on a ray. ``w1*`` is rebuilt from the
hit, and the scaled normal is ``n = t1 (w2 - c1 w1*)`` (``|n| = t1 s1``).

``X = beta_1^- [rho(c1) / p(c1) = 1/2pi] E(t1*) ss rho0 E(s*) / |n . psi|``; the short cone
needs ``t1* < T1`` and drops ``E(t1*)`` (track length).
"""

from __future__ import annotations

import numpy as np

from ..path_record import Pdfs, photon_record
from .base import Hits, Primitives, Technique, clip_bounds, dot, on_ray, segments_clear
from .surface_common import (
    NDP_MIN,
    beta1,
    camera_vertex,
    closest_shift,
    cone_bounds,
    expand,
    finish,
    gather,
    q_to_w2,
    quadratic_roots,
    radial,
    select_photons,
    transmittance,
    unit,
)


def scaled_normal(w2: np.ndarray, w1: np.ndarray, t1: np.ndarray) -> np.ndarray:
    """(H, 3) ``dx0/dt1 x dx0/dph1 = t1 (w2 - c1 w1)`` (up to sign), ``c1 = w1 . w2``."""
    return t1[:, None] * (w2 - dot(w1, w2)[:, None] * w1)


class PhotonCone(Technique):
    """The photon cone; ``short`` restricts ``t1* < T1`` (track-length)."""

    family = "cones"
    min_k = 2

    def __init__(self, short: bool):
        self.short = short
        self.name = "cone-short" if short else "cone"

    # ------------------------------------------------------------------ Create
    def create(self, paths, ctx) -> Primitives:
        photon, K = select_photons(self, paths, ctx, back=1)
        g = gather(paths, photon, K)
        c1, s1, _ = radial(g["w1"], g["w2"])
        lo, hi = cone_bounds(g["x1"], g["w2"], c1, s1, g["T1"] if self.short else None)
        lo, hi = clip_bounds(ctx.scene, lo, hi)
        return Primitives(self.name, photon, K, lo, hi,
                          dict(x1=g["x1"], w2=g["w2"], c1=c1, T1=g["T1"]))

    # ------------------------------------------------------------------ Intersect
    def intersect(self, prims, rays, ray, prim, ctx) -> Hits:
        d = prims.data
        x1, w2, c1 = d["x1"][prim], d["w2"][prim], d["c1"][prim]
        o, psi = rays.o[ray], rays.d[ray]
        sc = closest_shift(o, psi, x1)
        b = o + sc[:, None] * psi - x1
        bw, pw, cc = dot(b, w2), dot(psi, w2), c1 * c1
        roots = quadratic_roots(pw * pw - cc, bw * pw - cc * dot(b, psi),
                                bw * bw - cc * dot(b, b)) + sc
        ray, prim, s, _ = expand(ray, prim, roots)
        with np.errstate(invalid="ignore"):
            ok = np.isfinite(s) & on_ray(rays, ray, s)
        ray, prim, s = ray[ok], prim[ok], s[ok]
        w1, t1 = unit(rays.o[ray] + s[:, None] * rays.d[ray] - d["x1"][prim])
        w2, c1 = d["w2"][prim], d["c1"][prim]
        # The squared equation also holds on the mirror nappe: keep the photon's side.
        ok = (t1 > 0) & (dot(w1, w2) * c1 > 0)
        if self.short:
            ok &= t1 < d["T1"][prim]
        ndp = np.abs(dot(scaled_normal(w2, w1, t1), rays.d[ray]))
        keep = ok & (ndp > NDP_MIN)
        return Hits(ray[keep], prim[keep], s[keep],
                    dict(t1=t1[keep], w1=w1[keep], n_dot_psi=ndp[keep]))

    # ------------------------------------------------------------------ Evaluate
    def evaluate(self, hits, prims, paths, rays, ctx) -> np.ndarray:
        scene = ctx.scene
        p = hits.prim
        d = prims.data
        x0 = rays.o[hits.ray] + hits.s[:, None] * rays.d[hits.ray]
        valid = segments_clear(ctx.blockers, (d["x1"][p], x0))
        # beta_1^- (1/2pi) [E(t1*)] ss rho0 E(s) / |n . psi|
        scal = camera_vertex(scene, rays, hits, hits.data["w1"]) / (2.0 * np.pi)
        if not self.short:
            scal = scal * transmittance(ctx, hits.data["t1"])
        return finish(beta1(paths, prims.photon[p], prims.K[p]), scal, valid,
                      hits.data["n_dot_psi"])

    # ------------------------------------------------------------------ Fused
    def fused_pass(self, prims, paths, rays, ctx):
        """Intersect + Evaluate in one compiled loop (:mod:`.surfaces_fused`)."""
        from .surfaces_fused import surface_chunks

        return surface_chunks(self, "cone", prims, paths, rays, ctx)

    # ------------------------------------------------------------------ Reconstruct
    def reconstruct(self, hits, prims, paths, rays, ctx):
        p = hits.prim
        rec = photon_record(paths, prims.photon[p], prims.K[p], ctx.scene, rays, hits.ray, hits.s)
        return rec.with_(t1=hits.data["t1"], w1=hits.data["w1"])

    def density(self, rec, ctx):
        """Relative ``Q = q_{<=w2} p(t2) 2pi rho(c1) t1 |(w2 - c1 w1) . psi|`` (short:
        ``* E(t1)``)."""
        pdf = Pdfs(rec, ctx.scene)
        n = scaled_normal(rec.w2, rec.w1, rec.t1)
        q = q_to_w2(rec, pdf) * pdf.t2 * pdf.c1 * np.abs(dot(n, rec.psi))
        if self.short:
            q = q * transmittance(ctx, rec.t1)
        return q
