"""Ctrl-C at safe points: within :func:`held`, a SIGINT is recorded and raised as
``KeyboardInterrupt`` by the next :func:`check` (between pieces of a walk, chunks of a pass
and passes), not wherever the main thread happens to be.

Python's default handler raises the ``KeyboardInterrupt`` at the next bytecode the main thread
runs, and during a render that is often inside numba's dispatch or result boxing: there it came
back as a ``SystemError`` (``kernels.jit.ctrl_c_kept``), was lost (the render went on: 1 of
~340 interrupted renders in a loop, 2026-12-05; most likely cleared by C code that retries a
failed lookup), and is the likeliest cause of a SIGSEGV on Ctrl-C that one fresh-clone
``make test`` saw (not reproduced in 600 interrupted renders since). A recorded signal can be
neither lost nor raised mid-call. A second Ctrl-C while one is pending raises at
once (where ``second_raises``), so code without a check point can still be stopped.
"""

from __future__ import annotations

import signal
import threading
from contextlib import contextmanager

#: Signals recorded by :func:`held` and not yet raised by :func:`check`.
_pending = [0]
#: Nesting depth of :func:`held` (the outermost raises what the inner ones recorded).
_depth = [0]


def check() -> None:
    """Raise ``KeyboardInterrupt`` if a Ctrl-C arrived within :func:`held` since the last
    check (a module-level read: cheap enough for every piece of work)."""
    if _pending[0]:
        _pending[0] = 0
        raise KeyboardInterrupt


@contextmanager
def held(second_raises: bool = True, reraise: bool = True):
    """Record SIGINT instead of raising it, for :func:`check` to raise at a safe point.

    Leaving the outermost block with a signal still pending raises it (Ctrl-C always
    interrupts). With ``second_raises`` a second SIGINT while one is pending raises at once;
    without (moving files into place) every signal waits for the block's end. Without
    ``reraise`` (saving after a Ctrl-C: the run is ending anyway) a signal recorded by the
    block is dropped at its end. Only the main thread can set a handler (elsewhere, and where
    SIGINT is ignored, this is a no-op).
    """
    if (threading.current_thread() is not threading.main_thread()
            or signal.getsignal(signal.SIGINT) is signal.SIG_IGN):  # ignored: stays ignored
        yield
        return

    def record(signum, frame):
        _pending[0] += 1
        if second_raises and _pending[0] > 1:
            _pending[0] = 0
            raise KeyboardInterrupt

    old = signal.signal(signal.SIGINT, record)
    _depth[0] += 1
    pending = 0
    try:
        yield
    finally:
        _depth[0] -= 1
        signal.signal(signal.SIGINT, old)
        if _depth[0] == 0:  # nothing stale is left for a later block
            pending, _pending[0] = _pending[0], 0
    # Not in ``finally``: an exception already on its way out is not replaced by the signal.
    if pending and reraise:
        raise KeyboardInterrupt
