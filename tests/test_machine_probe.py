"""``benchmarks/machine_probe.py``'s per-CPU timing: each call runs alone on one CPU, with
numba's thread count 1 there, alternating between the two CPUs."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numba
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks import machine_probe  # noqa: E402


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity") or len(os.sched_getaffinity(0)) < 2,
                    reason="needs two CPUs to pin to")
def test_cpu_speeds_runs_each_call_pinned_to_one_cpu_on_one_numba_thread():
    seen = []

    def fn():
        seen.append((frozenset(os.sched_getaffinity(0)), numba.get_num_threads()))
        sum(range(20_000))

    before = os.sched_getaffinity(0)
    r = machine_probe.cpu_speeds(fn, rounds=3)
    cpus = sorted(before)[:2]
    assert sorted(int(c) for c in r["seconds"]) == cpus
    assert r["ratio"] >= 1.0
    # The warm-up call runs here, unpinned; then three calls on each CPU alone, alternating.
    pinned = seen[1:]
    assert [next(iter(a)) for a, _ in pinned] == [cpus[0], cpus[1], cpus[1], cpus[0],
                                                  cpus[0], cpus[1]]
    assert all(len(a) == 1 and n == 1 for a, n in pinned)
    assert os.sched_getaffinity(0) == before  # this thread's own pins untouched
    line = machine_probe.cpu_speeds_line(r)
    assert f"CPU {cpus[0]}" in line and f"CPU {cpus[1]}" in line and line.endswith("x)")
