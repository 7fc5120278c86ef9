"""What this machine gives a pass: a second thread, its execution units, and memory
bandwidth on one and two.

Three probes, each repeated in series (the spread between series is the point: a virtual
machine's second vCPU or its memory can be taken by a neighbour for seconds at a time):

* **threads**: :func:`psurf_core.kernels.threads.on_threads` hands 8 pieces of ~0.125 ms of
  compiled arithmetic (no memory traffic, the GIL released) to 1 and to 2 threads, as the
  walkers and the trace hand out theirs; the median and the least wall time of ``--reps``
  hand-outs per series. Two threads should take half of one.
* **units**: whether the two threads share one core's execution units (two hyperthreads
  of one core, which a virtual machine's vCPUs may be though ``lscpu`` says one thread a
  core, or whose cores the host lends to other guests). Three compiled loops, each run on
  one thread alone and then on two threads at once (each its own copy, pinned to CPUs 0
  and 1 where ``sched_setaffinity`` exists): eight independent multiply-add chains, the
  same packed in vector registers (``fastmath``), and one dependent chain of square roots.
  The slower thread's time at once over alone: ~1.0 on two cores of their own; more where
  the two share a core's units (up to ~2 for loops that keep them busy). ``make bench``
  records a reading before and after its headline (``out/bench.json``, ``machine.units``):
  the same code read 2.8-3.8e7 ``planes`` hits/s a few minutes apart on this machine;
* **memory**: a compiled loop reads one float64 array and writes another (``--mb`` MB each)
  on one thread, then two such loops on two threads at once: GB/s moved (read + write).

:func:`cpu_speeds` times any callable alone on each of the two CPUs in turn (``make bench``
times a one-thread ``planes`` pass so: a vCPU can run the walker 1.3x slower than the other
while the units read 1.0x).

Usage::

    python benchmarks/machine_probe.py [--series 3] [--reps 50] [--mb 32]

Not a test: it prints what the machine did while it ran.
"""

from __future__ import annotations

import argparse
import os
import sys
import threading
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


def _chain_steps(n):  # pragma: no cover - compiled
    """Eight independent multiply-add chains of ``n`` steps."""
    a0 = a1 = a2 = a3 = a4 = a5 = a6 = a7 = 1.0
    for _ in range(n):
        a0 = a0 * 0.9999 + 1.0
        a1 = a1 * 0.9998 + 1.0
        a2 = a2 * 0.9997 + 1.0
        a3 = a3 * 0.9996 + 1.0
        a4 = a4 * 0.9995 + 1.0
        a5 = a5 * 0.9994 + 1.0
        a6 = a6 * 0.9993 + 1.0
        a7 = a7 * 0.9992 + 1.0
    return a0 + a1 + a2 + a3 + a4 + a5 + a6 + a7


#: The chains as scalar code, and with ``fastmath``, where LLVM packs them into vector
#: registers (the loop that read 2x on two threads at once at 12:05 on 2026-12-07, when the
#: square roots read 1.0x).
_chains = numba.njit(nogil=True, cache=False)(_chain_steps)
_vector_chains = numba.njit(nogil=True, cache=False, fastmath=True)(_chain_steps)


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


def _pinned(cpu, fn, n, barrier):
    """Seconds of ``fn(n)`` on a thread of its own, pinned to ``cpu`` (where Linux allows),
    started together with the other threads at ``barrier``; numba's thread count is 1 there
    (it is the calling thread's own), so a walker's pieces stay on that CPU."""
    if cpu is not None:
        os.sched_setaffinity(0, {cpu})
    numba.set_num_threads(1)
    barrier.wait()
    t = time.perf_counter()
    fn(n)
    return time.perf_counter() - t


def _at_once(fn, n, cpus) -> list:
    """Seconds of ``fn(n)`` on each of ``len(cpus)`` new threads started together."""
    bar = threading.Barrier(len(cpus))
    with ThreadPoolExecutor(len(cpus)) as ex:  # new threads: the pins die with them
        return [f.result() for f in [ex.submit(_pinned, c, fn, n, bar) for c in cpus]]


