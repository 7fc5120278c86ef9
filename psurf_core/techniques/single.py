"""Single-scattering photon surfaces about the light (K = 1): sphere, cone, disk (spec 3.2).

A K = 1 path is ``x1 -> x0``: ``x1`` on the light, ``x0 = x1 + t1 w1 = y(s)`` on the camera
ray. Each technique keeps some of the photon's emission dimensions and integrates two
others against the camera-ray delta:

* ``ss-sphere`` ``[cos th, ph]``: sphere of radius ``T`` about the photon's light point (a
  hemisphere about ``n_L`` for area/mesh lights), no short variant;
* ``ss-cone`` ``[t, ph]``: one nappe, apex the light point, axis ``a`` / ``n_L`` / ``n_k``,
  the photon's ``c = w . axis``;
* ``ss-disk`` ``[t, cos th]``: the half-plane through the axis containing ``w``.

Evaluate is the generic ``X = f / (P_L Q_i)`` of spec section 2 on the reconstructed path,
with ``Q_i`` = :meth:`density` (the MIS density, so Evaluate and MIS can never disagree).
Emission is importance-sampled exactly (uniform sphere for the isotropic point light,
cosine-weighted for area/mesh lights), so ``beta0 = paths.beta[:, 0] = Phi / P_L`` equals
``Le-term / (P_L p(u,v) p(w))`` for every front-side direction, and

``f / P_L = beta0 p(u,v) p(w*) E(t*) ss rho0 E(s*)``

(``p(u,v)`` = 1 for point lights and parallelograms, ``2 P_k`` for mesh triangles; ``p(w*)``
the emission pdf at the *reconstructed* direction). Bounded-scene rules (spec section 4):
``x0`` on the ray's in-box interval (Intersect), emission one-sided (``w*.n_L > 0``), the
segment light -> x0 unoccluded (one shadow test; the emitter's own surface is skipped by
``Blockers.occluded``'s end offsets). Long: keep ``E(t*)``; short: ``t* < T``, ``E(t*)`` is
dropped from ``f`` and multiplies ``Q`` (track-length), which is the same ``f / Q``.
"""

from __future__ import annotations

import numpy as np

from ..path_record import KIND_CODE, Pdfs, photon_record
from ..sampling import phase_value
from .base import Hits, Primitives, Technique, camera_transmittance, clip_bounds, dot, on_ray


# ------------------------------------------------------------------------- helpers
def quadratic_roots(a: np.ndarray, b: np.ndarray, c: np.ndarray):
    """Both real roots ``r1, r2`` (N,) of ``a s^2 + b s + c = 0`` for (N,) coefficients
    (stable form; NaN/inf where absent). With ``a = 0``, ``r2`` is the linear root ``-c/b``
    (``r1`` infinite), so a ray parallel to a cone generator is still hit once."""
    disc = b * b - 4.0 * a * c
    with np.errstate(divide="ignore", invalid="ignore"):
        q = -0.5 * (b + np.where(b >= 0.0, 1.0, -1.0) * np.sqrt(np.where(disc >= 0, disc, np.nan)))
        return q / a, c / q


def sweep_bounds(x: np.ndarray, dmin: np.ndarray, dmax: np.ndarray, length: np.ndarray | None):
    """Bounds of ``{x + t d : 0 <= t <= length}`` with every ``d_k`` in ``[dmin_k, dmax_k]``.

    Parameters
    ----------
    x, dmin, dmax : (M, 3) float
    length : (M,) float or None
        ``None``: rays to infinity.
    """
    if length is None:
        return np.where(dmin < 0, -np.inf, x), np.where(dmax > 0, np.inf, x)
    L = length[:, None]
    return x + L * np.minimum(dmin, 0.0), x + L * np.maximum(dmax, 0.0)


def arc_range(a: np.ndarray, b: np.ndarray, theta_max: np.ndarray):
    """Component range of ``cos(th) a + sin(th) b`` over ``th in [0, theta_max]`` (M, 3).

    ``a``, ``b`` orthonormal; ``theta_max`` (M,) in ``(0, pi]``.
    """
    tm = theta_max[:, None]
    end = np.cos(tm) * a + np.sin(tm) * b
    r = np.sqrt(a * a + b * b)
    th_hi = np.arctan2(b, a)  # maximiser of each component, in (-pi, pi]
    th_lo = np.mod(th_hi + np.pi, 2.0 * np.pi)  # minimiser, in [0, 2 pi)
    hi = np.where((th_hi >= 0) & (th_hi <= tm), r, np.maximum(a, end))
    lo = np.where(th_lo <= tm, -r, np.minimum(a, end))
    return lo, hi


