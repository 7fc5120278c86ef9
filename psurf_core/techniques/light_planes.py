"""Photon planes through the light for multiple scattering: ``[u, t_K]`` and ``[v, t_K]``
(K = 2, 3; parallelogram and mesh lights).

A K-event photon path ``x_K -> x_{K-1} -> ... -> x_0`` starts at the light point
``x_K = x_L(u, v)``. Moving the light point along one light edge moves the whole path rigidly
(every later direction, flight and scattering angle is kept), so integrating that light
coordinate and the emission flight ``t_K`` sweeps a planar strip:

``x0 = x_L(u, V) + t_K w_K + R``, ``R = T_{K-1} w_{K-1} + ... + T_1 w_1`` (the photon's own
later segments), the plane through ``x_L(0, V) + R`` spanned by ``e_u`` and ``w_K``; scaled
normal ``n = e_u x w_K`` (``plane-ut``; ``plane-vt``: ``e_v``, ``u <-> v``). These are the
single-scattering strips ``ss-plane-ut`` / ``-vt`` (spec 3.2) carried over to K = 2, 3: at
K = 1 ``R = 0``.

Their normal is perpendicular to the light edge and to the emission direction, not to the
last direction ``w1``: where every surface that integrates ``t1`` (photon planes, cones)
is seen edge-on (``psi`` in their tangent planes, all of which hold ``w1``), a strip is
not, and for a light facing down seen from the side it is mostly seen face-on.

Per photon (``beta_1^-``: the photon's weight arriving at ``x1``, :func:`~.surface_common.beta1`)::

    X = beta_1^- [p(u,v) / p_kept] [E(t_K*)] ss rho0 E(s*) / |n . psi|

The photon sampled ``t_K`` (its ``beta_1^-`` holds ``E(T_K) ss / p(T_K) = ss / st``);
integrating it puts ``ss E(t_K*)`` in its place (factor ``st E(t_K*)``); its last flight
``T1`` stays sampled (``E / p = 1 / st``, with ``ss rho0`` at ``x0``): together
``E(t_K*) ss rho0``. The integrated light coordinate replaces ``1 / p(u, v)`` by
``1 / p_kept`` (``p(v)`` for ``[u, t_K]``; 1 on a parallelogram, the barycentric marginal on
a triangle, as in :mod:`.single_planes`). Short: ``t_K* < T_K`` and ``E(t_K*)`` dropped.

``Q`` (relative: the light-position pdf, and at K = 3 the emission pdf ``p(w3)``, are
dropped as for every member, ``path_record``)::

    K = 2: [p_kept / p(u,v)] p(w2) p(w1) p(t1) |(e_u x w2) . psi|
    K = 3: [p_kept / p(u,v)] p(w2) p(t2) p(w1) p(t1) |(e_u x w3) . psi|

(short: ``* E(t_K)``). The tracer samples every photon through its first three segments
whatever its vertices do (``trace_numpy.LOOKBACK``), so each photon that reaches segment K
sweeps a strip (spec 4); K >= 4 would need the photons' deeper prefixes, so ``max_k = 3``.
The rebuilt vertices ``x_{K-1}*, ..., x_1*`` must lie in the box and every rebuilt segment be
clear (the light itself blocks). Each numpy function has its compiled twin (``@twin``)
beneath it; see :mod:`.cones`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..geometry import inside_box
from ..kernels.jit import scalar, twin
from ..kernels.shadow import BLOCKED, CLEAR, status
from ..kernels.vec import madd
from ..path_record import photon_table, with_light_point, with_t2, with_t3
from ..pdfs import MESH, position_pdfs
from ..records import Vec, table
from ..records import replace as set_field
from . import grids
from . import shadow_cull as cull
from .base import Compiled, Primitives, Technique, cross, dot, segments_clear
from .bounds import strip_bounds
from .surface_common import (
    NDP_MIN,
    beta1,
    box_reach,
    cached_solve,
    camera_term,
    solve_columns,
)


class LPlaneGeometry(NamedTuple):
    """One light strip (a row of its ``Primitives.data``)."""

    org: Vec  # the strip's corner x_L(0, V) + R (ut) or x_L(U, 0) + R (vt)
    A: Vec  # the light edge e_u (ut) or e_v (vt)
    B: Vec  # w_K: the photon's emission direction
    amax: float  # upper limit of the light coordinate (1, or 1 - V / 1 - U on a triangle)
    TK: float  # the photon's emission flight (the short strip's extent)
    a0: float  # the photon's own light coordinate along A (U or V)
    xL: Vec  # the photon's light point x_K
    w2: Vec  # the middle segment (K = 3; unused at K = 2)
    T2: float  # its length (0 at K = 2)
    w1: Vec  # the last direction (kept)
    T1: float
    p_ratio: float  # p(u,v) / p_kept
    beta: Vec  # beta_1^- (W)
    clear0: float  # 1: no blocker can block x_K* -> x_{K-1}* of any hit (shadow_cull)
    clear1: float  # ... x_{K-1}* -> x_1* (K = 3)
    clear2: float  # ... x_1* -> x0
    eye: Vec  # the camera position the solver vectors below were computed for
    m0: Vec  # solver vectors (surface_common.plane_solver) for rays from ``eye``
    m1: Vec
    m2: Vec
    sdet: float


class LPlaneHit(NamedTuple):
    """One strip hit (a row of its ``Hits.data``)."""

    a: float  # the integrated light coordinate u* (ut) or v* (vt)
    b: float  # the integrated emission flight t_K*
    n_dot_psi: float  # |(A x B) . psi|


# ------------------------------------------------------------------------- geometry
def scaled_normal(which, eu, ev, wK):
    """(H, 3) ``e_u x w_K`` (ut) or ``e_v x w_K`` (vt)."""
    return cross(eu if which == "ut" else ev, wK)


def vertices(G, hit):
    """(H, 3) the rebuilt light point ``x_K*``, first scattering ``x_{K-1}*`` and ``x_1*``
    (``= x_{K-1}*`` at K = 2): the photon's path moved by ``(a* - a0) A``, its emission
    flight ``t_K*``."""
    xl = G.xL + (hit.a - G.a0)[:, None] * G.A
    xm = xl + hit.b[:, None] * G.B
    return xl, xm, xm + G.T2[:, None] * G.w2


@twin(vertices)
def _vertices(G, hit):
    xl = madd(G.xL, hit.a - G.a0, G.A)
    xm = madd(xl, hit.b, G.B)
    return xl, xm, madd(xm, G.T2, G.w2)


# ------------------------------------------------------------------------- Intersect
def roots(G, o, psi):
    """(1, N) ray distance of the strip's plane ``org + a A + b B`` (Cramer's rule,
    :func:`~.surface_common.cached_solve`; inf / NaN if parallel)."""
    return cached_solve(G.org, G.A, G.B, G, o, psi)[3][None]


@twin(roots)
def _roots(G, o, psi):
    return (cached_solve(G.org, G.A, G.B, G, o, psi)[3],)


def accept(G, o, psi, s, short):
    """Hits: ``0 <= a <= amax``, ``b > 0`` (``b < T_K`` if short), not grazing."""
    det, a, b, _ = cached_solve(G.org, G.A, G.B, G, o, psi)
    ndp = np.abs(det)
    with np.errstate(invalid="ignore"):
        ok = (ndp > NDP_MIN) & (a >= 0.0) & (a <= G.amax) & (b > 0.0)
        if short:
            ok &= b < G.TK
    return ok, table(LPlaneHit, a=a, b=b, n_dot_psi=ndp)


@twin(accept)
def _accept(G, o, psi, s, short):
    det, a, b, _ = cached_solve(G.org, G.A, G.B, G, o, psi)
    ndp = abs(det)
    ok = (ndp > NDP_MIN and a >= 0.0 and a <= G.amax and b > 0.0
          and (not short or b < G.TK))
    return ok, LPlaneHit(a, b, ndp)


# ------------------------------------------------------------------------- Evaluate
def segments(G, x0, hit):
    """The rebuilt path's segments: ``x_K* -> x_{K-1}*``, ``x_{K-1}* -> x_1*`` and
    ``x_1* -> x0``; at K = 2, where the middle one is a point, the first again (its twin's
    status there is CLEAR: nothing is deferred to it)."""
    return _pairs(G, x0, *vertices(G, hit))


def _pairs(G, x0, xl, xm, x1):
    """:func:`segments` from the rebuilt vertices."""
    k3 = (G.T2 > 0.0)[:, None]
    return [(xl, xm), (np.where(k3, xm, xl), np.where(k3, x1, xm)), (x1, x0)]


def visibility(G, x0, hit, medium, blockers):
    """(H,) bool: ``x_{K-1}*`` and ``x_1*`` in the box, and the rebuilt segments clear (each
    tested where its strip's ``clear`` flag does not already say so:
    :func:`.shadow_cull.strip_clear`)."""
    xl, xm, x1 = vertices(G, hit)
    ok = (inside_box(xm, medium.bounds_min, medium.bounds_max)
          & inside_box(x1, medium.bounds_min, medium.bounds_max))
    for (a, b), known in zip(_pairs(G, x0, xl, xm, x1), (G.clear0, G.clear1, G.clear2),
                             strict=True):
        ok = segments_clear(blockers, (a, b), ok=ok, known=known != 0.0)
    return ok


@twin(visibility, inline=True)
def _visibility(G, x0, hit, medium, blockers):
    xl, xm, x1 = vertices(G, hit)
    if not inside_box(xm, medium.bounds_min, medium.bounds_max):
        return BLOCKED, CLEAR, CLEAR
    st0 = CLEAR if G.clear0 != 0.0 else status(xl, xm, blockers)
    if st0 == BLOCKED:
        return BLOCKED, CLEAR, CLEAR
    st1 = CLEAR
    if G.T2 > 0.0:
        if not inside_box(x1, medium.bounds_min, medium.bounds_max):
            return st0, BLOCKED, CLEAR
        st1 = CLEAR if G.clear1 != 0.0 else status(xm, x1, blockers)
        if st1 == BLOCKED:
            return st0, BLOCKED, CLEAR
    return st0, st1, CLEAR if G.clear2 != 0.0 else status(x1, x0, blockers)


def contribution(G, psi, s, s_min, hit, short, medium):
    """``[p(u,v) / p_kept] [E(t_K*)] ss rho0 E(s* - s_min) / |n . psi|`` per unit photon
    weight (``beta_1^-``)."""
    extra = 0.0 if short else hit.b
    return G.p_ratio * camera_term(-dot(G.w1, psi), s - s_min, extra, medium) / hit.n_dot_psi


@twin(contribution)
def _contribution(G, psi, s, s_min, hit, short, medium):
    extra = 0.0 if short else hit.b
    return G.p_ratio * camera_term(-dot(G.w1, psi), s - s_min, extra, medium) / hit.n_dot_psi


# ------------------------------------------------------------------------- MIS
def reconstruct(rec, G, hit, which):
    """The hit's full path: the light point and every later vertex moved by
    ``(a* - a0) A``, ``t_K* = b``, the light coordinate ``a*``."""
    xl, xm, x1 = vertices(G, hit)
    k3 = (rec.K >= 3)[:, None]
    kept = rec.uv[:, 1] if which == "ut" else rec.uv[:, 0]
    uv = np.stack([hit.a, kept] if which == "ut" else [kept, hit.a], axis=1)
    return rec.with_(uv=uv, x3=np.where(k3, xl, rec.x3), x2=np.where(k3, xm, xl), x1=x1,
                     t3=np.where(k3[:, 0], hit.b, rec.t3), t2=np.where(k3[:, 0], rec.t2, hit.b))


@scalar
def _moved(row, G, hit, u, v):
    """``row`` with the light point moved (its position pdfs), the rebuilt ``x2*``, ``x1*``
    and ``t_K* = b`` (with their pdfs)."""
    xl, xm, x1 = vertices(G, hit)
    row = with_light_point(row, x1, u, v)  # x1 and the light-position pdfs
    if row.K >= 3:
        return with_t3(set_field(row, "x2", xm), hit.b)
    return with_t2(set_field(row, "x2", xl), hit.b)


def reconstruct_ut(rec, G, hit):
    """:func:`reconstruct` of ``plane-ut``."""
    return reconstruct(rec, G, hit, "ut")


@twin(reconstruct_ut)
def _reconstruct_ut(rec, G, hit):
    return _moved(rec, G, hit, hit.a, rec.uv[1])


def reconstruct_vt(rec, G, hit):
    """:func:`reconstruct` of ``plane-vt``."""
    return reconstruct(rec, G, hit, "vt")


@twin(reconstruct_vt)
def _reconstruct_vt(rec, G, hit):
    return _moved(rec, G, hit, rec.uv[0], hit.a)


def emission(rec):
    """(H, 3) the record's emission direction ``w_K`` (``w2`` at K = 2, ``w3`` at K = 3)."""
    return np.where((rec.K >= 3)[:, None], rec.w3, rec.w2)


