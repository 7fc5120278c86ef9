"""Compiled shadow tests shared by the fused kernels (:mod:`.planes_fused`,
:mod:`.surface_kernels`): the status of one shadow segment against the scene's spheres, boxes
and emitter quads, with segments that meet a triangle mesh's box handed back for the exact
test.

:func:`blocker_table` packs :class:`~psurf_core.geometry.Blockers` into one array;
:func:`occluded` reads it inside the kernels' loops and answers ``CLEAR``, ``BLOCKED`` or
``DEFER`` (the caller then runs :meth:`Blockers.occluded`: Embree plus the exact float64
re-test). One copy of the tests, so that every fused kernel agrees with ``first_hit``.

:func:`occluded` is inlined (``inline="always"``) into the kernels that call it, and numba's
on-disk cache (``cache=True``) watches only the caller's file: after changing it (or
:func:`_slab`), touch :mod:`.planes_fused` and :mod:`.surface_kernels` (or clear
``__pycache__``) so that their kernels recompile."""

from __future__ import annotations

import numpy as np
from numba import njit

from ..constants import PARALLEL_EPS, SHADOW_EPS
from ..geometry import _BOUNDS_PAD

#: Shadow-segment status written by the kernel.
CLEAR, BLOCKED, DEFER = 0, 1, 2

#: Blocker kinds in :func:`blocker_table` (order of ``Blockers.bounds``).
_SPHERE, _BOX, _QUAD, _MESH = 0, 1, 2, 3


@njit(cache=True, error_model="numpy")
def _slab(o, d, lo, hi):  # pragma: no cover - compiled
    """Entry and exit of one axis's slab (``geometry.ray_box``)."""
    inv = 1.0 / (PARALLEL_EPS if abs(d) < PARALLEL_EPS else d)
    ta = (lo - o) * inv
    tb = (hi - o) * inv
    return min(ta, tb), max(ta, tb)


@njit(cache=True, error_model="numpy", inline="always")
def occluded(a0, a1, a2, b0, b1, b2, blk):  # pragma: no cover - compiled
    """Status of the open segment ``a -> b``: ``CLEAR``, ``BLOCKED`` or ``DEFER`` (a mesh's
    box meets it: the caller runs the exact test). Mirrors :meth:`Blockers.occluded`: the
    per-blocker box (and quad plane) reject, then the first-hit tests of ``first_hit`` in
    ``(SHADOW_EPS, |b - a| - SHADOW_EPS)``. ``blk``: rows of :func:`blocker_table`."""
    nbl = blk.shape[0]
    lo0, hi0 = min(a0, b0), max(a0, b0)
    lo1, hi1 = min(a1, b1), max(a1, b1)
    lo2, hi2 = min(a2, b2), max(a2, b2)
    near = False
    mesh = False
    for k in range(nbl):
        meet = (lo0 <= blk[k, 4] + _BOUNDS_PAD and hi0 >= blk[k, 1] - _BOUNDS_PAD
                and lo1 <= blk[k, 5] + _BOUNDS_PAD and hi1 >= blk[k, 2] - _BOUNDS_PAD
                and lo2 <= blk[k, 6] + _BOUNDS_PAD and hi2 >= blk[k, 3] - _BOUNDS_PAD)
        if meet and blk[k, 0] == _QUAD:
            # geometry._crosses_plane
            da = a0 * blk[k, 7] + a1 * blk[k, 8] + a2 * blk[k, 9] - blk[k, 10]
            db = b0 * blk[k, 7] + b1 * blk[k, 8] + b2 * blk[k, 9] - blk[k, 10]
            meet = da * db <= 0.0
            if meet:  # only then the distance (a square root and a division)
                ln = np.sqrt((b0 - a0) ** 2 + (b1 - a1) ** 2 + (b2 - a2) ** 2)
                t = da / (da - db) * ln
                meet = t >= 0.5 * SHADOW_EPS and t <= ln - 0.5 * SHADOW_EPS
        if meet:
            near = True
            if blk[k, 0] == _MESH:
                mesh = True
    if not near:
        return CLEAR
    if mesh:
        return DEFER
    v0, v1, v2 = b0 - a0, b1 - a1, b2 - a2
    length = np.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    nrm = length if length > 0 else 1.0
    d0, d1, d2 = v0 / nrm, v1 / nrm, v2 / nrm
    t_min = SHADOW_EPS
    t_max = length - SHADOW_EPS
    for k in range(nbl):
        if blk[k, 0] == _SPHERE:  # geometry.ray_sphere
            o0, o1, o2 = a0 - blk[k, 11], a1 - blk[k, 12], a2 - blk[k, 13]
            bb = o0 * d0 + o1 * d1 + o2 * d2
            cc = o0 * o0 + o1 * o1 + o2 * o2 - blk[k, 14] * blk[k, 14]
            disc = bb * bb - cc
            if disc >= 0.0:
                sq = np.sqrt(disc)
                tn, tf = -bb - sq, -bb + sq
                t = tn if tn > t_min else tf
                if np.isfinite(t) and t > t_min and t < t_max:
                    return BLOCKED
        elif blk[k, 0] == _BOX:  # geometry.ray_box
            te0, tx0 = _slab(a0, d0, blk[k, 11], blk[k, 14])
            te1, tx1 = _slab(a1, d1, blk[k, 12], blk[k, 15])
            te2, tx2 = _slab(a2, d2, blk[k, 13], blk[k, 16])
            te, tx = max(te0, te1, te2), min(tx0, tx1, tx2)
            if te < tx:
                t = te if te > t_min else tx
                if np.isfinite(t) and t > t_min and t < t_max:
                    return BLOCKED
        elif blk[k, 0] == _QUAD:  # geometry.ray_parallelogram
            denom = d0 * blk[k, 20] + d1 * blk[k, 21] + d2 * blk[k, 22]
            t = ((blk[k, 11] - a0) * blk[k, 20] + (blk[k, 12] - a1) * blk[k, 21]
                 + (blk[k, 13] - a2) * blk[k, 22]) / denom
            p0 = a0 + t * d0 - blk[k, 11]
            p1 = a1 + t * d1 - blk[k, 12]
            p2 = a2 + t * d2 - blk[k, 13]
            r0 = p0 * blk[k, 14] + p1 * blk[k, 15] + p2 * blk[k, 16]
            r1 = p0 * blk[k, 17] + p1 * blk[k, 18] + p2 * blk[k, 19]
            u = r0 * blk[k, 23] + r1 * blk[k, 24]
            w = r0 * blk[k, 25] + r1 * blk[k, 26]
            if (abs(denom) > PARALLEL_EPS and u >= 0.0 and u <= 1.0 and w >= 0.0
                    and w <= 1.0 and np.isfinite(t) and t > t_min and t < t_max):
                return BLOCKED
    return CLEAR


