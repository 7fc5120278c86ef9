"""Photon beams x camera rays with a 1D kernel (Jarosz et al. 11; spec 3.4 and section 4).

A beam is the photon's segment ``j >= 1`` (tracer numbering): it starts at vertex ``j-1``
(the light for ``j = 1``) with direction ``w_j`` and weight ``beta_j = paths.beta[:, j-1]``,
and estimates paths with ``K = j`` events. It is valid when the segment was sampled and the
start vertex's prefix is valid (``alive[:, j-1] & prefix_ok[:, j-1]``).

A hit is the pair of closest points ``x(t*)`` on the beam line and ``y(s*)`` on the camera
ray, with line-line distance ``d < r``, ``y(s*)`` on the ray's valid interval and ``x(t*)``
inside the box (the blur between them is not visibility-tested: part of the bias):

* ``beams`` (short, as in Tungsten): ``0 < t* < T_j``, ``X = beta ss rho E(s*) K1/|w x psi|``;
* ``beams-long``: ``t* > 0``, ``X = beta ss rho E(t*) E(s*) K1/|w x psi|``;

with ``K1 = 1/(2r)``, ``rho = rho(-w . psi)`` and ``E(s*)`` the camera transmittance inside
the box. Near-parallel pairs (``|w x psi| < 1e-12``) are skipped.

**Beam visibility rule.** The beam part from vertex ``j-1`` to ``x(t*)`` must be unoccluded
(both end points lie in the convex box, so it is in the medium).

* Long beams: one shadow test ``x_{j-1} -> x(t*)`` per hit.
* Short beams: when the photon's sampled segment ``j`` is known clear
  (``prefix_ok[:, j]``: ``x_j`` in the box, segment unoccluded) the part ``t* < T_j`` is
  clear too and no test is made; otherwise (the sampled segment leaves the box or meets a
  blocker beyond ``t*``, or before it) the same shadow test ``x_{j-1} -> x(t*)`` decides.
"""

from __future__ import annotations

import numpy as np

from ..sampling import phase_value
from . import grids
from .base import (
    Hits,
    PassContext,
    Primitives,
    Technique,
    camera_transmittance,
    clip_bounds,
    dot,
    in_medium,
    on_ray,
    segments_clear,
)
from .bounds import ray_bounds
from .points import kernel_radius

#: ``|w x psi|`` below this is treated as parallel (no hit).
PARALLEL_SIN = 1e-12


