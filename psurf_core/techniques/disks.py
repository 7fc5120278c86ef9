"""Photon disk ``[t1, cos th1]`` (spec 3.1, disk row; K >= 2).

The photon keeps everything up to ``x1`` (tracer vertex ``K-1``) and the azimuth ``ph1`` of its
last direction, i.e. the radial unit ``e_r`` of ``w1`` about ``w2``; it integrates ``t1`` and
``cos th1``. ``x0 = x1 + t1 (c1 w2 + s1 e_r)`` sweeps the half-plane through ``x1`` spanned by
``w2`` and ``e_r`` (``(p - x1) . e_r > 0``); one line-plane root. The scaled normal is
``n = t1 (w1 x w2) / s1^2``, ``|n . psi| = t1 |e_ph . psi| / s1`` with ``e_ph = w2 x e_r``.

``X = beta_1^- [rho(c1*) / p(ph1) = 2pi rho(c1*)] E(t1*) ss rho0 E(s*) s1* / (t1* |e_ph.psi|)``;
short: ``t1* < T1`` and drop ``E(t1*)``.

``Q = q_{<=w2} p(t2) (1/2pi) t1 |(w1 x w2) . psi| / s1^2`` (short: ``* E(t1)``).

Each numpy function has its compiled twin (``@twin``) beneath it; see :mod:`.cones`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..kernels.jit import twin
from ..kernels.vec import madd, scale, sub
from ..records import Vec, table
from ..sampling import phase_value
from . import grids
from . import shadow_cull as cull
from .base import Compiled, Primitives, Technique, clip_bounds, cross, dot
from .cones import reconstruct, segments, visibility  # the path x1 + t1 w1, its segment x1 -> x0
from .surface_common import (
    NDP_MIN,
    SIN_MIN,
    beta1,
    camera_term,
    gather,
    half_disk_bounds,
    q_to_w2,
    radial,
    select_photons,
    unit,
)

#: ``p(ph1)``: the azimuth is sampled uniformly (``Pdfs.ph``, a constant).
P_PH = 1.0 / (2.0 * np.pi)


class DiskGeometry(NamedTuple):
    """One photon disk (a row of its ``Primitives.data``)."""

    x1: Vec  # the half-plane's corner: the photon's vertex x1
    w2: Vec  # the half-plane's edge direction (th1 = 0)
    e_r: Vec  # the photon's radial unit (w1 - c1 w2) / s1: inside the half-plane
    e_ph: Vec  # the half-plane's normal w2 x e_r
    T1: float  # the photon's flight from x1 (the short disk's radius)
    beta: Vec  # beta_1^- (W)
    clear: float  # 1: no blocker can block x1 -> x0 of any hit (shadow_cull.box_clear of
    # the bounds, which hold x1 and every hit)


class DiskHit(NamedTuple):
    """One disk hit (a row of its ``Hits.data``)."""

    t1: float  # integrated distance x1 -> x0
    w1: Vec  # rebuilt direction (x0 - x1) / t1
    n_dot_psi: float  # |n . psi| = t1 |e_ph . psi| / s1*


# ------------------------------------------------------------------------- geometry
def scaled_normal(w2, w1, t1):
    """(H, 3) ``dx0/dt1 x dx0/dcos th1 = t1 (w1 x w2) / s1^2`` (up to sign); infinite-free
    only for ``s1 > 0`` (callers guard)."""
    cr = cross(w1, w2)
    with np.errstate(divide="ignore", invalid="ignore"):
        return (t1 / dot(cr, cr))[:, None] * cr


@twin(scaled_normal)
def _scaled_normal(w2, w1, t1):
    cr = cross(w1, w2)
    return scale(t1 / dot(cr, cr), cr)


# ------------------------------------------------------------------------- Intersect
def roots(G, o, psi):
    """(1, N) ray distance of the ray's crossing of the half-plane's plane (NaN or inf:
    none; the caller keeps finite roots on the ray)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return (dot(G.x1 - o, G.e_ph) / dot(psi, G.e_ph))[None]


@twin(roots)
def _roots(G, o, psi):
    return (dot(sub(G.x1, o), G.e_ph) / dot(psi, G.e_ph),)


