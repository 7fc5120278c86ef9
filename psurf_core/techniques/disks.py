"""Photon disk ``[t1, cos th1]`` (spec 3.1, disk row; K >= 2).

The photon keeps everything up to ``x1`` (tracer vertex ``K-1``) and the azimuth ``ph1`` of its
last direction, i.e. the radial unit ``e_r`` of ``w1`` about ``w2``; it integrates ``t1`` and
``cos th1``. ``x0 = x1 + t1 (c1 w2 + s1 e_r)`` sweeps the half-plane through ``x1`` spanned by
``w2`` and ``e_r`` (``(p - x1) . e_r > 0``); one line-plane root. The scaled normal is
``n = t1 (w1 x w2) / s1^2``, ``|n . psi| = t1 |e_ph . psi| / s1`` with ``e_ph = w2 x e_r``.

``X = beta_1^- [rho(c1*) / p(ph1) = 2pi rho(c1*)] E(t1*) ss rho0 E(s*) s1* / (t1* |e_ph.psi|)``;
short: ``t1* < T1`` and drop ``E(t1*)``.
"""

from __future__ import annotations

import numpy as np

from ..path_record import Pdfs, photon_record
from ..sampling import phase_value
from .base import Hits, Primitives, Technique, clip_bounds, dot, on_ray, segments_clear
from .surface_common import (
    NDP_MIN,
    SIN_MIN,
    beta1,
    camera_vertex,
    finish,
    gather,
    half_disk_bounds,
    q_to_w2,
    radial,
    select_photons,
    transmittance,
    unit,
)


def scaled_normal(w2: np.ndarray, w1: np.ndarray, t1: np.ndarray) -> np.ndarray:
    """(H, 3) ``dx0/dt1 x dx0/dcos th1 = t1 (w1 x w2) / s1^2`` (up to sign); infinite-free
    only for ``s1 > 0`` (callers guard)."""
    cr = np.cross(w1, w2)
    with np.errstate(divide="ignore", invalid="ignore"):
        return (t1 / dot(cr, cr))[:, None] * cr


class PhotonDisk(Technique):
    """The photon disk; ``short`` restricts ``t1* < T1`` (track-length)."""

    family = "disks"
    min_k = 2

    def __init__(self, short: bool):
        self.short = short
        self.name = "disk-short" if short else "disk"

    # ------------------------------------------------------------------ Create
    def create(self, paths, ctx) -> Primitives:
        photon, K = select_photons(self, paths, ctx, back=1)
        g = gather(paths, photon, K)
        c1, s1, e_r = radial(g["w1"], g["w2"])
        # th1 = 0 or pi (probability zero) leaves no azimuth, hence no half-plane.
        ok = s1 > SIN_MIN
        photon, K = photon[ok], K[ok]
        x1, w2, e_r, T1 = g["x1"][ok], g["w2"][ok], e_r[ok], g["T1"][ok]
        lo, hi = half_disk_bounds(x1, w2, e_r, T1 if self.short else None)
        lo, hi = clip_bounds(ctx.scene, lo, hi)
        return Primitives(self.name, photon, K, lo, hi,
                          dict(x1=x1, w2=w2, e_r=e_r, e_ph=np.cross(w2, e_r), T1=T1))

    # ------------------------------------------------------------------ Intersect
    def intersect(self, prims, rays, ray, prim, ctx) -> Hits:
        d = prims.data
        x1, e_ph = d["x1"][prim], d["e_ph"][prim]
        o, psi = rays.o[ray], rays.d[ray]
        den = dot(psi, e_ph)
        with np.errstate(divide="ignore", invalid="ignore"):
            s = dot(x1 - o, e_ph) / den
            ok = np.isfinite(s) & on_ray(rays, ray, s)
        ray, prim, s = ray[ok], prim[ok], s[ok]
        w1, t1 = unit(rays.o[ray] + s[:, None] * rays.d[ray] - d["x1"][prim])
        s1 = dot(w1, d["e_r"][prim])  # sin th1* >= 0 on the photon's half-plane
        ok = (t1 > 0) & (s1 > 0)
        if self.short:
            ok &= t1 < d["T1"][prim]
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            ndp = t1 * np.abs(dot(d["e_ph"][prim], rays.d[ray])) / s1
        keep = ok & (ndp > NDP_MIN) & np.isfinite(ndp)
        return Hits(ray[keep], prim[keep], s[keep],
                    dict(t1=t1[keep], w1=w1[keep], n_dot_psi=ndp[keep]))

    # ------------------------------------------------------------------ Evaluate
    def evaluate(self, hits, prims, paths, rays, ctx) -> np.ndarray:
        scene = ctx.scene
        p = hits.prim
        d = prims.data
        w1 = hits.data["w1"]
        x0 = rays.o[hits.ray] + hits.s[:, None] * rays.d[hits.ray]
        valid = segments_clear(ctx.blockers, (d["x1"][p], x0))
        # beta_1^- 2pi rho(c1*) [E(t1*)] ss rho0 E(s) / |n . psi|
        rho1 = phase_value(dot(d["w2"][p], w1), scene.medium.phase.g)
        scal = 2.0 * np.pi * rho1 * camera_vertex(scene, rays, hits, w1)
        if not self.short:
            scal = scal * transmittance(ctx, hits.data["t1"])
        return finish(beta1(paths, prims.photon[p], prims.K[p]), scal, valid,
                      hits.data["n_dot_psi"])

    # ------------------------------------------------------------------ Reconstruct
    def reconstruct(self, hits, prims, paths, rays, ctx):
        p = hits.prim
        rec = photon_record(paths, prims.photon[p], prims.K[p], ctx.scene, rays, hits.ray, hits.s)
        return rec.with_(t1=hits.data["t1"], w1=hits.data["w1"])

    def density(self, rec, ctx):
        """Relative ``Q = q_{<=w2} p(t2) (1/2pi) t1 |(w1 x w2) . psi| / s1^2`` (short:
        ``* E(t1)``)."""
        pdf = Pdfs(rec, ctx.scene)
        n = scaled_normal(rec.w2, rec.w1, rec.t1)
        with np.errstate(invalid="ignore"):
            q = q_to_w2(rec, pdf) * pdf.t2 * pdf.ph * np.abs(dot(n, rec.psi))
        if self.short:
            q = q * transmittance(ctx, rec.t1)
        return q
