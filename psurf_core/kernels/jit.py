"""How psurf compiles: the decorators every compiled function uses, the compiled twin of a
numpy function, and Ctrl-C kept a ``KeyboardInterrupt`` across a compiled call.

* :func:`kernel`: a compiled entry point (called from Python), cached on disk by its sources
  (:mod:`.cache`);
* :func:`inline`: a helper that takes arrays, inlined into the kernels that call it
  (numba IR);
* :func:`scalar`: a helper of numbers and tuples only, compiled once and inlined by LLVM;
* :func:`twin`: the compiled twin of a numpy function. The numpy function keeps its name and
  stays what Python calls; compiled code calling the same name gets the twin (a numba
  ``overload``), so a formula has one name in both worlds and the two implementations sit
  side by side in the family's module, where a test holds them equal.
"""

from __future__ import annotations

import inspect as _inspect
from contextlib import contextmanager

from numba import njit
from numba.core.extending import overload

from .cache import cached
from .numba_flags import install as _install_flags

# Before anything compiles: cheaper flag comparisons while numba types a kernel (numba_flags).
_install_flags()

#: Options of every compiled function: numpy's floating-point model (a division by zero is
#: inf or NaN, as in the numpy reference, not an exception).
OPTIONS = dict(error_model="numpy")

#: Options of the MIS weight's functions (``@twin(..., weight=True)``, ``@scalar(weight=True)``):
#: a division may be a multiplication by the reciprocal (LLVM's ``arcp``), so that ``x / st``
#: at every hit is a multiplication once the walker hoists ``1 / st`` out of its loop. Only
#: there: a weight is a ratio of products (a rounding more changes it by an ulp or two),
#: where the roots and acceptance tests must round as their numpy twins do (an ill-conditioned
#: ``|n . psi|`` of a disk moved by 5e-12 of itself with ``arcp`` everywhere). ``arcp``
#: rewrites LLVM's IR before code generation, so it should not make an image depend on the
#: CPU as ``contract`` (fused multiply-adds) would (reasoned, not checked on a second
#: machine). ``fast-multi``'s walk at 256x192: 0.95x the CPU a photon (docs/study.md,
#: "Reciprocals in the MIS weights").
WEIGHT_OPTIONS = dict(OPTIONS, fastmath={"arcp"})


def kernel(fn=None, **options):
    """``@kernel`` / ``@kernel(nogil=True)``: compile ``fn`` as a kernel (see module doc)."""

    def deco(f):
        return cached(njit(cache=False, **OPTIONS, **options)(f))

    return deco(fn) if fn is not None else deco


def inline(fn):
    """``@inline``: a helper that takes arrays, inlined into its compiled callers in numba's
    IR (every call site gets a typed copy). An array passed to a function numba calls is
    reference-counted at every call; inlined in the IR, numba's reference-count pruning
    removes that (measured 2026-12-04: with every helper called instead, ``paper-multi``'s
    passes took 1.68x as long). Helpers of numbers and tuples only take :func:`scalar`."""
    return njit(cache=False, inline="always", **OPTIONS)(fn)


def scalar(fn=None, *, weight: bool = False):
    """``@scalar``: a small helper whose arguments are numbers and tuples only, compiled once
    per signature and called; LLVM inlines it into its callers all the same (checked in the
    walkers' LLVM IR, 2026-12-04: no call to one remains; a helper too large for LLVM's
    inliner, such as ``kernels.shadow._first_hit``, stays :func:`inline`). Inlined in numba's
    IR instead, it is typed again at every call site of every walker (on fresh clones,
    ``make test``'s walkers compiled in 786 s instead of 830 s once ``vec``'s, ``path_record``'s
    row updates and the span and shadow box helpers were ``@scalar``; README, Tests).
    ``weight``: compiled with :data:`WEIGHT_OPTIONS` (the MIS weight's terms)."""
    def deco(f):
        return njit(cache=False, **(WEIGHT_OPTIONS if weight else OPTIONS))(f)

    return deco(fn) if fn is not None else deco


def twin(numpy_function, inline: bool = False, weight: bool = False):
    """``@twin(f)``: the decorated scalar function is what compiled code runs when it calls
    ``f``. It must take the same arguments as ``f`` (numba checks the names). ``inline``:
    inline it in numba's IR at every call site (for the few tiny ones on every pair: each
    copy costs compile time). ``weight``: a term of the MIS weight (a density, a Jacobian, a
    ``short_ratio``), compiled with :data:`WEIGHT_OPTIONS`."""

    def deco(impl):
        def typer(*args):
            return impl

        sig = _inspect.signature(numpy_function)  # numba compares names, not annotations
        empty = _inspect.Parameter.empty
        typer.__signature__ = sig.replace(
            parameters=[q.replace(annotation=empty) for q in sig.parameters.values()],
            return_annotation=empty)
        # Not inlined in numba's IR (a typed copy per call site: 40% more compile time);
        # LLVM inlines them into the walker all the same (measured: the same run time).
        overload(numpy_function, inline="always" if inline else "never",
                 jit_options=WEIGHT_OPTIONS if weight else OPTIONS)(typer)
        return impl

    return deco


def interrupted(e: BaseException | None) -> bool:
    """Was ``e`` caused (at any depth of its cause / context chain) by a KeyboardInterrupt?"""
    seen = set()
    while e is not None and id(e) not in seen:
        if isinstance(e, KeyboardInterrupt):
            return True
        seen.add(id(e))
        e = e.__cause__ or e.__context__
    return False


@contextmanager
def ctrl_c_kept():
    """Run a compiled call with Ctrl-C kept a KeyboardInterrupt.

    A SIGINT whose Python handler runs while a compiled function returns (numba boxing its
    result) surfaces as ``SystemError: ... returned a result with an exception set``, caused
    by the KeyboardInterrupt; callers (``render --checkpoint``: save and exit 130) must see
    the Ctrl-C itself.
    """
    try:
        yield
    except SystemError as e:
        if interrupted(e):
            raise KeyboardInterrupt from None
        raise
