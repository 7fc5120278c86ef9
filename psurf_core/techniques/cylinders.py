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

``Q = q_{<=w2} 2pi rho(c1) p(t1) t1 s1 |e_r . psi|`` (short: ``* E(t2)``).

Each numpy function has its compiled twin (``@twin``) beneath it; see :mod:`.cones`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..kernels.jit import twin
from ..kernels.vec import add, madd, scale, sub
from ..path_record import with_t2, with_w1
from ..records import Vec, table
from . import grids
from . import shadow_cull as cull
from .base import Compiled, Primitives, Technique, clip_bounds, dot
from .outside_box import cut_to_outside, tube_edges
from .planes import segments, visibility  # the path x2 -> x1* = x2 + t2* w2 -> x0
from .surface_common import (
    NDP_MIN,
    beta1,
    box_reach,
    camera_term,
    circle_extent,
    gather,
    own_segment,
    q_to_w2,
    quadratic_roots,
    radial,
    ring,
    select_photons,
    sweep_bounds,
)


class CylinderGeometry(NamedTuple):
    """One photon cylinder (a row of its ``Primitives.data``)."""

    x2: Vec  # a point of the axis: the photon's vertex x2
    w2: Vec  # axis direction
    c1: float  # cos th1 of the photon's w1 about w2
    s1: float  # sin th1
    T1: float  # the photon's flight from x1 (radius T1 s1)
    T2: float  # the photon's flight from x2
    own: float  # 1: segment x2 -> x1 is the photon's own, clear for t2 < T2 (own_segment)
    beta: Vec  # beta_1^- (W)
    clear: float  # 1: no blocker can block x1* -> x0 of any hit (shadow_cull.hull_clear of
    # the footprint's rings and the axis from x2: x0 on the surface, x1* on the axis)
    line: float  # 1: no blocker can block x2 -> x1* of any hit (shadow_cull.line_clear)


class CylinderHit(NamedTuple):
    """One cylinder hit (a row of its ``Hits.data``)."""

    t2: float  # integrated distance x2 -> x1*
    w1: Vec  # rebuilt direction c1 w2 + s1 e_r*
    n_dot_psi: float  # |n . psi| = T1 s1 |e_r* . psi|


# ------------------------------------------------------------------------- geometry
def scaled_normal(w2, w1, t1):
    """(H, 3) ``dx0/dt2 x dx0/dph1 = t1 (c1 w2 - w1)`` (up to sign), ``c1 = w1 . w2``."""
    return t1[:, None] * (dot(w1, w2)[:, None] * w2 - w1)


@twin(scaled_normal)
def _scaled_normal(w2, w1, t1):
    return scale(t1, sub(scale(dot(w1, w2), w2), w1))


def radial_unit(vp, r):
    """(H, 3) the unit radial ``e_r`` of a point on the cylinder from its offset ``vp``
    (perpendicular to the axis) and the radius ``r = T1 s1`` ((H,)): ``vp / r``, since a
    root of :func:`roots` puts the point at ``|vp| = r`` to rounding (``|vp|``'s square root
    and divisions sat on the pair's serial chain: 0.976x the cylinder walker's CPU without
    them, docs/study.md, "Square roots off the cones' and cylinders' chains"). Zero where
    ``r = 0`` (``s1 = 0``: a line, met with probability zero)."""
    return vp * (1.0 / np.where(r > 0.0, r, np.inf))[:, None]  # the twin's operations


@twin(radial_unit)
def _radial_unit(vp, r):
    return scale(1.0 / r if r > 0.0 else 0.0, vp)


# ------------------------------------------------------------------------- Intersect
def roots(G, o, psi):
    """(2, N) ray distances where the ray meets the infinite cylinder (NaN: none): the
    quadratic in the components perpendicular to the axis, in ``s - sc``."""
    sc = dot(G.x2 - o, psi)
    b = o + sc[:, None] * psi - G.x2
    bp = b - dot(b, G.w2)[:, None] * G.w2
    pp = psi - dot(psi, G.w2)[:, None] * G.w2
    r = G.T1 * G.s1
    return quadratic_roots(dot(pp, pp), dot(bp, pp), dot(bp, bp) - r * r) + sc


@twin(roots)
def _roots(G, o, psi):
    sc = dot(sub(G.x2, o), psi)
    b = sub(madd(o, sc, psi), G.x2)
    bp = sub(b, scale(dot(b, G.w2), G.w2))
    pp = sub(psi, scale(dot(psi, G.w2), G.w2))
    r = G.T1 * G.s1
    r0, r1 = quadratic_roots(dot(pp, pp), dot(bp, pp), dot(bp, bp) - r * r)
    return r0 + sc, r1 + sc


def accept(G, o, psi, s, short):
    """Hits: past ``x1`` on the axis (``t2* > 0``; ``< T2`` if short), not grazing."""
    v = o + s[:, None] * psi - G.x2
    h = dot(v, G.w2)
    e_r = radial_unit(v - h[:, None] * G.w2, G.T1 * G.s1)
    t2 = h - G.T1 * G.c1
    ok = t2 > 0
    if short:
        ok &= t2 < G.T2
    w1 = G.c1[:, None] * G.w2 + G.s1[:, None] * e_r
    ndp = G.T1 * G.s1 * np.abs(dot(e_r, psi))
    return ok & (ndp > NDP_MIN), table(CylinderHit, t2=t2, w1=w1, n_dot_psi=ndp)


