"""Memory of the compiled Trace: a per-thread scratch workspace, and constants computed once
per scene.

A 32768-photon batch of ``scenes/area.toml`` returns ~55 MB (``PhotonPaths``' arrays are
padded to the deepest photon) and needs ~20 MB of scratch. Fresh memory costs a page fault
per page on first touch; on this project's 2-core VM that was 5-10 ms of a ~25 ms batch when
idle and up to 200 ms under memory pressure. So the scratch (:class:`Workspace`: the state,
variates, step records and ``prefix_ok`` of a trace) is kept by the thread between calls, and
the returned arrays are cut from ``kernels.buffers.HitBuffers`` (``trace_compiled.OUTPUTS``),
reused once the caller has dropped every view of them. A thread thus keeps the workspace
(~25 MB) and two output buffers per kind (~150 MB on ``scenes/area.toml``) until it ends.
"""

from __future__ import annotations

import threading
import weakref

import numpy as np

#: Photons up to which a thread keeps its workspace between calls (render's batches are
#: ``render.PHOTON_BATCH`` = 32768); larger calls use a workspace of their own.
KEEP_PHOTONS = 1 << 16
#: Columns of a step record (one row per sampled segment): ``t``, ``w`` (3), clip (2).
REC_T, REC_W, REC_CLIP, REC_COLS = 0, 1, 4, 6

_local = threading.local()


class Workspace:
    """Scratch arrays of one trace of up to ``n`` photons and ``depth`` segments.

    Attributes
    ----------
    idx : (n,) int64
    x, w : (n, 3) float
        State: photon, current vertex, direction (compacted rows).
    x0, w1, beta0 : (n, 3) float
        Light points, first directions, emitted weights (W).
    r : (3 n,) float
        One depth's variates: phase cosine, azimuth (then its cosine), flight (then its
        length).
    sin : (n,) float
        Sine of the azimuth.
    u : (n,) float
        The next depth's roulette variates.
    oks : (depth + 1, n) bool
        ``prefix_ok`` per vertex.
    near_photon, near_a, near_b, near_inside, verdict : (n,), (n, 3), (n, 3), (n,), (n,)
        Segments near a blocker and their verdicts (``trace_shadow.shade``).
    rec_idx : (R,) int64
    rec : (R, REC_COLS) float
        Step records (photon; ``t``, ``w``, clip), grown by :meth:`records`.
    """

    def __init__(self, n: int, depth: int):
        self.n, self.depth = n, depth
        self.idx = np.empty(n, dtype=np.int64)
        self.x, self.w = np.empty((n, 3)), np.empty((n, 3))
        self.x0, self.w1, self.beta0 = np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3))
        self.r, self.sin, self.u = np.empty(3 * n), np.empty(n), np.empty(n)
        self.oks = np.empty((depth + 1, n), dtype=bool)
        self.near_photon = np.empty(n, dtype=np.int64)
        self.near_a, self.near_b = np.empty((n, 3)), np.empty((n, 3))
        self.near_inside = np.empty(n, dtype=bool)
        self.verdict = np.empty(n, dtype=np.int64)
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


_constants: dict[tuple, tuple] = {}


def constants(make, *objs):
    """``make(*objs)``, computed once per set of live objects (by identity; kept while they
    live, a few at a time): a scene's and its blockers' constants for the kernels. The objects
    are frozen dataclasses: a change makes a new one."""
    key = (make, *map(id, objs))
    hit = _constants.get(key)
    if hit is not None and all(r() is o for r, o in zip(hit[0], objs, strict=True)):
        return hit[1]
    value = make(*objs)
    if len(_constants) >= 16:
        _constants.clear()
    _constants[key] = (tuple(weakref.ref(o) for o in objs), value)
    return value
