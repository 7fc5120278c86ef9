"""Trace, compiled: the depth loop of :mod:`psurf_core.trace` (``step``, ``assemble``,
``trace``) as per-photon numba loops, and the compiled twin of each of its formulas.

Every formula of ``trace.py`` has a scalar twin here under the same name
(:func:`psurf_core.kernels.jit.twin`; emission's are in :mod:`psurf_core.trace_emit_compiled`):
compiled code calling ``ref.phase_cosine`` runs the twin, Python calling it runs the numpy
function. A twin performs the numpy function's IEEE operations in the same order (no
``fastmath``, so no fused multiply-add; ``sqrt``, ``+ - * /`` and comparisons are exactly
rounded in both); a (3,) vector is a 3-tuple. The random numbers stay numpy's (drawn on
this thread, in order); the azimuths' ``cos``/``sin`` and the flights' logarithm are
:mod:`psurf_core.variates`' ``+ - * /`` maps, whose twins the depth kernel calls per photon
(numba's own ``cos`` or ``log`` would be other implementations than numpy's).

Where this path differs from the numpy reference in work, not in values:

* **one kernel per depth**: :func:`step` samples segment ``j``, records it, and already
  selects the photons of segment ``j + 1`` (roulette, look-back): the selection reads
  ``prefix_ok`` of vertex ``j + 1 - LOOKBACK <= j - 1``, final before segment ``j``, and its
  roulette variates follow segment ``j``'s in the stream, so they are drawn first;
* **records, then one scatter**: each depth writes compact step records (``REC_*`` columns);
  :func:`assemble` writes the photon-major ``PhotonPaths`` arrays once, recomputing every
  vertex (``advance``) and weight (``scattered_weight``) with the twins;
* **shadow tests**: a segment whose box meets a blocker's padded box is *near*;
  ``trace_shadow.shade`` decides what ``Blockers.occluded`` answers for the near segments
  from rounding bounds, and only a depth with an undecided one calls ``Blockers.occluded``,
  on all its near segments: exactly the rows the reference's call keeps for its exact test;
* **threads** (:func:`psurf_core.kernels.threads.thread_count`, 1 in pass-pool workers): the
  depth kernel runs over ranges of the active photons, each compacting and listing its near
  segments from its own first row, closed up in range order afterwards (:func:`_steps`);
  ``assemble`` runs over ranges of photons (:func:`psurf_core.kernels.threads.in_pieces`).
  Every element is computed from its own inputs, so the arrays do not depend on the thread
  count
  (``tests/test_trace_reference.py``); the random numbers are drawn on this thread, in order;
* **memory**: scratch in a per-thread workspace (:mod:`psurf_core.trace_buffers`), outputs
  in ``kernels.buffers`` reused once the caller has dropped them: no page faults on fresh
  memory per batch.

Compiled with :func:`psurf_core.kernels.jit.kernel` (cached on disk, keyed by the sources
they inline: editing ``trace.py`` or ``trace_shadow.py`` recompiles).
"""

from __future__ import annotations

import math

import numpy as np

from . import (
    geometry,
    variates,
    variates_compiled,  # noqa: F401 - registers the twins the kernels call
)
from . import trace_buffers as buffers
from . import trace_emit_compiled as emission
from . import trace_numpy as ref
from . import trace_shadow as shadow
from .kernels.buffers import HitBuffers
from .kernels.jit import kernel, twin
from .kernels.shadow import BlockerRow
from .kernels.threads import PIECES_PER_THREAD, guided_cut, in_pieces, on_threads, thread_count
from .photon_sampler import uniforms
from .records import load
from .trace_buffers import REC_CLIP, REC_T, REC_W


# --------------------------------------------------------------------------- twins
# Each is documented by the numpy function it twins (trace.py), operation for operation.
@twin(ref.phase_cosine)
def phase_cosine(g, u):  # pragma: no cover - compiled
    if abs(g) < ref.sampling.HG_ISOTROPIC_G:
        return 1.0 - 2.0 * u
    sq = (1.0 - g * g) / (1.0 - g + 2.0 * g * u)
    mu = (1.0 + g * g - sq * sq) / (2.0 * g)
    mu = mu if mu > -1.0 else -1.0  # np.clip(., -1, 1)
    return mu if mu < 1.0 else 1.0


