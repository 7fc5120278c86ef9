"""Ray tests against the medium box and everything that blocks light.

Blockers are the black occluders *and* the emitters (area and mesh lights are opaque,
SCENES.md). All tests are vectorized over rays/segments; triangle tests run in chunks so
that ``rays x triangles`` work never exceeds a fixed number of elements.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .constants import BOUNDS_PAD, BOX_EPS, PARALLEL_EPS, SHADOW_EPS
from .kernels.jit import twin
from .memo import memo
from .scene import AreaLight, BoxOccluder, MeshLight, MeshOccluder, Scene, SphereOccluder

#: Padding (scene units) of the blocker boxes of the segment reject in ``Blockers.occluded``.
_BOUNDS_PAD = BOUNDS_PAD  # (name kept for the tracer)

#: Elements (rays x triangles) processed per chunk by the numpy triangle test.
_TRI_CHUNK = 1 << 21


def ray_box(o: np.ndarray, d: np.ndarray, bmin: np.ndarray, bmax: np.ndarray):
    """Slab test of rays against one axis-aligned box.

    Parameters
    ----------
    o, d : (N, 3) float
        Origins and directions (need not be unit; distances are in units of ``|d|``).
    bmin, bmax : (3,) float

    Returns
    -------
    t_enter, t_exit : (N,) float
        The ray is inside for ``t_enter < t < t_exit``; a miss has ``t_enter >= t_exit``.
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / np.where(np.abs(d) < PARALLEL_EPS, PARALLEL_EPS, d)
        t0 = (bmin - o) * inv
        t1 = (bmax - o) * inv
    lo = np.minimum(t0, t1)
    hi = np.maximum(t0, t1)
    return lo.max(axis=-1), hi.min(axis=-1)


def inside_box(x: np.ndarray, bmin: np.ndarray, bmax: np.ndarray,
               eps: float = BOX_EPS) -> np.ndarray:
    """(N,) bool: points ``x`` (N, 3) inside the closed box (with tolerance ``eps``)."""
    return np.all((x >= bmin - eps) & (x <= bmax + eps), axis=-1)


@twin(inside_box)
def _inside_box(x, bmin, bmax, eps=BOX_EPS):
    # & rather than `and`: no branches (Trace's step kernel: ~0.4 ms of ~4 per 32768 photons)
    return ((bmin[0] - eps <= x[0]) & (x[0] <= bmax[0] + eps) & (bmin[1] - eps <= x[1])
            & (x[1] <= bmax[1] + eps) & (bmin[2] - eps <= x[2]) & (x[2] <= bmax[2] + eps))


def ray_sphere(o, d, center, radius):
    """Both roots of ``|o + t d - c| = r`` for unit ``d``; NaN where the ray misses.

    Returns
    -------
    t_near, t_far : (N,) float
    """
    oc = o - center
    b = np.einsum("ij,ij->i", oc, d)
    c = np.einsum("ij,ij->i", oc, oc) - radius * radius
    disc = b * b - c
    sq = np.sqrt(np.where(disc >= 0.0, disc, np.nan))
    return -b - sq, -b + sq


def ray_parallelogram(o, d, corner, edge_u, edge_v):
    """Hit distance of rays with the parallelogram ``corner + u eu + v ev`` (inf on a miss)."""
    n = np.cross(edge_u, edge_v)
    denom = d @ n
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((corner - o) @ n) / denom
    p = o + t[:, None] * d - corner
    # Solve p = u eu + v ev in the least-squares sense via the Gram matrix.
    g = np.array([[edge_u @ edge_u, edge_u @ edge_v], [edge_u @ edge_v, edge_v @ edge_v]])
    rhs = np.stack([p @ edge_u, p @ edge_v], axis=-1)
    uv = rhs @ np.linalg.inv(g).T
    ok = (np.abs(denom) > PARALLEL_EPS) & np.all((uv >= 0.0) & (uv <= 1.0), axis=-1)
    return np.where(ok & np.isfinite(t), t, np.inf)


