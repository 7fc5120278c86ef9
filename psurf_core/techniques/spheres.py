"""Photon sphere ``[cos th1, ph1]`` (spec 3.1, sphere row; K >= 2).

The photon keeps everything up to ``x1`` (tracer vertex ``K-1``) and its last flight ``T1``,
and integrates the direction ``w1``: ``x0 = x1 + T1 w1`` sweeps the sphere of radius ``T1``
about ``x1``. The camera ray meets it in up to two points; each gives ``w1* = (y(s*) - x1)/T1``
and the scaled normal ``n = T1^2 w1*`` (``|dw/dcos x dw/dph| = 1``).

``X = beta_1^- rho(w2 . w1*) ss rho0 E(s*) / (st T1^2 |w1* . psi|)``. The sphere has no short
variant: its only distance is sampled, so there is no transmittance to trade.

``Q = q_{<=w2} p(t2) p(t1) t1^2 |w1 . psi|``.

Each numpy function has its compiled twin (``@twin``) beneath it; see :mod:`.cones`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..kernels.jit import twin
from ..kernels.vec import madd, scale, sub
from ..path_record import with_w1
from ..records import Vec, table
from ..sampling import phase_value
from . import grids
from . import shadow_cull as cull
from .base import Compiled, Primitives, Technique, clip_bounds, dot
from .cones import segments, visibility  # the path's one segment x1 -> x0
from .outside_box import ball_edges, cut_to_outside
from .surface_common import (
    NDP_MIN,
    beta1,
    camera_term,
    gather,
    q_to_w2,
    quadratic_roots,
    select_photons,
    unit,
)


class SphereGeometry(NamedTuple):
    """One photon sphere (a row of its ``Primitives.data``)."""

    x1: Vec  # centre: the photon's vertex x1
    w2: Vec  # the direction that arrived at x1 (the phase function's axis)
    T1: float  # radius: the photon's sampled flight from x1
    beta: Vec  # beta_1^- (W)
    clear: float  # 1: no blocker can block x1 -> x0 of any hit (shadow_cull.box_clear of
    # the bounds, which hold x1 and every hit)


class SphereHit(NamedTuple):
    """One sphere hit (a row of its ``Hits.data``)."""

    w1: Vec  # rebuilt direction (x0 - x1) / T1
    n_dot_psi: float  # |n . psi| = T1^2 |w1 . psi|


# ------------------------------------------------------------------------- geometry
def scaled_normal(w1, t1):
    """(H, 3) ``dx0/dcos th1 x dx0/dph1 = t1^2 w1`` (up to sign)."""
    return (t1**2)[:, None] * w1


@twin(scaled_normal)
def _scaled_normal(w1, t1):
    return scale(t1**2, w1)


# ------------------------------------------------------------------------- Intersect
def roots(G, o, psi):
    """(2, N) ray distances where the ray meets the sphere (NaN: none), solved in
    ``s - sc`` about the ray point closest to the centre (no cancellation)."""
    sc = dot(G.x1 - o, psi)
    b = o + sc[:, None] * psi - G.x1
    return quadratic_roots(np.ones_like(sc), dot(b, psi), dot(b, b) - G.T1 * G.T1) + sc


@twin(roots)
def _roots(G, o, psi):
    sc = dot(sub(G.x1, o), psi)
    b = sub(madd(o, sc, psi), G.x1)
    r0, r1 = quadratic_roots(1.0, dot(b, psi), dot(b, b) - G.T1 * G.T1)
    return r0 + sc, r1 + sc


def accept(G, o, psi, s, short):
    """Which roots are hits (not grazing), and their records (:class:`SphereHit`)."""
    w1, _ = unit(o + s[:, None] * psi - G.x1)
    ndp = G.T1**2 * np.abs(dot(w1, psi))
    return ndp > NDP_MIN, table(SphereHit, w1=w1, n_dot_psi=ndp)


@twin(accept)
def _accept(G, o, psi, s, short):
    w1, _ = unit(sub(madd(o, s, psi), G.x1))
    ndp = G.T1**2 * abs(dot(w1, psi))
    return ndp > NDP_MIN, SphereHit(w1, ndp)


# ------------------------------------------------------------------------- Evaluate
def contribution(G, psi, s, s_min, hit, short, medium):
    """``[rho(w2 . w1*) E(T1) / p(T1) = rho / st] ss rho0 E(s* - s_min) / |n . psi|`` per
    unit photon weight."""
    rho1 = phase_value(dot(G.w2, hit.w1), medium.g)
    return rho1 / medium.sigma_t * camera_term(-dot(hit.w1, psi), s - s_min, 0.0, medium) / \
        hit.n_dot_psi


@twin(contribution)
def _contribution(G, psi, s, s_min, hit, short, medium):
    rho1 = phase_value(dot(G.w2, hit.w1), medium.g)
    return rho1 / medium.sigma_t * camera_term(-dot(hit.w1, psi), s - s_min, 0.0, medium) / \
        hit.n_dot_psi


# ------------------------------------------------------------------------- MIS
def reconstruct(rec, G, hit):
    """The hit's full path: the photon's record with ``w1*``."""
    return rec.with_(w1=hit.w1)


@twin(reconstruct)
def _reconstruct(rec, G, hit):
    return with_w1(rec, hit.w1)


def density(rec, short):
    """Relative ``Q = q_{<=w2} p(t2) p(t1) t1^2 |w1 . psi|``."""
    n = scaled_normal(rec.w1, rec.t1)
    return q_to_w2(rec) * rec.pdf.t2 * rec.pdf.t1 * np.abs(dot(n, rec.psi))


@twin(density, weight=True)
def _density(rec, short):
    n = scaled_normal(rec.w1, rec.t1)
    return q_to_w2(rec) * rec.pdf.t2 * rec.pdf.t1 * abs(dot(n, rec.psi))


# ------------------------------------------------------------------------- drawing
def surface_grid(G, short, far):
    """(M, nt, nph, 3) the sphere of radius ``T1`` about ``x1``: the drawing's sweep grid."""
    return grids.sphere(G.x1, G.T1)


# ------------------------------------------------------------------------- Create
class PhotonSphere(Technique):
    """The photon sphere (long only)."""

    family = "spheres"
    min_k = 2
    compiled = Compiled(SphereGeometry, SphereHit, 2, roots, accept, visibility, contribution,
                        segments, reconstruct, density, staged=True)

    names = ("sphere", None)
    grid = staticmethod(surface_grid)

    def create(self, paths, ctx) -> Primitives:
        photon, K = select_photons(self, paths, ctx, back=1)
        g = gather(paths, photon, K)
        x1, T1 = g["x1"], g["T1"]
        lo, hi = clip_bounds(ctx.scene, x1 - T1[:, None], x1 + T1[:, None])
        # The shadow cull on the bounds before the cut below: the cut can leave them empty,
        # and a larger box only makes the cull more cautious.
        clear = cull.box_clear(ctx.blockers, ctx.scene, lo, hi)
        # Hits lie in the box outside the ball (.outside_box).
        cut_to_outside(ctx.scene, lo, hi, ball_edges(x1, T1))
        return Primitives(self.name, photon, K, lo, hi,
                          table(SphereGeometry, x1=x1, w2=g["w2"], T1=T1,
                                beta=beta1(paths, photon, K), clear=clear))

    def scaled_normal(self, rec):
        """(H, 3) scaled normal on records ``rec`` (the inspector's)."""
        return scaled_normal(rec.w1, rec.t1)
