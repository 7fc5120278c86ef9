"""Trace, compiled: the stages of :mod:`psurf_core.trace` (``emit``, ``step``, ``assemble``,
``trace``) as per-photon numba loops, and the compiled twin of each of its formulas.

Every formula of ``trace.py`` has a scalar twin here under the same name
(:func:`psurf_core.kernels.jit.twin`): compiled code calling ``ref.direction_about`` runs the
twin, Python calling it runs the numpy function. A twin performs the numpy function's IEEE
operations in the same order (no ``fastmath``, so no fused multiply-add; ``sqrt``,
``+ - * /`` and comparisons are exactly rounded in both); a (3,) vector is a 3-tuple.
The random numbers and ``cos``, ``sin``, ``log1p`` stay numpy's (numba's would be other
implementations): they are computed here in place into scratch buffers, between the kernels.

Where the numpy reference and this path differ in work, not in values:

* **one kernel per depth**: :func:`step` samples segment ``j``, records it, and already
  selects the photons of segment ``j + 1`` (roulette, look-back): the selection reads
  ``prefix_ok`` of vertex ``j + 1 - LOOKBACK <= j - 1``, final before segment ``j``, and its
  roulette variates follow segment ``j``'s draws in the stream, so they are drawn first;
* **records, then one scatter**: each depth writes compact step records (``REC_*`` columns);
  :func:`assemble` writes the photon-major ``PhotonPaths`` arrays once, recomputing every
  vertex (``advance``) and weight (``scattered_weight``) with the twins;
* **scratch reuse**: state, variates, records and ``prefix_ok`` live in a per-thread
  workspace kept between calls (no page faults on fresh memory per batch);
* **shadow tests**: :mod:`psurf_core.trace_shadow` decides, per segment, what
  ``Blockers.occluded`` would answer, where rounding cannot change the answer; only when
  some segment of a depth is undecided is ``Blockers.occluded`` called, on exactly the rows
  the reference's call would keep for its own exact test.

Compiled with :func:`psurf_core.kernels.jit.kernel` (cached on disk, keyed by the sources
they inline: editing ``trace.py`` or ``trace_shadow.py`` recompiles).
"""

from __future__ import annotations

import threading

import numpy as np

from . import trace as ref
from . import trace_shadow as shadow
from .kernels.jit import kernel, twin
from .scene import AreaLight, MeshLight, PointLight

#: Columns of a step record (one row per sampled segment): ``t``, ``w`` (3), clip (2).
REC_T, REC_W, REC_CLIP, REC_COLS = 0, 1, 4, 6


# --------------------------------------------------------------------------- twins
@twin(ref.direction_about)
def direction_about(axis, cos_theta, cos_phi, sin_phi):  # pragma: no cover - compiled
    a0, a1, a2 = axis
    sign = 1.0 if a2 >= 0.0 else -1.0  # sampling.orthonormal_basis (Duff et al.)
    a = -1.0 / (sign + a2)
    b = a0 * a1 * a
    b10, b11, b12 = 1.0 + sign * (a0 * a0) * a, sign * b, -sign * a0
    b20, b21, b22 = b, sign + (a1 * a1) * a, -a1
    s2 = 1.0 - cos_theta * cos_theta
    sin_theta = np.sqrt(s2 if s2 > 0.0 else 0.0)
    p = sin_theta * cos_phi
    q = sin_theta * sin_phi
    return (p * b10 + q * b20 + cos_theta * a0,
            p * b11 + q * b21 + cos_theta * a1,
            p * b12 + q * b22 + cos_theta * a2)


@twin(ref.uniform_direction)
def uniform_direction(u_z, cos_phi, sin_phi):  # pragma: no cover - compiled
    z = 1.0 - 2.0 * u_z
    s2 = 1.0 - z * z
    r = np.sqrt(s2 if s2 > 0.0 else 0.0)
    return r * cos_phi, r * sin_phi, z


@twin(ref.cosine_direction)
def cosine_direction(normal, u_c, cos_phi, sin_phi):  # pragma: no cover - compiled
    return ref.direction_about(normal, np.sqrt(u_c), cos_phi, sin_phi)


