"""Photon cylinder ``[t2, ph1]`` (spec 3.1, cylinder row; K >= 2).

The photon keeps everything up to ``x2`` (tracer vertex ``K-2``), the polar cosine ``c1`` and
its last flight ``T1``; it integrates the distance ``t2`` into ``x1`` and the azimuth ``ph1``.
``x0 = x2 + t2 w2 + T1 (c1 w2 + s1 e_r(ph1))`` sweeps the circular cylinder of radius
``T1 s1`` about the axis ``x2 + h w2``, valid where ``t2* = h - T1 c1 > 0``. At a hit,
``x1* = x2 + t2* w2`` and ``w1* = c1 w2 + s1 e_r*``; the scaled normal is
``n = T1 (c1 w2 - w1*) = -T1 s1 e_r*``.

``X = beta_2 E(t2*) ss [rho(c1)/p(c1) = 1/2pi] [E(T1)/p(T1) = 1/st] ss rho0 E(s*) / |n.psi|
= beta_1^- (1/2pi) E(t2*) ss rho0 E(s*) / |n . psi|``. Short: ``t2* < T2``, drop ``E(t2*)``.
Because ``x1`` is rebuilt, photons whose own ``x1`` left the box still count (spec 4).
"""

from __future__ import annotations

import numpy as np

from ..path_record import Pdfs, photon_record
from .base import (
    Hits,
    Primitives,
    Technique,
    clear_from,
    clip_bounds,
    dot,
    on_own_segment,
    on_ray,
    segments_clear,
)
from .surface_common import (
    NDP_MIN,
    beta1,
    camera_vertex,
    circle_extent,
    closest_shift,
    expand,
    finish,
    gather,
    q_to_w2,
    quadratic_roots,
    radial,
    select_photons,
    sweep_bounds,
    transmittance,
    unit,
)


def scaled_normal(w2: np.ndarray, w1: np.ndarray, t1: np.ndarray) -> np.ndarray:
    """(H, 3) ``dx0/dt2 x dx0/dph1 = t1 (c1 w2 - w1)`` (up to sign), ``c1 = w1 . w2``."""
    return t1[:, None] * (dot(w1, w2)[:, None] * w2 - w1)


class PhotonCylinder(Technique):
    """The photon cylinder; ``short`` restricts ``t2* < T2`` (track-length)."""

    family = "cylinders"
    min_k = 2

    def __init__(self, short: bool):
        self.short = short
        self.name = "cylinder-short" if short else "cylinder"

    # ------------------------------------------------------------------ Create
    def create(self, paths, ctx) -> Primitives:
        photon, K = select_photons(self, paths, ctx, back=2)
        g = gather(paths, photon, K)
        x2, w2, T1 = g["x2"], g["w2"], g["T1"]
        c1, s1, _ = radial(g["w1"], w2)
        # The t2 = 0 circle, swept along w2 for T2 (short) or forever (long).
        centre = x2 + (T1 * c1)[:, None] * w2
        ext = circle_extent(w2, T1 * s1)
        lo, hi = sweep_bounds(centre - ext, centre + ext, w2, g["T2"] if self.short else None)
        lo, hi = clip_bounds(ctx.scene, lo, hi)
        return Primitives(self.name, photon, K, lo, hi,
                          dict(x2=x2, w2=w2, c1=c1, s1=s1, T1=T1, T2=g["T2"]))

    # ------------------------------------------------------------------ Intersect
    def intersect(self, prims, rays, ray, prim, ctx) -> Hits:
        d = prims.data
        x2, w2 = d["x2"][prim], d["w2"][prim]
        r = d["T1"][prim] * d["s1"][prim]
        o, psi = rays.o[ray], rays.d[ray]
        sc = closest_shift(o, psi, x2)
        b = o + sc[:, None] * psi - x2
        bp = b - dot(b, w2)[:, None] * w2
        pp = psi - dot(psi, w2)[:, None] * w2
        roots = quadratic_roots(dot(pp, pp), dot(bp, pp), dot(bp, bp) - r * r) + sc
        ray, prim, s, _ = expand(ray, prim, roots)
        with np.errstate(invalid="ignore"):
            ok = np.isfinite(s) & on_ray(rays, ray, s)
        ray, prim, s = ray[ok], prim[ok], s[ok]
        w2, c1, s1, T1 = d["w2"][prim], d["c1"][prim], d["s1"][prim], d["T1"][prim]
        v = rays.o[ray] + s[:, None] * rays.d[ray] - d["x2"][prim]
        h = dot(v, w2)
        e_r, _ = unit(v - h[:, None] * w2)
        t2 = h - T1 * c1
        ok = t2 > 0
        if self.short:
            ok &= t2 < d["T2"][prim]
        w1 = c1[:, None] * w2 + s1[:, None] * e_r
        ndp = T1 * s1 * np.abs(dot(e_r, rays.d[ray]))
        keep = ok & (ndp > NDP_MIN)
        return Hits(ray[keep], prim[keep], s[keep],
                    dict(t2=t2[keep], w1=w1[keep], n_dot_psi=ndp[keep]))

    # ------------------------------------------------------------------ Evaluate
    def evaluate(self, hits, prims, paths, rays, ctx) -> np.ndarray:
        scene = ctx.scene
        p = hits.prim
        d = prims.data
        x2 = d["x2"][p]
        x1 = x2 + hits.data["t2"][:, None] * d["w2"][p]
        x0 = rays.o[hits.ray] + hits.s[:, None] * rays.d[hits.ray]
        own = on_own_segment(scene, paths, prims.photon[p], prims.K[p] - 1, hits.data["t2"],
                             d["T2"][p], x2)
        valid = segments_clear(ctx.blockers, (x1, x0),
                               ok=clear_from(scene, ctx.blockers, x2, x1, own))
        # beta_1^- (1/2pi) [E(t2*)] ss rho0 E(s) / |n . psi|
        scal = camera_vertex(scene, rays, hits, hits.data["w1"]) / (2.0 * np.pi)
        if not self.short:
            scal = scal * transmittance(ctx, hits.data["t2"])
        return finish(beta1(paths, prims.photon[p], prims.K[p]), scal, valid,
                      hits.data["n_dot_psi"])

    # ------------------------------------------------------------------ Fused
    def fused_pass(self, prims, paths, rays, ctx):
        """Intersect + Evaluate in one compiled loop (:mod:`.surfaces_fused`)."""
        from .surfaces_fused import surface_chunks

        return surface_chunks(self, "cylinder", prims, paths, rays, ctx)

    # ------------------------------------------------------------------ Reconstruct
    def reconstruct(self, hits, prims, paths, rays, ctx):
        p = hits.prim
        rec = photon_record(paths, prims.photon[p], prims.K[p], ctx.scene, rays, hits.ray, hits.s)
        t2 = hits.data["t2"]
        return rec.with_(t2=t2, x1=rec.x2 + t2[:, None] * rec.w2, w1=hits.data["w1"])

    def density(self, rec, ctx):
        """Relative ``Q = q_{<=w2} 2pi rho(c1) p(t1) t1 s1 |e_r . psi|`` (short: ``* E(t2)``)."""
        pdf = Pdfs(rec, ctx.scene)
        n = scaled_normal(rec.w2, rec.w1, rec.t1)
        q = q_to_w2(rec, pdf) * pdf.c1 * pdf.t1 * np.abs(dot(n, rec.psi))
        if self.short:
            q = q * transmittance(ctx, rec.t2)
        return q