@twin(emission)
def _emission(rec):
    return rec.w3 if rec.K >= 3 else rec.w2


def jacobian(p_kept, edge, rec):
    """(H,) ``[p_kept / p(u, v)] |(edge x w_K) . psi|`` on records ``rec``: the strip's change
    of variables with the light point's pdf traded for the kept coordinate's."""
    return p_kept / rec.pdf.uv * np.abs(dot(cross(edge, emission(rec)), rec.psi))


@twin(jacobian, weight=True)
def _jacobian(p_kept, edge, rec):
    return p_kept / rec.pdf.uv * abs(dot(cross(edge, emission(rec)), rec.psi))


def density(p_kept, edge, rec, short):
    """Relative ``Q`` of a light strip (module docstring): ``p_kept`` the pdf of the light
    coordinate it keeps, ``edge`` the one it sweeps."""
    k3 = rec.K >= 3
    q = (rec.pdf.w2 * np.where(k3, rec.pdf.t2, 1.0) * rec.pdf.w1 * rec.pdf.t1
         * jacobian(p_kept, edge, rec))
    return q * np.where(k3, rec.pdf.e3, rec.pdf.e2) if short else q


@twin(density, weight=True)
def _density(p_kept, edge, rec, short):
    k3 = rec.K >= 3
    q = (rec.pdf.w2 * (rec.pdf.t2 if k3 else 1.0) * rec.pdf.w1 * rec.pdf.t1
         * jacobian(p_kept, edge, rec))
    if short:
        return q * (rec.pdf.e3 if k3 else rec.pdf.e2)
    return q