#: The three loops of the units probe: (key, compiled loop, what it is).
_UNIT_LOOPS = (("scalar", _chains, "8 independent multiply-add chains"),
               ("vector", _vector_chains, "the same in vector registers"),
               ("latency", _busy, "one dependent chain (square roots)"))


#: Steps of each units loop a millisecond took, about, alone on this machine (2026-12-07,
#: the least of five): a reading runs a fixed number of steps so that its ``alone`` time
#: shows the machine's speed too (the same code's single-thread ``planes`` hit read 46 and
#: 61 CPU ns minutes apart).
_STEPS_PER_MS = {"scalar": 1e6 / 1.72, "vector": 1e6 / 0.271, "latency": 1e6 / 2.32}


def units_reading(ms: float = 50.0) -> dict:
    """One reading of the units probe (module docstring): per loop (``scalar``, ``vector``,
    ``latency``), the seconds of a fixed number of its steps (``ms`` ms' worth on this
    machine at its fastest, :data:`_STEPS_PER_MS`) on one thread alone (``alone``), on two
    threads at once (``both``: each thread's) and ``ratio`` = the slower of ``both`` over
    ``alone`` (~1: two cores; up to ~2: one core's units shared)."""
    pin = hasattr(os, "sched_setaffinity")
    cpus = sorted(os.sched_getaffinity(0))[:2] if pin else []
    pair = cpus if len(cpus) == 2 else [None, None]
    out = {}
    for key, fn, _ in _UNIT_LOOPS:
        fn(10)
        n = int(ms * _STEPS_PER_MS[key])  # the same work every reading: the time is the speed
        alone = _at_once(fn, n, pair[:1])[0]
        both = _at_once(fn, n, pair)
        out[key] = {"alone": alone, "both": both, "ratio": max(both) / alone}
    return out


def units_line(reading: dict) -> str:
    """``reading`` (:func:`units_reading`) in one line: per loop its time alone (the same
    work each reading: a slower machine reads more) and the ratio."""
    return ", ".join(f"{k} {1e3 * reading[k]['alone']:.1f} ms alone, {reading[k]['ratio']:.2f}x"
                     for k, _, _ in _UNIT_LOOPS)


def units(series: int) -> None:
    for s in range(series):
        r = units_reading()
        for key, _, name in _UNIT_LOOPS:
            alone, both = r[key]["alone"], r[key]["both"]
            print(f"units: series {s + 1}, {name}: {1e3 * alone:.1f} ms alone, "
                  f"{1e3 * both[0]:.1f} / {1e3 * both[1]:.1f} ms on two threads at once "
                  f"({r[key]['ratio']:.2f}x)")


def cpu_speeds(fn, rounds: int = 4) -> dict:
    """``fn()`` alone on each of the first two CPUs in turn, ``rounds`` times each
    (alternating, so that drift hits both alike): per CPU the median seconds, and ``ratio``,
    the slower CPU's over the faster's. A walker's pass read 1.3x on this machine while
    :func:`units_reading` read 1.0x (docs/study.md, "Large pieces first"): whichever vCPU
    another guest's load lands on runs memory-bound code slower, not these arithmetic loops.
    Empty where the process cannot be pinned to two CPUs."""
    cpus = sorted(os.sched_getaffinity(0))[:2] if hasattr(os, "sched_setaffinity") else []
    if len(cpus) < 2:
        return {}
    fn()  # warm
    times: dict = {c: [] for c in cpus}
    for r in range(rounds):
        for c in (cpus if r % 2 == 0 else cpus[::-1]):
            times[c].append(_at_once(lambda _: fn(), 0, [c])[0])
    med = {c: float(np.median(v)) for c, v in times.items()}
    return {"seconds": {str(c): v for c, v in med.items()},
            "ratio": max(med.values()) / min(med.values())}


def cpu_speeds_line(reading: dict) -> str:
    """:func:`cpu_speeds`' ``reading`` in one line."""
    if not reading:
        return "not pinned (fewer than two CPUs to pin to)"
    each = " / ".join(f"CPU {c} {1e3 * t:.1f} ms" for c, t in reading["seconds"].items())
    return f"{each} ({reading['ratio']:.2f}x)"


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
    units(args.series)
    memory(args.series, args.mb)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
