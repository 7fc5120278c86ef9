"""Photon points: kernel (biased) baselines over photon collision points (spec 3.4, section 4).

A primitive is the photon's scattering vertex ``j >= 1`` (tracer numbering, ``x[:, j]``); it
estimates paths with ``K = j`` events, the camera vertex being the K-th scattering. It is
valid when segment ``j`` was sampled and the photon's prefix up to vertex ``j`` is valid
(``alive[:, j-1] & prefix_ok[:, j]``: the point lies in the box, segments ``1..j`` are
unoccluded). The weight arriving at the point is ``beta_j / st`` (``E(T)/p(T) = 1/st``, with
``beta_j = paths.beta[:, j-1]`` the weight leaving vertex ``j-1``); the camera vertex adds
``ss rho(-w_j . psi)``. The blur itself is not visibility-tested (part of the bias).

* ``points`` (Jensen & Christensen 98): 3D box kernel ``K3 = 3/(4 pi r^3)`` integrated along
  the camera ray over the chord of the kernel sphere, clipped to ``[s_min, s_max]``:
  ``X = beta_j (ss/st) rho (E(a) - E(b))/st K3``.
* ``bre`` (Jarosz et al. 08): 2D kernel ``K2 = 1/(pi r^2)`` on the distance of the point to
  the ray, evaluated at its projection ``s_p`` (which must lie in ``(s_min, s_max)``):
  ``X = beta_j (ss/st) rho E(s_p) K2``.

``E(s) = exp(-st (s - s_min))`` is the camera transmittance inside the box. The kernel radius
is ``ctx.radius`` (or ``default_radius_fraction`` of the box diagonal when it is not set).
"""

from __future__ import annotations

import numpy as np

from ..sampling import phase_value
from .base import Hits, PassContext, Primitives, Technique, camera_transmittance, clip_bounds, dot


def kernel_radius(tech: Technique, ctx: PassContext) -> float:
    """The pass radius ``ctx.radius``, or the technique's default fraction of the diagonal."""
    if ctx.radius > 0:
        return float(ctx.radius)
    return float(tech.default_radius_fraction * ctx.scene.medium.diagonal)


class _PointKernel(Technique):
    """Shared Create stage of the photon-point baselines (one primitive per valid vertex)."""

    family = "points"
    surface = False  # a kernel blurs photon points: no swept surface, no scaled normal
    min_k = 1
    default_radius_fraction = 0.03

    def create(self, paths, ctx: PassContext) -> Primitives:
        """Photon points of every valid vertex ``j = K`` in :meth:`k_range`.

        Returns
        -------
        Primitives
            ``data``: ``xp`` (M, 3) the point, ``w`` (M, 3) the direction arriving at it.
            Bounds are the point +- radius, clipped to the box.
        """
        scene = ctx.scene
        lmask = self.light_mask(paths, scene)
        photon, kk = [], []
        for k in self.k_range(scene, paths.depth):
            idx = np.flatnonzero(lmask & paths.alive[:, k - 1] & paths.prefix_ok[:, k])
            photon.append(idx)
            kk.append(np.full(idx.size, k))
        photon = np.concatenate(photon) if photon else np.zeros(0, np.int64)
        K = np.concatenate(kk) if kk else np.zeros(0, np.int64)
        xp = paths.x[photon, K]
        w = paths.w[photon, K - 1]
        r = kernel_radius(self, ctx)
        lo, hi = clip_bounds(scene, xp - r, xp + r)
        return Primitives(self.name, photon, K, lo, hi, dict(xp=xp, w=w))

    def kernel_extent(self, prims, idx, scene, far) -> np.ndarray:
        """(M, 1, 3) the photon points (drawn as balls of the kernel radius)."""
        return prims.data["xp"][idx][:, None, :]

    def _weight(self, hits: Hits, prims: Primitives, paths, rays, ctx) -> np.ndarray:
        """(H, 3) ``beta_j (ss/st) rho(-w_j . psi)``: the photon's weight at the camera vertex."""
        med = ctx.scene.medium
        p = hits.prim
        rho = phase_value(-dot(prims.data["w"][p], rays.d[hits.ray]), med.phase.g)
        beta = paths.beta[prims.photon[p], prims.K[p] - 1]
        return beta * (med.sigma_s / med.sigma_t * rho)[:, None]


class PhotonPoints(_PointKernel):
    """Photon points with a 3D box kernel integrated along the camera ray."""

    name = "points"
    kernel_dim = 3
    default_radius_fraction = 0.03

    def intersect(self, prims, rays, ray, prim, ctx) -> Hits:
        """Non-empty chords ``[a, b]`` of the rays through the kernel spheres.

        Returns
        -------
        Hits
            ``s`` the chord midpoint; ``data``: ``a``, ``b`` (H,) the clipped chord ends.
        """
        r = kernel_radius(self, ctx)
        v = prims.data["xp"][prim] - rays.o[ray]
        sc = dot(v, rays.d[ray])
        d2 = dot(v, v) - sc * sc
        h = np.sqrt(np.maximum(r * r - d2, 0.0))
        a = np.maximum(sc - h, rays.s_min[ray])
        b = np.minimum(sc + h, rays.s_max[ray])
        keep = np.flatnonzero((d2 < r * r) & (a < b))
        a, b = a[keep], b[keep]
        return Hits(ray[keep], prim[keep], 0.5 * (a + b), dict(a=a, b=b))

    def evaluate(self, hits, prims, paths, rays, ctx) -> np.ndarray:
        """(H, 3) ``beta_j (ss/st) rho int_a^b E(s) ds K3``."""
        st = ctx.scene.medium.sigma_t
        r = kernel_radius(self, ctx)
        a, b = hits.data["a"], hits.data["b"]
        ea = camera_transmittance(ctx.scene, rays, hits.ray, a)
        # int_a^b exp(-st (s - s_min)) ds = E(a) (1 - exp(-st (b - a))) / st, stable for small st.
        integral = ea * -np.expm1(-st * (b - a)) / st
        k3 = 3.0 / (4.0 * np.pi * r**3)
        return self._weight(hits, prims, paths, rays, ctx) * (integral * k3)[:, None]


class BeamRadianceEstimate(_PointKernel):
    """Beam radiance estimate: photon points against the camera beam with a 2D kernel."""

    name = "bre"
    kernel_dim = 2
    default_radius_fraction = 0.02

    def intersect(self, prims, rays, ray, prim, ctx) -> Hits:
        """Points within ``r`` of the ray whose projection lies in ``(s_min, s_max)``.

        Returns
        -------
        Hits
            ``s`` the projection ``s_p``; ``data``: ``d2`` (H,) squared distance to the ray.
        """
        r = kernel_radius(self, ctx)
        v = prims.data["xp"][prim] - rays.o[ray]
        sp = dot(v, rays.d[ray])
        d2 = np.maximum(dot(v, v) - sp * sp, 0.0)
        keep = np.flatnonzero((d2 < r * r) & (sp > rays.s_min[ray]) & (sp < rays.s_max[ray]))
        return Hits(ray[keep], prim[keep], sp[keep], dict(d2=d2[keep]))

    def evaluate(self, hits, prims, paths, rays, ctx) -> np.ndarray:
        """(H, 3) ``beta_j (ss/st) rho E(s_p) K2``."""
        r = kernel_radius(self, ctx)
        e = camera_transmittance(ctx.scene, rays, hits.ray, hits.s)
        k2 = 1.0 / (np.pi * r * r)
        return self._weight(hits, prims, paths, rays, ctx) * (e * k2)[:, None]