def short_ratio(p_kept, edge, rec):
    """(H,) the short strip's ``Q`` over the path's pdfs (as ``planes.short_ratio``): its
    Jacobian over ``st`` (the short emission flight's ``E(t_K*) / p(t_K*)``)."""
    return jacobian(p_kept, edge, rec) / rec.st


@twin(short_ratio, weight=True)
def _short_ratio(p_kept, edge, rec):
    return jacobian(p_kept, edge, rec) / rec.st


def density_ut(rec, short):
    """``Q`` of ``plane-ut``: the kept ``v``, the swept edge ``e_u``."""
    return density(rec.pdf.v, rec.eu, rec, short)


@twin(density_ut, weight=True)
def _density_ut(rec, short):
    return density(rec.pdf.v, rec.eu, rec, short)


def density_vt(rec, short):
    """``Q`` of ``plane-vt``: the kept ``u``, the swept edge ``e_v``."""
    return density(rec.pdf.u, rec.ev, rec, short)


@twin(density_vt, weight=True)
def _density_vt(rec, short):
    return density(rec.pdf.u, rec.ev, rec, short)


def short_ratio_ut(rec):
    """``short_ratio`` of ``plane-ut-short``."""
    return short_ratio(rec.pdf.v, rec.eu, rec)


@twin(short_ratio_ut, weight=True)
def _short_ratio_ut(rec):
    return short_ratio(rec.pdf.v, rec.eu, rec)


