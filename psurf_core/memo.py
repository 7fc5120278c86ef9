"""Values derived from an object that does not change, computed once per object.

A pass reads the same scene-derived tables many times: the camera's basis, its compiled row,
the blockers' table, one pass's ray table (once per technique), the photons' light rows.
Each was rebuilt on every call (~2 ms of a ~7 ms pass of a three-member MIS set at 64
photons: the fixed cost ``c0`` that equal-time runs pay once per pass, docs/study.md).
:func:`memo` keeps such a value beside the object it came from, for as long as the object
lives.

Only for objects that are never changed after they are built (the scene's frozen
dataclasses, a pass's :class:`~psurf_core.camera.Rays` and photon paths, the
:class:`~psurf_core.geometry.Blockers`). Keys are ``id``'s, dropped when the object is
collected (before the id can be reused), so nothing outlives its object and nothing is
pickled with it.
"""

from __future__ import annotations

import threading
import weakref
from collections.abc import Callable, Hashable
from typing import TypeVar

T = TypeVar("T")

_MEMO: dict[int, dict] = {}
_LOCK = threading.Lock()
_MISSING = object()


def memo(obj: object, key: Hashable, build: Callable[[], T]) -> T:
    """``build()`` the first time ``(obj, key)`` is asked for, the same value after.

    Parameters
    ----------
    obj : object
        Never changed after it was built, and weak-referenceable.
    key : hashable
        Which value of ``obj`` (a name, or a name and the arguments it depends on).
    build : callable
        ``() -> value``; called at most once per ``(obj, key)`` (twice only if two threads
        ask at the same moment: both build, one value is kept).
    """
    d = _MEMO.get(id(obj))
    if d is None:
        with _LOCK:
            d = _MEMO.get(id(obj))
            if d is None:
                d = _MEMO[id(obj)] = {}
                weakref.finalize(obj, _MEMO.pop, id(obj), None)
    v = d.get(key, _MISSING)
    if v is _MISSING:
        v = d.setdefault(key, build())
    return v


def frozen(a):
    """``a`` (an ndarray) made read-only: a memoized array is shared by every caller."""
    a.flags.writeable = False
    return a
