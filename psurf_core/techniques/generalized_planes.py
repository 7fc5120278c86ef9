"""Generalized photon planes ``[t1, t3]`` and ``[t2, t3]`` (spec 3.1, rows 2 and 3; K >= 3).

Both integrate the distance ``t3`` into ``x2`` and one later distance, keeping the directions
``w3, w2, w1`` the photon sampled (x3 = tracer vertex ``K-3`` is kept):

* ``[t1, t3]``: ``x0 = x3 + t3 w3 + T2 w2 + t1 w1`` -- the plane through ``x3 + T2 w2``
  spanned by ``w3, w1``; scaled normal ``w1 x w3``; rebuilt ``x2* = x3 + t3* w3``,
  ``x1* = x2* + T2 w2``.
* ``[t2, t3]``: ``x0 = x3 + t3 w3 + t2 w2 + T1 w1`` -- the plane through ``x3 + T1 w1``
  spanned by ``w3, w2``; scaled normal ``w2 x w3``; rebuilt ``x2* = x3 + t3* w3``,
  ``x1* = x2* + t2* w2``.

Per photon ``X = beta_1^- st E(integrated) ss rho0 E(s) / |n . psi|``: the spec's
``beta_3 (ss/st) ss`` (``[t1,t3]``) and ``beta_3 ss^2/st`` (``[t2,t3]``) both equal
``st beta_3 (ss/st)^2 = st beta_1^-`` (see ``surface_common``). Long keeps
``E(t_a* + t3*)``; short requires ``t* < T`` for both and drops it.
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
    in_medium,
    on_own_segment,
    on_ray,
    ray_bounds,
    segments_clear,
    wedge_hull,
)
from .surface_common import (
    NDP_MIN,
    beta1,
    camera_vertex,
    finish,
    gather,
    plane_solve,
    select_photons,
    transmittance,
)


def scaled_normal(which: str, w3: np.ndarray, w2: np.ndarray, w1: np.ndarray) -> np.ndarray:
    """(H, 3) ``dx0/dxi1 x dx0/dxi2`` up to sign: ``w1 x w3`` (t1t3) or ``w2 x w3`` (t2t3)."""
    return np.cross(w1 if which == "t1t3" else w2, w3)


class GeneralizedPlane(Technique):
    """Generalized plane ``[t1, t3]`` (``which="t1t3"``) or ``[t2, t3]`` (``"t2t3"``)."""

    family = "planes"
    min_k = 3

    def __init__(self, short: bool, which: str):
        if which not in ("t1t3", "t2t3"):
            raise ValueError(f"unknown generalized plane '{which}'")
        self.short = short
        self.which = which
        self.name = f"plane-{which}" + ("-short" if short else "")

    # ------------------------------------------------------------------ Create
    def create(self, paths, ctx) -> Primitives:
        photon, K = select_photons(self, paths, ctx, back=3)
        g = gather(paths, photon, K)
        # The fixed sampled segment (T2 w2 or T1 w1) offsets the plane's origin from x3;
        # the other integrated direction is the kept w1 (t1t3) or w2 (t2t3).
        if self.which == "t1t3":
            origin, v, Tv = g["x3"] + g["T2"][:, None] * g["w2"], g["w1"], g["T1"]
        else:
            origin, v, Tv = g["x3"] + g["T1"][:, None] * g["w1"], g["w2"], g["T2"]
        u, Tu = g["w3"], g["T3"]
        if self.short:
            c = [origin, origin + Tu[:, None] * u, origin + Tv[:, None] * v,
                 origin + Tu[:, None] * u + Tv[:, None] * v]
            lo, hi = np.minimum.reduce(c), np.maximum.reduce(c)
        else:
            lo3, hi3 = ray_bounds(origin, u, None)
            lov, hiv = ray_bounds(origin, v, None)
            lo, hi = np.minimum(lo3, lov), np.maximum(hi3, hiv)
        lo, hi = clip_bounds(ctx.scene, lo, hi)
        hull = (wedge_hull(ctx.scene, origin, u, v, Tu, Tv) if self.short
                else wedge_hull(ctx.scene, origin, u, v))
        return Primitives(self.name, photon, K, lo, hi,
                          dict(origin=origin, x3=g["x3"], w3=u, v=v, w2=g["w2"], w1=g["w1"],
                               Tu=Tu, Tv=Tv, T2=g["T2"]), hull=hull)

    # ------------------------------------------------------------------ Intersect
    def intersect(self, prims, rays, ray, prim, ctx) -> Hits:
        d = prims.data
        t3, tv, s, ndp = plane_solve(d["origin"][prim], d["w3"][prim], d["v"][prim],
                                     rays.o[ray], rays.d[ray])
        with np.errstate(invalid="ignore"):
            ok = (ndp > NDP_MIN) & (t3 > 0) & (tv > 0) & on_ray(rays, ray, s)
            if self.short:
                ok &= (t3 < d["Tu"][prim]) & (tv < d["Tv"][prim])
        keep = np.flatnonzero(ok)
        return Hits(ray[keep], prim[keep], s[keep],
                    dict(t3=t3[keep], tv=tv[keep], n_dot_psi=ndp[keep]))

    # ------------------------------------------------------------------ Evaluate
    def _vertices(self, hits, prims):
        """Rebuilt ``x2*, x1*`` (H, 3) of each hit."""
        d, p = prims.data, hits.prim
        x2 = d["x3"][p] + hits.data["t3"][:, None] * d["w3"][p]
        step = d["T2"][p] if self.which == "t1t3" else hits.data["tv"]
        return x2, x2 + step[:, None] * d["w2"][p]

    def evaluate(self, hits, prims, paths, rays, ctx) -> np.ndarray:
        scene = ctx.scene
        p = hits.prim
        d = prims.data
        x2, x1 = self._vertices(hits, prims)
        x0 = rays.o[hits.ray] + hits.s[:, None] * rays.d[hits.ray]
        photon, K = prims.photon[p], prims.K[p]
        own = on_own_segment(scene, paths, photon, K - 2, hits.data["t3"], d["Tu"][p],
                             d["x3"][p])
        ok = clear_from(scene, ctx.blockers, d["x3"][p], x2, own)
        ok &= in_medium(scene, x1)
        valid = segments_clear(ctx.blockers, (x2, x1), (x1, x0), ok=ok)
        # beta_1^- st [E(t3*) E(t_a*)] ss rho0 E(s) / |n . psi|
        scal = scene.medium.sigma_t * camera_vertex(scene, rays, hits, d["w1"][p])
        if not self.short:
            scal = scal * transmittance(ctx, hits.data["t3"], hits.data["tv"])
        return finish(beta1(paths, prims.photon[p], prims.K[p]), scal, valid,
                      hits.data["n_dot_psi"])

    # ------------------------------------------------------------------ Fused
    def fused_pass(self, prims, paths, rays, ctx):
        """Intersect + Evaluate in one compiled loop (:mod:`.surfaces_fused`)."""
        from .surfaces_fused import surface_chunks

        return surface_chunks(self, self.which, prims, paths, rays, ctx)

    # ------------------------------------------------------------------ Reconstruct
    def reconstruct(self, hits, prims, paths, rays, ctx):
        p = hits.prim
        rec = photon_record(paths, prims.photon[p], prims.K[p], ctx.scene, rays, hits.ray, hits.s)
        x2, x1 = self._vertices(hits, prims)
        tv = "t1" if self.which == "t1t3" else "t2"
        return rec.with_(t3=hits.data["t3"], x2=x2, x1=x1, **{tv: hits.data["tv"]})

    def density(self, rec, ctx):
        """Relative ``Q`` (``q_{<=w3}`` dropped): ``p(t2) p(w2) p(w1) |(w1 x w3).psi|``
        (t1t3) or ``p(w2) p(w1) p(t1) |(w2 x w3).psi|`` (t2t3); short: ``* E(t_a + t3)``."""
        pdf = Pdfs(rec, ctx.scene)
        n = scaled_normal(self.which, rec.w3, rec.w2, rec.w1)
        other = pdf.t2 if self.which == "t1t3" else pdf.t1
        q = other * pdf.w2 * pdf.w1 * np.abs(dot(n, rec.psi))
        if self.short:
            ta = rec.t1 if self.which == "t1t3" else rec.t2
            q = q * transmittance(ctx, ta, rec.t3)
        return q