@twin(ref.free_flight)
def free_flight(u, sigma_t):  # pragma: no cover - compiled
    return variates.neg_log_complement(u) / sigma_t


@twin(ref.advance)
def advance(x, w, t):  # pragma: no cover - compiled
    return x[0] + t * w[0], x[1] + t * w[1], x[2] + t * w[2]


@twin(ref.segment_clip)
def segment_clip(x, w, t, bmin, bmax):  # pragma: no cover - compiled
    enter, leave = -np.inf, np.inf
    for c in range(3):
        wc = w[c]
        inv = 1.0 / (ref.PARALLEL_EPS if abs(wc) < ref.PARALLEL_EPS else wc)
        p, q = (bmin[c] - x[c]) * inv, (bmax[c] - x[c]) * inv
        lo, hi = (p, q) if p < q else (q, p)
        if c == 0:
            enter, leave = lo, hi
        else:
            enter = lo if lo > enter else enter
            leave = hi if hi < leave else leave
    enter = enter if enter > 0.0 else 0.0
    leave = leave if leave > 0.0 else 0.0
    return (enter if enter < t else t), (leave if leave < t else t)


@twin(ref.survives)
def survives(ok_look, u, q):  # pragma: no cover - compiled
    return ok_look and (u < q if q < 1.0 else True)


@twin(ref.scattered_weight)
def scattered_weight(beta, q, albedo):  # pragma: no cover - compiled
    b0, b1, b2 = beta
    if q < 1.0:
        b0, b1, b2 = b0 / q, b1 / q, b2 / q
    return b0 * albedo, b1 * albedo, b2 * albedo


# --------------------------------------------------------------------------- depth steps
@kernel(nogil=True)
def step(i0, i1, scatter, g, sigma_t, idx, x, w, u_mu, u_phi, sin_phi, u_t, box, ok_prev, ok_cur,
         select, ok_look, u_next, q_next, rec_idx, rec, off, near_photon, near_a, near_b,
         near_inside, blockers, test_all):  # pragma: no cover - compiled
    """Segment ``j`` of the active photons in state rows ``i0 .. i1 - 1`` (``trace.step``),
    then the selection of segment ``j + 1``'s photons (``trace.survives``), compacting the
    state in place from row ``i0`` and listing the near segments from row ``i0``: a range
    reads and writes only its own rows (and ``ok_cur`` of its own photons), so the driver
    runs ranges on several threads and closes up their outputs (:func:`_steps`).

    Parameters
    ----------
    i0, i1 : int
        The state rows to step (active photons, in photon order).
    scatter : bool
        Sample a new direction (every segment but the first): ``phase_cosine``,
        ``direction_about``.
    g, sigma_t : float
        Phase asymmetry; extinction (1 / scene unit).
    idx : (P,) int64
    x, w : (P, 3) float
        State: photon, start vertex and direction of each active photon; on return, rows
        ``0 .. k - 1`` hold the selected photons' end vertex and direction.
    u_mu, u_phi, u_t : (>= i1,) float
        Variates of the phase cosine, the azimuth (turns) and the flight; on return (rows
        ``i0 .. i1 - 1``) ``u_phi`` holds the azimuth's cosine and ``u_t`` the flight length.
    sin_phi : (>= i1,) float
        Scratch: the azimuth's sine.
    box : (2, 3) float
        ``bmin, bmax``.
    ok_prev, ok_cur : (N,) bool
        ``prefix_ok`` of the start and end vertex; ``ok_cur`` false on entry, written here
        but for the near segments (``trace_shadow.shade``, ``resolve``).
    select : bool
        Select segment ``j + 1``'s photons (else keep every row).
    ok_look : (N,) bool
        ``prefix_ok`` of vertex ``j + 1 - LOOKBACK``.
    u_next : (>= i1,) float
        Roulette variates of segment ``j + 1`` (unused when ``q_next >= 1``).
    q_next : float
    rec_idx : (R,) int64
    rec : (R, REC_COLS) float
        Step records, written at rows ``off + i0 .. off + i1 - 1``.
    off : int
    near_photon : (P,) int64
    near_a, near_b : (P, 3) float
    near_inside : (P,) bool
        The near segments (box meets a blocker's padded box; every one when ``test_all``):
        photon, start, end, end in the box.
    blockers : (B, F) float
    test_all : bool
        The blocker rows and flag of ``trace_shadow.table``.

    Returns
    -------
    k : int
        End of the selected photons' rows (``k - i0`` selected for segment ``j + 1``).
    nn : int
        End of the near segments' rows (``nn - i0`` listed).
    """
    bmin, bmax = (box[0, 0], box[0, 1], box[0, 2]), (box[1, 0], box[1, 1], box[1, 2])
    # The variates' maps first, each in a loop of its own: branch-free, so LLVM vectorizes
    # them (2 ns per azimuth here, against 15 inside the photon loop).
    if scatter:
        for i in range(i0, i1):
            u_phi[i], sin_phi[i] = variates.cos_sin_turn(u_phi[i])
    for i in range(i0, i1):
        u_t[i] = ref.free_flight(u_t[i], sigma_t)
    k, nn = i0, i0
    for i in range(i0, i1):
        p = idx[i]
        a = (x[i, 0], x[i, 1], x[i, 2])
        d = (w[i, 0], w[i, 1], w[i, 2])
        if scatter:
            d = ref.direction_about(d, ref.phase_cosine(g, u_mu[i]), u_phi[i], sin_phi[i])
        t = u_t[i]
        b = ref.advance(a, d, t)
        r = off + i
        rec_idx[r] = p
        rec[r, REC_T] = t
        rec[r, REC_W], rec[r, REC_W + 1], rec[r, REC_W + 2] = d
        rec[r, REC_CLIP], rec[r, REC_CLIP + 1] = ref.segment_clip(a, d, t, bmin, bmax)
        if ok_prev[p]:
            inb = geometry.inside_box(b, bmin, bmax)
            near = test_all  # its box meets a blocker's padded box: trace_shadow.shade
            for kb in range(blockers.shape[0]):
                near |= shadow.meets(a, b, load(blockers, kb, BlockerRow))
            if near:
                near_photon[nn] = p
                near_a[nn, 0], near_a[nn, 1], near_a[nn, 2] = a
                near_b[nn, 0], near_b[nn, 1], near_b[nn, 2] = b
                near_inside[nn] = inb
                nn += 1
            else:
                ok_cur[p] = inb
        if not select or ref.survives(ok_look[p], u_next[i], q_next):
            idx[k] = p
            x[k, 0], x[k, 1], x[k, 2] = b
            w[k, 0], w[k, 1], w[k, 2] = d
            k += 1
    return k, nn


