"""Triangle meshes in compiled code: a bounding volume hierarchy over the scene's triangles
and the exact float64 ray test of :func:`psurf_core.geometry.ray_triangles_first` run over it.

Why: a shadow segment that met a mesh's box used to leave the walker (``DEFER``) for
``Blockers.occluded`` in numpy, through Embree (float32, via trimesh) and an exact re-test;
on a mesh light every single-scattering hit's segment ends on the mesh, so every hit took
that road (~1.8 us a hit against ~0.1 us in the walker, ``scenes/dense_mesh_light.toml``).
Here the walkers test the triangles themselves, and ``Blockers`` answers its numpy callers
with the same kernel, so both paths give one verdict for one segment.

The hierarchy (:func:`build`) is stored *stackless*: its nodes in depth-first order, each
with the index of the node after its subtree (``skip``), so a traversal is a loop over one
index (a node whose box the ray misses jumps to ``skip``; any other goes to the next node)
and needs no per-call stack. Boxes are padded by :data:`NODE_PAD` so that the slab test's
rounding can never drop a triangle the exact test would hit.

:func:`first_hit` is the nearest hit in ``(t_min, t_max)``; :func:`any_hit` stops at the
first one (shadow tests); :func:`first_hits` is the batch kernel ``Blockers`` calls.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..constants import PARALLEL_EPS
from ..records import Vec, flat, load, table
from .jit import inline, kernel, scalar

#: Triangles per leaf at most.
LEAF_SIZE = 4
#: Padding of every node's box (scene units): far above the slab test's rounding at scene
#: scale (~1e-16 relative), far below a triangle's size.
NODE_PAD = 1e-7
#: ``geometry.ray_triangles_first``'s degenerate-determinant bound.
DET_MIN = 1e-14


class BvhNode(NamedTuple):
    """One node, in depth-first order.

    Attributes
    ----------
    lo, hi : Vec
        Its box, padded by :data:`NODE_PAD` (scene units).
    skip : float
        Index of the first node after this node's subtree (the node count for the last).
    start, count : float
        A leaf's triangles (rows ``start .. start + count - 1`` of the triangle table);
        ``count`` 0 for an inner node, whose children follow it.
    """

    lo: Vec
    hi: Vec
    skip: float
    start: float
    count: float


class Triangle(NamedTuple):
    """One triangle as ``geometry.ray_triangles_first`` reads it: ``v0`` and the edges
    ``e1 = v1 - v0``, ``e2 = v2 - v0`` (scene units)."""

    v0: Vec
    e1: Vec
    e2: Vec


def build(tris: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The hierarchy over a triangle soup: median splits of the centroids along the longest
    axis of their box, leaves of at most :data:`LEAF_SIZE` triangles. Deterministic.

    Parameters
    ----------
    tris : (F, 3, 3) float
        Triangle vertices (scene units).

    Returns
    -------
    nodes : (M, 9) float
        Flat :class:`BvhNode` rows in depth-first order (M = 0 when F = 0).
    triangles : (F, 9) float
        Flat :class:`Triangle` rows, in the order the leaves name them.
    """
    tris = np.asarray(tris, dtype=float).reshape(-1, 3, 3)
    order = np.arange(tris.shape[0])
    cent, tlo, thi = tris.mean(axis=1), tris.min(axis=1), tris.max(axis=1)
    rows: list[tuple] = []  # (lo, hi, skip, start, count)

    def emit(a: int, b: int) -> None:
        """Write the subtree of ``order[a:b]`` in depth-first order (depth ~log2(F))."""
        idx = order[a:b]
        lo, hi = tlo[idx].min(axis=0) - NODE_PAD, thi[idx].max(axis=0) + NODE_PAD
        me = len(rows)
        rows.append(None)
        if b - a <= LEAF_SIZE:
            rows[me] = (lo, hi, me + 1, a, b - a)
            return
        c = cent[idx]
        axis = int(np.argmax(c.max(axis=0) - c.min(axis=0)))
        order[a:b] = idx[np.argsort(c[:, axis], kind="stable")]
        mid = (a + b) // 2
        emit(a, mid)  # the left child is the next node
        emit(mid, b)
        rows[me] = (lo, hi, len(rows), 0, 0)  # skip: the node after the whole subtree

    if tris.shape[0]:
        emit(0, tris.shape[0])
    nodes = table(BvhNode, len(rows))
    for i, (lo, hi, skip, start, count) in enumerate(rows):
        nodes["lo"][i], nodes["hi"][i] = lo, hi
        nodes["skip"][i], nodes["start"][i], nodes["count"][i] = skip, start, count
    t = tris[order]
    tri = table(Triangle, t.shape[0])
    tri["v0"], tri["e1"], tri["e2"] = t[:, 0], t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
    return flat(nodes), flat(tri)


