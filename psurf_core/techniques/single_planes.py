"""Single-scattering photon planes from area and mesh lights (K = 1, spec 3.2).

The path is ``x_L(u, v) + t w = y(s)`` with ``x_L = p + u e_u + v e_v`` (parallelogram,
``(u, v) in [0, 1]^2``) or ``v0 + u (v1 - v0) + v (v2 - v0)`` (barycentric on the photon's
triangle ``k``, ``u, v >= 0, u + v <= 1``). Two of ``u, v, t`` are integrated; in the
patch's own coordinates a hit is ``org + a A + b B``:

* ``ss-plane-uv`` ``[u, v]``: the light (its triangle ``k``) translated by ``T w``
  (``A, B = e_u, e_v``); ``n = e_u x e_v``; ``Q = P_k p(w) st E(T) |n . psi|`` (no short
  variant: ``t`` is sampled);
* ``ss-plane-ut`` ``[u, t]``: the strip ``{p + v e_v + u e_u + t w}`` at the photon's ``v``
  (``A, B = e_u, w``); ``n = e_u x w``; ``Q = p(v) p(w) |n . psi|``;
* ``ss-plane-vt`` ``[v, t]``: the same with ``u <-> v``.

The light point moves: a hit's record gets ``x1 = x_L(u*, v*)`` and ``uv = (u*, v*)``. For a
triangle the strip runs over ``u in [0, 1 - v]`` (resp. ``v in [0, 1 - u]``) and the sampled
coordinate's pdf is the **marginal** of the uniform barycentric density, ``P_k 2 (1 - v)``
(resp. ``P_k 2 (1 - u)``, :func:`~psurf_core.pdfs.position_pdfs`); the joint density
``2 P_k`` would be biased (spec 3.2). With ``f / P_L`` of :mod:`.single` (the photon's own
``w``: ``p(w)`` cancels), ``X = beta0 [p(u,v) / P_k] ss rho0 E(s*) / (st |n . psi|)`` (uv)
and ``beta0 [p(u,v) / p(v)] [E(t*)] ss rho0 E(s*) / |n . psi|`` (strips; short: ``t* < T``,
``E(t*)`` dropped). Photons emitted backwards (``w . n_L <= 0``, measure zero) make no
patch. Each numpy function has its compiled twin (``@twin``) beneath it; see :mod:`.cones`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..kernels.jit import twin
from ..kernels.shadow import CLEAR, status
from ..kernels.vec import madd
from ..path_record import photon_table, with_light_point, with_t1
from ..pdfs import MESH, position_pdfs
from ..records import Vec, table
from . import grids
from .base import Compiled, Primitives, cross, dot, segments_clear
from .bounds import wedge_hull
from .single import SingleScatter, columns, sweep_bounds
from .surface_common import NDP_MIN, box_reach, cached_solve, camera_term, solve_columns


class SPlaneGeometry(NamedTuple):
    """One single-scattering plane patch (a row of its ``Primitives.data``)."""

    org: Vec  # the point at patch coordinates (0, 0)
    A: Vec  # spanning vectors: e_u, e_v (uv) / e_u, w (ut) / e_v, w (vt)
    B: Vec
    amax: float  # upper limit of a on a strip (1, or 1 - v / 1 - u on a triangle)
    tri: float  # 1: barycentric (a mesh triangle), 0: a parallelogram
    strip: float  # 1: [u, t] or [v, t] (b is t*), 0: [u, v] (a, b are u*, v*)
    w: Vec  # the photon's emission direction (kept)
    T1: float  # the photon's sampled flight (the short strip's extent)
    u: float  # the photon's light coordinates (the kept one stays)
    v: float
    p_uv: float  # the joint light-position pdf p(u,v) (1, or 2 P_k)
    p_kept: float  # pdf of the kept position dimensions (P_k / p(v) / p(u))
    beta: Vec  # beta0 = Phi / P_L (W)
    eye: Vec  # the camera position the solver vectors below were computed for
    m0: Vec  # solver vectors (surface_common.plane_solver) for rays from ``eye``
    m1: Vec
    m2: Vec
    sdet: float


class SPlaneHit(NamedTuple):
    """One plane hit (a row of its ``Hits.data``)."""

    a: float  # first patch coordinate: u* (uv, ut) or v* (vt)
    b: float  # second: v* (uv) or t* (strips)
    n_dot_psi: float  # |(A x B) . psi|


# ------------------------------------------------------------------------- geometry
def scaled_normal(which, eu, ev, w1):
    """(H, 3) ``e_u x e_v`` (uv), ``e_u x w`` (ut) or ``e_v x w`` (vt)."""
    if which == "uv":
        return cross(eu, ev)
    return cross(eu if which == "ut" else ev, w1)


def light_point(G, hit):
    """(H, 3) the hit's light point ``x_L(u*, v*)``: ``org - T w + a A + b B`` (uv; ``org``
    is the translated corner) or ``org + a A`` (strips)."""
    uv = G.org - G.T1[:, None] * G.w + hit.a[:, None] * G.A + hit.b[:, None] * G.B
    return np.where((G.strip != 0.0)[:, None], G.org + hit.a[:, None] * G.A, uv)


@twin(light_point)
def _light_point(G, hit):
    if G.strip != 0.0:
        return madd(G.org, hit.a, G.A)
    return madd(madd(madd(G.org, -G.T1, G.w), hit.a, G.A), hit.b, G.B)


# ------------------------------------------------------------------------- Intersect
def roots(G, o, psi):
    """(1, N) ray distance of the patch's plane ``org + a A + b B`` (Cramer's rule,
    :func:`~.surface_common.cached_solve`; inf / NaN if parallel)."""
    return cached_solve(G.org, G.A, G.B, G, o, psi)[3][None]


@twin(roots)
def _roots(G, o, psi):
    return (cached_solve(G.org, G.A, G.B, G, o, psi)[3],)


def accept(G, o, psi, s, short):
    """Hits: inside the patch (the translated light, or the strip ``b > 0``, ``b < T`` if
    short), not grazing."""
    det, a, b, _ = cached_solve(G.org, G.A, G.B, G, o, psi)
    ndp = np.abs(det)
    with np.errstate(invalid="ignore"):
        patch = (b >= 0.0) & np.where(G.tri != 0.0, a + b <= 1.0, (a <= 1.0) & (b <= 1.0))
        strip = (a <= G.amax) & (b > 0.0)
        if short:
            strip &= b < G.T1
        ok = (ndp > NDP_MIN) & (a >= 0.0) & np.where(G.strip != 0.0, strip, patch)
    return ok, table(SPlaneHit, a=a, b=b, n_dot_psi=ndp)


@twin(accept)
def _accept(G, o, psi, s, short):
    det, a, b, _ = cached_solve(G.org, G.A, G.B, G, o, psi)
    ndp = abs(det)
    if G.strip != 0.0:
        inside = a <= G.amax and b > 0.0 and (not short or b < G.T1)
    elif G.tri != 0.0:
        inside = b >= 0.0 and a + b <= 1.0
    else:
        inside = b >= 0.0 and a <= 1.0 and b <= 1.0
    return ndp > NDP_MIN and a >= 0.0 and inside, SPlaneHit(a, b, ndp)


# ------------------------------------------------------------------------- Evaluate
def segments(G, x0, hit):
    """The reconstructed path's one segment to test: ``x_L(u*, v*) -> x0``."""
    return [(light_point(G, hit), x0)]


