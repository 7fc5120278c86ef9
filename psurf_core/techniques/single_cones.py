"""Single-scattering photon cone ``ss-cone`` ``[t, ph]`` (spec 3.2; K = 1).

The photon keeps its light point ``x`` and the polar cosine ``c = w . a`` of its emission
direction about the fixed axis ``a`` (the point light's axis, ``n_L`` or ``n_k``); the
azimuth and the distance are integrated. ``x0 = x + t w(ph)`` sweeps one nappe of the cone
with apex ``x``, axis ``a`` and half-angle ``acos c``: the photon cone of :mod:`.cones` with
its apex ``x1`` on the light and the axis ``a`` for ``w2``. So Evaluate and Reconstruct, and
Intersect but for the roots, are that cone's: the photon's nappe of
``((p - x) . a)^2 = c^2 |p - x|^2``, ``w*`` and ``t* = |x0 - x|`` rebuilt from the hit,
scaled normal ``n = t (a - c w*)``, and the contribution

``X = beta0 [E(t*)] ss rho0 E(s*) / (2 pi |n . psi|)``

(point light: ``2 I ss rho0 E(t* + s*) / (t* |(a - c w*) . psi|)``): here ``f / P_L`` of
:mod:`.single` over ``Q`` below, where ``p(u,v)`` cancels and ``p(w*) / p(c) = 1/2pi``. The
short cone needs ``t* < T`` and drops ``E(t*)``. An area light emits only forwards: with
``c > 0`` the photon's nappe is the front one (``w* . n_L > 0``); photons with ``c <= 0``
(measure zero under cosine emission) make no cone.

The roots are solved in ``s`` itself (the multiple-scattering cone solves in ``s - sc``
about the ray point closest to the apex, which moves this technique's values by up to
~1e-8 relative); ``Q = p(u,v) p(c) t |(a - c w) . psi|`` (short: ``* E(t)``) is
:func:`density`. Each has its compiled twin beneath it.
"""

from __future__ import annotations

import numpy as np

from ..kernels.jit import twin
from ..kernels.vec import sub
from ..records import table
from .base import Compiled, Primitives, dot
from .cones import (
    ConeGeometry,
    ConeHit,
    accept,
    contribution,
    footprint,
    reconstruct,
    scaled_normal,
    segments,
    surface_grid,  # the same nappe: apex x1, axis w2, cos c1
    visibility,
)
from .single import SingleScatter, sweep_bounds
from .surface_common import quadratic_roots


def roots(G, o, psi):
    """(2, N) ray distances of the cone equation's roots (NaN: none), solved in ``s``."""
    D = o - G.x1
    da, pa, c2 = dot(D, G.w2), dot(psi, G.w2), G.c1 * G.c1
    return quadratic_roots(pa * pa - c2, da * pa - c2 * dot(D, psi), da * da - c2 * dot(D, D))


@twin(roots)
def _roots(G, o, psi):
    D = sub(o, G.x1)
    da, pa, c2 = dot(D, G.w2), dot(psi, G.w2), G.c1 * G.c1
    return quadratic_roots(pa * pa - c2, da * pa - c2 * dot(D, psi), da * da - c2 * dot(D, D))


def density(rec, short):
    """``Q = p(u,v) p(c) t |(a - c w) . psi|`` (short: ``* E(t)``)."""
    q = rec.pdf.uv * rec.pdf.c1 * np.abs(dot(scaled_normal(rec.axis, rec.w1, rec.t1),
                                             rec.psi))
    return q * rec.pdf.e1 if short else q


@twin(density, weight=True)
def _density(rec, short):
    q = rec.pdf.uv * rec.pdf.c1 * abs(dot(scaled_normal(rec.axis, rec.w1, rec.t1), rec.psi))
    return q * rec.pdf.e1 if short else q


class SingleCone(SingleScatter):
    """``ss-cone`` ``[t, ph]``: the nappe of half-angle ``acos(w . axis)`` about the axis;
    ``short`` restricts ``t* < T`` (track-length)."""

    compiled = Compiled(ConeGeometry, ConeHit, 2, roots, accept, visibility, contribution,
                        segments, reconstruct, density, staged=True)

    names = ("ss-cone", "ss-cone-short")
    grid = staticmethod(surface_grid)

    def create(self, paths, ctx) -> Primitives:
        """One nappe per photon (:class:`~psurf_core.techniques.cones.ConeGeometry`: apex
        ``x1`` the light point, axis ``w2`` the light's, ``c1 = c``, ``T1 = T``,
        ``beta = beta0``)."""
        photon = self._photons(paths, ctx)
        d = self._emission(paths, photon, ctx.scene)
        c = dot(d["w"], d["axis"])
        keep = (d["one_sided"] == 0.0) | (c > 0.0)  # a backward area-light photon: no cone
        photon, d, c = photon[keep], {k: v[keep] for k, v in d.items()}, c[keep]
        a = d["axis"]
        # Generator directions c a + sin (cos ph e1 + sin ph e2): component k spans
        # c a_k +- sin sqrt(1 - a_k^2) (e1, e2, a orthonormal).
        sin = np.sqrt(np.clip(1.0 - c * c, 0.0, None))
        spread = sin[:, None] * np.sqrt(np.clip(1.0 - a * a, 0.0, None))
        length = d["T1"] if self.short else None
        lo, hi = sweep_bounds(d["x1"], c[:, None] * a - spread, c[:, None] * a + spread, length)
        # The compiled walk visits the pixels of the nappe's footprint solid clipped to the
        # box, not its whole screen rectangle (the multiple-scattering cone's; on area.toml
        # a third of the rectangle's pairs were hits).
        cloud = footprint(ctx.scene, d["x1"], a, c, sin, length)
        return self._prims(photon, lo, hi, ctx, table(
            ConeGeometry, x1=d["x1"], w2=a, c1=c, T1=d["T1"], beta=d["beta"],
            # Not culled: the apex is the light point, which an area light's own quad holds
            # in its plane, where shadow_cull cannot decide; every hit is tested.
            clear=0.0), cloud=cloud)

    def scaled_normal(self, rec):
        """(H, 3) ``t (a - c w)`` on records ``rec`` (the inspector's)."""
        return scaled_normal(rec.axis, rec.w1, rec.t1)