class PhotonBeams(Technique):
    """Photon beams with a 1D kernel; ``short`` limits each beam to its sampled flight."""

    family = "beams"
    names = ("beams-long", "beams")
    surface = False  # a kernel blurs photon beams: no swept surface, no scaled normal
    kernel_dim = 1
    min_k = 1
    default_radius_fraction = 0.01

    # ------------------------------------------------------------------ Create
    def create(self, paths, ctx: PassContext) -> Primitives:
        """One beam per valid segment ``j = K`` in :meth:`k_range`.

        Returns
        -------
        Primitives
            ``data``: ``o`` (M, 3) start vertex, ``w`` (M, 3) direction, ``T`` (M,) sampled
            length, ``seg_ok`` (M,) bool whether the sampled segment is known clear. Bounds:
            the segment (short) or ray (long) padded by the radius, clipped to the box.
        """
        scene = ctx.scene
        lmask = self.light_mask(paths, scene)
        photon, kk = [], []
        for k in self.k_range(scene, paths.depth):
            idx = np.flatnonzero(lmask & paths.alive[:, k - 1] & paths.prefix_ok[:, k - 1])
            photon.append(idx)
            kk.append(np.full(idx.size, k))
        photon = np.concatenate(photon) if photon else np.zeros(0, np.int64)
        K = np.concatenate(kk) if kk else np.zeros(0, np.int64)
        o = paths.x[photon, K - 1]
        w = paths.w[photon, K - 1]
        T = paths.t[photon, K - 1]
        seg_ok = paths.prefix_ok[photon, K]
        lo, hi = ray_bounds(o, w, T if self.short else None)
        r = kernel_radius(self, ctx)
        lo, hi = clip_bounds(scene, lo - r, hi + r)
        return Primitives(self.name, photon, K, lo, hi, dict(o=o, w=w, T=T, seg_ok=seg_ok))

    # ------------------------------------------------------------------ Intersect
    def intersect(self, prims, rays, ray, prim, ctx) -> Hits:
        """Closest points of beam lines and camera rays within the kernel radius.

        Returns
        -------
        Hits
            ``s`` is ``s*``; ``data``: ``t`` (H,) ``t*``, ``sin`` (H,) ``|w x psi|``.
        """
        r = kernel_radius(self, ctx)
        o, w = prims.data["o"][prim], prims.data["w"][prim]
        psi = rays.d[ray]
        b = rays.o[ray] - o
        n = np.cross(w, psi)
        sin2 = dot(n, n)
        sin = np.sqrt(sin2)
        par = sin < PARALLEL_SIN
        inv2 = 1.0 / np.where(par, 1.0, sin2)
        # o + t w - (c + s psi) is parallel to n: cross with psi (or w) and dot with n.
        # (Better conditioned for near-parallel lines than the normal equations.)
        t = dot(np.cross(b, psi), n) * inv2
        s = dot(np.cross(b, w), n) * inv2
        dist = np.abs(dot(b, n)) * np.sqrt(inv2)
        ok = ~par & (dist < r) & (t > 0) & on_ray(rays, ray, s)
        if self.short:
            ok &= t < prims.data["T"][prim]
        keep = np.flatnonzero(ok)
        keep = keep[in_medium(ctx.scene, o[keep] + t[keep, None] * w[keep])]
        return Hits(ray[keep], prim[keep], s[keep], dict(t=t[keep], sin=sin[keep]))

    # ------------------------------------------------------------------ Evaluate
    def evaluate(self, hits, prims, paths, rays, ctx) -> np.ndarray:
        """(H, 3) per-photon contribution ``beta ss rho [E(t*)] E(s*) K1 / |w x psi|``."""
        scene = ctx.scene
        med = scene.medium
        p = hits.prim
        o, w = prims.data["o"][p], prims.data["w"][p]
        t = hits.data["t"]
        # Shadow test of the beam part x_{j-1} -> x(t*) (see the module docstring).
        test = np.ones(len(hits), dtype=bool) if not self.short else ~prims.data["seg_ok"][p]
        valid = np.ones(len(hits), dtype=bool)
        idx = np.flatnonzero(test)
        if idx.size:
            valid[idx] = segments_clear(ctx.blockers, (o[idx], o[idx] + t[idx, None] * w[idx]))
        rho = phase_value(-dot(w, rays.d[hits.ray]), med.phase.g)
        scal = med.sigma_s * rho * camera_transmittance(scene, rays, hits.ray, hits.s)
        if not self.short:
            scal = scal * np.exp(-med.sigma_t * t)
        sin = hits.data["sin"]
        scal = np.where(valid & (sin >= PARALLEL_SIN),
                        scal / (2.0 * kernel_radius(self, ctx) * np.maximum(sin, PARALLEL_SIN)),
                        0.0)
        return paths.beta[prims.photon[p], prims.K[p] - 1] * scal[:, None]

    # ------------------------------------------------------------------ drawing
    def kernel_extent(self, prims, idx, scene, far) -> np.ndarray:
        """(K, 2, 3) each beam's part inside the medium box (out to ``T``, short, or ``far``);
        beams that miss the box are left out."""
        o, w = prims.data["o"][idx], prims.data["w"][idx]
        T = grids.lengths(prims.data["T"][idx] if self.short else None, len(idx), far)
        lo, hi = scene.medium.bounds_min, scene.medium.bounds_max
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / w
            t0, t1 = (lo - o) * inv, (hi - o) * inv
        te = np.nanmax(np.minimum(t0, t1), axis=1).clip(0.0)
        tx = np.minimum(np.nanmin(np.maximum(t0, t1), axis=1), T)
        keep = tx > te
        return np.stack([(o + te[:, None] * w)[keep], (o + tx[:, None] * w)[keep]], axis=1)
