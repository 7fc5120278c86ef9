"""This process's peak resident memory, for measurements made in fresh subprocesses
(``benchmarks/memory_model.py``, ``benchmarks/extras.py``, ``tests/test_memory.py``).

``getrusage(RUSAGE_SELF).ru_maxrss`` is not the peak of the process's own address space on
Linux: the kernel keeps it across ``execve``, so a child started from a large parent (a pytest
process that imported VTK for the window's tests: ~0.9 GiB) reports at least the parent's size,
and a growth measured as ``after - before`` comes out too small, or zero (found when
``make test-slow`` collected every test module: the memory model's check measured 103 instead
of 326 MiB and failed). ``VmHWM`` in ``/proc/self/status`` is the high-water mark of the
current address space, which ``execve`` replaces.
"""

from __future__ import annotations

import sys

__all__ = ["peak_rss_bytes"]


def peak_rss_bytes() -> int:
    """Peak resident set size of this process's address space (bytes): Linux's ``VmHWM``;
    elsewhere ``ru_maxrss`` (bytes on macOS, KiB on other systems)."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) * 1024  # kB
    except OSError:
        pass
    import resource

    r = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return int(r) if sys.platform == "darwin" else int(r) * 1024