@twin(ref.parallelogram_point)
def parallelogram_point(corner, edge_u, edge_v, u):  # pragma: no cover - compiled
    return (corner[0] + u[0] * edge_u[0] + u[1] * edge_v[0],
            corner[1] + u[0] * edge_u[1] + u[1] * edge_v[1],
            corner[2] + u[0] * edge_u[2] + u[1] * edge_v[2])


@twin(ref.triangle_point)
def triangle_point(tri, u_s, u_r):  # pragma: no cover - compiled
    v0, v1, v2 = tri  # 3-tuples
    su = np.sqrt(u_s)
    b0, b1 = 1.0 - su, u_r * su
    x = (v0[0] + b0 * (v1[0] - v0[0]) + b1 * (v2[0] - v0[0]),
         v0[1] + b0 * (v1[1] - v0[1]) + b1 * (v2[1] - v0[1]),
         v0[2] + b0 * (v1[2] - v0[2]) + b1 * (v2[2] - v0[2]))
    return (b0, b1), x


@twin(ref.search_right)
def search_right(cdf, u):  # pragma: no cover - compiled
    # Bisection in numpy's order (NaN after every number); numpy's own search took ~170 ns
    # per random key here.
    lo, hi = 0, cdf.shape[0]
    while lo < hi:
        mid = (lo + hi) >> 1
        c = cdf[mid]
        if u < c or (c != c and u == u):
            hi = mid
        else:
            lo = mid + 1
    return lo


@twin(ref.phase_cosine)
def phase_cosine(g, u):  # pragma: no cover - compiled
    if abs(g) < ref.sampling.HG_ISOTROPIC_G:
        return 1.0 - 2.0 * u
    sq = (1.0 - g * g) / (1.0 - g + 2.0 * g * u)
    mu = (1.0 + g * g - sq * sq) / (2.0 * g)
    mu = mu if mu > -1.0 else -1.0  # np.clip(., -1, 1)
    return mu if mu < 1.0 else 1.0


@twin(ref.free_flight)
def free_flight(log1p_neg_u, sigma_t):  # pragma: no cover - compiled
    return -log1p_neg_u / sigma_t


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


@twin(ref.inside)
def inside(x, lo, hi):  # pragma: no cover - compiled
    return (lo[0] <= x[0] <= hi[0]) and (lo[1] <= x[1] <= hi[1]) and (lo[2] <= x[2] <= hi[2])


@twin(ref.survives)
def survives(ok_look, u, q):  # pragma: no cover - compiled
    return ok_look and (u < q if q < 1.0 else True)


@twin(ref.scattered_weight)
def scattered_weight(beta, q, albedo):  # pragma: no cover - compiled
    b0, b1, b2 = beta
    if q < 1.0:
        b0, b1, b2 = b0 / q, b1 / q, b2 / q
    return b0 * albedo, b1 * albedo, b2 * albedo


# --------------------------------------------------------------------------- emission
@kernel
def emit_point(u_z, cos_phi, sin_phi, w_out):  # pragma: no cover - compiled
    """``uniform_direction`` per photon. (M,) variates; ``w_out`` (M, 3), written."""
    for i in range(u_z.shape[0]):
        w_out[i, 0], w_out[i, 1], w_out[i, 2] = ref.uniform_direction(u_z[i], cos_phi[i],
                                                                      sin_phi[i])


@kernel
def emit_area(u, u_c, cos_phi, sin_phi, corner, edge_u, edge_v, normal, x_out,
              w_out):  # pragma: no cover - compiled
    """``parallelogram_point`` and ``cosine_direction`` per photon.

    Parameters
    ----------
    u : (M, 2) float
        Parallelogram coordinates.
    u_c, cos_phi, sin_phi : (M,) float
    corner, edge_u, edge_v, normal : (3,) float
    x_out, w_out : (M, 3) float
        Written.
    """
    nl = (normal[0], normal[1], normal[2])
    c, eu, ev = (corner[0], corner[1], corner[2]), (edge_u[0], edge_u[1], edge_u[2]), \
        (edge_v[0], edge_v[1], edge_v[2])
    for i in range(u.shape[0]):
        x_out[i, 0], x_out[i, 1], x_out[i, 2] = ref.parallelogram_point(c, eu, ev,
                                                                        (u[i, 0], u[i, 1]))
        w_out[i, 0], w_out[i, 1], w_out[i, 2] = ref.cosine_direction(nl, u_c[i], cos_phi[i],
                                                                     sin_phi[i])