def visibility(G, x0, hit, medium, blockers):
    """(H,) bool: ``x_L(u*, v*) -> x0`` unoccluded (the light lies in the box, spec 4)."""
    return segments_clear(blockers, (light_point(G, hit), x0))


@twin(visibility)
def _visibility(G, x0, hit, medium, blockers):
    return status(light_point(G, hit), x0, blockers), CLEAR, CLEAR


def contribution(G, psi, s, s_min, hit, short, medium):
    """``[p(u,v) / P_k] ss rho0 E(s* - s_min) / (st |n . psi|)`` (uv) or ``[p(u,v) / p(v)]
    [E(t*)] ss rho0 E(s* - s_min) / |n . psi|`` (strips) per unit photon weight."""
    strip = G.strip != 0.0
    extra = np.where(strip & (not short), hit.b, 0.0)
    den = np.where(strip, 1.0, medium.sigma_t) * hit.n_dot_psi
    return G.p_uv / G.p_kept * camera_term(-dot(G.w, psi), s - s_min, extra, medium) / den


@twin(contribution)
def _contribution(G, psi, s, s_min, hit, short, medium):
    strip = G.strip != 0.0
    extra = hit.b if strip and not short else 0.0
    den = (1.0 if strip else medium.sigma_t) * hit.n_dot_psi
    return G.p_uv / G.p_kept * camera_term(-dot(G.w, psi), s - s_min, extra, medium) / den


# ------------------------------------------------------------------------- MIS
def reconstruct_uv(rec, G, hit):
    """The hit's full path: the light point moved to ``x_L(u*, v*)``, ``uv = (u*, v*)``."""
    return rec.with_(x1=light_point(G, hit), uv=np.stack([hit.a, hit.b], axis=1))


