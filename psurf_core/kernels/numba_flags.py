"""Cheaper comparisons of numba's compiler flags: 7-17 % of a walker's compilation.

numba caches the typing of every ``overload`` call (each twin, ``records.load``, the shadow
status) by ``(context, argument types, flags)``. The flags (a ``TargetConfig``) hash to their
option *names* only, so every instance has the same hash and each cache lookup compares the
flags with ``__eq__``, which builds two dicts of ~40 options through property getters. A
walker's typing resolves its calls ~20 000 times (type inference repeats until nothing
changes): 16 of 96 profiled seconds of ``paper-multi``'s five walkers went to those dicts.

:func:`install` replaces ``values``, ``__eq__`` and ``__hash__`` by versions that read the
same mapping directly (the same results: checked on a sample when installing, and in
``tests/test_numba_flags.py``); where the sample disagrees (another numba), nothing is
replaced.
"""

from __future__ import annotations

from numba.core import targetconfig

_TC = targetconfig.TargetConfig
#: numba's own methods, kept for the check and the tests.
ORIGINAL = {"values": _TC.values, "__eq__": _TC.__eq__, "__hash__": _TC.__hash__}


def values(self) -> dict:
    """Every option's value, set or default (``TargetConfig.values``)."""
    get = self._values.get
    return {k: get(k, o.default) for k, o in self.options.items()}


def equal(self, other):
    """``TargetConfig.__eq__``: the same values. Flags of one class compare only the options
    set on either side (an option set on neither has its default on both) instead of
    building two dicts of every option: a compilation's typing-cache lookups compare flags
    ~100 000 times, two thirds of them unequal."""
    if not isinstance(other, _TC):
        return NotImplemented
    options = self.options
    if options is not other.options:
        return values(self) == values(other)
    a, b = self._values, other._values
    if a == b:
        return True
    for k in a.keys() | b.keys():
        d = options[k].default
        if a.get(k, d) != b.get(k, d):
            return False
    return True


_HASHES: dict[int, int] = {}


def hashed(self) -> int:
    """``TargetConfig.__hash__``: numba hashes the sorted option names (once per class's
    option table: the table is fixed when the class is defined)."""
    options = self.options
    h = _HASHES.get(id(options))
    if h is None:
        h = _HASHES[id(options)] = hash(tuple(sorted(options)))
    return h


def _agrees() -> bool:
    from numba.core.compiler import Flags

    a, b = Flags(), Flags()
    b.nrt = True
    b.error_model = "numpy"
    return all(values(f) == ORIGINAL["values"](f) and hashed(f) == ORIGINAL["__hash__"](f)
               for f in (a, b)) and equal(a, b) == ORIGINAL["__eq__"](a, b)


def install() -> bool:
    """Replace the three methods when they agree with numba's on a sample; True if so."""
    if _TC.values is values:
        return True
    try:
        ok = _agrees()
    except Exception:  # noqa: BLE001 - a numba whose flags look different: leave it alone
        ok = False
    if ok:
        _TC.values, _TC.__eq__, _TC.__hash__ = values, equal, hashed
    return ok
