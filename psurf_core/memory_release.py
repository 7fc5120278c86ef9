"""Memory handed back to the system while a long run goes on (glibc / Linux; no-ops elsewhere).

A long render or the window's background render allocates and frees the same sizes pass
after pass. Two things would keep resident memory rising without any leak:

* glibc keeps freed heap up to its trim threshold (~16 MiB here, which the next pass touches
  again): :func:`release_free_memory` (``malloc_trim``) hands it back; ``render`` calls it
  every :data:`TRIM_SECONDS`;
* memory kept to be reused (:class:`psurf_core.kernels.buffers.HitBuffers`) is sized for the
  largest need so far and would stay resident as far as any earlier pass wrote into it: a
  high-water mark that only rises, because each new record (a trace's outputs span the
  deepest photon of its batch, a rare deep one) touches a few more pages. That was the slow
  growth of long renders (``benchmarks/rss_slope.py``). :func:`release_pages` hands back a
  buffer's pages past the need of the lease in hand, so what stays resident follows the
  pass being rendered.

Neither changes a value anyone reads: released pages read as zeros when touched again, and
only memory past what a lease hands out is released.
"""

from __future__ import annotations

import os
import sys

__all__ = ["TRIM_SECONDS", "release_free_memory", "release_pages"]

#: Seconds between :func:`release_free_memory` calls of a long render.
TRIM_SECONDS = 30.0

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
                _LIBC = lib
            except (OSError, AttributeError):
                pass
    return _LIBC or None