@twin(reconstruct_uv)
def _reconstruct_uv(rec, G, hit):
    return with_light_point(rec, light_point(G, hit), hit.a, hit.b)


def reconstruct_ut(rec, G, hit):
    """The hit's full path: light point ``x_L(u*, v)``, ``t1* = b``."""
    return rec.with_(x1=light_point(G, hit), uv=np.stack([hit.a, G.v], axis=1), t1=hit.b)


@twin(reconstruct_ut)
def _reconstruct_ut(rec, G, hit):
    return with_t1(with_light_point(rec, light_point(G, hit), hit.a, G.v), hit.b)


def reconstruct_vt(rec, G, hit):
    """The hit's full path: light point ``x_L(u, v*)``, ``t1* = b``."""
    return rec.with_(x1=light_point(G, hit), uv=np.stack([G.u, hit.a], axis=1), t1=hit.b)


@twin(reconstruct_vt)
def _reconstruct_vt(rec, G, hit):
    return with_t1(with_light_point(rec, light_point(G, hit), G.u, hit.a), hit.b)


def density_uv(rec, short):
    """``Q = P_k p(w) st E(T) |(e_u x e_v) . psi|`` (``P_k`` = 1 on a parallelogram)."""
    p_k = np.where(rec.kind == MESH, 0.5 * rec.pdf.uv, 1.0)
    return p_k * rec.pdf.w1 * np.abs(dot(cross(rec.eu, rec.ev), rec.psi)) * rec.pdf.t1


@twin(density_uv, weight=True)
def _density_uv(rec, short):
    p_k = 0.5 * rec.pdf.uv if rec.kind == MESH else 1.0
    return p_k * rec.pdf.w1 * abs(dot(cross(rec.eu, rec.ev), rec.psi)) * rec.pdf.t1


def strip_density(p_kept, edge, rec, short):
    """``Q = p_kept p(w) |(edge x w) . psi|`` of a strip (short: ``* E(t)``)."""
    q = p_kept * rec.pdf.w1 * np.abs(dot(cross(edge, rec.w1), rec.psi))
    return q * rec.pdf.e1 if short else q


@twin(strip_density)
def _strip_density(p_kept, edge, rec, short):
    q = p_kept * rec.pdf.w1 * abs(dot(cross(edge, rec.w1), rec.psi))
    return q * rec.pdf.e1 if short else q


def density_ut(rec, short):
    """``Q = p(v) p(w) |(e_u x w) . psi|`` (short: ``* E(t)``)."""
    return strip_density(rec.pdf.v, rec.eu, rec, short)


@twin(density_ut, weight=True)
def _density_ut(rec, short):
    return strip_density(rec.pdf.v, rec.eu, rec, short)


def density_vt(rec, short):
    """``Q = p(u) p(w) |(e_v x w) . psi|`` (short: ``* E(t)``)."""
    return strip_density(rec.pdf.u, rec.ev, rec, short)


@twin(density_vt, weight=True)
def _density_vt(rec, short):
    return strip_density(rec.pdf.u, rec.ev, rec, short)


_COMPILED = {
    which: Compiled(SPlaneGeometry, SPlaneHit, 1, roots, accept, visibility, contribution,
                    segments, rec_fn, dens_fn, one_origin=True)
    for which, rec_fn, dens_fn in (("uv", reconstruct_uv, density_uv),
                                   ("ut", reconstruct_ut, density_ut),
                                   ("vt", reconstruct_vt, density_vt))
}


# ------------------------------------------------------------------------- drawing
def surface_grid(G, short, far):
    """(M, 2, 2, 3) each patch's corners: ``org + a A + b B`` over the light's parallelogram
    or triangle (``[u, v]``), or over ``a <= amax`` and ``b <= T1`` (short) or ``far`` (a
    strip): the drawing's sweep grid (:mod:`.grids`)."""
    tri = G.tri.astype(bool)
    a = np.linspace(0, 1, 2)
    uv = (G.org[:, None, None, :] + a[None, :, None, None] * G.A[:, None, None]
          + (a[None, None, :, None] * np.where(tri[:, None, None, None],
                                               1.0 - a[None, :, None, None], 1.0))
          * G.B[:, None, None])
    tb = grids.lengths(G.T1 if short else None, len(G), far)
    strip = grids.parallelograms(G.org, G.A, G.B, G.amax, tb)
    return np.where((G.strip != 0.0)[:, None, None, None], strip, uv)


