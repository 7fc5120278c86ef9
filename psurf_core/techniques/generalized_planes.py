"""Generalized photon planes ``[t1, t3]`` and ``[t2, t3]`` (spec 3.1, rows 2 and 3; K >= 3).

Both integrate the distance ``t3`` into ``x2`` and one later distance, keeping the directions
``w3, w2, w1`` the photon sampled (x3 = tracer vertex ``K-3`` is kept):

* ``[t1, t3]``: ``x0 = x3 + t3 w3 + T2 w2 + t1 w1`` -- the plane through ``x3 + T2 w2``
  spanned by ``w3, w1``; scaled normal ``w1 x w3``; rebuilt ``x2* = x3 + t3* w3``,
  ``x1* = x2* + T2 w2``.
* ``[t2, t3]``: ``x0 = x3 + t3 w3 + t2 w2 + T1 w1`` -- the plane through ``x3 + T1 w1``
  spanned by ``w3, w2``; scaled normal ``w2 x w3``; rebuilt ``x2* = x3 + t3* w3``,
  ``x1* = x2* + t2* w2``.

Per photon ``X = beta_1^- st E(integrated) ss rho0 E(s) / |n . psi|``: the spec's
``beta_3 (ss/st) ss`` (``[t1,t3]``) and ``beta_3 ss^2/st`` (``[t2,t3]``) both equal
``st beta_3 (ss/st)^2 = st beta_1^-`` (see ``surface_common``). Long keeps
``E(t_a* + t3*)``; short requires ``t* < T`` for both and drops it.

``Q`` (``q_{<=w3}`` dropped): ``p(t2) p(w2) p(w1) |(w1 x w3).psi|`` (t1t3) or
``p(w2) p(w1) p(t1) |(w2 x w3).psi|`` (t2t3); short: ``* E(t_a + t3)``.

In the plane's own coordinates the hit is ``origin + t3 w3 + tv v`` (``v`` = ``w1`` or
``w2``); ``fixed`` in the geometry says which (1: ``[t1, t3]``, the step ``x2* -> x1*`` is the
photon's ``T2``). Each numpy function has its compiled twin (``@twin``) beneath it; see
:mod:`.cones`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..geometry import inside_box
from ..kernels.jit import twin
from ..kernels.shadow import BLOCKED, CLEAR, status
from ..kernels.vec import madd
from ..path_record import with_t1, with_t2, with_t3
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
from .bounds import ray_bounds, wedge_hull
from .surface_common import (
    NDP_MIN,
    beta1,
    cached_solve,
    camera_term,
    gather,
    own_segment,
    rebuilt_clear,
    select_photons,
    solve_columns,
)


class GPlaneGeometry(NamedTuple):
    """One generalized photon plane (a row of its ``Primitives.data``)."""

    origin: Vec  # x3 + T2 w2 (t1t3) or x3 + T1 w1 (t2t3)
    w3: Vec  # first spanning direction (integrated t3)
    v: Vec  # second: w1 (t1t3) or w2 (t2t3)
    Tu: float  # T3: the photon's flight along w3 (short limit of t3)
    Tv: float  # T1 or T2: the short limit along v
    x3: Vec  # the photon's vertex x3 (kept)
    w2: Vec
    w1: Vec
    T2: float
    fixed: float  # 1: [t1, t3] (x1* = x2* + T2 w2); 0: [t2, t3] (x1* = x2* + tv w2)
    own: float  # 1: segment x3 -> x2 is the photon's own, clear for t3 < T3
    beta: Vec  # beta_1^- (W)
    eye: Vec  # the camera position the solver vectors below were computed for
    m0: Vec  # solver vectors (surface_common.plane_solver) for rays from ``eye``
    m1: Vec
    m2: Vec
    sdet: float
    clear0: float  # 1: no blocker can block x3 -> x2* of any hit (shadow_cull.line_clear)
    clear1: float  # ... x2* -> x1* (shadow_cull.plane_clear)
    clear2: float  # ... x1* -> x0 (plane_clear, t1t3; swept_clear, t2t3)


class GPlaneHit(NamedTuple):
    """One generalized-plane hit (a row of its ``Hits.data``)."""

    t3: float  # integrated distance x3 -> x2*
    tv: float  # integrated t1 (t1t3) or t2 (t2t3)
    n_dot_psi: float  # |(v x w3) . psi|


# ------------------------------------------------------------------------- geometry
def scaled_normal(which, w3, w2, w1):
    """(H, 3) ``dx0/dxi1 x dx0/dxi2`` up to sign: ``w1 x w3`` (t1t3) or ``w2 x w3`` (t2t3)."""
    return cross(w1 if which == "t1t3" else w2, w3)


# ------------------------------------------------------------------------- Intersect
def roots(G, o, psi):
    """(1, N) ray distance of the plane hit (:func:`~.surface_common.cached_solve`; inf / NaN
    where the ray is parallel)."""
    return cached_solve(G.origin, G.w3, G.v, G, o, psi)[3][None]


@twin(roots)
def _roots(G, o, psi):
    return (cached_solve(G.origin, G.w3, G.v, G, o, psi)[3],)


def accept(G, o, psi, s, short):
    """Hits: inside the quadrant (parallelogram if short), not grazing."""
    det, t3, tv, _ = cached_solve(G.origin, G.w3, G.v, G, o, psi)
    ndp = np.abs(det)
    with np.errstate(invalid="ignore"):
        ok = (ndp > NDP_MIN) & (t3 > 0) & (tv > 0)
        if short:
            ok &= (t3 < G.Tu) & (tv < G.Tv)
    return ok, table(GPlaneHit, t3=t3, tv=tv, n_dot_psi=ndp)


@twin(accept)
def _accept(G, o, psi, s, short):
    det, t3, tv, _ = cached_solve(G.origin, G.w3, G.v, G, o, psi)
    ndp = abs(det)
    ok = ndp > NDP_MIN and t3 > 0.0 and tv > 0.0 and (not short or (t3 < G.Tu and tv < G.Tv))
    return ok, GPlaneHit(t3, tv, ndp)


# ------------------------------------------------------------------------- Evaluate
def vertices(G, hit):
    """Rebuilt ``x2* = x3 + t3* w3`` and ``x1* = x2* + (T2 | tv*) w2`` (H, 3)."""
    x2 = G.x3 + hit.t3[:, None] * G.w3
    step = np.where(G.fixed != 0.0, G.T2, hit.tv)
    return x2, x2 + step[:, None] * G.w2


@twin(vertices)
def _vertices(G, hit):
    x2 = madd(G.x3, hit.t3, G.w3)
    return x2, madd(x2, G.T2 if G.fixed != 0.0 else hit.tv, G.w2)


def segments(G, x0, hit):
    """The reconstructed path's segments: ``x3 -> x2*``, ``x2* -> x1*``, ``x1* -> x0``."""
    x2, x1 = vertices(G, hit)
    return [(G.x3, x2), (x2, x1), (x1, x0)]