# --------------------------------------------------------------------------- compiled
@scalar
def slab(o, d, lo, hi):
    """Entry and exit of one axis's slab (``geometry.ray_box``; ``kernels.shadow``'s box test
    too)."""
    inv = 1.0 / (PARALLEL_EPS if abs(d) < PARALLEL_EPS else d)
    ta = (lo - o) * inv
    tb = (hi - o) * inv
    return min(ta, tb), max(ta, tb)


@scalar
def _meets_box(o, d, node, t_min, t_max):
    """Does the ray's interval ``[t_min, t_max]`` meet the node's (padded) box?"""
    e0, x0 = slab(o[0], d[0], node.lo[0], node.hi[0])
    e1, x1 = slab(o[1], d[1], node.lo[1], node.hi[1])
    e2, x2 = slab(o[2], d[2], node.lo[2], node.hi[2])
    te, tx = max(e0, e1, e2, t_min), min(x0, x1, x2, t_max)
    return te <= tx


@scalar
def _triangle_t(o, d, tr, t_min, t_max):
    """``geometry.ray_triangles_first``'s Moller-Trumbore test of one triangle, operation
    for operation: the hit distance in ``(t_min, t_max)``, else ``inf``."""
    v0, e1, e2 = tr.v0, tr.e1, tr.e2
    p0 = d[1] * e2[2] - d[2] * e2[1]  # pvec = d x e2
    p1 = d[2] * e2[0] - d[0] * e2[2]
    p2 = d[0] * e2[1] - d[1] * e2[0]
    det = p0 * e1[0] + p1 * e1[1] + p2 * e1[2]
    if not abs(det) > DET_MIN:
        return np.inf
    inv = 1.0 / det
    s0, s1, s2 = o[0] - v0[0], o[1] - v0[1], o[2] - v0[2]  # tvec
    u = (s0 * p0 + s1 * p1 + s2 * p2) * inv
    q0 = s1 * e1[2] - s2 * e1[1]  # qvec = tvec x e1
    q1 = s2 * e1[0] - s0 * e1[2]
    q2 = s0 * e1[1] - s1 * e1[0]
    v = (d[0] * q0 + d[1] * q1 + d[2] * q2) * inv
    t = (q0 * e2[0] + q1 * e2[1] + q2 * e2[2]) * inv
    if u >= 0.0 and v >= 0.0 and u + v <= 1.0 and t > t_min and t < t_max:
        return t
    return np.inf


@inline
def _walk(o, d, t_min, t_max, nodes, tris, stop_at_first):
    """The nearest hit in ``(t_min, t_max)`` (``inf`` if none); with ``stop_at_first``, the
    first found."""
    best = np.inf
    i, m = 0, nodes.shape[0]
    while i < m:
        node = load(nodes, i, BvhNode)
        if not _meets_box(o, d, node, t_min, min(t_max, best)):
            i = int(node.skip)
            continue
        if node.count > 0.0:
            s = int(node.start)
            for k in range(s, s + int(node.count)):
                t = _triangle_t(o, d, load(tris, k, Triangle), t_min, t_max)
                if t < best:
                    best = t
                    if stop_at_first:
                        return best
            i = int(node.skip)
        else:
            i += 1
    return best


@inline
def first_hit(o, d, t_min, t_max, nodes, tris):
    """Nearest hit of the ray ``o + t d`` (3-tuples, ``d`` unit) with the triangles in
    ``(t_min, t_max)``, or ``inf``."""
    return _walk(o, d, t_min, t_max, nodes, tris, False)


@inline
def any_hit(o, d, t_min, t_max, nodes, tris):
    """Is some triangle hit in ``(t_min, t_max)``? (Stops at the first found.)"""
    return _walk(o, d, t_min, t_max, nodes, tris, True) < np.inf


@kernel(nogil=True)
def first_hits(o, d, t_min, t_max, nodes, tris):  # pragma: no cover - compiled
    """(N,) float: :func:`first_hit` of each ray (``o``, ``d``: (N, 3); ``t_min``,
    ``t_max``: (N,)), ``inf`` where none: ``geometry.ray_triangles_first``'s answer."""
    n = o.shape[0]
    out = np.empty(n)
    for r in range(n):
        out[r] = first_hit((o[r, 0], o[r, 1], o[r, 2]), (d[r, 0], d[r, 1], d[r, 2]),
                           t_min[r], t_max[r], nodes, tris)
    return out
