"""3-vectors in compiled code: tuples ``(x, y, z)`` of floats, and the few operations the
compiled twins need (numpy writes these as array operators; ``dot`` and ``cross`` are the
twins of :func:`psurf_core.techniques.base.dot` / ``cross``).

All are inlined into their callers, so a tuple never leaves registers.
"""

from __future__ import annotations

import numpy as np

from .jit import inline, scalar


@inline
def vec(a):
    """A 3-tuple from anything indexable (a record's (3,) field, a row of an array)."""
    return (a[0], a[1], a[2])


@scalar
def add(a, b):
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


@scalar
def sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


@scalar
def scale(k, a):
    """``k a`` (numpy: ``k[:, None] * a``)."""
    return (k * a[0], k * a[1], k * a[2])


@scalar
def madd(a, k, b):
    """``a + k b``."""
    return (a[0] + k * b[0], a[1] + k * b[1], a[2] + k * b[2])


@scalar
def norm(a):
    """``|a|`` (numpy's ``linalg.norm`` of a row: the square root of the sum in order)."""
    return np.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