@kernel(nogil=True)
def assemble(p0, p1, x0, beta0, q, albedo, oks, rec_idx, rec, rec_off, xs, ws, ts, betas,
             alives, clips, prefix_ok):  # pragma: no cover - compiled
    """``trace.assemble`` for photons ``p0 .. p1 - 1``: scatter the step records into the
    photon-major ``PhotonPaths`` arrays, recomputing each vertex (``advance``) and weight
    (``scattered_weight``) as the reference computed them. Each step's records are in photon
    order and a photon's segments are consecutive from segment 1, so one cursor per step
    (found by binary search for ``p0``) walks them. Photon ranges write disjoint rows: the
    driver runs ranges on several threads (the GIL released).

    Parameters
    ----------
    p0, p1 : int
        The photons to write.
    x0, beta0 : (N, 3) float
        Light points, emitted weights (W).
    q : (D,) float
        Roulette survival before segment ``s + 1`` (``q[0]`` unused).
    albedo : float
    oks : (>= D + 1, >= N) bool
        ``prefix_ok`` per vertex, vertex-major.
    rec_idx, rec : (R,) int64, (R, REC_COLS) float
        Step records; step ``s`` holds rows ``rec_off[s] .. rec_off[s + 1] - 1``.
    rec_off : (D + 1,) int64
    xs, ws, ts, betas, alives, clips, prefix_ok
        Outputs, shapes as in ``PhotonPaths`` (rows ``p0 .. p1 - 1`` written entirely).
    """
    d = ts.shape[1]
    cur = np.empty(d, np.int64)
    for s in range(d):
        cur[s] = rec_off[s] + np.searchsorted(rec_idx[rec_off[s]:rec_off[s + 1]], p0)
    for p in range(p0, p1):
        v = (x0[p, 0], x0[p, 1], x0[p, 2])
        xs[p, 0, 0], xs[p, 0, 1], xs[p, 0, 2] = v
        bp = (beta0[p, 0], beta0[p, 1], beta0[p, 2])
        run = True
        for s in range(d):
            r = cur[s]
            run = run and r < rec_off[s + 1] and rec_idx[r] == p
            if run:
                cur[s] = r + 1
                if s > 0:
                    bp = ref.scattered_weight(bp, q[s], albedo)
                t = rec[r, REC_T]
                dr = (rec[r, REC_W], rec[r, REC_W + 1], rec[r, REC_W + 2])
                v = ref.advance(v, dr, t)
                ts[p, s] = t
                ws[p, s, 0], ws[p, s, 1], ws[p, s, 2] = dr
                betas[p, s, 0], betas[p, s, 1], betas[p, s, 2] = bp
                clips[p, s, 0], clips[p, s, 1] = rec[r, REC_CLIP], rec[r, REC_CLIP + 1]
            else:
                ts[p, s] = 0.0
                ws[p, s, 0] = ws[p, s, 1] = ws[p, s, 2] = 0.0
                betas[p, s, 0] = betas[p, s, 1] = betas[p, s, 2] = 0.0
                clips[p, s, 0] = clips[p, s, 1] = 0.0
            alives[p, s] = run
            xs[p, s + 1, 0], xs[p, s + 1, 1], xs[p, s + 1, 2] = v
    for s in range(d + 1):  # vertex-major reads: contiguous (photon-major: 1.4 ms more)
        for p in range(p0, p1):
            prefix_ok[p, s] = oks[s, p]


