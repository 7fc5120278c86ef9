"""What this machine gives a pass: a second thread, and memory bandwidth on one and two.

Two probes, each repeated in series (the spread between series is the point: a virtual
machine's second vCPU or its memory can be taken by a neighbour for seconds at a time):

* **threads**: :func:`psurf_core.kernels.threads.on_threads` hands 8 pieces of ~0.125 ms of
  compiled arithmetic (no memory traffic, the GIL released) to 1 and to 2 threads, as the
  walkers and the trace hand out theirs; the median and the least wall time of ``--reps``
  hand-outs per series. Two threads should take half of one.
* **memory**: a compiled loop reads one float64 array and writes another (``--mb`` MB each)
  on one thread, then two such loops on two threads at once: GB/s moved (read + write).

Usage::

    python benchmarks/machine_probe.py [--series 3] [--reps 50] [--mb 32]

Not a test: it prints what the machine did while it ran.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from concurrent.futures import ThreadPoolExecutor

import numba
import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from psurf_core.kernels.threads import on_threads  # noqa: E402


@numba.njit(nogil=True, cache=False)
def _busy(n):  # pragma: no cover - compiled
    s = 0.0
    for i in range(n):
        s += np.sqrt(i + 1.0)
    return s


@numba.njit(nogil=True, cache=False)
def _copy(a, b):  # pragma: no cover - compiled
    for i in range(a.size):
        b[i] = a[i] * 1.0000001


def threads(series: int, reps: int) -> None:
    _busy(10)
    t = time.perf_counter()
    _busy(1_000_000)
    n = max(int(0.125e-3 / ((time.perf_counter() - t) / 1e6)), 1)
    for s in range(series):
        for th in (1, 2):
            ts = []
            for _ in range(reps):
                t = time.perf_counter()
                on_threads(lambda j: _busy(n), 8, th)
                ts.append(time.perf_counter() - t)
            print(f"threads: series {s + 1}, {th} thread(s): 8 pieces of 0.125 ms took "
                  f"{1e3 * np.median(ts):.3f} ms (median of {reps}), least "
                  f"{1e3 * min(ts):.3f} ms")


def memory(series: int, mb: int) -> None:
    size = mb * 1_000_000 // 8
    rng = np.random.default_rng(0)
    a, b = rng.random(size), np.empty(size)
    a2, b2 = rng.random(size), np.empty(size)
    _copy(a, b)
    _copy(a2, b2)
    with ThreadPoolExecutor(2) as ex:
        for s in range(series):
            t = time.perf_counter()
            _copy(a, b)
            one = 2 * a.nbytes / (time.perf_counter() - t) / 1e9
            t = time.perf_counter()
            f1, f2 = ex.submit(_copy, a, b), ex.submit(_copy, a2, b2)
            f1.result()
            f2.result()
            two = 4 * a.nbytes / (time.perf_counter() - t) / 1e9
            print(f"memory: series {s + 1}, {mb} MB read + written: {one:.1f} GB/s on one "
                  f"thread, {two:.1f} GB/s on two")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--series", type=int, default=3)
    ap.add_argument("--reps", type=int, default=50)
    ap.add_argument("--mb", type=int, default=32)
    args = ap.parse_args(argv)
    print(f"# {time.strftime('%Y-%m-%d %H:%M:%S', time.gmtime())} UTC, load average "
          f"{os.getloadavg()[0]:.2f}, numba threads {numba.get_num_threads()}")
    threads(args.series, args.reps)
    memory(args.series, args.mb)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
