"""Single scattering from the lights (K = 1, spec 3.2): what every ``ss-*`` technique shares.

A K = 1 path is ``x1 -> x0``: ``x1`` on the light, ``x0 = x1 + t1 w1 = y(s)`` on the camera
ray. Each technique keeps some of the photon's emission dimensions and integrates two
others against the camera-ray delta; one module each:

* ``ss-sphere`` ``[cos th, ph]`` (:mod:`.single_spheres`): sphere of radius ``T`` about the
  photon's light point (a hemisphere about ``n_L`` for area/mesh lights), no short variant;
* ``ss-cone`` ``[t, ph]`` (:mod:`.single_cones`): one nappe, apex the light point, axis
  ``a`` / ``n_L`` / ``n_k``, the photon's ``c = w . axis``;
* ``ss-disk`` ``[t, cos th]`` (:mod:`.single_disks`): the half-plane through the axis
  containing ``w``;
* ``ss-plane-uv``, ``ss-plane-ut``, ``ss-plane-vt`` (:mod:`.single_planes`): the area / mesh
  light translated by ``T w``, or a strip swept from it.

Every contribution is the generic ``X = f / (P_L Q_i)`` of spec section 2 on the
reconstructed path, with ``Q_i`` the technique's MIS ``density``. Emission is
importance-sampled exactly (uniform sphere for the isotropic point light, cosine-weighted
for area/mesh lights), so ``beta0 = paths.beta[:, 0] = Phi / P_L`` equals
``Le-term / (P_L p(u,v) p(w))`` for every front-side direction, and

``f / P_L = beta0 p(u,v) p(w*) E(t*) ss rho0 E(s*)``

(``p(u,v)`` = 1 for point lights and parallelograms, ``2 P_k`` for mesh triangles; ``p(w*)``
the emission pdf at the *reconstructed* direction). Each family's ``contribution`` is that
ratio over its ``Q`` with the shared factors cancelled (its docstring says which), per unit
photon weight ``G.beta = beta0``.

Bounded-scene rules (spec section 4): ``x0`` on the ray's in-box interval (Intersect),
emission one-sided (``w* . n_L > 0``: the surface's front part, in ``accept``), the segment
light -> x0 unoccluded (one shadow test; the emitter's own surface is
skipped by the shadow test's end offsets). Long: keep ``E(t*)``; short: ``t* < T``,
``E(t*)`` is dropped from ``f`` and multiplies ``Q`` (track-length), which is the same
``f / Q``.
"""

from __future__ import annotations

import numpy as np

from ..pdfs import KIND_CODE
from .base import Primitives, Technique, clip_bounds


# ------------------------------------------------------------------------- Create
class SingleScatter(Technique):
    """Shared Create of the K = 1 techniques: which photons, and their emission record."""

    family = "single"
    min_k = 1
    max_k = 1

    def _photons(self, paths, ctx) -> np.ndarray:
        """(M,) photons that get a primitive: every emitted photon of an applicable light
        (escaped or not, spec 4) when K = 1 is in the scene's scatter window."""
        if 1 not in self.k_range(ctx.scene, paths.depth):
            return np.zeros(0, np.int64)
        return np.flatnonzero(self.light_mask(paths, ctx.scene) & paths.alive[:, 0])

    @staticmethod
    def _emission(paths, photon, scene) -> dict:
        """The photon's emission record (M, ...): light point ``x1``, direction ``w``, flight
        ``T1``, ``axis`` (``a`` / ``n_L`` / ``n_k``), ``one_sided`` (1.0: area / mesh),
        ``kind`` (light kind code) and weight ``beta`` (``beta0``, W)."""
        kinds = np.array([KIND_CODE[lt.kind] for lt in scene.lights], dtype=float)
        kind = kinds[paths.light[photon]]
        return dict(x1=paths.x[photon, 0], w=paths.w[photon, 0], T1=paths.t[photon, 0],
                    axis=paths.light_normal[photon],
                    one_sided=(kind != KIND_CODE["point"]).astype(float), kind=kind,
                    beta=paths.beta[photon, 0])

    def _prims(self, photon, lo, hi, ctx, data, hull=None, cloud=None) -> Primitives:
        """Primitives of ``photon`` (K = 1) with bounds ``[lo, hi]`` clipped to the box and
        the footprint the spans visit (``hull`` or ``cloud``: ``Primitives``; neither: the
        screen rectangle)."""
        lo, hi = clip_bounds(ctx.scene, lo, hi)
        return Primitives(self.name, photon, np.ones(photon.size, np.int64), lo, hi, data,
                          hull=hull, cloud=cloud)


def columns(cls, d: dict, **extra) -> dict:
    """The columns of record class ``cls`` from an emission record ``d`` and ``extra``."""
    return {f: extra[f] if f in extra else d[f] for f in cls._fields}


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
