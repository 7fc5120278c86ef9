"""Borrowed views: an array (or a tuple of arrays) re-seen without its reference count, for
the walkers' innermost loops.

numba reference-counts an array at every call it is passed to (``NRT_incref`` before,
``NRT_decref`` after: an atomic add each), and an ``inline="always"`` overload that binds its
argument to a new name counts it again. The walkers pass the blocker table to the shadow
test, and its counts stood at every hit, whether or not the test was called: three
``NRT_incref`` of it past the walker's entry (``benchmarks/walk_ir.py planes``), each an atomic
add on one cache line that both threads write. A view made by :func:`borrowed` has no owner
(numba's ``meminfo`` is NULL, and ``NRT_incref`` of NULL returns at once), so passing it costs
nothing, and LLVM drops the calls. It is valid while the
array it views lives: make it inside the kernel that received the array, which holds that
array until it returns.
"""

from __future__ import annotations

import numba
from numba import types
from numba.core import cgutils
from numba.core.extending import intrinsic, overload


@intrinsic
def _void_pointer(typingctx, address):
    """The integer ``address`` as a ``void *``."""
    sig = types.voidptr(address)

    def codegen(context, builder, signature, args):
        return builder.inttoptr(args[0], cgutils.voidptr_t)

    return sig, codegen


def borrowed(a):
    """A C-contiguous array ``a`` (or a tuple of them) as views without a reference count, in
    compiled code only (see the module docstring)."""
    raise NotImplementedError("kernels.views.borrowed runs in compiled code only")


@overload(borrowed, inline="always")
def _borrowed(a):
    if isinstance(a, types.Array):
        if a.layout != "C":
            return None
        dt = a.dtype

        def one(a):  # pragma: no cover - compiled
            return numba.carray(_void_pointer(a.ctypes.data), a.shape, dt)

        return one
    if isinstance(a, types.BaseTuple) and all(isinstance(t, types.Array) and t.layout == "C"
                                              for t in a.types):
        n = len(a.types)
        names = ", ".join(f"borrowed(a[{i}])" for i in range(n))
        ns = {"borrowed": borrowed}
        exec(f"def many(a):\n    return ({names}{',' if n == 1 else ''})\n", ns)  # noqa: S102
        return ns["many"]
    return None