# --------------------------------------------------------------------------- the driver
def trace(scene, n: int, rng, blockers, depth: int) -> ref.PhotonPaths:
    """``trace.trace`` compiled (same draws, same arrays); see the module docstring.

    Parameters
    ----------
    scene : Scene
    n : int
        Photons.
    rng : numpy.random.Generator
    blockers : Blockers
    depth : int
        Segments to trace at most.
    """
    med = scene.medium
    # Threads for the elementwise steps and assemble (each element or photon written from its
    # own inputs; the depth kernel's ranges are closed up in order: the arrays do not depend
    # on the count).
    threads = thread_count()
    box = buffers.constants(_box, med)
    rows, test_all = buffers.constants(shadow.table, blockers)
    ws = buffers.workspace(n, depth)
    keep = n <= buffers.KEEP_PHOTONS  # outputs in reused buffers (OUTPUTS)
    out = _outputs(keep, "lights", [(k, (n, *shape), dt)
                                    for k, (shape, dt) in emission.FIELDS.items()
                                    if k not in ("x0", "w1", "beta")])
    e = emission.emit(scene, rng, n, dict(out, x0=ws.x0[:n], w1=ws.w[:n], beta=ws.beta0[:n]))
    idx, x, w, oks, r = ws.idx, ws.x, ws.w, ws.oks, ws.r
    idx[:n] = np.arange(n)
    x[:n] = e["x0"]
    oks[0, :n] = True
    m, qs, rec_off, empty = n, [1.0], [0], r[:0]
    for j in range(1, depth + 1):
        # Segment j's variates: phase cosine, azimuth and flight (the flight alone at j = 1).
        nr = (3 if j > 1 else 1) * m
        rj = uniforms(rng, 3 if j > 1 else 1, m, out=r[:nr], rows=idx[:m])
        u_phi = rj[m : 2 * m] if j > 1 else empty
        # Then segment j + 1's roulette variates (the reference draws them next).
        q_next = ref.roulette_survival(scene, j) if j < depth else 1.0
        select = j < depth and m > 0
        u_next = (uniforms(rng, 1, m, out=ws.u[:m], rows=idx[:m]) if select and q_next < 1.0
                  else empty)
        off = rec_off[-1]
        ws.records(off + m)
        ok = oks[j]
        ok[:n] = False
        args = (j > 1, med.phase.g, med.sigma_t, idx, x, w, rj[:m], u_phi, ws.sin, rj[nr - m :],
                box,
                oks[j - 1], ok, select, oks[max(j + 1 - ref.LOOKBACK, 0)], u_next, q_next,
                ws.rec_idx, ws.rec, off, ws.near_photon, ws.near_a, ws.near_b,
                ws.near_inside, rows, test_all)
        k, nn = _steps(m, threads, args, (idx, x, w),
                       (ws.near_photon, ws.near_a, ws.near_b, ws.near_inside))
        if nn and shadow.shade(nn, ws.near_a, ws.near_b, ws.near_inside, rows, test_all, ok,
                               ws.near_photon, ws.verdict, threads):
            shadow.resolve(ws.near_photon[:nn], ws.near_a[:nn], ws.near_b[:nn],
                           ws.near_inside[:nn], blockers, ok)
        rec_off.append(off + m)
        if m == 0:
            break
        qs.append(q_next)
        m = k
    d = len(rec_off) - 1
    p = _outputs(keep, "paths", [
        ("x", (n, d + 1, 3), np.float64), ("w", (n, d, 3), np.float64), ("t", (n, d), np.float64),
        ("beta", (n, d, 3), np.float64), ("alive", (n, d), np.bool_),
        ("clip", (n, d, 2), np.float64), ("prefix_ok", (n, d + 1), np.bool_)])
    args = (e["x0"], e["beta"], np.array(qs[:d]), med.albedo, oks, ws.rec_idx, ws.rec,
            np.array(rec_off, dtype=np.int64), p["x"], p["w"], p["t"], p["beta"], p["alive"],
            p["clip"], p["prefix_ok"])
    # Memory-bound (~50 MB written per 32768 photons): two threads write faster than one.
    in_pieces(lambda a, b: assemble(a, b, *args), n, threads, ASSEMBLE_MIN)
    return ref.PhotonPaths(n_emitted=n, **{k: e[k] for k in out}, **p)