def visibility(G, x0, hit, medium, blockers):
    """(H,) bool: ``x3 -> x2*`` counts (own segment, or ``x2*`` in the box and clear),
    ``x1*`` is in the box, and ``x2* -> x1* -> x0`` are unoccluded (each segment tested where
    the plane's ``clear0`` / ``clear1`` / ``clear2`` flag does not already say so)."""
    x2, x1 = vertices(G, hit)
    known = (G.own != 0.0) & (hit.t3 < G.Tu)
    ok = rebuilt_clear(G.x3, x2, known, G.clear0 != 0.0, medium, blockers)
    ok &= inside_box(x1, medium.bounds_min, medium.bounds_max)
    ok = segments_clear(blockers, (x2, x1), ok=ok, known=G.clear1 != 0.0)
    return segments_clear(blockers, (x1, x0), ok=ok, known=G.clear2 != 0.0)


@twin(visibility, inline=True)
def _visibility(G, x0, hit, medium, blockers):
    x2, x1 = vertices(G, hit)
    st0 = rebuilt_clear(G.x3, x2, G.own != 0.0 and hit.t3 < G.Tu, G.clear0 != 0.0, medium,
                        blockers)
    if st0 == BLOCKED:
        return BLOCKED, CLEAR, CLEAR
    if not inside_box(x1, medium.bounds_min, medium.bounds_max):
        return st0, BLOCKED, CLEAR
    st1 = CLEAR if G.clear1 != 0.0 else status(x2, x1, blockers)
    if st1 == BLOCKED:
        return st0, BLOCKED, CLEAR
    return st0, st1, CLEAR if G.clear2 != 0.0 else status(x1, x0, blockers)


