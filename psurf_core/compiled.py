"""Helpers shared by the modules that call compiled (numba) kernels."""

from __future__ import annotations

from contextlib import contextmanager


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
