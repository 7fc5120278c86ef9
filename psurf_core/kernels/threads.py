"""Threads for the walkers: how many to use and the helper threads that run the pieces.

:func:`thread_count` is numba's thread count (``numba.set_num_threads``,
``NUMBA_NUM_THREADS``; 1 in pass-pool workers, which already fill the cores), at most the cores
other processes leave idle (:class:`_OtherLoad`). :func:`on_threads` hands numbered pieces of
work to this thread and to shared helper threads (the compiled kernels release the GIL). The
callers (:mod:`.fused`, :mod:`.spans`) cut their work so that the result does not
depend on which thread ran which piece: the thread count changes the time, never the image."""

from __future__ import annotations

import functools
import os
import threading
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from numba import get_num_threads

from ..interrupt import check

#: Pieces per thread a shared job is cut into (hull spans, the tracer's steps: by
#: :func:`guided_cut`), handed out in order to whichever thread is free: a thread that loses
#: its core to another process does not hold the others back by more than one piece. (A
#: walker's chunk is cut into a fixed ``fused.CHUNK_PIECES``: its image's bits depend on the
#: cut.)
PIECES_PER_THREAD = 4

#: Each piece of a shared job is this fraction of the one before it (:func:`guided_cut`):
#: large pieces first, small ones last, so that the thread that takes the last piece keeps
#: the other waiting for little. Equal pieces leave a slow thread's last one to wait for: on
#: the 2-vCPU machine of docs/study.md one vCPU often ran the walker 1.3x slower than the
#: other (which one changed from minute to minute), and a ``planes`` walk in 8 equal pieces
#: had its main thread idle for 3 of its 13 ms ("Large pieces first").
GUIDED_RATIO = 0.8


@functools.cache
def guided_fractions(k: int) -> np.ndarray:
    """(k + 1,) float, read-only: ``0 = f_0 < f_1 < ... < f_k = 1``, piece ``j`` of a job
    cut at these fractions taking ``GUIDED_RATIO ** j`` of the whole over their sum (kept:
    every pass cuts its spans with the same ``k``)."""
    w = GUIDED_RATIO ** np.arange(k, dtype=float)
    f = np.concatenate([[0.0], np.cumsum(w) / w.sum()])
    f[-1] = 1.0
    f.flags.writeable = False
    return f


def guided_cut(n: int, k: int) -> list[int]:
    """Bounds ``0 = c_0 < ... < c_m = n`` of ``0 .. n - 1`` cut into ``m <= k`` consecutive
    ranges at :func:`guided_fractions` (``m < k`` where ``n`` is small: an empty range is
    dropped)."""
    cut = np.floor(n * guided_fractions(k)).astype(np.int64)
    cut[-1] = n
    return np.unique(cut).tolist() if n > 0 else [0, 0]


class _OtherLoad:
    """Cores that other processes kept busy lately (Linux ``/proc/stat``, minus this process's
    own CPU time), so that threads are used only where a core is free.

    On a machine whose cores are taken by other work a second thread cannot gain: it waits in
    the run queue while holding a piece the first thread then waits for (measured on a
    2-core machine with three other busy processes: 2 threads 20% slower than 1). The
    estimate is refreshed at most every ``_LOAD_REFRESH`` seconds; where ``/proc/stat`` is
    missing it is 0 (all of numba's threads are used). It only chooses the thread count,
    which changes no result.
    """

    def __init__(self):
        self.last = None  # (monotonic s, all CPUs' busy s, this process's CPU s)
        self.others = 0.0
        self.lock = threading.Lock()

    def __call__(self) -> float:
        now = time.monotonic()
        with self.lock:
            if self.last is not None and now - self.last[0] < _LOAD_REFRESH:
                return self.others
            try:
                with open("/proc/stat") as f:
                    ticks = [int(x) for x in f.readline().split()[1:]]
            except (OSError, ValueError):
                return 0.0
            # user nice system idle iowait irq softirq steal: all but idle and iowait are
            # taken (steal: by other virtual machines).
            busy = (sum(ticks[:8]) - ticks[3] - ticks[4]) / os.sysconf("SC_CLK_TCK")
            t = os.times()
            own = t.user + t.system
            if self.last is not None:
                dt = now - self.last[0]
                self.others = max(0.0, (busy - self.last[1] - (own - self.last[2])) / dt)
            self.last = (now, busy, own)
            return self.others


#: Seconds between two readings of :class:`_OtherLoad`.
_LOAD_REFRESH = 0.5

_OTHER_LOAD = _OtherLoad()


#: The machine's CPUs (``os.cpu_count`` reads ``/sys`` at every call: ~6 us, twice a pass).
_CPUS = os.cpu_count() or 1


def thread_count() -> int:
    """Threads for a large chunk: numba's thread count (``numba.set_num_threads``,
    ``NUMBA_NUM_THREADS``), at most the cores other processes leave free (at least 1)."""
    n = get_num_threads()
    if n > 1:
        free = _CPUS - _OTHER_LOAD()
        n = max(1, min(n, int(free + 0.5)))
    return n


#: Name prefix of :func:`on_threads`' helper threads.
_POOL_NAME = "psurf-pieces"
#: Helper threads of :func:`on_threads` (started on first use, shared by all callers).
_HELPERS: dict[int, ThreadPoolExecutor] = {}
# A forked child has none of the parent's threads: its pools would never run a task.
if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_HELPERS.clear)


def on_threads(fn, n: int, threads: int) -> None:
    """``fn(j)`` for ``j = 0 .. n - 1`` on ``threads`` threads (this one and ``threads - 1``
    helpers), each taking the next ``j`` when free. An exception (Ctrl-C included) stops the
    handing out; the helpers finish the item they hold, then it is re-raised. On the main
    thread a Ctrl-C held by :func:`psurf_core.interrupt.held` is raised before each item."""
    # On a helper thread (a piece that hands out pieces itself) the pool's only free thread
    # may be this one: waiting for a queued piece would wait for ever. Run them here.
    me = threading.current_thread()
    on_main = me is threading.main_thread()
    if threads <= 1 or me.name.startswith(_POOL_NAME):
        for j in range(n):
            if on_main:
                check()
            fn(j)
        return
    pool = _HELPERS.get(threads - 1)
    if pool is None:
        pool = _HELPERS[threads - 1] = ThreadPoolExecutor(threads - 1, _POOL_NAME)
    items = iter(range(n))
    lock = threading.Lock()
    stop = []

    def work(main=False):
        while not stop:
            if main:
                check()
            with lock:
                j = next(items, None)
            if j is None:
                return
            fn(j)

    helpers = [pool.submit(work) for _ in range(threads - 1)]
    try:
        work(on_main)
    except BaseException:
        stop.append(True)
        raise
    finally:
        for f in helpers:
            f.result()


def in_pieces(fn, n: int, threads: int, min_size: int = 1) -> None:
    """``fn(a, b)`` over ``0 .. n - 1`` cut into consecutive ranges ``[a, b)``, run on
    ``threads`` threads (:func:`on_threads`, ``PIECES_PER_THREAD`` ranges per thread,
    :func:`guided_cut`). For
    work whose result does not depend on the cut (each element written from its own
    inputs): numpy ufuncs, which release the GIL, and kernels over independent rows. Below
    ``min_size`` elements per thread it runs ``fn(0, n)`` here (handing out costs ~50 us)."""
    if threads <= 1 or n < threads * max(min_size, 1):
        if n:
            fn(0, n)
        return
    cut = guided_cut(n, min(threads * PIECES_PER_THREAD, n))
    on_threads(lambda j: fn(cut[j], cut[j + 1]), len(cut) - 1, threads)
