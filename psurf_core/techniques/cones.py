"""Photon cone ``[t1, ph1]`` (spec 3.1, cone row; K >= 2).

The photon keeps everything up to ``x1`` (tracer vertex ``K-1``) and the polar cosine
``c1 = w1 . w2`` of its last direction; the azimuth ``ph1`` and the distance ``t1`` are
integrated. ``x0 = x1 + t1 w1(ph1)`` sweeps one nappe of the cone with apex ``x1``, axis
``w2`` and half-angle ``th1``: ``((p - x1) . w2)^2 = c1^2 |p - x1|^2`` with
``sign((p - x1) . w2) = sign(c1)``, at most two roots on a ray. ``w1*`` is rebuilt from the
hit, and the scaled normal is ``n = t1 (w2 - c1 w1*)`` (``|n| = t1 s1``).

``X = beta_1^- [rho(c1) / p(c1) = 1/2pi] E(t1*) ss rho0 E(s*) / |n . psi|``; the short cone
needs ``t1* < T1`` and drops ``E(t1*)`` (track length).

``Q = q_{<=w2} p(t2) 2pi rho(c1) t1 |(w2 - c1 w1) . psi|`` (short: ``* E(t1)``).

Each function below is the numpy reference (arrays of hits); the function decorated
``@twin`` beneath it is its compiled twin (one hit, vectors as 3-tuples), which the walker
(:mod:`psurf_core.kernels.walk`) calls under the same name.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..kernels.jit import twin
from ..kernels.shadow import CLEAR, status
from ..kernels.vec import madd, norm, scale, sub
from ..path_record import with_t1, with_w1
from ..records import Vec, table
from . import grids
from . import shadow_cull as cull
from .base import Compiled, Primitives, Technique, clip_bounds, dot, segments_clear
from .surface_common import (
    NDP_MIN,
    beta1,
    box_reach,
    camera_term,
    cone_bounds,
    gather,
    q_to_w2,
    quadratic_roots,
    radial,
    ring,
    select_photons,
)


class ConeGeometry(NamedTuple):
    """One photon cone (a row of its ``Primitives.data``)."""

    x1: Vec  # apex: the photon's vertex x1
    w2: Vec  # axis: the direction that arrived at x1
    c1: float  # cos th1 = w1 . w2 of the photon's own w1
    T1: float  # the photon's sampled flight from x1
    beta: Vec  # beta_1^- (W)
    clear: float  # 1: no blocker can block x1 -> x0 of any hit (shadow_cull.hull_clear of
    # the footprint: the apex and the ring about the base at the reach)


class ConeHit(NamedTuple):
    """One cone hit (a row of its ``Hits.data``)."""

    t1: float  # integrated distance x1 -> x0
    w1: Vec  # rebuilt direction (x0 - x1) / t1
    n_dot_psi: float  # |n . psi|, n = t1 (w2 - c1 w1)


# ------------------------------------------------------------------------- geometry
def scaled_normal(w2, w1, t1):
    """(H, 3) ``dx0/dt1 x dx0/dph1 = t1 (w2 - c1 w1)`` (up to sign), ``c1 = w1 . w2``."""
    return t1[:, None] * (w2 - dot(w1, w2)[:, None] * w1)


@twin(scaled_normal)
def _scaled_normal(w2, w1, t1):
    return scale(t1, sub(w2, scale(dot(w1, w2), w1)))


# ------------------------------------------------------------------------- Intersect
def roots(G, o, psi):
    """(2, N) ray distances of the cone equation's roots (NaN: none), solved in ``s - sc``
    about the ray point closest to the apex (well conditioned)."""
    sc = dot(G.x1 - o, psi)
    b = o + sc[:, None] * psi - G.x1
    bw, pw, cc = dot(b, G.w2), dot(psi, G.w2), G.c1 * G.c1
    return quadratic_roots(pw * pw - cc, bw * pw - cc * dot(b, psi),
                           bw * bw - cc * dot(b, b)) + sc


@twin(roots)
def _roots(G, o, psi):
    sc = dot(sub(G.x1, o), psi)
    b = sub(madd(o, sc, psi), G.x1)
    bw, pw, cc = dot(b, G.w2), dot(psi, G.w2), G.c1 * G.c1
    r0, r1 = quadratic_roots(pw * pw - cc, bw * pw - cc * dot(b, psi),
                             bw * bw - cc * dot(b, b))
    return r0 + sc, r1 + sc


#: ``|c1|`` from which :func:`slant` reads a root's slant length off the axis, ``t1 = h / c1``
#: (no square root): a root leaves the cone equation's residual at rounding level of
#: ``|v|^2``, which this divides into an error of ~``eps / c1^2`` relative, 2e-12 here.
C1_DIRECT = 1e-2


def slant(v, w2, c1):
    """(H,) the signed slant length of the points ``x1 + v`` ((H, 3)) of the double cone
    ``(v . w2)^2 = c1^2 |v|^2``: ``|v|`` on the photon's nappe (``sign(v . w2) = sign(c1)``),
    ``-|v|`` on the mirror one. On the cone, ``v . w2 = c1 |v|``: read as ``h / c1`` where
    ``|c1| >= C1_DIRECT``, which spares a pair's square root (the pair's serial chain waits
    on it: the cone walker's CPU 0.985x without it, docs/study.md, "Square roots off the
    cones' and cylinders' chains"), else as ``|v|`` signed by the side."""
    h = dot(v, w2)
    with np.errstate(divide="ignore", invalid="ignore"):
        direct = h / c1
    far = np.linalg.norm(v, axis=1)
    return np.where(np.abs(c1) >= C1_DIRECT, direct, np.where(h * c1 > 0.0, far, -far))