def contribution(G, psi, s, s_min, hit, short, medium):
    """``st [E(t3* + tv*)] ss rho0 E(s* - s_min) / |n . psi|`` per unit photon weight."""
    extra = 0.0 if short else hit.t3 + hit.tv
    return medium.sigma_t * camera_term(-dot(G.w1, psi), s - s_min, extra, medium) / \
        hit.n_dot_psi


@twin(contribution)
def _contribution(G, psi, s, s_min, hit, short, medium):
    extra = 0.0 if short else hit.t3 + hit.tv
    return medium.sigma_t * camera_term(-dot(G.w1, psi), s - s_min, extra, medium) / \
        hit.n_dot_psi


# ------------------------------------------------------------------------- MIS: [t1, t3]
def reconstruct_t1t3(rec, G, hit):
    """The hit's full path: ``t3*``, ``t1*`` and the rebuilt ``x2*, x1*``."""
    x2, x1 = vertices(G, hit)
    return rec.with_(t3=hit.t3, t1=hit.tv, x2=x2, x1=x1)


@twin(reconstruct_t1t3)
def _reconstruct_t1t3(rec, G, hit):
    return with_t1(with_t3(rec, hit.t3), hit.tv)  # (no compiled density reads x2, x1)


def density_t1t3(rec, short):
    """Relative ``Q = p(t2) p(w2) p(w1) |(w1 x w3) . psi|`` (short: ``* E(t1 + t3)``)."""
    q = rec.pdf.t2 * rec.pdf.w2 * rec.pdf.w1 * np.abs(dot(cross(rec.w1, rec.w3), rec.psi))
    return q * rec.pdf.e1 * rec.pdf.e3 if short else q


@twin(density_t1t3, weight=True)
def _density_t1t3(rec, short):
    q = rec.pdf.t2 * rec.pdf.w2 * rec.pdf.w1 * abs(dot(cross(rec.w1, rec.w3), rec.psi))
    return q * rec.pdf.e1 * rec.pdf.e3 if short else q


# ------------------------------------------------------------------------- MIS: [t2, t3]
def reconstruct_t2t3(rec, G, hit):
    """The hit's full path: ``t3*``, ``t2*`` and the rebuilt ``x2*, x1*``."""
    x2, x1 = vertices(G, hit)
    return rec.with_(t3=hit.t3, t2=hit.tv, x2=x2, x1=x1)


@twin(reconstruct_t2t3)
def _reconstruct_t2t3(rec, G, hit):
    return with_t2(with_t3(rec, hit.t3), hit.tv)


def density_t2t3(rec, short):
    """Relative ``Q = p(w2) p(w1) p(t1) |(w2 x w3) . psi|`` (short: ``* E(t2 + t3)``)."""
    q = rec.pdf.t1 * rec.pdf.w2 * rec.pdf.w1 * np.abs(dot(cross(rec.w2, rec.w3), rec.psi))
    return q * rec.pdf.e2 * rec.pdf.e3 if short else q


@twin(density_t2t3, weight=True)
def _density_t2t3(rec, short):
    q = rec.pdf.t1 * rec.pdf.w2 * rec.pdf.w1 * abs(dot(cross(rec.w2, rec.w3), rec.psi))
    return q * rec.pdf.e2 * rec.pdf.e3 if short else q


_COMPILED = {
    which: Compiled(GPlaneGeometry, GPlaneHit, 1, roots, accept, visibility, contribution,
                    segments, rec_fn, dens_fn)
    for which, rec_fn, dens_fn in (("t1t3", reconstruct_t1t3, density_t1t3),
                                   ("t2t3", reconstruct_t2t3, density_t2t3))
}


# ------------------------------------------------------------------------- drawing
def surface_grid(G, short, far):
    """(M, 2, 2, 3) each plane's corners ``origin + a w3 + b v``, ``a <= Tu``, ``b <= Tv``
    (short; long: out to ``far``): the drawing's sweep grid (:mod:`.grids`)."""
    m = len(G)
    return grids.parallelograms(G.origin, G.w3, G.v, grids.lengths(G.Tu if short else None, m, far),
                                grids.lengths(G.Tv if short else None, m, far))