def both_roots(ray, prim, r1, r2):
    """Candidate pairs (H,) repeated for two roots: ``(ray, prim, s)`` of length 2H."""
    return np.concatenate([ray, ray]), np.concatenate([prim, prim]), np.concatenate([r1, r2])


def unit_rows(v: np.ndarray):
    """``(v / |v|, |v|)`` row-wise; zero rows stay zero (no NaN)."""
    n = np.linalg.norm(v, axis=1)
    return v / np.where(n > 0, n, 1.0)[:, None], n


# ------------------------------------------------------------------------- base
class SingleScatter(Technique):
    """Shared Create / Evaluate / Reconstruct of the K = 1 techniques (spec 3.2 and 4).

    Subclasses implement ``create``, ``intersect``, :meth:`scaled_normal`, :meth:`density`
    and ``_rebuild`` (the integrated dimensions a hit replaces in the photon's record).
    """

    family = "single"
    min_k = 1
    max_k = 1

    def _photons(self, paths, ctx) -> np.ndarray:
        """(M,) photons that get a primitive: every emitted photon of an applicable light
        (escaped or not, spec 4) when K = 1 is in the scene's scatter window."""
        if 1 not in self.k_range(ctx.scene, paths.depth):
            return np.zeros(0, np.int64)
        return np.flatnonzero(self.light_mask(paths, ctx.scene) & paths.alive[:, 0])

    def _emission(self, paths, photon, scene):
        """The photon's light point, direction, flight, axis and one-sidedness (M, ...)."""
        one_sided = np.array([lt.kind != "point" for lt in scene.lights], dtype=bool)
        return dict(x=paths.x[photon, 0], w=paths.w[photon, 0], T=paths.t[photon, 0],
                    axis=paths.light_normal[photon], one_sided=one_sided[paths.light[photon]])

    def _prims(self, photon, lo, hi, ctx, data) -> Primitives:
        lo, hi = clip_bounds(ctx.scene, lo, hi)
        return Primitives(self.name, photon, np.ones(photon.size, np.int64), lo, hi, data)

    @staticmethod
    def _hits(ray, prim, s, keep, **data) -> Hits:
        k = np.flatnonzero(keep)
        return Hits(ray[k], prim[k], s[k], {n: v[k] for n, v in data.items()})

    # ------------------------------------------------------------------ Evaluate
    def evaluate(self, hits, prims, paths, rays, ctx) -> np.ndarray:
        """Per-photon contribution ``X = f / (P_L Q)`` of every hit (H, 3).

        ``f / P_L = beta0 p(u,v) p(w*) E(t*) ss rho0 E(s*)`` (module docstring); 0 for
        back-side emission or an occluded light -> x0 segment.
        """
        scene = ctx.scene
        med = scene.medium
        rec = self.reconstruct(hits, prims, paths, rays, ctx)
        pdf = Pdfs(rec, scene)
        ok = (rec.kind == KIND_CODE["point"]) | (dot(rec.w1, rec.axis) > 0.0)
        idx = np.flatnonzero(ok)
        if idx.size:
            ok[idx] = ~ctx.blockers.occluded(rec.x1[idx], rec.x0[idx])
        q = self.density(rec, ctx)
        rho0 = phase_value(-dot(rec.w1, rec.psi), med.phase.g)
        f = (pdf.uv * pdf.w1 * np.exp(-med.sigma_t * rec.t1) * med.sigma_s * rho0
             * camera_transmittance(scene, rays, hits.ray, hits.s))
        ok &= np.isfinite(q) & (q > 0.0) & np.isfinite(f)
        with np.errstate(over="ignore"):  # f / q overflows only on measure-zero paths
            x = paths.beta[prims.photon[hits.prim], 0] * np.where(ok, f / np.where(ok, q, 1.0),
                                                                  0.0)[:, None]
        return np.where(np.isfinite(x), x, 0.0)

    # ------------------------------------------------------------------ Reconstruct
    def reconstruct(self, hits, prims, paths, rays, ctx):
        """The K = 1 record of every hit: the photon's record with the integrated
        dimensions (and the light point / ``uv`` where they move) replaced."""
        p = hits.prim
        rec = photon_record(paths, prims.photon[p], prims.K[p], ctx.scene, rays, hits.ray,
                            hits.s)
        return self._rebuild(rec, hits, prims)

    def _rebuild(self, rec, hits, prims):  # pragma: no cover - abstract
        raise NotImplementedError

    def scaled_normal(self, rec) -> np.ndarray:  # pragma: no cover - abstract
        """(H, 3) ``n = dx0/dxi1 x dx0/dxi2`` on records ``rec``."""
        raise NotImplementedError

    def _short_factor(self, rec, ctx) -> np.ndarray | float:
        """``E(t1)`` for short variants (``Q_short = Q_long E(t*)``), else 1."""
        return np.exp(-ctx.scene.medium.sigma_t * rec.t1) if self.short else 1.0