@kernel
def emit_mesh(k, u_s, u_r, u_c, cos_phi, sin_phi, triangles, normals, bary_out, x_out, n_out,
              w_out):  # pragma: no cover - compiled
    """``triangle_point`` and ``cosine_direction`` about the triangle's normal per photon.

    Parameters
    ----------
    k : (M,) int
        Triangle of each photon.
    u_s, u_r, u_c, cos_phi, sin_phi : (M,) float
    triangles : (F, 3, 3) float
    normals : (F, 3) float
    bary_out : (M, 2) float
    x_out, n_out, w_out : (M, 3) float
        Written.
    """
    for i in range(k.shape[0]):
        f = k[i]
        tri = ((triangles[f, 0, 0], triangles[f, 0, 1], triangles[f, 0, 2]),
               (triangles[f, 1, 0], triangles[f, 1, 1], triangles[f, 1, 2]),
               (triangles[f, 2, 0], triangles[f, 2, 1], triangles[f, 2, 2]))
        (bary_out[i, 0], bary_out[i, 1]), (x_out[i, 0], x_out[i, 1], x_out[i, 2]) = \
            ref.triangle_point(tri, u_s[i], u_r[i])
        nk = (normals[f, 0], normals[f, 1], normals[f, 2])
        n_out[i, 0], n_out[i, 1], n_out[i, 2] = nk
        w_out[i, 0], w_out[i, 1], w_out[i, 2] = ref.cosine_direction(nk, u_c[i], cos_phi[i],
                                                                     sin_phi[i])


@kernel
def search(cdf, u, out):  # pragma: no cover - compiled
    """``out[i] = min(search_right(cdf, u[i]), K - 1)``: ``trace._discrete``'s index."""
    last = cdf.shape[0] - 1
    for i in range(u.shape[0]):
        out[i] = min(ref.search_right(cdf, u[i]), last)


def _discrete(pmf, rng, n):
    """``trace._discrete`` with the compiled search. (n,) intp."""
    u = rng.random(n)
    if len(pmf) == 1:
        return np.zeros(n, dtype=np.intp)
    cdf = np.cumsum(pmf)
    cdf /= cdf[-1]
    k = np.empty(n, dtype=np.intp)
    search(cdf, u, k)
    return k


def _azimuth(r):
    """``cos`` and ``sin`` of ``2 pi r`` (numpy's), in place of ``r`` and a new array."""
    np.multiply(r, 2.0 * np.pi, out=r)
    s = np.sin(r)
    return np.cos(r, out=r), s


