"""Single-scattering photon disk ``ss-disk`` ``[t, cos th]`` (spec 3.2; K = 1).

The photon keeps its light point ``x`` and the azimuth of its emission direction about the
fixed axis ``a`` (the point light's axis, ``n_L`` or ``n_k``); the distance and the polar
cosine are integrated. ``x0 = x + t (cos th a + sin th e_r)`` sweeps the half-plane through
``x`` containing ``a`` and ``w``: its normal is ``e_ph = normalize(a x w)`` (spec 4), its
radial unit ``e_r = e_ph x a`` (``(p - x) . e_r > 0``); one line-plane root. ``w*`` and
``t* = |x0 - x|`` are rebuilt from the hit; the scaled normal is ``n = t (w* x a) / sin^2 th``.
Photons with ``w`` parallel to the axis (measure zero) have no half-plane and make none.

``Q = p(u,v) (1/2pi) t |(w x a) . psi| / sin^2 th`` (short: ``* E(t)``); with ``f / P_L`` of
:mod:`.single`, ``p(u,v)`` cancels: ``X = beta0 2 pi p(w*) [E(t*)] ss rho0 E(s*) /
|n . psi|`` (point light: ``2 pi I ss rho0 E(t* + s*) sin th* / (t* |e_ph . psi|)``); the
short disk needs ``t* < T`` and drops ``E(t*)``.

Each numpy function has its compiled twin (``@twin``) beneath it; see :mod:`.cones`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..kernels.jit import twin
from ..kernels.vec import madd, scale, sub
from ..pdfs import emission_pdf
from ..records import Vec, table
from . import grids
from .base import Compiled, Primitives, cross, dot
from .cones import reconstruct, segments, visibility  # the path's one segment x1 -> x0
from .single import SingleScatter, arc_range, columns, sweep_bounds
from .surface_common import NDP_MIN, camera_term, unit

#: ``1 / (2 pi)``: the pdf of the photon's azimuth about the axis.
INV_2PI = 1.0 / (2.0 * np.pi)

#: ``sin^2 th`` floor of the scaled normal: keeps ``t / sin^2`` finite (no overflow) at
#: numerically axial directions; at or below it the normal is 0 (undefined on the axis).
SIN2_MIN = 1e-200


class DiskGeometry(NamedTuple):
    """One single-scattering photon disk (a row of its ``Primitives.data``)."""

    x1: Vec  # the photon's light point (on the half-plane's edge, the axis)
    axis: Vec  # a / n_L / n_k
    eph: Vec  # the half-plane's unit normal normalize(a x w)
    er: Vec  # its radial unit e_ph x a (towards w)
    T1: float  # the photon's sampled flight (the short disk's extent)
    one_sided: float  # 1: area / mesh light (the front quarter only)
    kind: float  # light kind code (the emission pdf's)
    beta: Vec  # beta0 = Phi / P_L (W)
    clear: float  # 0: every hit's segment from the light point is tested (not culled: an
    # area light's own quad holds that point in its plane, where shadow_cull cannot decide)


class DiskHit(NamedTuple):
    """One disk hit (a row of its ``Hits.data``)."""

    t1: float  # integrated distance x -> x0
    w1: Vec  # rebuilt direction (x0 - x) / t1
    n_dot_psi: float  # |n . psi|, n = t1 (w1 x a) / sin^2


# ------------------------------------------------------------------------- geometry
def scaled_normal(w1, axis, t1):
    """(H, 3) ``dx0/dt x dx0/dcos th = t (w x a) / sin^2 th`` (up to sign; 0 on the axis,
    where it is undefined)."""
    n = cross(w1, axis)
    sin2 = dot(n, n)
    with np.errstate(divide="ignore", invalid="ignore"):
        k = np.where(sin2 > SIN2_MIN, t1 / np.maximum(sin2, SIN2_MIN), 0.0)
    return k[:, None] * n


@twin(scaled_normal)
def _scaled_normal(w1, axis, t1):
    n = cross(w1, axis)
    sin2 = dot(n, n)
    return scale(t1 / max(sin2, SIN2_MIN) if sin2 > SIN2_MIN else 0.0, n)


# ------------------------------------------------------------------------- Intersect
def roots(G, o, psi):
    """(1, N) ray distance of the half-plane's plane (inf / NaN where parallel)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return (dot(G.x1 - o, G.eph) / dot(psi, G.eph))[None]


@twin(roots)
def _roots(G, o, psi):
    return (dot(sub(G.x1, o), G.eph) / dot(psi, G.eph),)


