"""Single-scattering photon planes from area and mesh lights (K = 1, spec 3.2).

The path is ``x_L(u, v) + t w = y(s)`` with ``x_L = p + u e_u + v e_v`` (parallelogram,
``(u, v) in [0, 1]^2``) or ``v0 + u (v1 - v0) + v (v2 - v0)`` (barycentric on the photon's
triangle ``k``, ``u, v >= 0, u + v <= 1``). Two of ``u, v, t`` are integrated:

* ``ss-plane-uv`` ``[u, v]``: the light (its triangle ``k``) translated by ``T w``;
  ``n = e_u x e_v``; ``Q = P_k p(w) st E(T) |n . psi|`` (no short variant: ``t`` is sampled);
* ``ss-plane-ut`` ``[u, t]``: the strip ``{p + v e_v + u e_u + t w}`` at the photon's ``v``;
  ``n = e_u x w``; ``Q = p(v) p(w) |n . psi|``;
* ``ss-plane-vt`` ``[v, t]``: the same with ``u <-> v``.

The light point moves: a hit's record gets ``x1 = x_L(u*, v*)`` and ``uv = (u*, v*)``. For a
triangle the strip runs over ``u in [0, 1 - v]`` (resp. ``v in [0, 1 - u]``) and the sampled
coordinate's pdf is the **marginal** of the uniform barycentric density, ``P_k 2 (1 - v)``
(resp. ``P_k 2 (1 - u)``), from :class:`~psurf_core.path_record.Pdfs`; the joint density
``2 P_k`` would be biased (spec 3.2). Evaluate, the bounded-scene rules and long/short are
those of :class:`~psurf_core.techniques.single.SingleScatter`.
"""

from __future__ import annotations

import numpy as np

from ..path_record import KIND_CODE, Pdfs
from ..scene import AreaLight, MeshLight
from .base import Hits, Primitives, dot, on_ray
from .single import SingleScatter, sweep_bounds


def light_edges(paths, photon: np.ndarray, scene):
    """Edges of the emitting patch of each photon.

    Returns
    -------
    eu, ev : (M, 3) float
        Parallelogram edges, or ``v1 - v0, v2 - v0`` of the photon's triangle.
    tri : (M,) bool
        Barycentric (mesh triangle) rather than a parallelogram.
    """
    m = photon.size
    eu, ev, tri = np.zeros((m, 3)), np.zeros((m, 3)), np.zeros(m, dtype=bool)
    light = paths.light[photon]
    for li, lt in enumerate(scene.lights):
        sel = light == li
        if isinstance(lt, AreaLight):
            eu[sel], ev[sel] = lt.edge_u, lt.edge_v
        elif isinstance(lt, MeshLight):
            t = lt.triangles[paths.tri[photon[sel]]]
            eu[sel], ev[sel], tri[sel] = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0], True
    return eu, ev, tri


def _det(a, b, c):
    """Row-wise ``det [a b c] = a . (b x c)``."""
    return dot(a, np.cross(b, c))