def _direction_rebuild(rec, keep_t: bool):
    """``w1* = normalize(x0 - x1)`` about the photon's own light point; ``t1* = |x0 - x1|``
    unless the flight is a sampled dimension (sphere)."""
    w1, t = unit_rows(rec.x0 - rec.x1)
    return rec.with_(w1=w1) if keep_t else rec.with_(w1=w1, t1=t)


# ------------------------------------------------------------------------- sphere
class SingleSphere(SingleScatter):
    """``ss-sphere`` ``[cos th, ph]``: sphere (area/mesh: front hemisphere) of radius ``T``."""

    def __init__(self, short: bool = False):
        if short:
            raise ValueError("ss-sphere has no short variant")
        self.short = False
        self.name = "ss-sphere"

    def create(self, paths, ctx) -> Primitives:
        """One sphere per photon: ``data`` x, w, T, axis (M, 3 / M), one_sided (M,) bool."""
        photon = self._photons(paths, ctx)
        d = self._emission(paths, photon, ctx.scene)
        keep = d["T"] > 0.0  # a zero radius is a measure-zero event and divides by T
        photon, d = photon[keep], {k: v[keep] for k, v in d.items()}
        n = d["axis"]
        side = np.sqrt(np.clip(1.0 - n * n, 0.0, None))  # hemisphere's reach across n
        hemi = d["one_sided"][:, None]
        dmax = np.where(hemi & (n < 0), side, 1.0)
        dmin = np.where(hemi & (n > 0), -side, -1.0)
        lo, hi = sweep_bounds(d["x"], dmin, dmax, d["T"])
        return self._prims(photon, lo, hi, ctx, d)

    def intersect(self, prims, rays, ray, prim, ctx) -> Hits:
        d = prims.data
        x, T = d["x"][prim], d["T"][prim]
        o, psi = rays.o[ray], rays.d[ray]
        oc = o - x
        r1, r2 = quadratic_roots(np.ones(ray.size), 2.0 * dot(oc, psi), dot(oc, oc) - T * T)
        ray2, prim2, s = both_roots(ray, prim, r1, r2)
        keep = np.isfinite(s) & on_ray(rays, ray2, s)
        v = rays.o[ray2] + np.where(keep, s, 0.0)[:, None] * rays.d[ray2] - d["x"][prim2]
        front = dot(v, d["axis"][prim2])
        keep &= ~d["one_sided"][prim2] | (front > 0.0)
        return self._hits(ray2, prim2, s, keep)

    def _rebuild(self, rec, hits, prims):
        return _direction_rebuild(rec, keep_t=True)

    def scaled_normal(self, rec):
        """``t^2 w``."""
        return (rec.t1**2)[:, None] * rec.w1

    def density(self, rec, ctx):
        """``p(u,v) st E(t) t^2 |w . psi|``."""
        pdf = Pdfs(rec, ctx.scene)
        return pdf.uv * pdf.t1 * np.abs(dot(self.scaled_normal(rec), rec.psi))


# ------------------------------------------------------------------------- cone
class SingleCone(SingleScatter):
    """``ss-cone`` ``[t, ph]``: the nappe of half-angle ``acos(w . axis)`` about the axis."""

    def __init__(self, short: bool = False):
        self.short = bool(short)
        self.name = "ss-cone-short" if short else "ss-cone"

    def create(self, paths, ctx) -> Primitives:
        """One nappe per photon: ``data`` x, w, T, axis, one_sided and ``c = w . axis``."""
        photon = self._photons(paths, ctx)
        d = self._emission(paths, photon, ctx.scene)
        a = d["axis"]
        c = dot(d["w"], a)
        d["c"] = c
        # Generator directions c a + sin (cos ph e1 + sin ph e2): component k spans
        # c a_k +- sin sqrt(1 - a_k^2) (e1, e2, a orthonormal).
        spread = np.sqrt(np.clip(1.0 - c * c, 0.0, None))[:, None] * np.sqrt(
            np.clip(1.0 - a * a, 0.0, None))
        lo, hi = sweep_bounds(d["x"], c[:, None] * a - spread, c[:, None] * a + spread,
                              d["T"] if self.short else None)
        return self._prims(photon, lo, hi, ctx, d)

    def intersect(self, prims, rays, ray, prim, ctx) -> Hits:
        """Roots of ``((p - x).a)^2 = c^2 |p - x|^2`` with ``sign((p - x).a) = sign(c)``."""
        d = prims.data
        x, a, c = d["x"][prim], d["axis"][prim], d["c"][prim]
        o, psi = rays.o[ray], rays.d[ray]
        D = o - x
        da, pa, c2 = dot(D, a), dot(psi, a), c * c
        r1, r2 = quadratic_roots(pa * pa - c2, 2.0 * (da * pa - c2 * dot(D, psi)),
                                 da * da - c2 * dot(D, D))
        ray2, prim2, s = both_roots(ray, prim, r1, r2)
        keep = np.isfinite(s) & on_ray(rays, ray2, s)
        v = rays.o[ray2] + np.where(keep, s, 0.0)[:, None] * rays.d[ray2] - d["x"][prim2]
        t = np.linalg.norm(v, axis=1)
        keep &= (dot(v, d["axis"][prim2]) * d["c"][prim2] > 0.0) & (t > 0.0)
        if self.short:
            keep &= t < d["T"][prim2]
        return self._hits(ray2, prim2, s, keep)

    def _rebuild(self, rec, hits, prims):
        return _direction_rebuild(rec, keep_t=False)

    def scaled_normal(self, rec):
        """``t (a - c w)`` with ``c = w . a``."""
        c = dot(rec.w1, rec.axis)
        return rec.t1[:, None] * (rec.axis - c[:, None] * rec.w1)

    def density(self, rec, ctx):
        """``p(u,v) p(c) t |(a - c w) . psi|`` (short: ``* E(t)``)."""
        pdf = Pdfs(rec, ctx.scene)
        q = pdf.uv * pdf.c1 * np.abs(dot(self.scaled_normal(rec), rec.psi))
        return q * self._short_factor(rec, ctx)


