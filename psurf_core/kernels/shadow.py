"""Compiled shadow tests: the status of one shadow segment against the scene's spheres,
boxes, emitter quads and triangle meshes.

:func:`blocker_table` packs :class:`~psurf_core.geometry.Blockers` into :class:`BlockerRow`
records; :func:`shadow_args` adds the triangles' hierarchy (:mod:`.mesh_bvh`, the one
``Blockers`` itself queries); :func:`status` reads them inside the walkers' loops and
answers ``CLEAR`` or ``BLOCKED``. One compiled copy of the tests of ``geometry.first_hit``, so
every compiled technique agrees with the numpy path. :func:`status` is the call the walkers
make. (``DEFER``, "left for ``Blockers.occluded``", is what Trace's rounding-bound tests,
:mod:`psurf_core.trace_shadow`, answer when they cannot decide.)
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import types
from numba.core.extending import overload

from ..constants import BOUNDS_PAD, PARALLEL_EPS, SHADOW_EPS
from ..memo import memo
from ..records import Vec, flat, load, table
from .jit import inline, kernel, scalar
from .mesh_bvh import any_hit, slab

#: Shadow-segment status.
CLEAR, BLOCKED, DEFER = 0, 1, 2

#: Blocker kinds (the order of ``Blockers.bounds``: spheres, boxes, quads, meshes).
SPHERE, BOX, QUAD, MESH = 0, 1, 2, 3


class BlockerRow(NamedTuple):
    """One blocker (a row of :func:`blocker_table`).

    Attributes
    ----------
    kind : float
        ``SPHERE``, ``BOX``, ``QUAD`` or ``MESH``.
    lo, hi : Vec
        Bounding box (every kind).
    normal, offset : Vec, float
        Quads: the plane ``x . normal = offset``.
    p, e1, e2 : Vec
        Sphere: centre, ``(radius, 0, 0)``; box: min, max; quad: corner, edges ``eu, ev``.
    n : Vec
        Quad: ``eu x ev``.
    gram : (float, float, float, float)
        Quad: the inverse Gram matrix of ``eu, ev`` (row-major).
    """

    kind: float
    lo: Vec
    hi: Vec
    normal: Vec
    offset: float
    p: Vec
    e1: Vec
    e2: Vec
    n: Vec
    gram: tuple[float, float, float, float]


@scalar
def meets(a, b, bl):  # pragma: no cover - compiled
    """Does the box of segment ``a -> b`` meet blocker ``bl``'s box padded by
    ``BOUNDS_PAD``? ``Blockers.occluded``'s first reject, the same comparisons. (``bl`` a
    :class:`BlockerRow`: an array handed to an inlined function in a loop costs numba a
    reference count per call.)"""
    lo = (bl.lo[0] - BOUNDS_PAD, bl.lo[1] - BOUNDS_PAD, bl.lo[2] - BOUNDS_PAD)
    hi = (bl.hi[0] + BOUNDS_PAD, bl.hi[1] + BOUNDS_PAD, bl.hi[2] + BOUNDS_PAD)
    # & rather than `and`: no branches (they mispredict on segments near the boxes)
    return ((min(a[0], b[0]) <= hi[0]) & (max(a[0], b[0]) >= lo[0])
            & (min(a[1], b[1]) <= hi[1]) & (max(a[1], b[1]) >= lo[1])
            & (min(a[2], b[2]) <= hi[2]) & (max(a[2], b[2]) >= lo[2]))


@scalar
def _near(a, b, bl):
    """Does segment ``a -> b`` meet blocker ``bl``'s padded box (and, for a quad, cross its
    plane within the segment's ends)?"""
    if not meets(a, b, bl):
        return False
    if bl.kind != QUAD:
        return True
    # geometry._crosses_plane
    da = a[0] * bl.normal[0] + a[1] * bl.normal[1] + a[2] * bl.normal[2] - bl.offset
    db = b[0] * bl.normal[0] + b[1] * bl.normal[1] + b[2] * bl.normal[2] - bl.offset
    if not da * db <= 0.0:
        return False
    ln = np.sqrt((b[0] - a[0]) ** 2 + (b[1] - a[1]) ** 2 + (b[2] - a[2]) ** 2)
    t = da / (da - db) * ln  # only now the square root and the division
    return t >= 0.5 * SHADOW_EPS and t <= ln - 0.5 * SHADOW_EPS