def short_ratio_vt(rec):
    """``short_ratio`` of ``plane-vt-short``."""
    return short_ratio(rec.pdf.u, rec.ev, rec)


@twin(short_ratio_vt, weight=True)
def _short_ratio_vt(rec):
    return short_ratio(rec.pdf.u, rec.ev, rec)


_COMPILED = {
    which: Compiled(LPlaneGeometry, LPlaneHit, 1, roots, accept, visibility, contribution,
                    segments, rec_fn, dens_fn, ratio_fn, one_origin=True)
    for which, rec_fn, dens_fn, ratio_fn in (
        ("ut", reconstruct_ut, density_ut, short_ratio_ut),
        ("vt", reconstruct_vt, density_vt, short_ratio_vt))
}


# ------------------------------------------------------------------------- drawing
def surface_grid(G, short, far):
    """(M, 2, 2, 3) each strip's corners ``org + a A + b B``, ``a <= amax``, ``b <= T_K``
    (short; long: out to ``far``): the drawing's sweep grid (:mod:`.grids`)."""
    return grids.parallelograms(G.org, G.A, G.B, G.amax,
                                grids.lengths(G.TK if short else None, len(G), far))


# ------------------------------------------------------------------------- Create
class LightPlane(Technique):
    """``plane-ut`` / ``plane-vt``: the strip swept by a light coordinate and the emission
    flight, the rest of the photon's path carried along (K = 2, 3).

    Parameters
    ----------
    short : bool
        ``t_K* < T_K`` with ``E(t_K*)`` dropped (track length).
    which : {'ut', 'vt'}
    """

    family = "planes"
    min_k = 2
    max_k = 3
    lights = ("area", "mesh")

    grid = staticmethod(surface_grid)

    def __init__(self, short: bool = False, which: str = "ut"):
        if which not in ("ut", "vt"):
            raise ValueError(f"unknown light plane '{which}'")
        self.which = which
        self.short = bool(short)
        self.name = f"plane-{which}" + ("-short" if short else "")
        self.compiled = _COMPILED[which]

    def create(self, paths, ctx) -> Primitives:
        """One strip per photon and K (:class:`LPlaneGeometry`)."""
        scene = ctx.scene
        lmask = self.light_mask(paths, scene)
        # Every segment up to K is sampled whatever the photon's own vertices did (spec 4;
        # LOOKBACK = 3 >= K): only the light vertex (always valid) is kept.
        ks = list(self.k_range(scene, paths.depth))
        sel = [np.flatnonzero(lmask & paths.alive[:, k - 1] & paths.prefix_ok[:, 0])
               for k in ks]
        photon = np.concatenate(sel) if sel else np.zeros(0, np.int64)
        K = (np.concatenate([np.full(s.size, k) for s, k in zip(sel, ks, strict=True)])
             if sel else np.zeros(0, np.int64))
        # The light columns this strip reads (plain-array gathers: indexing the record table
        # itself copies every field), and the photon's segments from x_{K-1} on.
        tab = photon_table(paths, scene)
        ut = self.which == "ut"
        kind, pk, u, v = (tab[f][photon] for f in ("kind", "pk", "u", "v"))
        p_uv, p_u, p_v = position_pdfs(kind, pk, u, v)
        p_kept = p_v if ut else p_u
        # Back-side emission (zero f) and a kept coordinate of zero pdf are measure-zero.
        keep = (dot(paths.w[photon, 0], tab["axis"][photon]) > 0.0) & (p_kept > 0.0)
        photon, K, kind, u, v = photon[keep], K[keep], kind[keep], u[keep], v[keep]
        p_uv, p_kept = p_uv[keep], p_kept[keep]
        k3 = K >= 3
        xL, wK, TK = paths.x[photon, 0], paths.w[photon, 0], paths.t[photon, 0]
        w1, T1 = paths.w[photon, K - 1], paths.t[photon, K - 1]
        w2 = np.where(k3[:, None], paths.w[photon, K - 2], 0.0)
        T2 = np.where(k3, paths.t[photon, K - 2], 0.0)
        R = T2[:, None] * w2 + T1[:, None] * w1
        tri = kind == MESH
        if ut:
            A, a0, amax = tab["eu"][photon], u, np.where(tri, 1.0 - v, 1.0)
        else:
            A, a0, amax = tab["ev"][photon], v, np.where(tri, 1.0 - u, 1.0)
        org = xL - a0[:, None] * A + R
        edge = amax * np.linalg.norm(A, axis=1)
        lo, hi, hull, box, reach = strip_bounds(scene, org, A, amax, wK,
                                                TK if self.short else None, edge,
                                                (R, T1[:, None] * w1))
        # The first scatterings x_{K-1}* lie as far from the light edge (from start).
        start = xL - a0[:, None] * A
        reach_p = TK if self.short else box_reach(scene, start) + edge
        c0, c1, c2 = cull.strip_clear(ctx.blockers, scene, start, A, amax, wK, reach_p,
                                      reach, k3, T2[:, None] * w2, R, w2)
        data = table(LPlaneGeometry, org=org, A=A, B=wK, amax=amax, TK=TK, a0=a0, xL=xL,
                     w2=w2, T2=T2, w1=w1, T1=T1, p_ratio=p_uv / p_kept,
                     beta=beta1(paths, photon, K), clear0=c0, clear1=c1, clear2=c2,
                     **solve_columns(scene, org, A, wK))
        return Primitives(self.name, photon, K, lo, hi, data, hull=hull, box=box)

    def scaled_normal(self, rec):
        """(H, 3) ``e_u x w_K`` / ``e_v x w_K`` on records ``rec``."""
        return scaled_normal(self.which, rec.eu, rec.ev, emission(rec))

