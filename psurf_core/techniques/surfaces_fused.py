"""Fused Intersect + Evaluate of the photon cone, cylinder and generalized planes: candidate
pixel spans -> each pixel's rays -> roots -> contribution, in compiled loops.

The stage path (``binning.candidate_pairs`` -> ``intersect`` -> ``evaluate``) materialises
every candidate pair and every intermediate as numpy arrays; the quadrics test ~3.5 pairs per
hit and keep both roots, which made them the slowest members of ``paper-multi``. Here the
candidate spans are those binning yields (the screen rectangle's rows for the cone and the
cylinder, the clipped hull's per-row spans for the generalized planes, via
``fused_spans.hull_spans``), and the kernels of :mod:`.surface_kernels` walk them, writing
only the hits with their per-photon values. Shadow segments whose box meets a triangle mesh's
box come back ``DEFER`` and are tested here by :meth:`Blockers.occluded`, as the stage path
does. Hits and values equal the stage path's (``tests/test_fused_surfaces.py``): the same hits
with the same ``data`` fields (what ``reconstruct``, hence the MIS weights, and the UI read),
values to rounding; only the hit order within a chunk differs (span, pixel, ray, root instead
of root-major).

The kernels are single-threaded (the output order does not depend on thread scheduling) and
compiled once per clone (``cache=True``)."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from ..binning import _chunk_bounds, _pixel_ray_table, _spans, screen_rects
from ..compiled import ctrl_c_kept
from ..geometry import inside_box
from .base import Hits
from .fused_shadow import BLOCKED, DEFER, blocker_table
from .fused_spans import hull_spans
from .surface_kernels import _cone_kernel, _cylinder_kernel, _gplane_kernel

#: Families with a kernel: roots per candidate pair (the output capacity per pair).
_ROOTS = {"cone": 2, "cylinder": 2, "t1t3": 1, "t2t3": 1}


def surface_chunks(tech, kind: str, prims, paths, rays,
                   ctx) -> Iterator[tuple[Hits, np.ndarray]] | None:
    """All hits of ``prims`` (a cone, cylinder or generalized plane technique ``tech``) with
    ``rays`` and their per-photon contributions, as ``(Hits, values (H, 3))`` chunks of at
    most ~``ctx.max_pairs`` candidate pairs.

    Parameters
    ----------
    tech : PhotonCone, PhotonCylinder or GeneralizedPlane
    kind : {"cone", "cylinder", "t1t3", "t2t3"}
    prims : Primitives
        From ``tech.create``.
    paths : PhotonPaths
    rays : Rays
    ctx : PassContext

    Returns
    -------
    iterator of (Hits, (H, 3) float), or None
        The hits and values ``tech.intersect`` + ``tech.evaluate`` give over
        ``binning.candidate_pairs``; ``None`` where the fused path does not apply (64 or fewer
        pixels with medium: binning's per-pixel branch; blockers without bounds), so the
        caller runs the stages.
    """
    if kind not in _ROOTS:
        raise ValueError(f"no fused kernel for '{kind}'")
    bl = blocker_table(ctx.blockers)
    if bl is None:
        return None
    order, start, counts = _pixel_ray_table(rays, ctx.scene.camera.n_pixels)
    if np.count_nonzero(counts) <= 64:
        return None
    return _chunks(tech, kind, prims, paths, rays, ctx, bl, order, start, counts)


def _chunks(tech, kind, prims, paths, rays, ctx, bl, order, start, counts):
    """:func:`_fused_chunks`, with Ctrl-C kept a KeyboardInterrupt
    (:func:`~psurf_core.compiled.ctrl_c_kept`: a SIGINT handled while numba boxes a result
    surfaces as a SystemError caused by it)."""
    with ctrl_c_kept():
        yield from _fused_chunks(tech, kind, prims, paths, rays, ctx, bl, order, start, counts)


def _own(paths, photon, j, start, med) -> np.ndarray:
    """(M,) bool, the per-primitive part of ``base.on_own_segment``: the photon's own segment
    ``j`` is unoccluded with its vertices in the box, and (``j = 1``) its start, the light,
    lies in the box; the kernels add ``t < T`` per hit."""
    pk = paths.prefix_ok
    own = pk.reshape(-1)[photon * pk.shape[1] + j].copy()
    light = np.flatnonzero(own & (j == 1))
    if light.size:
        own[light] = inside_box(start[light], med.bounds_min, med.bounds_max)
    return own


def _prim_table(kind, prims, paths, med) -> np.ndarray:
    """(M, F) float64 primitive table of ``kind`` (columns: ``surface_kernels._*_COLS``)."""
    d, photon, K = prims.data, prims.photon, prims.K
    beta = paths.beta[photon, K - 1]  # surface_common.beta1
    if kind == "cone":
        cols = (d["x1"], d["w2"], d["c1"], d["T1"], beta)
    elif kind == "cylinder":
        own = _own(paths, photon, K - 1, d["x2"], med)
        cols = (d["x2"], d["w2"], d["c1"], d["s1"], d["T1"], d["T2"], own, beta)
    else:
        own = _own(paths, photon, K - 2, d["x3"], med)
        cols = (d["origin"], d["w3"], d["v"], d["x3"], d["w2"], d["w1"], d["Tu"], d["Tv"],
                d["T2"], own, beta, np.cross(d["v"], d["w3"]))
    return np.ascontiguousarray(np.column_stack(cols), dtype=float)


def _candidate_spans(prims, cam, box, max_pairs):
    """(S, 4) int64 rows ``(prim, row, c0, c1)``: the spans ``binning.candidate_pairs`` walks
    (primitive-major, then row), or None."""
    if prims.hull is not None:
        spans = hull_spans(cam, prims.lo, prims.hi, prims.hull, box)
    else:
        x0, x1, y0, y1 = screen_rects(cam, prims.lo, prims.hi)
        spans = _spans(cam, x0, x1, y0, y1, None, box, max_pairs)
        if spans is None:
            return None
    return np.ascontiguousarray(np.stack(spans, axis=1), dtype=np.int64)


def _fused_chunks(tech, kind, prims, paths, rays, ctx, bl, order, start, counts):
    scene = ctx.scene
    cam, med = scene.camera, scene.medium
    if len(prims) == 0 or len(rays) == 0:
        return
    box = (med.bounds_min, med.bounds_max)
    spans = _candidate_spans(prims, cam, box, ctx.max_pairs)
    if spans is None or spans.shape[0] == 0:
        return
    c = np.ascontiguousarray
    pt = _prim_table(kind, prims, paths, med)
    rt = c(np.column_stack((rays.o, rays.d, rays.s_min, rays.s_max)), dtype=float)
    mv = np.concatenate([[med.sigma_t, med.sigma_s, med.phase.g], med.bounds_min,
                         med.bounds_max]).astype(float)
    pix = c(np.stack((start, counts), axis=1), dtype=np.int64)
    order = c(order, dtype=np.int64)
    short = bool(tech.short)
    n_pix = spans[:, 3] - spans[:, 2]
    per_pix = max(int(counts.max()), 1)
    bounds = _chunk_bounds(n_pix * per_pix, ctx.max_pairs)
    for a, b in zip(bounds[:-1], bounds[1:], strict=True):
        cap = int(n_pix[a:b].sum()) * per_pix * _ROOTS[kind]
        sp = spans[a:b]
        w = int(cam.width)
        if kind == "cone":
            out = _cone_kernel(sp, w, order, pix, rt, pt, mv, bl, short, cap)
        elif kind == "cylinder":
            out = _cylinder_kernel(sp, w, order, pix, rt, pt, mv, bl, short, cap)
        else:
            out = _gplane_kernel(sp, w, order, pix, rt, pt, mv, bl, short, kind == "t1t3", cap)
        n, n_defer = out[:2]
        if n == 0:
            continue
        ray, prim, s, r0, r1, ndp, val, st = (x[:n] for x in out[2:])
        if kind in ("cone", "cylinder"):
            data = {"t1" if kind == "cone" else "t2": r0, "w1": r1, "n_dot_psi": ndp}
        else:
            data = dict(t3=r0, tv=r1, n_dot_psi=ndp)
        hits = Hits(ray, prim, s, data)
        if n_defer:
            _resolve(kind, ctx.blockers, rays, prims, hits, st, val)
        yield hits, val


def _segments(kind, rays, prims, hits):
    """The shadow segments ``(a, b)`` (H, 3) of ``hits``, in the kernels' status order,
    computed as ``evaluate`` computes them."""
    d, p = prims.data, hits.prim
    x0 = rays.o[hits.ray] + hits.s[:, None] * rays.d[hits.ray]
    if kind == "cone":
        return [(d["x1"][p], x0)]
    if kind == "cylinder":
        x2 = d["x2"][p]
        x1 = x2 + hits.data["t2"][:, None] * d["w2"][p]
        return [(x2, x1), (x1, x0)]
    x3 = d["x3"][p]
    x2 = x3 + hits.data["t3"][:, None] * d["w3"][p]
    step = d["T2"][p] if kind == "t1t3" else hits.data["tv"]
    x1 = x2 + step[:, None] * d["w2"][p]
    return [(x3, x2), (x2, x1), (x1, x0)]


def _resolve(kind, blockers, rays, prims, hits, st, val):
    """Exact shadow tests (:meth:`Blockers.occluded`) of the deferred segments; zero the
    values (rows of ``val``, (H, 3), in place) of the hits found blocked. A hit is visible
    when every segment is clear, whichever order they are tested in."""
    rows = np.flatnonzero(np.any(st == DEFER, axis=1))
    sub = hits.select(rows)
    st = st[rows]
    ok = ~np.any(st == BLOCKED, axis=1)
    for k, (a, b) in enumerate(_segments(kind, rays, prims, sub)):
        idx = np.flatnonzero(ok & (st[:, k] == DEFER))
        if idx.size:
            ok[idx] = ~blockers.occluded(a[idx], b[idx])
    val[rows[~ok]] = 0.0