@inline  # too large for LLVM to inline: a call per blocker row (planes 1.09x)
def _first_hit(a, d, bl, t_min, t_max):
    """Does the ray ``a + t d`` hit sphere / box / quad ``bl`` in ``(t_min, t_max)``?"""
    if bl.kind == SPHERE:  # geometry.ray_sphere
        o0, o1, o2 = a[0] - bl.p[0], a[1] - bl.p[1], a[2] - bl.p[2]
        bb = o0 * d[0] + o1 * d[1] + o2 * d[2]
        cc = o0 * o0 + o1 * o1 + o2 * o2 - bl.e1[0] * bl.e1[0]
        disc = bb * bb - cc
        if disc >= 0.0:
            sq = np.sqrt(disc)
            tn, tf = -bb - sq, -bb + sq
            t = tn if tn > t_min else tf
            return np.isfinite(t) and t > t_min and t < t_max
        return False
    if bl.kind == BOX:  # geometry.ray_box
        te0, tx0 = slab(a[0], d[0], bl.p[0], bl.e1[0])
        te1, tx1 = slab(a[1], d[1], bl.p[1], bl.e1[1])
        te2, tx2 = slab(a[2], d[2], bl.p[2], bl.e1[2])
        te, tx = max(te0, te1, te2), min(tx0, tx1, tx2)
        if te < tx:
            t = te if te > t_min else tx
            return np.isfinite(t) and t > t_min and t < t_max
        return False
    # QUAD: geometry.ray_parallelogram
    denom = d[0] * bl.n[0] + d[1] * bl.n[1] + d[2] * bl.n[2]
    t = ((bl.p[0] - a[0]) * bl.n[0] + (bl.p[1] - a[1]) * bl.n[1]
         + (bl.p[2] - a[2]) * bl.n[2]) / denom
    q0, q1, q2 = a[0] + t * d[0] - bl.p[0], a[1] + t * d[1] - bl.p[1], a[2] + t * d[2] - bl.p[2]
    r0 = q0 * bl.e1[0] + q1 * bl.e1[1] + q2 * bl.e1[2]
    r1 = q0 * bl.e2[0] + q1 * bl.e2[1] + q2 * bl.e2[2]
    u = r0 * bl.gram[0] + r1 * bl.gram[1]
    w = r0 * bl.gram[2] + r1 * bl.gram[3]
    return (abs(denom) > PARALLEL_EPS and u >= 0.0 and u <= 1.0 and w >= 0.0 and w <= 1.0
            and np.isfinite(t) and t > t_min and t < t_max)


@kernel
def occluded(a, b, rows):  # pragma: no cover - compiled
    """Status of the open segment ``a -> b`` (3-tuples) against the non-mesh blockers:
    ``CLEAR``, ``BLOCKED``, or ``DEFER`` when a mesh's box meets it (then
    :func:`mesh_occluded` decides). Mirrors :meth:`Blockers.occluded`: the per-blocker box
    (and quad plane) reject, then the first-hit tests of ``first_hit`` in
    ``(SHADOW_EPS, |b - a| - SHADOW_EPS)``. ``rows``: the flat :func:`blocker_table`.

    Compiled once as a function of its own (not inlined): a copy per call site in every
    walker tripled the compile time, and a call costs little beside the tests. It takes the
    one table, not :func:`shadow_args`' three: each array passed to a compiled call is
    reference-counted per call, and three cost ``planes`` 28 % of its pass on ``area.toml``
    (``benchmarks/before_after.py``, 2026-12-04).
    """
    near = False
    mesh = False
    for k in range(rows.shape[0]):
        bl = load(rows, k, BlockerRow)
        if _near(a, b, bl):
            near = True
            if bl.kind == MESH:
                mesh = True
    if not near:
        return CLEAR
    if mesh:
        return DEFER
    length, d = _direction(a, b)
    return _blocked(a, d, length, rows)


@scalar
def _direction(a, b):
    """``|b - a|`` and the unit direction, as ``Blockers.occluded`` computes them."""
    v0, v1, v2 = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    length = np.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    nrm = length if length > 0 else 1.0
    return length, (v0 / nrm, v1 / nrm, v2 / nrm)


@inline
def _blocked(a, d, length, rows):
    """``BLOCKED`` if a sphere, box or quad is hit along ``a + t d`` in
    ``(SHADOW_EPS, length - SHADOW_EPS)``, else ``CLEAR``."""
    for k in range(rows.shape[0]):
        bl = load(rows, k, BlockerRow)
        if bl.kind != MESH and _first_hit(a, d, bl, SHADOW_EPS, length - SHADOW_EPS):
            return BLOCKED
    return CLEAR


