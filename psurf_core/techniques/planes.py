"""Photon planes ``[t1, t2]`` (Bitterli & Jarosz 17): 0D blur, unbiased (spec 3.1, first row).

For a K-event path the plane passes through ``x2`` (tracer vertex ``K-2``, the light when
K = 2) and is spanned by ``w2`` (segment ``K-1``) and ``w1`` (segment ``K``). The camera ray
hits it where ``x2 + t2 w2 + t1 w1 = c + s psi``; the Jacobian of that change of variables is
``|(w1 x w2) . psi|``.

* ``plane-t1t2`` (long): ``t1, t2 > 0``, contribution keeps ``exp(-st (t1 + t2))``;
* ``planes`` = ``plane-t1t2-short``: ``t2 < T2, t1 < T1`` (the photon's own flights, a
  parallelogram, as in Tungsten) and the transmittances are dropped (track-length).

``X = beta_2 E(t2) ss [rho/p(w1) = 1] E(t1) ss rho0 E(s) / |n . psi|``; with the weight read
after ``x1`` (``beta_1^- = beta_2 ss/st / q_roulette(x1)``: ``w1`` was sampled only if the
photon survived roulette at ``x1``) that is ``beta_1^- st ss rho0 E(...) / |n . psi|``.

``Q = q_{<=w2} p(w1) |(w1 x w2) . psi|`` (short: ``* E(t1) E(t2)``).

Cramer's rule for ``[w2 w1 -psi] (t2, t1, s) = c - x2 = b``: with triple-product identities
every determinant is a dot product of ``psi`` with a per-primitive vector
(:func:`~.surface_common.plane_solver`):
``det = (w1 x w2).psi, t2 det = (w1 x b).psi, t1 det = (b x w2).psi, s det = w2.(w1 x b)``.
For a pinhole camera ``b`` depends on the primitive only, so Create computes those vectors
once per plane for the camera's position and a candidate pair costs three dot products.
Each numpy function has its compiled twin (``@twin``) beneath it; see :mod:`.cones`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..kernels.jit import twin
from ..kernels.shadow import BLOCKED, CLEAR, status
from ..kernels.vec import madd
from ..path_record import with_t1, with_t2
from ..records import Vec, table
from . import grids
from . import shadow_cull as cull
from .base import (
    Compiled,
    Primitives,
    Technique,
    clip_bounds,
    cross,
    dot,
    segments_clear,
)
from .bounds import box_span, ray_bounds, wedge_hull
from .surface_common import (
    beta1,
    cached_solve,
    camera_term,
    own_segment,
    q_to_w2,
    rebuilt_clear,
    solve_columns,
)


class PlaneGeometry(NamedTuple):
    """One photon plane (a row of its ``Primitives.data``)."""

    x2: Vec  # plane origin: the photon's vertex x2
    w2: Vec
    w1: Vec
    T2: float  # the photon's flights (the short plane's extent)
    T1: float
    own: float  # 1: segment x2 -> x1 is the photon's own, clear for t2 < T2
    beta: Vec  # beta_1^- (W)
    eye: Vec  # the camera position the solver vectors below were computed for
    m0: Vec  # solver vectors (surface_common.plane_solver) for rays from ``eye``
    m1: Vec
    m2: Vec
    sdet: float
    clear: float  # 1: no blocker can block x1* -> x0 of any hit (shadow_cull.plane_clear)
    line: float  # 1: no blocker can block x2 -> x1* of any hit (shadow_cull.line_clear)


class PlaneHit(NamedTuple):
    """One plane hit (a row of its ``Hits.data``)."""

    t2: float
    t1: float
    n_dot_psi: float  # |(w1 x w2) . psi|


# ------------------------------------------------------------------------- Intersect
def roots(G, o, psi):
    """(1, N) ray distance of the plane hit."""
    return cached_solve(G.x2, G.w2, G.w1, G, o, psi)[3][None]


@twin(roots)
def _roots(G, o, psi):
    return (cached_solve(G.x2, G.w2, G.w1, G, o, psi)[3],)


def accept(G, o, psi, s, short):
    """Hits: in the quadrant ``t1, t2 > 0`` (the parallelogram ``t < T`` if short)."""
    det, t2, t1, _ = cached_solve(G.x2, G.w2, G.w1, G, o, psi)
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(1.0 / det) & (t2 > 0) & (t1 > 0)
        if short:
            ok &= (t2 < G.T2) & (t1 < G.T1)
    return ok, table(PlaneHit, t2=t2, t1=t1, n_dot_psi=np.abs(det))


@twin(accept)
def _accept(G, o, psi, s, short):
    det, t2, t1, _ = cached_solve(G.x2, G.w2, G.w1, G, o, psi)
    ok = np.isfinite(1.0 / det) and t2 > 0.0 and t1 > 0.0 and (
        not short or (t2 < G.T2 and t1 < G.T1))
    return ok, PlaneHit(t2, t1, abs(det))


# ------------------------------------------------------------------------- Evaluate
def segments(G, x0, hit):
    """The reconstructed path's segments: ``x2 -> x1*``, ``x1* -> x0``."""
    x1 = G.x2 + hit.t2[:, None] * G.w2
    return [(G.x2, x1), (x1, x0)]