def emit(scene, rng, n: int) -> dict:
    """``trace.emit`` (same draws, same values, same dict) with compiled per-photon loops.
    The outputs are written in place where one light emits every photon."""
    pmf = scene.light_pmf
    light = _discrete(pmf, rng, n)
    x0, w1, normal, beta = (np.empty((n, 3)) for _ in range(4))
    uv = np.zeros((n, 2))
    tri = np.full(n, -1, dtype=np.int64)
    for li, lt in enumerate(scene.lights):
        sel = np.flatnonzero(light == li)
        m = sel.size
        if m == 0:
            continue
        whole = m == n
        rows = slice(None) if whole else sel
        xo, wo = (x0, w1) if whole else (np.empty((m, 3)), np.empty((m, 3)))
        beta[rows] = lt.power_rgb / pmf[li]
        if isinstance(lt, PointLight):
            r = rng.random(2 * m)
            emit_point(r[:m], *_azimuth(r[m:]), wo)
            xo[:] = lt.position
            normal[rows] = lt.axis
        elif isinstance(lt, AreaLight):
            r = rng.random(4 * m)
            u = r[: 2 * m].reshape(m, 2)
            emit_area(u, r[2 * m : 3 * m], *_azimuth(r[3 * m :]), lt.corner, lt.edge_u,
                      lt.edge_v, lt.normal, xo, wo)
            uv[rows] = u
            normal[rows] = lt.normal
        elif isinstance(lt, MeshLight):
            k = _discrete(lt.areas / lt.area, rng, m)
            r = rng.random(4 * m)
            bo, no = (uv, normal) if whole else (np.empty((m, 2)), np.empty((m, 3)))
            emit_mesh(k, r[:m], r[m : 2 * m], r[2 * m : 3 * m], *_azimuth(r[3 * m :]),
                      np.ascontiguousarray(lt.triangles, dtype=float),
                      np.ascontiguousarray(lt.normals, dtype=float), bo, xo, no, wo)
            tri[sel] = k
            if not whole:
                uv[sel], normal[sel] = bo, no
        else:  # pragma: no cover - the scene loader admits no other light
            raise TypeError(f"unknown light {lt!r}")
        if not whole:
            x0[sel], w1[sel] = xo, wo
    return dict(light=light, light_pmf=pmf[light], light_uv=uv, tri=tri, light_normal=normal,
                x0=x0, w1=w1, beta=beta)


# --------------------------------------------------------------------------- depth steps
@kernel
def step(m, scatter, g, sigma_t, idx, x, w, u_mu, cos_phi, sin_phi, log1p_neg_u, box,
         ok_prev, ok_cur, select, ok_look, u_next, q_next, rec_idx, rec, off, near_photon,
         near_a, near_b, near_inside, blockers, test_all):  # pragma: no cover - compiled
    """Segment ``j`` of the ``m`` active photons (``trace.step``), then the selection of
    segment ``j + 1``'s photons (``trace.survives``), compacting the state in place.

    Parameters
    ----------
    m : int
        Active photons: state rows ``0 .. m - 1``, in photon order.
    scatter : bool
        Sample a new direction (every segment but the first): ``phase_cosine``,
        ``direction_about``.
    g, sigma_t : float
        Phase asymmetry; extinction (1 / scene unit).
    idx : (P,) int64
    x, w : (P, 3) float
        State: photon, start vertex and direction of each active photon; on return, rows
        ``0 .. k - 1`` hold the selected photons' end vertex and direction.
    u_mu, cos_phi, sin_phi, log1p_neg_u : (m,) float
        Variates of the phase cosine, ``cos``/``sin`` of the azimuth, ``log1p(-u)`` of the
        flight.
    box : (4, 3) float
        ``bmin, bmax, lo, hi`` (``trace.inside``'s slackened bounds).
    ok_prev, ok_cur : (N,) bool
        ``prefix_ok`` of the start and end vertex; ``ok_cur`` false on entry, written here
        (for an ``UNSURE`` segment, rewritten by ``trace_shadow.resolve``).
    select : bool
        Select segment ``j + 1``'s photons (else keep every row).
    ok_look : (N,) bool
        ``prefix_ok`` of vertex ``j + 1 - LOOKBACK``.
    u_next : (m,) float
        Roulette variates of segment ``j + 1`` (unused when ``q_next >= 1``).
    q_next : float
    rec_idx : (R,) int64
    rec : (R, REC_COLS) float
        Step records, written at rows ``off .. off + m - 1``.
    off : int
    near_photon : (P,) int64
    near_a, near_b : (P, 3) float
    near_inside : (P,) bool
        The near segments (``trace_shadow.classify``): photon, start, end, end in the box.
    blockers : (B, trace_shadow.COLS) float
    test_all : bool
        The blocker rows and flag of ``trace_shadow.table``.

    Returns
    -------
    k : int
        Photons selected for segment ``j + 1``.
    nn : int
        Near segments listed.
    unsure : bool
        Whether ``Blockers.occluded`` must run on them (some verdict is ``UNSURE``).
    """
    bmin, bmax = (box[0, 0], box[0, 1], box[0, 2]), (box[1, 0], box[1, 1], box[1, 2])
    lo, hi = (box[2, 0], box[2, 1], box[2, 2]), (box[3, 0], box[3, 1], box[3, 2])
    k, nn, unsure = 0, 0, False
    for i in range(m):
        p = idx[i]
        a = (x[i, 0], x[i, 1], x[i, 2])
        d = (w[i, 0], w[i, 1], w[i, 2])
        if scatter:
            d = ref.direction_about(d, ref.phase_cosine(g, u_mu[i]), cos_phi[i], sin_phi[i])
        t = ref.free_flight(log1p_neg_u[i], sigma_t)
        b = ref.advance(a, d, t)
        r = off + i
        rec_idx[r] = p
        rec[r, REC_T] = t
        rec[r, REC_W], rec[r, REC_W + 1], rec[r, REC_W + 2] = d
        rec[r, REC_CLIP], rec[r, REC_CLIP + 1] = ref.segment_clip(a, d, t, bmin, bmax)
        if ok_prev[p]:
            inb = ref.inside(b, lo, hi)
            near, verdict = shadow.classify(a, b, blockers, test_all)
            if near:  # listed for Blockers.occluded, in case the depth is unsure
                near_photon[nn] = p
                near_a[nn, 0], near_a[nn, 1], near_a[nn, 2] = a
                near_b[nn, 0], near_b[nn, 1], near_b[nn, 2] = b
                near_inside[nn] = inb
                nn += 1
                unsure = unsure or verdict == shadow.UNSURE
            ok_cur[p] = inb and verdict == shadow.CLEAR
        if not select or ref.survives(ok_look[p], u_next[i], q_next):
            idx[k] = p
            x[k, 0], x[k, 1], x[k, 2] = b
            w[k, 0], w[k, 1], w[k, 2] = d
            k += 1
    return k, nn, unsure