@kernel
def mesh_occluded(a, b, rows, nodes, tris):  # pragma: no cover - compiled
    """Status of a segment whose box meets a mesh's (:func:`occluded` said ``DEFER``): the
    other blockers, then the triangles through their hierarchy (:mod:`.mesh_bvh`)."""
    length, d = _direction(a, b)  # once for both tests
    if _blocked(a, d, length, rows) == BLOCKED:
        return BLOCKED
    return BLOCKED if any_hit(a, d, SHADOW_EPS, length - SHADOW_EPS, nodes, tris) else CLEAR


def status(a, b, blockers):
    """The status of segment ``a -> b`` (3-tuples), ``CLEAR`` or ``BLOCKED``, in compiled
    code (the walkers' visibility twins call it; the implementation is
    :func:`_status_impl`). ``blockers``: :func:`shadow_args`."""
    raise NotImplementedError("kernels.shadow.status runs in compiled code only")


@overload(status, inline="always")
def _status_impl(a, b, blockers):
    """:func:`occluded` (``CLEAR`` without a call when the scene has no blockers), then, where
    the scene has triangles (``blockers`` the tuple of :func:`shadow_args`),
    :func:`mesh_occluded` for a segment a mesh's box meets. Two implementations chosen by
    the type of ``blockers``: the tuple is read in the walkers' innermost loop, and its
    arrays' reference counts cost ``planes`` 12 % of a pass on ``area.toml`` against the
    table alone (``benchmarks/before_after.py``, 2026-12-04), so a scene without triangles
    passes the table alone."""
    if isinstance(blockers, types.Array):
        def table_only(a, b, blockers):  # pragma: no cover - compiled
            if blockers.shape[0] == 0:
                return CLEAR
            return occluded(a, b, blockers)

        return table_only

    def with_meshes(a, b, blockers):  # pragma: no cover - compiled
        rows = blockers[0]
        if rows.shape[0] == 0:
            return CLEAR
        st = occluded(a, b, rows)
        if st == DEFER:
            return mesh_occluded(a, b, rows, blockers[1], blockers[2])
        return st

    return with_meshes


def shadow_args(blockers):
    """What :func:`status` takes: the flat :func:`blocker_table` alone, or, where the scene
    has triangles, with their hierarchy ``(rows, nodes, triangles)`` (the hierarchy
    ``Blockers`` answers its numpy callers with, so both paths give one verdict); ``None``
    when the blockers carry no bounds (then the numpy path runs). Built once per
    ``blockers``."""
    tab = blocker_table(blockers)
    if tab is None:
        return None
    if blockers.triangles.shape[0] == 0:
        return memo(blockers, "shadow args", lambda: flat(tab))
    return memo(blockers, "shadow args", lambda: (flat(tab), *blockers.mesh_hierarchy()))


def blocker_table(blockers):
    """The compiled code's view of :class:`~psurf_core.geometry.Blockers`: (N,)
    :class:`BlockerRow` records, one per entry of ``blockers.bounds``, or ``None`` when the
    blockers carry no bounds (then the numpy path runs). Built once per ``blockers``
    (read-only)."""
    return memo(blockers, "table", lambda: _blocker_table(blockers))


def _blocker_table(blockers):
    if blockers.bounds is None or blockers.planes is None:
        return None
    n_all = 0 if blockers.empty else blockers.bounds.shape[0]
    tab = table(BlockerRow, n_all)
    if n_all == 0:
        return tab
    tab["kind"] = MESH
    tab["lo"], tab["hi"] = blockers.bounds[:, 0], blockers.bounds[:, 1]
    planes = np.nan_to_num(blockers.planes)
    tab["normal"], tab["offset"] = planes[:, :3], planes[:, 3]
    k = 0
    for c, r in zip(blockers.sphere_c, blockers.sphere_r, strict=True):
        tab["kind"][k], tab["p"][k], tab["e1"][k] = SPHERE, c, (r, 0.0, 0.0)
        k += 1
    for lo, hi in zip(blockers.box_min, blockers.box_max, strict=True):
        tab["kind"][k], tab["p"][k], tab["e1"][k] = BOX, lo, hi
        k += 1
    for corner, eu, ev in blockers.quads:
        g = np.linalg.inv(np.array([[eu @ eu, eu @ ev], [eu @ ev, ev @ ev]]))
        tab["kind"][k], tab["p"][k], tab["e1"][k], tab["e2"][k] = QUAD, corner, eu, ev
        tab["n"][k], tab["gram"][k] = np.cross(eu, ev), g.ravel()
        k += 1
    return tab