def visibility(G, x0, hit, medium, blockers):
    """(H,) bool: ``x2 -> x1*`` counts (own segment, or ``x1*`` in the box and clear) and
    ``x1* -> x0`` is unoccluded (each tested where the plane's ``line`` / ``clear`` flag does
    not already say so)."""
    x1 = G.x2 + hit.t2[:, None] * G.w2
    known = (G.own != 0.0) & (hit.t2 < G.T2)
    return segments_clear(blockers, (x1, x0), known=G.clear != 0.0,
                          ok=rebuilt_clear(G.x2, x1, known, G.line != 0.0, medium, blockers))


@twin(visibility, inline=True)
def _visibility(G, x0, hit, medium, blockers):
    x1 = madd(G.x2, hit.t2, G.w2)
    st0 = rebuilt_clear(G.x2, x1, G.own != 0.0 and hit.t2 < G.T2, G.line != 0.0, medium,
                        blockers)
    st1 = CLEAR if st0 == BLOCKED or G.clear != 0.0 else status(x1, x0, blockers)
    return st0, st1, CLEAR


def contribution(G, psi, s, s_min, hit, short, medium):
    """``st [E(t1* + t2*)] ss rho0 E(s* - s_min) / |n . psi|`` per unit photon weight."""
    extra = 0.0 if short else hit.t1 + hit.t2
    return medium.sigma_t * camera_term(-dot(G.w1, psi), s - s_min, extra, medium) / \
        hit.n_dot_psi


@twin(contribution)
def _contribution(G, psi, s, s_min, hit, short, medium):
    extra = 0.0 if short else hit.t1 + hit.t2
    return medium.sigma_t * camera_term(-dot(G.w1, psi), s - s_min, extra, medium) / \
        hit.n_dot_psi


# ------------------------------------------------------------------------- MIS
def reconstruct(rec, G, hit):
    """The hit's full path: ``t2*``, ``t1*`` and ``x1* = x2 + t2* w2``."""
    return rec.with_(t2=hit.t2, t1=hit.t1, x1=rec.x2 + hit.t2[:, None] * rec.w2)


@twin(reconstruct)
def _reconstruct(rec, G, hit):
    return with_t1(with_t2(rec, hit.t2), hit.t1)  # (no compiled density reads x1)


def jacobian(rec):
    """(H,) ``|(w1 x w2) . psi|`` on records ``rec``: the plane's change of variables."""
    return np.abs(dot(cross(rec.w1, rec.w2), rec.psi))


@twin(jacobian, weight=True)
def _jacobian(rec):
    return abs(dot(cross(rec.w1, rec.w2), rec.psi))


def density(rec, short):
    """Relative ``Q = q_{<=w2} p(w1) |(w1 x w2) . psi|`` (short: ``* E(t1) E(t2)``)."""
    q = q_to_w2(rec) * rec.pdf.w1 * jacobian(rec)
    return q * rec.pdf.e1 * rec.pdf.e2 if short else q


@twin(density, weight=True)
def _density(rec, short):
    q = q_to_w2(rec) * rec.pdf.w1 * jacobian(rec)
    return q * rec.pdf.e1 * rec.pdf.e2 if short else q


def short_ratio(rec):
    """(H,) the short plane's ``Q`` over the path's pdfs (all but the light point's, which
    every member shares): ``|(w1 x w2) . psi| / st^2``, since each short flight's
    ``E(t*) / p(t*)`` is ``1 / st``. The MIS weights of an all-short set weigh these
    (:mod:`psurf_core.kernels.mis`; ``tests/test_photon_surfaces_multi_forms.py``)."""
    return jacobian(rec) / (rec.st * rec.st)