def _steps(m: int, threads: int, args: tuple, state: tuple, near: tuple) -> tuple[int, int]:
    """:func:`step` over state rows ``0 .. m - 1``, in ranges on ``threads`` threads, the
    ranges' selected rows (``state``) and near segments (``near``) then closed up in range
    order: the rows and their order are those of one call over all rows.

    Returns
    -------
    (k, nn) : the selected photons and the near segments, rows ``0 ..`` of each.
    """
    if threads <= 1 or m < threads * STEP_MIN:
        return step(0, m, *args)
    cut = guided_cut(m, threads * PIECES_PER_THREAD)
    n_pieces = len(cut) - 1
    ends = [(0, 0)] * n_pieces

    def piece(j):
        ends[j] = step(cut[j], cut[j + 1], *args)

    on_threads(piece, n_pieces, threads)
    k, nn = ends[0]
    for j in range(1, n_pieces):
        a, (kj, nj) = cut[j], ends[j]
        if kj > a:  # numpy copies overlapping slices as if through a buffer
            for arr in state:
                arr[k : k + kj - a] = arr[a:kj]
        if nj > a:
            for arr in near:
                arr[nn : nn + nj - a] = arr[a:nj]
        k, nn = k + kj - a, nn + nj - a
    return k, nn


#: State rows per thread below which :func:`step` runs on one thread.
STEP_MIN = 4096
#: Photons per thread below which ``assemble`` runs on one thread.
ASSEMBLE_MIN = 2048


def _box(med) -> np.ndarray:
    """(2, 3) float: ``bmin, bmax``."""
    return np.stack([np.asarray(med.bounds_min, dtype=float),
                     np.asarray(med.bounds_max, dtype=float)])


#: Output memory reused between batches (``kernels.buffers``: two per kind and thread, a
#: buffer reused once nothing references the arrays cut from it).
OUTPUTS = HitBuffers()


def _outputs(recycled: bool, kind: str, specs) -> dict:
    """Uninitialised C-contiguous arrays ``name -> (shape, dtype)`` (the first axis the
    photons), cut from one of :data:`OUTPUTS`' buffers or, for calls too large to keep,
    new."""
    if not recycled:
        return {name: np.empty(shape, dtype=dt) for name, shape, dt in specs}
    n = specs[0][1][0]
    fields = [(dt, math.prod(shape[1:])) for _, shape, dt in specs]
    arrays = OUTPUTS.take(f"trace.{kind}", fields, n)
    return {name: a.reshape(shape) for (name, shape, _), a in zip(specs, arrays, strict=True)}
