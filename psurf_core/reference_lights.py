"""Points on the reference renderer's lights (:mod:`psurf_core.reference`): sampled by power
and area for next-event estimation and equiangular sampling (:func:`sample_light_points`),
found where a sampled direction meets an emitter (:func:`emitter_hits`), and the centre
each light's guided lobes and distances aim at (:func:`light_centres`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import sampling
from .constants import SHADOW_EPS
from .geometry import ray_parallelogram
from .scene import AreaLight, MeshLight, PointLight, Scene

__all__ = ["LightPoints", "emitter_hits", "light_centres", "ray_mesh", "sample_light_points"]

#: Ray x triangle elements per chunk of the emitter-mesh test.
_TRI_CHUNK = 1 << 18


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("ij,ij->i", a, b)


def ray_mesh(o: np.ndarray, d: np.ndarray, tris: np.ndarray):
    """Nearest triangle hit beyond ``SHADOW_EPS`` (Moller-Trumbore) and its index.

    ``geometry.ray_triangles_first`` returns only the distance; the emitter test also needs
    which triangle was hit (its normal decides the side, its light the radiance).

    Parameters
    ----------
    o, d : (N, 3) float
    tris : (F, 3, 3) float

    Returns
    -------
    t : (N,) float
        ``inf`` where no triangle is hit.
    tri : (N,) int
        Hit triangle, ``-1`` where none.
    """
    n, f = o.shape[0], tris.shape[0]
    best_t, best_k = np.full(n, np.inf), np.full(n, -1, dtype=np.int64)
    v0, e1, e2 = tris[:, 0], tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
    step = max(1, _TRI_CHUNK // max(f, 1))
    for a in range(0, n, step):
        oo, dd = o[a : a + step, None, :], d[a : a + step, None, :]
        p = np.cross(dd, e2[None])
        det = np.sum(p * e1[None], axis=-1)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            tv = oo - v0[None]
            u = np.sum(tv * p, axis=-1) * inv
            q = np.cross(tv, e1[None])
            v = np.sum(dd * q, axis=-1) * inv
            t = np.sum(q * e2[None], axis=-1) * inv
        ok = (np.abs(det) > 1e-14) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > SHADOW_EPS)
        t = np.where(ok, t, np.inf)
        k = np.argmin(t, axis=1)
        tk = t[np.arange(t.shape[0]), k]
        best_t[a : a + step] = tk
        best_k[a : a + step] = np.where(np.isfinite(tk), k, -1)
    return best_t, best_k



@dataclass
class LightPoints:
    """Points on the lights (sampled, or where a sampled direction hit an emitter).

    Attributes
    ----------
    y : (M, 3) float
        Point on the light (the position of a point light).
    le : (M, 3) float
        Radiance (area, mesh; 0 on an emitter's back side) or intensity (point).
    normal : (M, 3) float
        Emitting-side unit normal (zero for a point light).
    p_area : (M,) float
        Density of NEE's light point per unit area there, ``P_L / A_L`` (the probability
        ``P_L`` for a point light).
    point : (M,) bool
        Point light.
    """

    y: np.ndarray
    le: np.ndarray
    normal: np.ndarray
    p_area: np.ndarray
    point: np.ndarray

    @classmethod
    def empty(cls, m: int) -> LightPoints:
        return cls(np.zeros((m, 3)), np.zeros((m, 3)), np.zeros((m, 3)), np.zeros(m),
                   np.zeros(m, dtype=bool))

    def take(self, idx: np.ndarray) -> LightPoints:
        return LightPoints(self.y[idx], self.le[idx], self.normal[idx], self.p_area[idx],
                            self.point[idx])


def sample_light_points(scene: Scene, rng: np.random.Generator, m: int) -> LightPoints:
    """``m`` light points: light ``L`` with probability ``P_L`` (power), then uniform by area."""
    pmf = scene.light_pmf
    choice = sampling.sample_discrete(pmf, rng, m)
    lp = LightPoints.empty(m)
    for li, lt in enumerate(scene.lights):
        sel = np.flatnonzero(choice == li)
        if sel.size == 0:
            continue
        if isinstance(lt, PointLight):
            lp.y[sel] = lt.position
            lp.le[sel] = lt.intensity
            lp.p_area[sel] = pmf[li]
            lp.point[sel] = True
        elif isinstance(lt, AreaLight):
            uv = rng.random((sel.size, 2))
            lp.y[sel] = lt.corner + uv[:, :1] * lt.edge_u + uv[:, 1:] * lt.edge_v
            lp.le[sel] = lt.radiance
            lp.normal[sel] = lt.normal
            lp.p_area[sel] = pmf[li] / lt.area
        elif isinstance(lt, MeshLight):
            areas = lt.areas
            k = sampling.sample_discrete(areas / areas.sum(), rng, sel.size)
            b = sampling.sample_triangle_barycentric(rng, sel.size)
            v0, v1, v2 = (lt.triangles[k, i] for i in range(3))
            lp.y[sel] = v0 + b[:, :1] * (v1 - v0) + b[:, 1:] * (v2 - v0)
            lp.le[sel] = lt.radiance
            lp.normal[sel] = lt.normals[k]
            lp.p_area[sel] = pmf[li] / areas.sum()
        else:  # pragma: no cover - the scene loader admits no other light
            raise TypeError(f"unknown light {lt!r}")
    return lp



def light_centres(scene: Scene) -> np.ndarray:
    """(L, 3) the point each light's guided lobe aims at: a point light's position, a
    parallelogram's centre, a mesh's area-weighted triangle centroid."""
    out = []
    for lt in scene.lights:
        if isinstance(lt, PointLight):
            out.append(lt.position)
        elif isinstance(lt, AreaLight):
            out.append(lt.corner + 0.5 * (lt.edge_u + lt.edge_v))
        else:
            a = lt.areas
            out.append((lt.triangles.mean(axis=1) * a[:, None]).sum(axis=0) / a.sum())
    return np.array(out, dtype=float).reshape(-1, 3)


def emitter_hits(scene, x, w):
    """Nearest front- or back-side hit of sampled directions with any area or mesh light.

    Returns
    -------
    t : (M,) float
        Hit distance (``inf`` on a miss).
    lp : LightPoints
        The hit points, their light's radiance (0 on a back side or a miss), normal and
        ``P_L / A_L`` (what NEE's and equiangular sampling's densities need there).
    """
    m = x.shape[0]
    pmf = scene.light_pmf
    t_best = np.full(m, np.inf)
    lp = LightPoints.empty(m)
    for li, lt in enumerate(scene.lights):
        if isinstance(lt, AreaLight):
            t = ray_parallelogram(x, w, lt.corner, lt.edge_u, lt.edge_v)
            t = np.where(t > SHADOW_EPS, t, np.inf)
            nrm = np.broadcast_to(lt.normal, (m, 3))
        elif isinstance(lt, MeshLight):
            t, k = ray_mesh(x, w, lt.triangles)
            nrm = lt.normals[np.maximum(k, 0)]
        else:
            continue
        near = t < t_best
        t_best = np.where(near, t, t_best)
        front = near & (_dot(w, nrm) < 0)
        lp.le[near] = np.where(front[near, None], lt.radiance, 0.0)
        lp.normal[near] = nrm[near]
        lp.p_area[near] = pmf[li] / lt.area
    hit = np.isfinite(t_best)
    lp.y[hit] = x[hit] + t_best[hit, None] * w[hit]
    return t_best, lp