@kernel
def assemble(x0, beta0, q, albedo, oks, rec_idx, rec, rec_off, xs, ws, ts, betas, alives,
             clips, prefix_ok):  # pragma: no cover - compiled
    """``trace.assemble``: scatter the step records into the photon-major ``PhotonPaths``
    arrays, recomputing each vertex (``advance``) and weight (``scattered_weight``) as the
    reference computed them. Each step's records are in photon order and a photon's
    segments are consecutive from segment 1, so one cursor per step walks them.

    Parameters
    ----------
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
        Outputs, shapes as in ``PhotonPaths`` (written entirely).
    """
    n, d = xs.shape[0], ts.shape[1]
    cur = rec_off[:d].copy()
    for p in range(n):
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
        for s in range(d + 1):
            prefix_ok[p, s] = oks[s, p]


# --------------------------------------------------------------------------- the driver
#: Photons up to which a thread keeps its workspace between calls (render's batches are
#: ``render.PHOTON_BATCH`` = 32768); larger calls use a workspace of their own.
KEEP_PHOTONS = 1 << 16

_local = threading.local()


class Workspace:
    """Scratch arrays of one trace: the state and variates of up to ``n`` photons,
    ``prefix_ok`` of ``depth + 1`` vertices, the step records (grown on demand) and the
    segments left to ``Blockers.occluded``. Nothing in it is returned to the caller."""

    def __init__(self, n: int, depth: int):
        self.n, self.depth = n, depth
        self.idx = np.empty(n, dtype=np.int64)
        self.x, self.w = np.empty((n, 3)), np.empty((n, 3))
        self.r = np.empty(3 * n)  # phase cosine, azimuth, flight variates
        self.sin, self.u = np.empty(n), np.empty(n)
        self.oks = np.empty((depth + 1, n), dtype=bool)
        self.near_photon = np.empty(n, dtype=np.int64)
        self.near_a, self.near_b = np.empty((n, 3)), np.empty((n, 3))
        self.near_inside = np.empty(n, dtype=bool)
        self.rec_idx = np.empty(max(8 * n, 1), dtype=np.int64)
        self.rec = np.empty((max(8 * n, 1), REC_COLS))

    def records(self, rows: int) -> None:
        """Grow the record buffers to at least ``rows`` rows (kept contents)."""
        if rows > self.rec_idx.shape[0]:
            grow = max(2 * self.rec_idx.shape[0], rows)
            self.rec_idx = np.concatenate([self.rec_idx, np.empty(grow - self.rec_idx.size,
                                                                  dtype=np.int64)])
            self.rec = np.concatenate([self.rec, np.empty((grow - self.rec.shape[0], REC_COLS))])