def accept(G, o, psi, s, short):
    """Which roots are hits (the half-plane's side ``e_r``; area / mesh lights: its front
    quarter; ``t* < T`` if short; not grazing), and their records (:class:`DiskHit`)."""
    v = o + s[:, None] * psi - G.x1
    w1, t1 = unit(v)
    ok = (dot(v, G.er) > 0.0) & (t1 > 0.0)
    ok &= (G.one_sided == 0.0) | (dot(v, G.axis) > 0.0)
    if short:
        ok &= t1 < G.T1
    ndp = np.abs(dot(scaled_normal(w1, G.axis, t1), psi))
    return ok & (ndp > NDP_MIN), table(DiskHit, t1=t1, w1=w1, n_dot_psi=ndp)


@twin(accept)
def _accept(G, o, psi, s, short):
    v = sub(madd(o, s, psi), G.x1)
    w1, t1 = unit(v)
    ok = dot(v, G.er) > 0.0 and t1 > 0.0
    ok = ok and (G.one_sided == 0.0 or dot(v, G.axis) > 0.0) and (not short or t1 < G.T1)
    ndp = abs(dot(scaled_normal(w1, G.axis, t1), psi))
    return ok and ndp > NDP_MIN, DiskHit(t1, w1, ndp)


# ------------------------------------------------------------------------- Evaluate
def contribution(G, psi, s, s_min, hit, short, medium):
    """``2 pi p(w*) [E(t*)] ss rho0 E(s* - s_min) / |n . psi|`` per unit photon weight."""
    extra = 0.0 if short else hit.t1
    p_w = emission_pdf(G.kind, G.axis, hit.w1)
    return 2.0 * np.pi * p_w * camera_term(-dot(hit.w1, psi), s - s_min, extra, medium) / \
        hit.n_dot_psi


@twin(contribution)
def _contribution(G, psi, s, s_min, hit, short, medium):
    extra = 0.0 if short else hit.t1
    p_w = emission_pdf(G.kind, G.axis, hit.w1)
    return 2.0 * np.pi * p_w * camera_term(-dot(hit.w1, psi), s - s_min, extra, medium) / \
        hit.n_dot_psi


# ------------------------------------------------------------------------- MIS
# The record with ``t1*, w1*``: the cone's (:mod:`.cones`; the hits carry the same fields).
def density(rec, short):
    """``Q = p(u,v) (1/2pi) t |(w x a) . psi| / sin^2`` (short: ``* E(t)``)."""
    q = rec.pdf.uv * INV_2PI * np.abs(dot(scaled_normal(rec.w1, rec.axis, rec.t1), rec.psi))
    return q * rec.pdf.e1 if short else q


@twin(density, weight=True)
def _density(rec, short):
    q = rec.pdf.uv * INV_2PI * abs(dot(scaled_normal(rec.w1, rec.axis, rec.t1), rec.psi))
    return q * rec.pdf.e1 if short else q


# ------------------------------------------------------------------------- drawing
def surface_grid(G, short, far):
    """(M, 2, nth, 3) the half-disk from ``x1`` about ``axis`` through ``er`` (a quarter for
    an area / mesh light), out to ``T1`` (short) or ``far``: the drawing's sweep grid."""
    one = G.one_sided.astype(bool)
    return grids.half_disk(G.x1, G.axis, G.er,
                           grids.lengths(G.T1 if short else None, len(G), far),
                           np.where(one, 0.5 * np.pi, np.pi))


# ------------------------------------------------------------------------- Create
class SingleDisk(SingleScatter):
    """``ss-disk`` ``[t, cos th]``: the half-plane through the axis containing ``w``;
    ``short`` restricts ``t* < T`` (track-length)."""

    compiled = Compiled(DiskGeometry, DiskHit, 1, roots, accept, visibility, contribution,
                        segments, reconstruct, density, staged=True)

    names = ("ss-disk", "ss-disk-short")
    grid = staticmethod(surface_grid)

    def create(self, paths, ctx) -> Primitives:
        """One half-plane per photon (:class:`DiskGeometry`)."""
        photon = self._photons(paths, ctx)
        d = self._emission(paths, photon, ctx.scene)
        eph, sin = unit(np.cross(d["axis"], d["w"]))
        keep = sin > 1e-12
        photon, d, eph = photon[keep], {k: v[keep] for k, v in d.items()}, eph[keep]
        a = d["axis"]
        er = np.cross(eph, a)  # unit, in the half-plane, perpendicular to a, towards w
        # Directions cos th a + sin th er, th in [0, pi] (area/mesh: the front quarter only).
        dmin, dmax = arc_range(a, er, np.where(d["one_sided"] != 0.0, 0.5 * np.pi, np.pi))
        lo, hi = sweep_bounds(d["x1"], dmin, dmax, d["T1"] if self.short else None)
        return self._prims(photon, lo, hi, ctx,
                           table(DiskGeometry, **columns(DiskGeometry, d, eph=eph, er=er,
                                                         clear=0.0)))

    def scaled_normal(self, rec):
        """(H, 3) ``t (w x a) / sin^2`` on records ``rec`` (the inspector's)."""
        return scaled_normal(rec.w1, rec.axis, rec.t1)