@twin(short_ratio, weight=True)
def _short_ratio(rec):
    return jacobian(rec) / (rec.st * rec.st)


# ------------------------------------------------------------------------- drawing
def surface_grid(G, short, far):
    """(M, 2, 2, 3) each plane's corners ``x2 + a w2 + b w1``, ``a <= T2``, ``b <= T1``
    (short; long: out to ``far``): the drawing's sweep grid (:mod:`.grids`)."""
    m = len(G)
    return grids.parallelograms(G.x2, G.w2, G.w1, grids.lengths(G.T2 if short else None, m, far),
                                grids.lengths(G.T1 if short else None, m, far))


# ------------------------------------------------------------------------- Create
class PhotonPlane(Technique):
    """The photon plane ``[t1, t2]``; ``short`` selects the Tungsten (track-length) variant."""

    family = "planes"
    min_k = 2
    compiled = Compiled(PlaneGeometry, PlaneHit, 1, roots, accept, visibility, contribution,
                        segments, reconstruct, density, short_ratio, one_origin=True)

    names = ("plane-t1t2", "plane-t1t2-short")
    grid = staticmethod(surface_grid)

    def create(self, paths, ctx) -> Primitives:
        scene = ctx.scene
        lmask = self.light_mask(paths, scene)
        photon, kk = [], []
        for k in self.k_range(scene, paths.depth):
            ok = lmask & paths.alive[:, k - 1] & paths.prefix_ok[:, k - 2]
            idx = np.flatnonzero(ok)
            photon.append(idx)
            kk.append(np.full(idx.size, k))
        photon = np.concatenate(photon) if photon else np.zeros(0, np.int64)
        K = np.concatenate(kk) if kk else np.zeros(0, np.int64)
        x2 = paths.x[photon, K - 2]
        w2 = paths.w[photon, K - 2]
        w1 = paths.w[photon, K - 1]
        T2 = paths.t[photon, K - 2]
        T1 = paths.t[photon, K - 1]
        own = own_segment(paths, photon, K - 1, x2, scene)
        if self.short:
            # A hit counts only with x1* = x2 + t2* w2 in the box: off the photon's own
            # segment (own = 0) that is t2* within the line's span of the box (bounds.py).
            a0, a1 = np.zeros_like(T2), T2.copy()
            off = np.flatnonzero(own == 0.0)
            t_in, t_out = box_span(scene, x2[off], w2[off])
            a0[off], a1[off] = np.maximum(t_in, 0.0), np.minimum(t_out, T2[off])
            start, la = x2 + a0[:, None] * w2, np.maximum(a1 - a0, 0.0)
            c = [start, start + la[:, None] * w2, start + T1[:, None] * w1,
                 start + la[:, None] * w2 + T1[:, None] * w1]
            lo, hi = np.minimum.reduce(c), np.maximum.reduce(c)
            lo[a1 < a0], hi[a1 < a0] = 1.0, 0.0  # no such t2*: no hit counts
        else:
            lo2, hi2 = ray_bounds(x2, w2, None)
            lo1, hi1 = ray_bounds(x2, w1, None)
            lo, hi = np.minimum(lo2, lo1), np.maximum(hi2, hi1)
        lo, hi = clip_bounds(scene, lo, hi)
        hull = (wedge_hull(scene, start, w2, w1, la, T1) if self.short
                else wedge_hull(scene, x2, w2, w1))
        # Long: x1* and x0 in the box, so t2* and t1* are at most its diagonal.
        diag = np.full(x2.shape[0], scene.medium.diagonal)
        reach = (T2, T1) if self.short else (diag, diag)
        data = table(PlaneGeometry, x2=x2, w2=w2, w1=w1, T2=T2, T1=T1,
                     own=own,
                     beta=beta1(paths, photon, K), **solve_columns(scene, x2, w2, w1),
                     clear=cull.plane_clear(ctx.blockers, scene, x2, w2, w1, *reach),
                     line=cull.line_clear(ctx.blockers, scene, x2, w2, reach[0]))
        return Primitives(self.name, photon, K, lo, hi, data, hull=hull)

    def scaled_normal(self, rec):
        """(H, 3) ``w1 x w2`` on records ``rec``."""
        return cross(rec.w1, rec.w2)