# ------------------------------------------------------------------------- Create
class GeneralizedPlane(Technique):
    """Generalized plane ``[t1, t3]`` (``which="t1t3"``) or ``[t2, t3]`` (``"t2t3"``)."""

    family = "planes"
    min_k = 3

    grid = staticmethod(surface_grid)

    def __init__(self, short: bool, which: str):
        if which not in ("t1t3", "t2t3"):
            raise ValueError(f"unknown generalized plane '{which}'")
        self.short = short
        self.which = which
        self.name = f"plane-{which}" + ("-short" if short else "")
        self.compiled = _COMPILED[which]

    def create(self, paths, ctx) -> Primitives:
        photon, K = select_photons(self, paths, ctx, back=3)
        g = gather(paths, photon, K)
        # The fixed sampled segment (T2 w2 or T1 w1) offsets the plane's origin from x3;
        # the other integrated direction is the kept w1 (t1t3) or w2 (t2t3).
        if self.which == "t1t3":
            origin, v, Tv = g["x3"] + g["T2"][:, None] * g["w2"], g["w1"], g["T1"]
        else:
            origin, v, Tv = g["x3"] + g["T1"][:, None] * g["w1"], g["w2"], g["T2"]
        u, Tu = g["w3"], g["T3"]
        if self.short:
            c = [origin, origin + Tu[:, None] * u, origin + Tv[:, None] * v,
                 origin + Tu[:, None] * u + Tv[:, None] * v]
            lo, hi = np.minimum.reduce(c), np.maximum.reduce(c)
        else:
            lo3, hi3 = ray_bounds(origin, u, None)
            lov, hiv = ray_bounds(origin, v, None)
            lo, hi = np.minimum(lo3, lov), np.maximum(hi3, hiv)
        lo, hi = clip_bounds(ctx.scene, lo, hi)
        hull = (wedge_hull(ctx.scene, origin, u, v, Tu, Tv) if self.short
                else wedge_hull(ctx.scene, origin, u, v))
        data = table(GPlaneGeometry, origin=origin, w3=u, v=v, Tu=Tu, Tv=Tv, x3=g["x3"],
                     w2=g["w2"], w1=g["w1"], T2=g["T2"], fixed=float(self.which == "t1t3"),
                     own=own_segment(paths, photon, K - 2, g["x3"], ctx.scene),
                     beta=beta1(paths, photon, K), **solve_columns(ctx.scene, origin, u, v),
                     **self._clear_flags(ctx, g, origin, Tu, Tv))
        return Primitives(self.name, photon, K, lo, hi, data, hull=hull)

    def _clear_flags(self, ctx, g, origin, Tu, Tv) -> dict:
        """The ``clear0..2`` columns (:mod:`.shadow_cull`): ``x2* = x3 + t3 w3`` with ``t3``
        up to ``Tu`` (short) or the box's diagonal (long: ``x3`` and ``x2*`` in the box), and
        likewise ``tv``; ``x1*`` is ``x2* + T2 w2`` (t1t3) or ``x2* + tv w2`` (t2t3), and
        ``x0`` is ``x1* + tv w1`` (t1t3: from the edge ``origin + [0, Tu] w3``) or
        ``x1* + T1 w1`` (t2t3: from the parallelogram ``x3 + [0, Tu] w3 + [0, Tv] w2``)."""
        scene, bl = ctx.scene, ctx.blockers
        x3, u, w2, w1 = g["x3"], g["w3"], g["w2"], g["w1"]
        if self.short:
            ru, rv = Tu, Tv
        else:
            ru = rv = np.full(x3.shape[0], scene.medium.diagonal)
        t1t3 = self.which == "t1t3"
        clear1 = cull.plane_clear(bl, scene, x3, u, w2, ru, g["T2"] if t1t3 else rv)
        if t1t3:
            clear2 = cull.plane_clear(bl, scene, origin, u, w1, ru, rv)
        else:
            a, b = x3 + ru[:, None] * u, x3 + rv[:, None] * w2
            clear2 = cull.swept_clear(bl, scene, [x3, a, b, a + rv[:, None] * w2], w1,
                                      g["T1"])
        return dict(clear0=cull.line_clear(bl, scene, x3, u, ru), clear1=clear1,
                    clear2=clear2)

    def scaled_normal(self, rec):
        """(H, 3) scaled normal on records ``rec`` (the inspector's)."""
        return scaled_normal(self.which, rec.w3, rec.w2, rec.w1)