@twin(accept)
def _accept(G, o, psi, s, short):
    v = sub(madd(o, s, psi), G.x2)
    h = dot(v, G.w2)
    e_r = radial_unit(sub(v, scale(h, G.w2)), G.T1 * G.s1)
    t2 = h - G.T1 * G.c1
    ok = t2 > 0.0 and (not short or t2 < G.T2)
    w1 = add(scale(G.c1, G.w2), scale(G.s1, e_r))
    ndp = G.T1 * G.s1 * abs(dot(e_r, psi))
    return ok and ndp > NDP_MIN, CylinderHit(t2, w1, ndp)


# ------------------------------------------------------------------------- Evaluate
def contribution(G, psi, s, s_min, hit, short, medium):
    """``(1/2pi) [E(t2*)] ss rho0 E(s* - s_min) / |n . psi|`` per unit photon weight."""
    extra = 0.0 if short else hit.t2
    return camera_term(-dot(hit.w1, psi), s - s_min, extra, medium) / \
        (2.0 * np.pi * hit.n_dot_psi)


@twin(contribution)
def _contribution(G, psi, s, s_min, hit, short, medium):
    extra = 0.0 if short else hit.t2
    return camera_term(-dot(hit.w1, psi), s - s_min, extra, medium) / \
        (2.0 * np.pi * hit.n_dot_psi)


# ------------------------------------------------------------------------- MIS
def reconstruct(rec, G, hit):
    """The hit's full path: ``t2*``, ``x1* = x2 + t2* w2`` and ``w1*``."""
    return rec.with_(t2=hit.t2, x1=rec.x2 + hit.t2[:, None] * rec.w2, w1=hit.w1)


@twin(reconstruct)
def _reconstruct(rec, G, hit):
    return with_w1(with_t2(rec, hit.t2), hit.w1)  # (no compiled density reads x1)


def density(rec, short):
    """Relative ``Q = q_{<=w2} 2pi rho(c1) p(t1) t1 s1 |e_r . psi|`` (short: ``* E(t2)``)."""
    n = scaled_normal(rec.w2, rec.w1, rec.t1)
    q = q_to_w2(rec) * rec.pdf.c1 * rec.pdf.t1 * np.abs(dot(n, rec.psi))
    return q * rec.pdf.e2 if short else q


@twin(density, weight=True)
def _density(rec, short):
    n = scaled_normal(rec.w2, rec.w1, rec.t1)
    q = q_to_w2(rec) * rec.pdf.c1 * rec.pdf.t1 * abs(dot(n, rec.psi))
    return q * rec.pdf.e2 if short else q


# ------------------------------------------------------------------------- drawing
def surface_grid(G, short, far):
    """(M, 2, 36, 3) the cylinder of radius ``T1 s1`` about ``x2 + h w2``, from
    ``h = T1 c1`` over ``T2`` (short) or ``far``: the drawing's sweep grid (:mod:`.grids`)."""
    m = len(G)
    e1, e2 = grids.frame(G.w2)
    around = (G.T1 * G.s1)[:, None, None] * grids.ring(e1, e2, 36)
    start = G.x2 + (G.T1 * G.c1)[:, None] * G.w2
    h = grids.lengths(G.T2 if short else None, m, far)
    t = np.stack([np.zeros(m), h], axis=1)
    return (start[:, None, None, :] + t[:, :, None, None] * G.w2[:, None, None, :]
            + around[:, None, :, :])


# ------------------------------------------------------------------------- Create
class PhotonCylinder(Technique):
    """The photon cylinder; ``short`` restricts ``t2* < T2`` (track-length)."""

    family = "cylinders"
    min_k = 2
    compiled = Compiled(CylinderGeometry, CylinderHit, 2, roots, accept, visibility,
                        contribution, segments, reconstruct, density, staged=True)

    names = ("cylinder", "cylinder-short")
    grid = staticmethod(surface_grid)

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
        # Hits lie in the box outside the tube (.outside_box): where the tube holds the box,
        # or a corner or face of it, the prism of the footprint does not see that.
        cut_to_outside(ctx.scene, lo, hi, tube_edges(x2, w2, T1 * s1))
        # Footprint: rings circumscribing the circles at t2 = 0 and at its far end.
        h0 = T1 * c1
        h1 = h0 + g["T2"] if self.short else np.maximum(box_reach(ctx.scene, x2, w2), h0)
        cloud = np.concatenate([ring(x2 + h0[:, None] * w2, w2, T1 * s1),
                                ring(x2 + h1[:, None] * w2, w2, T1 * s1)], axis=1)
        # x1* = x2 + t2* w2 with t2* < T2 (short) or within the box's extent along w2 (long).
        reach = g["T2"] if self.short else h1
        return Primitives(self.name, photon, K, lo, hi, cloud=cloud, data=table(
            CylinderGeometry, x2=x2, w2=w2, c1=c1, s1=s1, T1=T1, T2=g["T2"],
            own=own_segment(paths, photon, K - 1, x2, ctx.scene), beta=beta1(paths, photon, K),
            clear=cull.hull_clear(ctx.blockers, ctx.scene, [
                *(cloud[:, i] for i in range(cloud.shape[1])), x2, x2 + reach[:, None] * w2]),
            line=cull.line_clear(ctx.blockers, ctx.scene, x2, w2, reach)))

    def scaled_normal(self, rec):
        """(H, 3) scaled normal on records ``rec`` (the inspector's)."""
        return scaled_normal(rec.w2, rec.w1, rec.t1)
