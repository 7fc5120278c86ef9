"""Photon planes ``[t1, t2]`` (Bitterli & Jarosz 17): 0D blur, unbiased (spec 3.1, first row).

For a K-event path the plane passes through ``x2`` (tracer vertex ``K-2``, the light when
K = 2) and is spanned by ``w2`` (segment ``K-1``) and ``w1`` (segment ``K``). The camera ray
hits it where ``x2 + t2 w2 + t1 w1 = c + s psi``; the Jacobian of that change of variables is
``|(w1 x w2) . psi|``.

* ``plane-t1t2`` (long): ``t1, t2 > 0``, contribution keeps ``exp(-st (t1 + t2))``;
* ``planes`` = ``plane-t1t2-short``: ``t2 < T2, t1 < T1`` (the photon's own flights, a
  parallelogram, as in Tungsten) and the transmittances are dropped (track-length).
"""

from __future__ import annotations

import numpy as np

from ..path_record import Pdfs, photon_record
from ..sampling import phase_value
from .base import (
    Hits,
    PassContext,
    Primitives,
    Technique,
    camera_transmittance,
    clear_from,
    clip_bounds,
    dot,
    on_own_segment,
    on_ray,
    ray_bounds,
    segments_clear,
    wedge_hull,
)


class PhotonPlane(Technique):
    """The photon plane ``[t1, t2]``; ``short`` selects the Tungsten (track-length) variant."""

    family = "planes"
    min_k = 2

    def __init__(self, short: bool):
        self.short = short
        self.name = "plane-t1t2-short" if short else "plane-t1t2"

    # ------------------------------------------------------------------ Create
    def create(self, paths, ctx: PassContext) -> Primitives:
        scene = ctx.scene
        lmask = self.light_mask(paths, scene)
        photon, kk = [], []
        for k in self.k_range(scene, paths.depth):
            ok = lmask & paths.alive[:, k - 1] & paths.prefix_ok[:, k - 2]
            idx = np.flatnonzero(ok)
            photon.append(idx)
            kk.append(np.full(idx.size, k))
        photon = np.concatenate(photon) if photon else np.zeros(0, np.int64)
        K = np.concatenate(kk) if kk else np.zeros(0, np.int64)
        x2 = paths.x[photon, K - 2]
        w2 = paths.w[photon, K - 2]
        w1 = paths.w[photon, K - 1]
        T2 = paths.t[photon, K - 2]
        T1 = paths.t[photon, K - 1]
        if self.short:
            c = [x2, x2 + T2[:, None] * w2, x2 + T1[:, None] * w1,
                 x2 + T2[:, None] * w2 + T1[:, None] * w1]
            lo, hi = np.minimum.reduce(c), np.maximum.reduce(c)
        else:
            lo2, hi2 = ray_bounds(x2, w2, None)
            lo1, hi1 = ray_bounds(x2, w1, None)
            lo, hi = np.minimum(lo2, lo1), np.maximum(hi2, hi1)
        lo, hi = clip_bounds(scene, lo, hi)
        hull = (wedge_hull(scene, x2, w2, w1, T2, T1) if self.short
                else wedge_hull(scene, x2, w2, w1))
        return Primitives(self.name, photon, K, lo, hi,
                          dict(x2=x2, w2=w2, w1=w1, T2=T2, T1=T1), hull=hull)

    # ------------------------------------------------------------------ Intersect
    def intersect(self, prims, rays, ray, prim, ctx) -> Hits:
        d = prims.data
        psi = rays.d[ray]
        # Cramer's rule for [w2 w1 -psi] (t2, t1, s) = c - x2 = b. With triple-product
        # identities every determinant is a dot product of psi with a per-primitive vector:
        #   det = (w1 x w2).psi, t2 det = (w1 x b).psi, t1 det = (b x w2).psi,
        #   s det = w2.(w1 x b).
        # For a pinhole camera b depends on the primitive only, so the pairs cost 3 dots.
        if rays.origin is not None:
            if "m" not in d:
                d.update(_plane_solver(d["x2"], d["w2"], d["w1"], rays.origin))
            m, sdet = d["m"][prim], d["sdet"][prim]
        else:
            sol = _plane_solver(d["x2"][prim], d["w2"][prim], d["w1"][prim], rays.o[ray])
            m, sdet = sol["m"], sol["sdet"]
        v = np.einsum("ijk,ik->ij", m, psi)  # (H, 3): det, t2 det, t1 det
        det = v[:, 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            t2 = v[:, 1] * inv
            t1 = v[:, 2] * inv
            s = sdet * inv
        ok = np.isfinite(inv) & (t2 > 0) & (t1 > 0) & on_ray(rays, ray, s)
        if self.short:
            ok &= (t2 < d["T2"][prim]) & (t1 < d["T1"][prim])
        keep = np.flatnonzero(ok)
        return Hits(ray[keep], prim[keep], s[keep],
                    dict(t2=t2[keep], t1=t1[keep], n_dot_psi=np.abs(det[keep])))

    # ------------------------------------------------------------------ Evaluate
    def evaluate(self, hits, prims, paths, rays, ctx) -> np.ndarray:
        scene = ctx.scene
        med = scene.medium
        p = hits.prim
        d = prims.data
        photon, K = prims.photon[p], prims.K[p]
        x2, w2, w1 = d["x2"][p], d["w2"][p], d["w1"][p]
        t2, t1 = hits.data["t2"], hits.data["t1"]
        x1 = x2 + t2[:, None] * w2
        x0 = rays.o[hits.ray] + hits.s[:, None] * rays.d[hits.ray]
        own = on_own_segment(scene, paths, photon, K - 1, t2, d["T2"][p], x2)
        valid = segments_clear(ctx.blockers, (x1, x0),
                               ok=clear_from(scene, ctx.blockers, x2, x1, own))
        rho0 = phase_value(-dot(w1, rays.d[hits.ray]), med.phase.g)
        # beta_2 E(t2) ss [rho/p(w1) = 1] E(t1) ss rho0 E(s) / |n . psi|. The weight is read
        # after x1 (beta leaving x1 = beta_2 ss/st / q_roulette(x1)): w1 was sampled only if
        # the photon survived roulette at x1, so that survival must be divided out.
        scal = med.sigma_t * med.sigma_s * rho0 * camera_transmittance(scene, rays, hits.ray,
                                                                      hits.s)
        if not self.short:
            scal = scal * np.exp(-med.sigma_t * (t1 + t2))
        with np.errstate(divide="ignore"):
            scal = np.where(valid, scal / hits.data["n_dot_psi"], 0.0)
        return paths.beta[photon, K - 1] * scal[:, None]

    # ------------------------------------------------------------------ Fused
    def fused_pass(self, prims, paths, rays, ctx):
        """Intersect + Evaluate in one compiled loop (:mod:`.planes_fused`)."""
        from .planes_fused import plane_chunks

        return plane_chunks(self, prims, paths, rays, ctx)

    # ------------------------------------------------------------------ Reconstruct
    def reconstruct(self, hits, prims, paths, rays, ctx):
        p = hits.prim
        rec = photon_record(paths, prims.photon[p], prims.K[p], ctx.scene, rays, hits.ray, hits.s)
        t2, t1 = hits.data["t2"], hits.data["t1"]
        return rec.with_(t2=t2, t1=t1, x1=rec.x2 + t2[:, None] * rec.w2)

    def density(self, rec, ctx):
        """``q_{<=w2} p(w1) |(w1 x w2) . psi|`` (short: ``* E(t1) E(t2)``)."""
        pdf = Pdfs(rec, ctx.scene)
        q = np.where(rec.K >= 3, pdf.t3, 1.0) * pdf.w2 * pdf.w1
        q = q * np.abs(dot(np.cross(rec.w1, rec.w2), rec.psi))
        if self.short:
            q = q * np.exp(-ctx.scene.medium.sigma_t * (rec.t1 + rec.t2))
        return q


def _plane_solver(x2, w2, w1, c):
    """Per-primitive vectors of the plane solve (see ``PhotonPlane.intersect``).

    Returns
    -------
    dict with ``m`` (M, 3, 3): rows ``w1 x w2``, ``w1 x b``, ``b x w2``; ``sdet`` (M,):
    ``w2 . (w1 x b)``, where ``b = c - x2``.
    """
    b = c - x2
    w1xb = np.cross(w1, b)
    m = np.stack([np.cross(w1, w2), w1xb, np.cross(b, w2)], axis=1)
    return {"m": m, "sdet": dot(w2, w1xb)}