@twin(slant)
def _slant(v, w2, c1):
    h = dot(v, w2)
    if abs(c1) >= C1_DIRECT:
        return h / c1
    far = norm(v)
    return far if h * c1 > 0.0 else -far


def inverse_slant(v, w2, c1, t1):
    """(H,) ``1 / t1`` of :func:`slant` ``t1`` ((H,)) of the points ``x1 + v``: read as
    ``c1 / h`` where :func:`slant` reads ``t1 = h / c1``, a division beside that one rather
    than after it (a hit's ``w1 = v / t1`` then waits on one division, not two: with the
    contribution's single division, the cone walker's CPU 0.97x, docs/study.md, "Each piece
    its own image"), else ``1 / t1``."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(np.abs(c1) >= C1_DIRECT, c1 / dot(v, w2), 1.0 / t1)


@twin(inverse_slant)
def _inverse_slant(v, w2, c1, t1):
    if abs(c1) >= C1_DIRECT:
        return c1 / dot(v, w2)
    return 1.0 / t1


def accept(G, o, psi, s, short):
    """Which roots are hits (the photon's nappe; ``t1 < T1`` if short; not grazing), and
    their records (:class:`ConeHit`)."""
    v = o + s[:, None] * psi - G.x1
    # The squared equation also holds on the mirror nappe (t1 < 0): keep the photon's side.
    t1 = slant(v, G.w2, G.c1)
    ok = t1 > 0
    if short:
        ok &= t1 < G.T1
    # 1 where not ok (t1 <= 0: unused there; the twin computes it, meaningless, anyway)
    w1 = v * np.where(ok, inverse_slant(v, G.w2, G.c1, t1), 1.0)[:, None]
    ndp = np.abs(dot(scaled_normal(G.w2, w1, t1), psi))
    return ok & (ndp > NDP_MIN), table(ConeHit, t1=t1, w1=w1, n_dot_psi=ndp)


@twin(accept)
def _accept(G, o, psi, s, short):
    v = sub(madd(o, s, psi), G.x1)
    t1 = slant(v, G.w2, G.c1)
    ok = t1 > 0.0 and (not short or t1 < G.T1)
    w1 = scale(inverse_slant(v, G.w2, G.c1, t1), v)  # meaningless where not ok: unused
    ndp = abs(dot(scaled_normal(G.w2, w1, t1), psi))
    return ok and ndp > NDP_MIN, ConeHit(t1, w1, ndp)


# ------------------------------------------------------------------------- Evaluate
def segments(G, x0, hit):
    """The reconstructed path's one segment to test: ``x1 -> x0``."""
    return [(G.x1, x0)]


def visibility(G, x0, hit, medium, blockers):
    """(H,) bool: ``x1 -> x0`` unoccluded (``x1`` is the photon's own vertex: in the box),
    tested where the cone's ``clear`` flag does not already say so."""
    return segments_clear(blockers, (G.x1, x0), known=G.clear != 0.0)


@twin(visibility, inline=True)
def _visibility(G, x0, hit, medium, blockers):
    return CLEAR if G.clear != 0.0 else status(G.x1, x0, blockers), CLEAR, CLEAR


def contribution(G, psi, s, s_min, hit, short, medium):
    """``[rho(c1)/p(c1) = 1/2pi] [E(t1*)] ss rho0 E(s* - s_min) / |n . psi|`` per unit
    photon weight."""
    extra = 0.0 if short else hit.t1
    return camera_term(-dot(hit.w1, psi), s - s_min, extra, medium) / \
        (2.0 * np.pi * hit.n_dot_psi)


@twin(contribution)
def _contribution(G, psi, s, s_min, hit, short, medium):
    extra = 0.0 if short else hit.t1
    return camera_term(-dot(hit.w1, psi), s - s_min, extra, medium) / \
        (2.0 * np.pi * hit.n_dot_psi)


# ------------------------------------------------------------------------- MIS
def reconstruct(rec, G, hit):
    """The hit's full path: the photon's record with ``t1*`` and ``w1*``."""
    return rec.with_(t1=hit.t1, w1=hit.w1)


@twin(reconstruct)
def _reconstruct(rec, G, hit):
    return with_w1(with_t1(rec, hit.t1), hit.w1)


def jacobian(rec):
    """(H,) ``|t1 (w2 - c1 w1) . psi|`` on records ``rec``: the cone's change of variables."""
    return np.abs(dot(scaled_normal(rec.w2, rec.w1, rec.t1), rec.psi))


@twin(jacobian, weight=True)
def _jacobian(rec):
    return abs(dot(scaled_normal(rec.w2, rec.w1, rec.t1), rec.psi))


def density(rec, short):
    """Relative ``Q = q_{<=w2} p(t2) 2pi rho(c1) t1 |(w2 - c1 w1) . psi|`` (short:
    ``* E(t1)``)."""
    q = q_to_w2(rec) * rec.pdf.t2 * rec.pdf.c1 * jacobian(rec)
    return q * rec.pdf.e1 if short else q


@twin(density, weight=True)
def _density(rec, short):
    q = q_to_w2(rec) * rec.pdf.t2 * rec.pdf.c1 * jacobian(rec)
    return q * rec.pdf.e1 if short else q


def short_ratio(rec):
    """(H,) the short cone's ``Q`` over the path's pdfs (as ``planes.short_ratio``):
    ``2 pi |t1 (w2 - c1 w1) . psi| / st``: the short flight gives ``E(t1*) / p(t1*) = 1 / st``,
    and ``p(c1) / p(w1) = 2 pi rho(c1) / rho(c1)`` is the azimuth's ``1 / p(ph1)``."""
    return 2.0 * np.pi * jacobian(rec) / rec.st


@twin(short_ratio, weight=True)
def _short_ratio(rec):
    return 2.0 * np.pi * jacobian(rec) / rec.st


# ------------------------------------------------------------------------- drawing
def surface_grid(G, short, far):
    """(M, 2, nph, 3) the nappe from apex ``x1`` about ``w2`` (``cos = c1``), out to ``T1``
    (short) or ``far``: the drawing's sweep grid (:mod:`.grids`)."""
    return grids.cone(G.x1, G.w2, G.c1, grids.lengths(G.T1 if short else None, len(G), far))


# ------------------------------------------------------------------------- Create
def footprint(scene, apex, axis, c, s, length=None):
    """(M, 1 + RING_VERTICES, 3) a nappe's footprint solid (``Primitives.cloud``): its apex
    and a ring circumscribing its circle at slant length ``length`` ((M,); None: as far as
    the medium box reaches from the apex, since a hit's ``x0`` is in the box), about unit
    ``axis`` with half-angle cosine ``c`` and sine ``s``. Every point of the nappe within
    that slant length lies in the solid."""
    L = box_reach(scene, apex) if length is None else length
    base = ring(apex + (L * c)[:, None] * axis, axis, L * s)
    return np.concatenate([apex[:, None], base], axis=1)


class PhotonCone(Technique):
    """The photon cone; ``short`` restricts ``t1* < T1`` (track-length)."""

    family = "cones"
    min_k = 2
    compiled = Compiled(ConeGeometry, ConeHit, 2, roots, accept, visibility, contribution,
                        segments, reconstruct, density, short_ratio, staged=True)

    names = ("cone", "cone-short")
    grid = staticmethod(surface_grid)

    def create(self, paths, ctx) -> Primitives:
        photon, K = select_photons(self, paths, ctx, back=1)
        g = gather(paths, photon, K)
        c1, s1, _ = radial(g["w1"], g["w2"])
        lo, hi = cone_bounds(g["x1"], g["w2"], c1, s1, g["T1"] if self.short else None)
        lo, hi = clip_bounds(ctx.scene, lo, hi)
        cloud = footprint(ctx.scene, g["x1"], g["w2"], c1, s1, g["T1"] if self.short else None)
        # x0 lies on the nappe within the slant length L (short: t1 < T1; long: x0 in the
        # box), so every segment x1 -> x0 lies in the hull of the footprint.
        clear = cull.hull_clear(ctx.blockers, ctx.scene,
                                [cloud[:, i] for i in range(cloud.shape[1])])
        return Primitives(self.name, photon, K, lo, hi,
                          table(ConeGeometry, x1=g["x1"], w2=g["w2"], c1=c1, T1=g["T1"],
                                beta=beta1(paths, photon, K), clear=clear),
                          cloud=cloud)

    def scaled_normal(self, rec):
        """(H, 3) scaled normal on records ``rec`` (the inspector's)."""
        return scaled_normal(rec.w2, rec.w1, rec.t1)
