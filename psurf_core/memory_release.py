"""Memory handed back to the system while a long run goes on (glibc / Linux; no-ops elsewhere).

A long render or the window's background render allocates and frees the same sizes pass
after pass. Two things would keep resident memory rising without any leak:

* glibc keeps freed heap up to its trim threshold (:data:`TRIM_THRESHOLD`, which the next
  pass touches again): :func:`release_free_memory` (``malloc_trim``) hands it back; every
  pass calls it at most every :data:`TRIM_SECONDS` (:func:`trim_now_and_then`);
* memory kept to be reused (:class:`psurf_core.kernels.buffers.HitBuffers`) is sized for the
  largest need so far and would stay resident as far as any earlier pass wrote into it: a
  high-water mark that only rises, because each new record (a trace's outputs span the
  deepest photon of its batch, a rare deep one) touches a few more pages. That was the slow
  growth of long renders (``benchmarks/rss_slope.py``). :func:`release_pages` hands back a
  buffer's pages past the need of the lease in hand, so what stays resident follows the
  pass being rendered.

Neither changes a value anyone reads: released pages read as zeros when touched again, and
only memory past what a lease hands out is released.

The opposite holds within a pass: it allocates and frees the same few-MiB arrays (screen spans,
candidate counts, numpy temporaries) every time, and glibc's defaults hand them back to the
system at every free (its trim threshold is twice the largest block it has mapped), so the
next pass takes a page fault for every page again: 7.3 % of a ``planes`` pass on
``area.toml`` was the kernel's page faults (``perf``, 2026-12-06, docs/study.md).
:func:`keep_freed_memory` (called when ``psurf_core`` is imported) keeps up to
:data:`TRIM_THRESHOLD` of freed heap for the next pass; :func:`trim_now_and_then` (every
:func:`psurf_core.render.render_pass` calls it) still hands it back every
:data:`TRIM_SECONDS` in long runs, the window's and the web sessions' included.
"""

from __future__ import annotations

import os
import sys
import time

__all__ = ["MMAP_THRESHOLD", "TRIM_SECONDS", "TRIM_THRESHOLD", "keep_freed_memory",
           "release_free_memory", "release_pages", "trim_now_and_then"]

#: Seconds between :func:`release_free_memory` calls of a long render.
TRIM_SECONDS = 30.0

#: Blocks from this size get their own mapping (glibc ``M_MMAP_THRESHOLD``; its default
#: adapts from 128 KiB up to this, 32 MiB on 64-bit): a pass's arrays at 64x48 to 256x192
#: come from the heap and are reused; larger ones are handed back at once, as before.
MMAP_THRESHOLD = 32 << 20
#: Free memory at the top of the heap kept for reuse (glibc ``M_TRIM_THRESHOLD``). The
#: mapping threshold is what matters: with it alone fixed, a ``planes`` pass on ``area.toml``
#: took ~170-230 page faults at a trim threshold of 16 to 256 MiB, against 1500-3200 with
#: glibc's defaults (the same peak resident memory, ~225 MiB; ``ru_minflt``, 2026-12-06).
TRIM_THRESHOLD = 64 << 20
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3  # <malloc.h>

_MADV_DONTNEED = 4  # <sys/mman.h> on Linux
_PAGE = os.sysconf("SC_PAGE_SIZE") if hasattr(os, "sysconf") else 4096
_LIBC = None


def release_free_memory() -> bool:
    """Hand the heap's free pages back to the system (glibc ``malloc_trim``); False where
    there is no glibc (nothing done)."""
    libc = _libc()
    if libc is None:
        return False
    libc.malloc_trim(0)
    return True


#: When :func:`trim_now_and_then` last trimmed (``time.monotonic``; a list: set in place).
_LAST_TRIM = [time.monotonic()]


def trim_now_and_then(seconds: float = TRIM_SECONDS) -> bool:
    """:func:`release_free_memory` if ``seconds`` have passed since this process last did
    so here; whether it did (a race between threads at worst trims twice)."""
    now = time.monotonic()
    if now - _LAST_TRIM[0] < seconds:
        return False
    _LAST_TRIM[0] = now
    return release_free_memory()


def keep_freed_memory() -> bool:
    """Keep freed heap for the next pass (glibc ``mallopt``: :data:`MMAP_THRESHOLD`,
    :data:`TRIM_THRESHOLD`; see the module docstring); False where there is no glibc
    (nothing done). A ``planes`` pass on ``area.toml`` faults 10 pages instead of ~2300
    (``benchmarks/before_after.py``, 2026-12-06, docs/study.md)."""
    libc = _libc()
    if libc is None:
        return False
    return bool(libc.mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)
                and libc.mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD))


def release_pages(buf, keep: int) -> bool:
    """Hand back the whole pages of ``buf``'s memory past its first ``keep`` bytes (Linux
    ``madvise(MADV_DONTNEED)``: they read as zeros when touched again); False where that is
    not available (nothing done).

    Parameters
    ----------
    buf : numpy.ndarray
        C-contiguous, owning or viewing memory nobody reads past ``keep`` bytes. Only pages
        wholly inside ``buf[keep:]`` are released (never a neighbour's bytes).
    keep : int
        Bytes from the start of ``buf`` to keep.
    """
    libc = _libc()
    if libc is None:
        return False
    start = buf.ctypes.data
    lo = -(-(start + max(int(keep), 0)) // _PAGE) * _PAGE
    hi = (start + buf.nbytes) // _PAGE * _PAGE
    if hi > lo:
        libc.madvise(lo, hi - lo, _MADV_DONTNEED)
    return True


def _libc():
    """glibc through ctypes (``malloc_trim``, ``madvise``), or None where it is missing."""
    global _LIBC
    if _LIBC is None:
        _LIBC = False
        if sys.platform.startswith("linux"):
            try:
                import ctypes

                lib = ctypes.CDLL("libc.so.6")
                lib.malloc_trim.argtypes = [ctypes.c_size_t]
                lib.madvise.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int]
                lib.mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
                _LIBC = lib
            except (OSError, AttributeError):
                pass
    return _LIBC or None
