"""Reusable output buffers of the walkers, so a pass writes to memory it has written before.

Fresh memory costs a page fault per 4 KiB on first write (the allocator hands large blocks
back to the system when they are freed); on this kind of virtual machine that was ~30% of a
walker's time. A buffer is handed out as a *lease* (a plain view of its storage) and reused
only when the lease is gone: every array made from it, views included, references it, so
memory someone still reads (``PassRecord`` keeps every chunk's hits) is never overwritten;
then the next chunk gets fresh memory.
"""

from __future__ import annotations

import threading
import weakref
from collections import deque

import numpy as np

from ..memory_release import release_pages


class _Storage(np.ndarray):
    """Memory of :class:`HitBuffers`. Its own type matters: numpy collapses a view's
    ``base`` through plain-ndarray views but stops at a change of type, so every view of a
    lease (a plain view of this) keeps that lease alive."""


#: Takes over which a buffer's resident extent follows the largest need. Releasing past every
#: smaller need would re-fault the same pages on the next larger one (an MIS pass's chunks
#: alternate between members' needs); past the largest of the recent ones, only a rare deep
#: batch's pages are handed back, once it is this many takes old.
RECENT_TAKES = 32

#: Bytes of resident excess worth an ``madvise`` call.
RELEASE_MIN_BYTES = 1 << 20


class HitBuffers(threading.local):
    """Two reusable buffers per kind of output and thread."""

    def __init__(self):
        self.storage: dict = {}
        self.leases: dict = {}
        self.recent: dict = {}    # (kind, i) -> the needs of its last RECENT_TAKES takes
        self.resident: dict = {}  # (kind, i) -> bytes of its storage possibly resident

    def take(self, kind: str, fields, rows: int) -> tuple[np.ndarray, ...]:
        """Arrays of ``rows`` rows, one per ``(dtype, width)`` of ``fields`` ((rows,) for
        width 1, else (rows, width)), cut from one lease."""
        need = sum(_padded(max(rows, 1) * k * np.dtype(t).itemsize) for t, k in fields)
        store = self.storage.setdefault(kind, [None, None])
        leases = self.leases.setdefault(kind, [None, None])
        for i in range(2):
            if leases[i] is not None and leases[i]() is not None:
                continue  # an earlier chunk's arrays are still referenced
            if store[i] is None or store[i].size < need:
                store[i] = None  # free the smaller one first
                store[i] = _Storage(shape=(need + need // 4,), dtype=np.uint8)
                self.resident[kind, i] = 0
            lease = store[i].view(np.ndarray)
            leases[i] = weakref.ref(lease)
            self._follow_recent_needs(kind, i, store[i], need)
            return _split(lease, fields, rows)
        return _split(np.empty(need, np.uint8), fields, rows)

    def _follow_recent_needs(self, kind: str, i: int, storage, need: int) -> None:
        """Keep ``storage`` resident only as far as the largest of its recent needs: hand back
        the pages a rare larger pass touched once it is :data:`RECENT_TAKES` takes old (what
        else would stay resident for the rest of a long render)."""
        recent = self.recent.setdefault((kind, i), deque(maxlen=RECENT_TAKES))
        recent.append(need)
        keep = max(recent)
        resident = self.resident.get((kind, i), 0)
        if resident - keep >= RELEASE_MIN_BYTES and release_pages(storage, keep):
            resident = keep
        self.resident[kind, i] = max(resident, need)


def _padded(size: int) -> int:
    """``size`` bytes rounded up to a multiple of 8 (every array starts aligned)."""
    return -(-size // 8) * 8


def _split(buf: np.ndarray, fields, rows: int) -> tuple[np.ndarray, ...]:
    """``buf`` (uint8) cut into the ``fields`` arrays of ``rows`` rows (views); each array
    starts on an 8-byte boundary."""
    out, at = [], 0
    for t, k in fields:
        size = rows * k * np.dtype(t).itemsize
        a = buf[at:at + size].view(t)
        out.append(a.reshape(rows, k) if k > 1 else a)
        at += _padded(size)
    return tuple(out)