def workspace(n: int, depth: int) -> Workspace:
    """This thread's workspace when it is large enough (replaced by a larger one up to
    ``KEEP_PHOTONS`` photons), else a new one for this call."""
    ws = getattr(_local, "ws", None)
    if ws is not None and ws.n >= n and ws.depth >= depth:
        return ws
    ws = Workspace(max(n, ws.n if ws else 0), max(depth, ws.depth if ws else 0))
    if ws.n <= KEEP_PHOTONS:
        _local.ws = ws
    return ws


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
    bmin = np.asarray(med.bounds_min, dtype=float)
    bmax = np.asarray(med.bounds_max, dtype=float)
    box = np.stack([bmin, bmax, bmin - ref.BOX_SLACK, bmax + ref.BOX_SLACK])
    rows, test_all = shadow.table(blockers)
    ws = workspace(n, depth)
    e = emit(scene, rng, n)
    idx, x, w, oks, r = ws.idx, ws.x, ws.w, ws.oks, ws.r
    idx[:n] = np.arange(n)
    x[:n], w[:n] = e["x0"], e["w1"]
    oks[0, :n] = True
    m, qs, rec_off, empty = n, [1.0], [0], r[:0]
    for j in range(1, depth + 1):
        # Segment j's variates: phase cosine, azimuth (cos, sin) and flight (log1p(-u)).
        nr = (3 if j > 1 else 1) * m
        rj = rng.random(out=r[:nr])
        lg = rj[nr - m :]
        np.log1p(np.negative(lg, out=lg), out=lg)
        if j > 1:
            cphi, sphi = _azimuth(rj[m : 2 * m])
        else:
            cphi = sphi = empty
        # Then segment j + 1's roulette variates (the reference draws them next).
        q_next = ref.roulette_survival(scene, j) if j < depth else 1.0
        select = j < depth and m > 0
        u_next = rng.random(out=ws.u[:m]) if select and q_next < 1.0 else empty
        off = rec_off[-1]
        ws.records(off + m)
        ok = oks[j]
        ok[:n] = False
        k, nn, unsure = step(m, j > 1, med.phase.g, med.sigma_t, idx, x, w, rj[:m], cphi,
                             sphi, lg, box, oks[j - 1], ok, select,
                             oks[max(j + 1 - ref.LOOKBACK, 0)], u_next, q_next, ws.rec_idx,
                             ws.rec, off, ws.near_photon, ws.near_a, ws.near_b,
                             ws.near_inside, rows, test_all)
        if unsure:
            shadow.resolve(ws.near_photon[:nn], ws.near_a[:nn], ws.near_b[:nn],
                           ws.near_inside[:nn], blockers, ok)
        rec_off.append(off + m)
        if m == 0:
            break
        qs.append(q_next)
        m = k
    d = len(rec_off) - 1
    xs = np.empty((n, d + 1, 3))
    wo, betas = np.empty((n, d, 3)), np.empty((n, d, 3))
    ts, alives, clips = np.empty((n, d)), np.empty((n, d), dtype=bool), np.empty((n, d, 2))
    prefix_ok = np.empty((n, d + 1), dtype=bool)
    assemble(e["x0"], e["beta"], np.array(qs[:d]), med.albedo, oks, ws.rec_idx, ws.rec,
             np.array(rec_off, dtype=np.int64), xs, wo, ts, betas, alives, clips, prefix_ok)
    return ref.PhotonPaths(n_emitted=n, light=e["light"], light_pmf=e["light_pmf"],
                           light_uv=e["light_uv"], tri=e["tri"],
                           light_normal=e["light_normal"], x=xs, w=wo, t=ts, beta=betas,
                           alive=alives, prefix_ok=prefix_ok, clip=clips)