# ------------------------------------------------------------------------- Create
class SinglePlane(SingleScatter):
    """``ss-plane-{uv,ut,vt}``: the light translated by ``T w`` or a strip swept along ``w``.

    Parameters
    ----------
    short : bool
        Strips only: ``t* < T`` with ``E(t*)`` dropped (track-length).
    which : {'uv', 'ut', 'vt'}
    """

    lights = ("area", "mesh")

    grid = staticmethod(surface_grid)

    def __init__(self, short: bool = False, which: str = "uv"):
        if which not in ("uv", "ut", "vt"):
            raise ValueError(f"unknown single-scattering plane '{which}'")
        if short and which == "uv":
            raise ValueError("ss-plane-uv has no short variant (t is a sampled dimension)")
        self.which = which
        self.short = bool(short)
        self.name = f"ss-plane-{which}" + ("-short" if short else "")
        self.compiled = _COMPILED[which]

    def sampled_position_pdf(self, kind, p_uv, p_u, p_v):
        """(M,) pdf of the light-position dimensions this technique keeps: ``P_k`` (uv
        plane: the triangle choice only; 1 on a parallelogram), the marginal ``p(v)``
        ([u, t]) or ``p(u)`` ([v, t]), from the joint and marginal pdfs (M,)."""
        if self.which == "uv":
            return np.where(kind == MESH, 0.5 * p_uv, 1.0)
        return p_v if self.which == "ut" else p_u

    def create(self, paths, ctx) -> Primitives:
        """One plane patch per photon (:class:`SPlaneGeometry`)."""
        scene = ctx.scene
        photon = self._photons(paths, ctx)
        lt = photon_table(paths, scene)[photon]
        p_uv, p_u, p_v = position_pdfs(lt.kind, lt.pk, lt.u, lt.v)
        p_kept = self.sampled_position_pdf(lt.kind, p_uv, p_u, p_v)
        # Back-side emission (zero f) and a kept coordinate of zero pdf (zero Q, a
        # triangle's edge) are measure-zero: no patch.
        keep = (dot(paths.w[photon, 0], lt.axis) > 0.0) & (p_kept > 0.0)
        photon, lt, p_uv, p_kept = photon[keep], lt[keep], p_uv[keep], p_kept[keep]
        d = self._emission(paths, photon, scene)
        eu, ev, u, v = lt.eu, lt.ev, lt.u, lt.v
        tri = lt.kind == MESH
        x, w, T = d["x1"], d["w"], d["T1"]
        if self.which == "uv":
            corner = x - u[:, None] * eu - v[:, None] * ev
            org, A, B = corner + T[:, None] * w, eu, ev
            amax = np.ones(photon.size)
            far = np.where(tri[:, None], org, org + eu + ev)  # a triangle has 3 corners
            corners = [org, org + eu, org + ev, far]
            lo, hi = np.minimum.reduce(corners), np.maximum.reduce(corners)
            # The patch as a convex polygon (a triangle's last vertex repeated).
            hull = np.stack([org, org + eu, np.where(tri[:, None], org + ev, far), org + ev],
                            axis=1)
        else:
            if self.which == "ut":
                org, A, amax = x - u[:, None] * eu, eu, np.where(tri, 1.0 - v, 1.0)
            else:
                org, A, amax = x - v[:, None] * ev, ev, np.where(tri, 1.0 - u, 1.0)
            B = w
            end = org + amax[:, None] * A
            lo0, hi0 = np.minimum(org, end), np.maximum(org, end)
            # The base segment swept along w (to T for short strips, to infinity for long).
            lo, _ = sweep_bounds(lo0, w, w, T if self.short else None)
            _, hi = sweep_bounds(hi0, w, w, T if self.short else None)
            # The strip as a parallelogram out to t = T (short), or as far as a point of it
            # in the box can be from its base (the box's reach from org plus the base's
            # length): the spans then visit the pixels it covers, not its whole rectangle.
            reach = T if self.short else box_reach(scene, org) + amax * np.linalg.norm(A, axis=1)
            hull = wedge_hull(scene, org, A, B, amax, reach)
        data = table(SPlaneGeometry, **columns(
            SPlaneGeometry, d, org=org, A=A, B=B, amax=amax, tri=tri.astype(float),
            strip=float(self.which != "uv"), u=u, v=v, p_uv=p_uv, p_kept=p_kept,
            **solve_columns(scene, org, A, B)))
        return self._prims(photon, lo, hi, ctx, data, hull=hull)

    def scaled_normal(self, rec):
        """(H, 3) ``e_u x e_v`` / ``e_u x w`` / ``e_v x w`` on records ``rec``."""
        return scaled_normal(self.which, rec.eu, rec.ev, rec.w1)
