"""Ctrl-C held for safe points (:mod:`psurf_core.interrupt`): a SIGINT inside ``held`` raises
only at ``check`` (between pieces, chunks and passes), a second one at once, none is lost, and
an ignored SIGINT stays ignored."""

import os
import signal
import sys
import time

import pytest

from psurf_core.interrupt import check, held
from psurf_core.kernels.threads import on_threads

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")


@pytest.fixture(autouse=True)
def default_sigint():
    """Python's own SIGINT handler for each test, whatever pytest inherited: a test suite
    started in the background of a shell without job control (``make test &`` in a script)
    inherits an *ignored* SIGINT, which ``held`` rightly leaves ignored, and every test here
    would then wait for a KeyboardInterrupt that never comes."""
    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)


def ctrl_c():
    # Delivered to this (main) thread; Python runs the handler at the next bytecode.
    os.kill(os.getpid(), signal.SIGINT)


def test_a_held_sigint_raises_at_the_next_check_only():
    ran = []
    with pytest.raises(KeyboardInterrupt), held():
        ctrl_c()
        ran.append("after the signal")  # not interrupted here
        check()
        ran.append("after the check")
    assert ran == ["after the signal"]
    check()  # nothing left pending


def test_a_second_sigint_raises_at_once():
    ran = []
    with pytest.raises(KeyboardInterrupt), held():
        ctrl_c()
        ran.append(1)
        ctrl_c()
        ran.append(2)
    assert ran == [1]


def test_a_sigint_never_checked_is_raised_when_the_block_ends():
    with pytest.raises(KeyboardInterrupt), held():
        ctrl_c()
    with held():  # and nothing stale is left behind for the next block
        check()


def test_without_reraise_the_signal_is_dropped_and_the_handler_restored():
    before = signal.getsignal(signal.SIGINT)
    with held(second_raises=False, reraise=False):
        ctrl_c()
        ctrl_c()
        check_called = True
    assert check_called
    assert signal.getsignal(signal.SIGINT) is before


def test_an_ignored_sigint_stays_ignored():
    old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        with held():
            ctrl_c()
            check()
    finally:
        signal.signal(signal.SIGINT, old)


@pytest.mark.parametrize("threads", [1, 2])
def test_on_threads_raises_a_held_sigint_before_the_next_item(threads):
    done = []

    def piece(j):
        if j == 0:
            ctrl_c()
        time.sleep(0.005)  # a piece of work: the other thread cannot take every item meanwhile
        done.append(j)

    with pytest.raises(KeyboardInterrupt), held():
        on_threads(piece, 100, threads)
    # Every item taken was finished (none torn); the rest were never handed out.
    assert 0 in done and len(done) < 100
    assert sorted(done) == sorted(set(done))