class SinglePlane(SingleScatter):
    """``ss-plane-{uv,ut,vt}``: the light translated by ``T w`` or a strip swept along ``w``.

    Parameters
    ----------
    short : bool
        Strips only: ``t* < T`` with ``E(t*)`` dropped (track-length).
    which : {'uv', 'ut', 'vt'}
    """

    lights = ("area", "mesh")

    def __init__(self, short: bool = False, which: str = "uv"):
        if which not in ("uv", "ut", "vt"):
            raise ValueError(f"unknown single-scattering plane '{which}'")
        if short and which == "uv":
            raise ValueError("ss-plane-uv has no short variant (t is a sampled dimension)")
        self.which = which
        self.short = bool(short)
        self.name = f"ss-plane-{which}" + ("-short" if short else "")

    # ------------------------------------------------------------------ Create
    def create(self, paths, ctx) -> Primitives:
        """One plane patch per photon.

        ``data``: ``org`` (M, 3) the point at parameters (0, 0), ``A``, ``B`` (M, 3) the
        spanning vectors (``e_u, e_v`` / ``e_u, w`` / ``e_v, w``), ``amax`` (M,) the first
        parameter's upper limit, ``tri`` (M,) bool, ``uv`` (M, 2) the photon's light
        coordinates, plus the emission record of :meth:`SingleScatter._emission`.
        """
        scene = ctx.scene
        photon = self._photons(paths, ctx)
        d = self._emission(paths, photon, scene)
        eu, ev, tri = light_edges(paths, photon, scene)
        uv = paths.light_uv[photon]
        x, w, T = d["x"], d["w"], d["T"]
        u, v = uv[:, 0], uv[:, 1]
        corner = x - u[:, None] * eu - v[:, None] * ev
        if self.which == "uv":
            org, A, B = corner + T[:, None] * w, eu, ev
            amax = np.ones(photon.size)
            far = np.where(tri[:, None], org, org + eu + ev)  # a triangle has 3 corners
            corners = [org, org + eu, org + ev, far]
            lo, hi = np.minimum.reduce(corners), np.maximum.reduce(corners)
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
        d.update(org=org, A=A, B=B, amax=amax, tri=tri, uv=uv)
        return self._prims(photon, lo, hi, ctx, d)

    # ------------------------------------------------------------------ Intersect
    def intersect(self, prims, rays, ray, prim, ctx) -> Hits:
        """Cramer's rule for ``org + a A + b B = o + s psi``; keep the patch's part."""
        d = prims.data
        A, B = d["A"][prim], d["B"][prim]
        o, psi = rays.o[ray], rays.d[ray]
        r = o - d["org"][prim]
        det = _det(A, B, -psi)  # = -(A x B) . psi: zero when psi lies in the plane
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            a = _det(r, B, -psi) * inv
            b = _det(A, r, -psi) * inv
            s = _det(A, B, r) * inv
        ok = np.isfinite(inv) & np.isfinite(s) & on_ray(rays, ray, s) & (a >= 0.0)
        if self.which == "uv":
            tri = d["tri"][prim]
            ok &= (b >= 0.0) & np.where(tri, a + b <= 1.0, (a <= 1.0) & (b <= 1.0))
        else:
            ok &= (a <= d["amax"][prim]) & (b > 0.0)
            if self.short:
                ok &= b < d["T"][prim]
        return self._hits(ray, prim, s, ok, a=a, b=b)

    # ------------------------------------------------------------------ Reconstruct
    def _rebuild(self, rec, hits, prims):
        """Move the light point (and ``uv``) to the hit's; ``t1* = b`` for strips."""
        d = prims.data
        p = hits.prim
        a, b = hits.data["a"], hits.data["b"]
        org, A, B = d["org"][p], d["A"][p], d["B"][p]
        uv = rec.uv.copy()
        if self.which == "uv":
            x1 = org - rec.t1[:, None] * rec.w1 + a[:, None] * A + b[:, None] * B
            uv[:, 0], uv[:, 1] = a, b
            return rec.with_(x1=x1, uv=uv)
        uv[:, 0 if self.which == "ut" else 1] = a
        return rec.with_(x1=org + a[:, None] * A, uv=uv, t1=b)

    # ------------------------------------------------------------------ MIS density
    def scaled_normal(self, rec):
        """``e_u x e_v`` / ``e_u x w`` / ``e_v x w``."""
        if self.which == "uv":
            return np.cross(rec.eu, rec.ev)
        return np.cross(rec.eu if self.which == "ut" else rec.ev, rec.w1)

    def sampled_position_pdf(self, pdf: Pdfs, rec) -> np.ndarray:
        """Pdf of the light-position dimensions this technique keeps: ``P_k`` (uv plane:
        the triangle choice only), the marginal ``p(v)`` ([u, t]) or ``p(u)`` ([v, t])."""
        if self.which == "uv":
            return np.where(rec.kind == KIND_CODE["mesh"], 0.5 * pdf.uv, 1.0)
        return pdf.v if self.which == "ut" else pdf.u

    def density(self, rec, ctx):
        """uv: ``P_k p(w) st E(T) |n . psi|``; strips: ``p(v) p(w) |n . psi|`` /
        ``p(u) p(w) |n . psi|`` (short: ``* E(t)``)."""
        pdf = Pdfs(rec, ctx.scene)
        q = self.sampled_position_pdf(pdf, rec) * pdf.w1
        q = q * np.abs(dot(self.scaled_normal(rec), rec.psi))
        if self.which == "uv":
            return q * pdf.t1
        return q * self._short_factor(rec, ctx)