def accept(G, o, psi, s, short):
    """Hits: on the photon's half-plane (``sin th1* = w1* . e_r > 0``; ``t1* < T1`` if
    short), not grazing; their records (:class:`DiskHit`)."""
    w1, t1 = unit(o + s[:, None] * psi - G.x1)
    s1 = dot(w1, G.e_r)  # sin th1* >= 0 on the photon's half-plane
    ok = (t1 > 0) & (s1 > 0)
    if short:
        ok &= t1 < G.T1
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        ndp = t1 * np.abs(dot(G.e_ph, psi)) / s1
    return ok & (ndp > NDP_MIN) & np.isfinite(ndp), table(DiskHit, t1=t1, w1=w1, n_dot_psi=ndp)


@twin(accept)
def _accept(G, o, psi, s, short):
    w1, t1 = unit(sub(madd(o, s, psi), G.x1))
    s1 = dot(w1, G.e_r)
    ok = t1 > 0.0 and s1 > 0.0 and (not short or t1 < G.T1)
    ndp = t1 * abs(dot(G.e_ph, psi)) / s1
    return ok and ndp > NDP_MIN and np.isfinite(ndp), DiskHit(t1, w1, ndp)


# ------------------------------------------------------------------------- Evaluate
def contribution(G, psi, s, s_min, hit, short, medium):
    """``2pi rho(c1*) [E(t1*)] ss rho0 E(s* - s_min) / |n . psi|`` per unit photon weight
    (``rho / p(ph1)``; ``p(c1)`` is not in ``q``)."""
    rho1 = phase_value(dot(G.w2, hit.w1), medium.g)
    extra = 0.0 if short else hit.t1
    return 2.0 * np.pi * rho1 * camera_term(-dot(hit.w1, psi), s - s_min, extra, medium) / \
        hit.n_dot_psi


@twin(contribution)
def _contribution(G, psi, s, s_min, hit, short, medium):
    rho1 = phase_value(dot(G.w2, hit.w1), medium.g)
    extra = 0.0 if short else hit.t1
    return 2.0 * np.pi * rho1 * camera_term(-dot(hit.w1, psi), s - s_min, extra, medium) / \
        hit.n_dot_psi


# ------------------------------------------------------------------------- MIS
def density(rec, short):
    """Relative ``Q = q_{<=w2} p(t2) (1/2pi) t1 |(w1 x w2) . psi| / s1^2`` (short:
    ``* E(t1)``)."""
    n = scaled_normal(rec.w2, rec.w1, rec.t1)
    with np.errstate(invalid="ignore"):
        q = q_to_w2(rec) * rec.pdf.t2 * P_PH * np.abs(dot(n, rec.psi))
    return q * rec.pdf.e1 if short else q


@twin(density, weight=True)
def _density(rec, short):
    n = scaled_normal(rec.w2, rec.w1, rec.t1)
    q = q_to_w2(rec) * rec.pdf.t2 * P_PH * abs(dot(n, rec.psi))
    return q * rec.pdf.e1 if short else q


# ------------------------------------------------------------------------- drawing
def surface_grid(G, short, far):
    """(M, 2, nth, 3) the half-disk from ``x1`` between ``w2`` and ``-w2`` through ``e_r``,
    out to ``T1`` (short) or ``far``: the drawing's sweep grid (:mod:`.grids`)."""
    m = len(G)
    return grids.half_disk(G.x1, G.w2, G.e_r, grids.lengths(G.T1 if short else None, m, far),
                           np.full(m, np.pi))


# ------------------------------------------------------------------------- Create
class PhotonDisk(Technique):
    """The photon disk; ``short`` restricts ``t1* < T1`` (track-length)."""

    family = "disks"
    min_k = 2
    compiled = Compiled(DiskGeometry, DiskHit, 1, roots, accept, visibility, contribution,
                        segments, reconstruct, density, staged=True)

    names = ("disk", "disk-short")
    grid = staticmethod(surface_grid)

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
                          table(DiskGeometry, x1=x1, w2=w2, e_r=e_r, e_ph=cross(w2, e_r),
                                T1=T1, beta=beta1(paths, photon, K),
                                clear=cull.box_clear(ctx.blockers, ctx.scene, lo, hi)))

    def scaled_normal(self, rec):
        """(H, 3) scaled normal on records ``rec`` (the inspector's)."""
        return scaled_normal(rec.w2, rec.w1, rec.t1)