def blocker_table(blockers):
    """The kernel's view of :class:`~psurf_core.geometry.Blockers`: (N, 27) float64, one row
    per entry of ``blockers.bounds`` (spheres, boxes, quads, meshes: ``first_hit``'s order),
    or ``None`` when the blockers carry no bounds (then the stage path runs).

    Columns: 0 kind (``_SPHERE``, ...); 1-3 / 4-6 box ``lo`` / ``hi``; 7-10 plane ``(n, n .
    p)`` (quads); from 11: sphere centre, radius | box min, max | quad corner, ``eu``, ``ev``,
    ``eu x ev``, inverse Gram matrix (row-major). One array, not one per field: every array
    argument of a compiled call costs reference counting.
    """
    if blockers.bounds is None or blockers.planes is None:
        return None
    n_all = blockers.bounds.shape[0]
    blk = np.zeros((0 if blockers.empty else n_all, 27))
    if blk.shape[0] == 0:
        return blk
    blk[:, 0] = _MESH
    blk[:, 1:4] = blockers.bounds[:, 0]
    blk[:, 4:7] = blockers.bounds[:, 1]
    blk[:, 7:11] = np.nan_to_num(blockers.planes)
    k = 0
    for c, r in zip(blockers.sphere_c, blockers.sphere_r, strict=True):
        blk[k, 0], blk[k, 11:14], blk[k, 14] = _SPHERE, c, r
        k += 1
    for lo, hi in zip(blockers.box_min, blockers.box_max, strict=True):
        blk[k, 0], blk[k, 11:14], blk[k, 14:17] = _BOX, lo, hi
        k += 1
    for corner, eu, ev in blockers.quads:
        g = np.linalg.inv(np.array([[eu @ eu, eu @ ev], [eu @ ev, ev @ ev]]))
        blk[k, 0] = _QUAD
        blk[k, 11:23] = np.concatenate([corner, eu, ev, np.cross(eu, ev)])
        blk[k, 23:27] = g.ravel()
        k += 1
    return blk