# ------------------------------------------------------------------------- disk
class SingleDisk(SingleScatter):
    """``ss-disk`` ``[t, cos th]``: the half-plane through the axis containing ``w``.

    Its normal is ``e_ph = normalize(a x w)`` (spec 4); photons with ``w`` parallel to the
    axis (measure zero) make no primitive.
    """

    def __init__(self, short: bool = False):
        self.short = bool(short)
        self.name = "ss-disk-short" if short else "ss-disk"

    def create(self, paths, ctx) -> Primitives:
        """One half-plane per photon: ``data`` adds ``eph`` (normal) and ``er`` (radial)."""
        photon = self._photons(paths, ctx)
        d = self._emission(paths, photon, ctx.scene)
        a, w = d["axis"], d["w"]
        eph, sin = unit_rows(np.cross(a, w))
        keep = sin > 1e-12
        photon, d, eph = photon[keep], {k: v[keep] for k, v in d.items()}, eph[keep]
        a = d["axis"]
        er = np.cross(eph, a)  # unit, in the half-plane, perpendicular to a, towards w
        d.update(eph=eph, er=er)
        # Directions cos th a + sin th er, th in [0, pi] (area/mesh: the front quarter only).
        dmin, dmax = arc_range(a, er, np.where(d["one_sided"], 0.5 * np.pi, np.pi))
        lo, hi = sweep_bounds(d["x"], dmin, dmax, d["T"] if self.short else None)
        return self._prims(photon, lo, hi, ctx, d)

    def intersect(self, prims, rays, ray, prim, ctx) -> Hits:
        d = prims.data
        x, n = d["x"][prim], d["eph"][prim]
        o, psi = rays.o[ray], rays.d[ray]
        with np.errstate(divide="ignore", invalid="ignore"):
            s = dot(x - o, n) / dot(psi, n)
        keep = np.isfinite(s) & on_ray(rays, ray, s)
        v = o + np.where(keep, s, 0.0)[:, None] * psi - x
        t = np.linalg.norm(v, axis=1)
        keep &= (dot(v, d["er"][prim]) > 0.0) & (t > 0.0)
        keep &= ~d["one_sided"][prim] | (dot(v, d["axis"][prim]) > 0.0)
        if self.short:
            keep &= t < d["T"][prim]
        return self._hits(ray, prim, s, keep)

    def _rebuild(self, rec, hits, prims):
        return _direction_rebuild(rec, keep_t=False)

    def scaled_normal(self, rec):
        """``t (w x a) / sin^2 th`` (0 on the axis, where it is undefined)."""
        n = np.cross(rec.w1, rec.axis)
        sin2 = dot(n, n)
        # The floor keeps t / sin^2 finite (no overflow) at numerically axial directions.
        with np.errstate(divide="ignore", invalid="ignore"):
            k = np.where(sin2 > 1e-200, rec.t1 / np.maximum(sin2, 1e-200), 0.0)
        return k[:, None] * n

    def density(self, rec, ctx):
        """``p(u,v) (1/2pi) t |(w x a) . psi| / sin^2`` (short: ``* E(t)``)."""
        pdf = Pdfs(rec, ctx.scene)
        q = pdf.uv * pdf.ph * np.abs(dot(self.scaled_normal(rec), rec.psi))
        return q * self._short_factor(rec, ctx)
