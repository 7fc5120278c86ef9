"""Single-scattering photon sphere ``ss-sphere`` ``[cos th, ph]`` (spec 3.2; K = 1).

The photon keeps its light point ``x`` and its flight ``T``; the emission direction is
integrated: ``x0 = x + T w(cos th, ph)`` sweeps the sphere of radius ``T`` about ``x`` (for
area / mesh lights its front hemisphere, ``(x0 - x) . n_L > 0``), at most two roots on a
ray. ``w*`` is rebuilt from the hit, and the scaled normal is ``n = T^2 w*``.

``Q = p(u,v) st E(T) T^2 |w . psi|``; with ``f / P_L`` of :mod:`.single`, ``p(u,v)`` and
``E(T)`` cancel: ``X = beta0 p(w*) ss rho0 E(s*) / (st T^2 |w* . psi|)`` (point light:
``I ss rho0 E(s*) / (st T^2 |w* . psi|)``). No short variant: ``t`` is a sampled dimension.

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
from .base import Compiled, Primitives, dot
from .cones import segments, visibility  # the path's one segment x1 -> x0
from .outside_box import ball_edges, cut_to_outside
from .single import SingleScatter, columns, sweep_bounds
from .spheres import reconstruct  # the photon's record with w1*
from .surface_common import NDP_MIN, camera_term, quadratic_roots, unit


class SphereGeometry(NamedTuple):
    """One single-scattering photon sphere (a row of its ``Primitives.data``)."""

    x1: Vec  # centre: the photon's light point
    axis: Vec  # a / n_L / n_k
    T1: float  # radius: the photon's sampled flight
    one_sided: float  # 1: area / mesh light (the front hemisphere only)
    kind: float  # light kind code (the emission pdf's)
    beta: Vec  # beta0 = Phi / P_L (W)
    clear: float  # 0: every hit's segment from the light point is tested (not culled: an
    # area light's own quad holds that point in its plane, where shadow_cull cannot decide)


class SphereHit(NamedTuple):
    """One sphere hit (a row of its ``Hits.data``)."""

    w1: Vec  # rebuilt direction (x0 - x) / |x0 - x|
    n_dot_psi: float  # |n . psi|, n = T^2 w1


# ------------------------------------------------------------------------- geometry
def scaled_normal(w1, t1):
    """(H, 3) ``dx0/dcos th x dx0/dph = t^2 w`` (up to sign)."""
    return (t1 * t1)[:, None] * w1


@twin(scaled_normal)
def _scaled_normal(w1, t1):
    return scale(t1 * t1, w1)


# ------------------------------------------------------------------------- Intersect
def roots(G, o, psi):
    """(2, N) ray distances where ``|y(s) - x| = T`` (NaN: none)."""
    oc = o - G.x1
    return quadratic_roots(1.0, dot(oc, psi), dot(oc, oc) - G.T1 * G.T1)


@twin(roots)
def _roots(G, o, psi):
    oc = sub(o, G.x1)
    return quadratic_roots(1.0, dot(oc, psi), dot(oc, oc) - G.T1 * G.T1)


def accept(G, o, psi, s, short):
    """Which roots are hits (area / mesh lights: the front hemisphere; not grazing), and
    their records (:class:`SphereHit`)."""
    v = o + s[:, None] * psi - G.x1
    w1, _ = unit(v)
    ok = (G.one_sided == 0.0) | (dot(v, G.axis) > 0.0)
    ndp = np.abs(dot(scaled_normal(w1, G.T1), psi))
    return ok & (ndp > NDP_MIN), table(SphereHit, w1=w1, n_dot_psi=ndp)


@twin(accept)
def _accept(G, o, psi, s, short):
    v = sub(madd(o, s, psi), G.x1)
    w1, _ = unit(v)
    ok = G.one_sided == 0.0 or dot(v, G.axis) > 0.0
    ndp = abs(dot(scaled_normal(w1, G.T1), psi))
    return ok and ndp > NDP_MIN, SphereHit(w1, ndp)


# ------------------------------------------------------------------------- Evaluate
def contribution(G, psi, s, s_min, hit, short, medium):
    """``p(w*) ss rho0 E(s* - s_min) / (st |n . psi|)`` per unit photon weight."""
    p_w = emission_pdf(G.kind, G.axis, hit.w1)
    return p_w * camera_term(-dot(hit.w1, psi), s - s_min, 0.0, medium) / \
        (medium.sigma_t * hit.n_dot_psi)


@twin(contribution)
def _contribution(G, psi, s, s_min, hit, short, medium):
    p_w = emission_pdf(G.kind, G.axis, hit.w1)
    return p_w * camera_term(-dot(hit.w1, psi), s - s_min, 0.0, medium) / \
        (medium.sigma_t * hit.n_dot_psi)


# ------------------------------------------------------------------------- MIS
def density(rec, short):
    """``Q = p(u,v) st E(t) t^2 |w . psi|``."""
    return rec.pdf.uv * rec.pdf.t1 * np.abs(dot(scaled_normal(rec.w1, rec.t1), rec.psi))


@twin(density, weight=True)
def _density(rec, short):
    return rec.pdf.uv * rec.pdf.t1 * abs(dot(scaled_normal(rec.w1, rec.t1), rec.psi))


# ------------------------------------------------------------------------- drawing
def surface_grid(G, short, far):
    """(M, nt, nph, 3) the sphere of radius ``T1`` about the light point ``x1`` (the front
    hemisphere about ``axis`` for an area / mesh light): the drawing's sweep grid."""
    one = G.one_sided.astype(bool)
    return grids.sphere(G.x1, G.T1, G.axis, np.where(one, 0.5 * np.pi, np.pi))


# ------------------------------------------------------------------------- Create
class SingleSphere(SingleScatter):
    """``ss-sphere`` ``[cos th, ph]``: sphere (area/mesh: front hemisphere) of radius ``T``."""

    compiled = Compiled(SphereGeometry, SphereHit, 2, roots, accept, visibility, contribution,
                        segments, reconstruct, density, staged=True)

    names = ("ss-sphere", None)
    grid = staticmethod(surface_grid)

    def create(self, paths, ctx) -> Primitives:
        """One sphere per photon (:class:`SphereGeometry`)."""
        photon = self._photons(paths, ctx)
        d = self._emission(paths, photon, ctx.scene)
        keep = d["T1"] > 0.0  # a zero radius is a measure-zero event and divides by T
        photon, d = photon[keep], {k: v[keep] for k, v in d.items()}
        n = d["axis"]
        side = np.sqrt(np.clip(1.0 - n * n, 0.0, None))  # hemisphere's reach across n
        hemi = d["one_sided"][:, None] != 0.0
        dmax = np.where(hemi & (n < 0), side, 1.0)
        dmin = np.where(hemi & (n > 0), -side, -1.0)
        lo, hi = sweep_bounds(d["x1"], dmin, dmax, d["T1"])
        # Hits lie in the box outside the ball (.outside_box).
        cut_to_outside(ctx.scene, lo, hi, ball_edges(d["x1"], d["T1"]))
        return self._prims(photon, lo, hi, ctx,
                           table(SphereGeometry, **columns(SphereGeometry, d, clear=0.0)))

    def scaled_normal(self, rec):
        """(H, 3) ``t^2 w`` on records ``rec`` (the inspector's)."""
        return scaled_normal(rec.w1, rec.t1)
