"""Photon sphere ``[cos th1, ph1]`` (spec 3.1, sphere row; K >= 2).

The photon keeps everything up to ``x1`` (tracer vertex ``K-1``) and its last flight ``T1``,
and integrates the direction ``w1``: ``x0 = x1 + T1 w1`` sweeps the sphere of radius ``T1``
about ``x1``. The camera ray meets it in up to two points; each gives ``w1* = (y(s*) - x1)/T1``
and the scaled normal ``n = T1^2 w1*`` (``|dw/dcos x dw/dph| = 1``).

``X = beta_1^- rho(w2 . w1*) ss rho0 E(s*) / (st T1^2 |w1* . psi|)``. The sphere has no short
variant: its only distance is sampled, so there is no transmittance to trade.
"""

from __future__ import annotations

import numpy as np

from ..path_record import Pdfs, photon_record
from ..sampling import phase_value
from .base import Hits, Primitives, Technique, clip_bounds, dot, on_ray, segments_clear
from .surface_common import (
    NDP_MIN,
    beta1,
    camera_vertex,
    closest_shift,
    expand,
    finish,
    gather,
    q_to_w2,
    quadratic_roots,
    select_photons,
    unit,
)


def scaled_normal(w1: np.ndarray, t1: np.ndarray) -> np.ndarray:
    """(H, 3) ``dx0/dcos th1 x dx0/dph1 = t1^2 w1`` (up to sign)."""
    return (t1**2)[:, None] * w1


class PhotonSphere(Technique):
    """The photon sphere (long only)."""

    family = "spheres"
    min_k = 2

    def __init__(self, short: bool = False):
        if short:
            raise ValueError("the photon sphere has no short variant")
        self.short = False
        self.name = "sphere"

    # ------------------------------------------------------------------ Create
    def create(self, paths, ctx) -> Primitives:
        photon, K = select_photons(self, paths, ctx, back=1)
        g = gather(paths, photon, K)
        x1, T1 = g["x1"], g["T1"]
        lo, hi = clip_bounds(ctx.scene, x1 - T1[:, None], x1 + T1[:, None])
        return Primitives(self.name, photon, K, lo, hi, dict(x1=x1, w2=g["w2"], T1=T1))

    # ------------------------------------------------------------------ Intersect
    def intersect(self, prims, rays, ray, prim, ctx) -> Hits:
        d = prims.data
        x1, T1 = d["x1"][prim], d["T1"][prim]
        o, psi = rays.o[ray], rays.d[ray]
        # Solve in u = s - s_c about the ray point closest to the centre (no cancellation).
        sc = closest_shift(o, psi, x1)
        b = o + sc[:, None] * psi - x1
        roots = quadratic_roots(np.ones_like(sc), dot(b, psi), dot(b, b) - T1 * T1) + sc
        ray, prim, s, _ = expand(ray, prim, roots)
        with np.errstate(invalid="ignore"):
            ok = np.isfinite(s) & on_ray(rays, ray, s)
        ray, prim, s = ray[ok], prim[ok], s[ok]
        w1, _ = unit(rays.o[ray] + s[:, None] * rays.d[ray] - d["x1"][prim])
        ndp = d["T1"][prim] ** 2 * np.abs(dot(w1, rays.d[ray]))
        keep = ndp > NDP_MIN
        return Hits(ray[keep], prim[keep], s[keep], dict(w1=w1[keep], n_dot_psi=ndp[keep]))

    # ------------------------------------------------------------------ Evaluate
    def evaluate(self, hits, prims, paths, rays, ctx) -> np.ndarray:
        scene = ctx.scene
        med = scene.medium
        p = hits.prim
        d = prims.data
        w1 = hits.data["w1"]
        x0 = rays.o[hits.ray] + hits.s[:, None] * rays.d[hits.ray]
        valid = segments_clear(ctx.blockers, (d["x1"][p], x0))
        # beta_1^- [rho(w2.w1*) E(T1) / p(T1) = rho / st] ss rho0 E(s) / (T1^2 |w1*.psi|)
        scal = (phase_value(dot(d["w2"][p], w1), med.phase.g) / med.sigma_t
                * camera_vertex(scene, rays, hits, w1))
        return finish(beta1(paths, prims.photon[p], prims.K[p]), scal, valid,
                      hits.data["n_dot_psi"])

    # ------------------------------------------------------------------ Reconstruct
    def reconstruct(self, hits, prims, paths, rays, ctx):
        p = hits.prim
        rec = photon_record(paths, prims.photon[p], prims.K[p], ctx.scene, rays, hits.ray, hits.s)
        return rec.with_(w1=hits.data["w1"])

    def density(self, rec, ctx):
        """Relative ``Q = q_{<=w2} p(t2) p(t1) t1^2 |w1 . psi|``."""
        pdf = Pdfs(rec, ctx.scene)
        n = scaled_normal(rec.w1, rec.t1)
        return q_to_w2(rec, pdf) * pdf.t2 * pdf.t1 * np.abs(dot(n, rec.psi))