def ray_triangles_first(o, d, tris, t_min, t_max):
    """Nearest hit in ``(t_min, t_max)`` of rays with any triangle (Moller-Trumbore).

    Parameters
    ----------
    o, d : (N, 3) float
    tris : (F, 3, 3) float
    t_min, t_max : (N,) float

    Returns
    -------
    (N,) float
        Nearest hit distance, ``inf`` where none.
    """
    n, f = o.shape[0], tris.shape[0]
    best = np.full(n, np.inf)
    if n == 0 or f == 0:
        return best
    # Coarse pass: only rays whose interval meets the mesh's bounding box are tested.
    lo, hi = tris.reshape(-1, 3).min(0) - BOUNDS_PAD, tris.reshape(-1, 3).max(0) + BOUNDS_PAD
    te, tx = ray_box(o, d, lo, hi)
    cand = np.flatnonzero((te < tx) & (tx > t_min) & (te < t_max))
    v0 = tris[:, 0]
    e1 = tris[:, 1] - v0
    e2 = tris[:, 2] - v0
    step = max(1, _TRI_CHUNK // f)
    for a in range(0, cand.size, step):
        idx = cand[a : a + step]
        oo, dd = o[idx, None, :], d[idx, None, :]
        pvec = np.cross(dd, e2[None])
        det = np.einsum("ijk,jk->ij", pvec, e1)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            tvec = oo - v0[None]
            u = np.einsum("ijk,ijk->ij", tvec, pvec) * inv
            qvec = np.cross(tvec, e1[None])
            v = np.einsum("ijk,ijk->ij", np.broadcast_to(dd, qvec.shape), qvec) * inv
            t = np.einsum("ijk,jk->ij", qvec, e2) * inv
        ok = (
            (np.abs(det) > 1e-14)
            & (u >= 0.0)
            & (v >= 0.0)
            & (u + v <= 1.0)
            & (t > t_min[idx, None])
            & (t < t_max[idx, None])
        )
        t = np.where(ok, t, np.inf)
        best[idx] = t.min(axis=1)
    return best


class _MeshHierarchy:
    """First-hit queries on a triangle soup through :mod:`psurf_core.kernels.mesh_bvh`: the
    exact float64 test of :func:`ray_triangles_first` over a bounding volume hierarchy,
    compiled. The compiled shadow tests (``kernels.shadow.occluded``) walk the same
    hierarchy, so a segment gets one verdict on either path. (Until 2026-12 this was Embree,
    float32 through trimesh, with an exact re-test near ``t_min``: the walkers then had to
    hand every segment near a mesh back to numpy, ~1.8 us a hit on a mesh light.)"""

    def __init__(self, tris: np.ndarray):
        from .kernels import mesh_bvh

        self._first_hits = mesh_bvh.first_hits
        self.nodes, self.tris = mesh_bvh.build(tris)

    def first(self, o, d, t_min, t_max):
        c = np.ascontiguousarray
        return self._first_hits(c(o, float), c(d, float), c(t_min, float), c(t_max, float),
                                self.nodes, self.tris)


@dataclass(frozen=True)
class Blockers:
    """Everything opaque in a scene: sphere/box/mesh occluders and area/mesh emitters.

    Build with :func:`blockers_of`; query with :meth:`first_hit` and :meth:`occluded`.
    """

    sphere_c: np.ndarray  # (S, 3)
    sphere_r: np.ndarray  # (S,)
    box_min: np.ndarray  # (B, 3)
    box_max: np.ndarray  # (B, 3)
    quads: tuple  # of (corner, edge_u, edge_v)
    triangles: np.ndarray  # (F, 3, 3), all mesh occluders and mesh lights
    engine: object = None  # _MeshHierarchy over `triangles` (None without triangles)
    bounds: np.ndarray | None = None  # (N, 2, 3) world boxes holding every blocker
    planes: np.ndarray | None = None  # (N, 4) (n, n . p) of a planar blocker, NaN otherwise

    @property
    def empty(self) -> bool:
        return (
            self.sphere_r.size == 0
            and self.box_min.shape[0] == 0
            and not self.quads
            and self.triangles.shape[0] == 0
        )

    def mesh_hierarchy(self) -> tuple[np.ndarray, np.ndarray]:
        """``(nodes, triangles)`` of the triangles' hierarchy (``kernels.mesh_bvh``;
        only for blockers with triangles): what the compiled shadow tests walk."""
        return self.engine.nodes, self.engine.tris

    def first_hit(self, o, d, t_min=None, t_max=None) -> np.ndarray:
        """Distance to the first blocker along unit rays, in ``(t_min, t_max)``.

        Parameters
        ----------
        o, d : (N, 3) float
        t_min, t_max : (N,) float, optional
            Defaults ``SHADOW_EPS`` and ``inf``.

        Returns
        -------
        (N,) float
            ``inf`` where nothing is hit.
        """
        n = o.shape[0]
        t_min = np.full(n, SHADOW_EPS) if t_min is None else np.asarray(t_min, float)
        t_max = np.full(n, np.inf) if t_max is None else np.asarray(t_max, float)
        best = np.full(n, np.inf)

        def keep(t):
            t = np.where(np.isfinite(t) & (t > t_min) & (t < t_max), t, np.inf)
            np.minimum(best, t, out=best)

        for c, r in zip(self.sphere_c, self.sphere_r, strict=True):
            t0, t1 = ray_sphere(o, d, c, r)
            keep(np.where(t0 > t_min, t0, t1))
        for lo, hi in zip(self.box_min, self.box_max, strict=True):
            te, tx = ray_box(o, d, lo, hi)
            hit = te < tx
            keep(np.where(hit, np.where(te > t_min, te, tx), np.inf))
        for corner, eu, ev in self.quads:
            keep(ray_parallelogram(o, d, corner, eu, ev))
        if self.triangles.shape[0]:
            t_hi = np.minimum(t_max, best)
            if self.engine is not None:
                keep(self.engine.first(o, d, t_min, t_hi))
            else:
                keep(ray_triangles_first(o, d, self.triangles, t_min, t_hi))
        return best

    def occluded(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """(N,) bool: is the open segment ``a -> b`` (N, 3) blocked?

        Both ends are shrunk by ``SHADOW_EPS`` so the surface a vertex sits on (an emitter)
        does not block its own segment.
        """
        n = a.shape[0]
        if self.empty or n == 0:
            return np.zeros(n, dtype=bool)
        out = np.zeros(n, dtype=bool)
        if self.bounds is not None and self.planes is not None:
            # Cheap reject: a segment lies inside its own bounding box, so one whose box meets
            # no blocker's box is clear; the exact test runs on the others only.
            # A planar blocker (emitter quad) can only block a segment that crosses its plane
            # inside the part of the segment the exact test looks at.
            lo, hi = np.minimum(a, b), np.maximum(a, b)
            near = np.zeros(n, dtype=bool)
            for (blo, bhi), pl in zip(self.bounds, self.planes, strict=True):
                meet = np.all((lo <= bhi + _BOUNDS_PAD) & (hi >= blo - _BOUNDS_PAD), axis=1)
                if not np.isnan(pl[0]):
                    meet[np.flatnonzero(meet)] = _crosses_plane(a[meet], b[meet], pl)
                near |= meet
            idx = np.flatnonzero(near)
            if idx.size == 0:
                return out
            if idx.size < n:
                a, b = a[idx], b[idx]
                n = idx.size
        else:
            idx = slice(None)
        v = b - a
        length = np.linalg.norm(v, axis=-1)
        with np.errstate(invalid="ignore", divide="ignore"):
            d = v / np.where(length > 0, length, 1.0)[:, None]
        hit = self.first_hit(a, d, np.full(n, SHADOW_EPS), length - SHADOW_EPS)
        out[idx] = np.isfinite(hit)
        return out


def _crosses_plane(a: np.ndarray, b: np.ndarray, plane: np.ndarray) -> np.ndarray:
    """(N,) bool: may segment ``a -> b`` cross the plane ``x . n = c`` (``plane = (n, c)``)
    at a distance from ``a`` in ``(SHADOW_EPS, |b - a| - SHADOW_EPS)`` (the interval
    :meth:`Blockers.occluded` tests)? Conservative by half of ``SHADOW_EPS`` at both ends,
    far more than the rounding of either computation."""
    da = a @ plane[:3] - plane[3]
    db = b @ plane[:3] - plane[3]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = da / (da - db) * np.linalg.norm(b - a, axis=1)
    return (da * db <= 0.0) & (t >= 0.5 * SHADOW_EPS) & (t <= np.linalg.norm(b - a, axis=1)
                                                          - 0.5 * SHADOW_EPS)


def blockers_of(scene: Scene) -> Blockers:
    """Collect a scene's opaque surfaces (occluders and emitters) into one :class:`Blockers`
    (built once per scene: every pass and table reads the same one)."""
    return memo(scene, "blockers", lambda: _blockers_of(scene))


def _blockers_of(scene: Scene) -> Blockers:
    sc, sr, bmin, bmax, quads, tris = [], [], [], [], [], []
    for oc in scene.occluders:
        if isinstance(oc, SphereOccluder):
            sc.append(oc.center)
            sr.append(oc.radius)
        elif isinstance(oc, BoxOccluder):
            bmin.append(oc.min)
            bmax.append(oc.max)
        elif isinstance(oc, MeshOccluder):
            tris.append(oc.triangles)
    for lt in scene.lights:
        if isinstance(lt, AreaLight):
            quads.append((lt.corner, lt.edge_u, lt.edge_v))
        elif isinstance(lt, MeshLight):
            tris.append(lt.triangles)
    bounds = [np.stack([np.asarray(c) - r, np.asarray(c) + r]) for c, r in zip(sc, sr, strict=True)]
    bounds += [np.stack([lo, hi]) for lo, hi in zip(bmin, bmax, strict=True)]
    planes = [np.full(4, np.nan)] * len(bounds)
    for corner, eu, ev in quads:
        q = np.stack([corner, corner + eu, corner + ev, corner + eu + ev])
        bounds.append(np.stack([q.min(0), q.max(0)]))
        nq = np.cross(eu, ev)
        planes.append(np.append(nq, nq @ corner))
    for t in tris:
        if t.shape[0]:
            bounds.append(np.stack([t.reshape(-1, 3).min(0), t.reshape(-1, 3).max(0)]))
            planes.append(np.full(4, np.nan))
    return Blockers(
        sphere_c=np.array(sc, dtype=float).reshape(-1, 3),
        sphere_r=np.array(sr, dtype=float),
        box_min=np.array(bmin, dtype=float).reshape(-1, 3),
        box_max=np.array(bmax, dtype=float).reshape(-1, 3),
        quads=tuple(quads),
        triangles=(tri := np.concatenate(tris, axis=0) if tris else np.zeros((0, 3, 3))),
        engine=_MeshHierarchy(tri) if tri.shape[0] else None,
        bounds=np.array(bounds, dtype=float).reshape(-1, 2, 3),
        planes=np.array(planes, dtype=float).reshape(-1, 4),
    )
