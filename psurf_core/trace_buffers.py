"""Memory of the compiled Trace: a per-thread scratch workspace, and recycled output blocks.

A 32768-photon batch of ``scenes/area.toml`` returns ~55 MB (``PhotonPaths``' arrays are
padded to the deepest photon) and needs ~20 MB of scratch. Fresh memory costs a page fault
per page on first touch; on this project's 2-core VM that was 5-10 ms of a ~25 ms batch when
idle and up to 200 ms under memory pressure (``tests/test_trace_reference.py`` holds the
results equal either way). So:

* :class:`Workspace`: the state, variates, step records and ``prefix_ok`` of a trace, kept by
  the thread between calls (nothing in it is returned);
* :class:`Recycler`: the returned arrays are views of blocks the thread keeps. A numpy view
  holds a reference to the array that owns its memory, so a block that nothing but the
  recycler references cannot be read or written by anyone: only such a block is reused.
  A caller keeping a ``PhotonPaths`` (or any view of one of its arrays) keeps its block.
  The test is CPython's reference count (``sys.getrefcount``);
  ``tests/test_trace_reference.py::test_recycled_outputs`` checks it still holds. A thread
  keeps at most ``Recycler.keep`` blocks: for render's batches about two ``PhotonPaths``,
  ~150 MB on ``scenes/area.toml``, held after the render until the thread ends.
"""

from __future__ import annotations

import math
import sys
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
        One depth's variates: phase cosine, azimuth (then its cosine), flight.
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


#: Alignment (bytes) of every array carved from a block.
_ALIGN = 64


class Recycler:
    """Output blocks of one thread, reused once nothing outside references them.

    Parameters
    ----------
    keep : int
        Blocks kept; beyond them the smallest unused one is dropped (a used one is only
        forgotten: its arrays live on with their caller).
    """

    def __init__(self, keep: int = 4):
        self.keep = keep
        self.blocks: list[np.ndarray] = []

    def _free(self, i: int) -> bool:
        # References to an unused block: the list's and getrefcount's argument.
        return sys.getrefcount(self.blocks[i]) <= 2

    def block(self, nbytes: int) -> np.ndarray:
        """An unused block of at least ``nbytes`` bytes: the smallest one kept, else a new
        one (with a quarter to spare, as the next batch may trace deeper)."""
        fits = [i for i in range(len(self.blocks))
                if self.blocks[i].nbytes >= nbytes and self._free(i)]
        if fits:
            return self.blocks[min(fits, key=lambda i: self.blocks[i].nbytes)]
        new = np.empty(nbytes + nbytes // 4 + _ALIGN, dtype=np.uint8)
        if len(self.blocks) >= self.keep:
            unused = [i for i in range(len(self.blocks)) if self._free(i)]
            drop = min(unused, key=lambda i: self.blocks[i].nbytes) if unused else 0
            del self.blocks[drop]
        self.blocks.append(new)
        return new

    def arrays(self, specs) -> list[np.ndarray]:
        """Uninitialised C-contiguous arrays of the given ``(shape, dtype)``, views of one
        unused block."""
        spans, total = [], 0
        for shape, dt in specs:
            size = math.prod(shape) * np.dtype(dt).itemsize
            spans.append((total, size))
            total += -(-size // _ALIGN) * _ALIGN
        blk = self.block(total)
        base = -blk.ctypes.data % _ALIGN
        return [blk[base + o : base + o + size].view(dt).reshape(shape)
                for (shape, dt), (o, size) in zip(specs, spans, strict=True)]


def recycler() -> Recycler:
    """This thread's :class:`Recycler`."""
    rc = getattr(_local, "recycler", None)
    if rc is None:
        rc = _local.recycler = Recycler()
    return rc


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
