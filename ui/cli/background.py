"""Background worker processes for the window: spawn, talk, notice a death, restart, stop.

The window's progressive renderer (:mod:`ui.cli.progressive`) and its stage inspector
(:mod:`ui.cli.inspector`) each run their work in processes of their own so that the UI thread
never waits. :class:`Workers` is the machinery they share:

* processes come from the ``spawn`` context (safer beside VTK than ``fork``; a fresh
  interpreter per worker), as daemons, at a lower priority (:data:`WORKER_NICE`: the UI's
  frames come first on a busy machine);
* every worker has two pipes of its own, control in and results out. The UI keeps only its
  own ends (it closes its copies of the worker's), so a worker killed in the middle of
  sending a message leaves a pipe that reads as closed (``EOFError``), never one that blocks
  the UI forever waiting for the rest of the message (what one shared
  ``multiprocessing.Queue`` does);
* in the worker, :class:`Outbox` sends from a thread with a bounded buffer (back-pressure:
  a UI that stops reading stops the worker after a few messages) and :class:`Inbox` reads
  with a timeout, like a queue;
* :meth:`Workers.deaths` reports workers that exited (or broke their pipe) without being
  asked to (killed by a signal, out of memory, a crash), :func:`describe_exit` words it, and
  :meth:`Workers.restart` replaces every process (the owners decide what the new ones are
  told, so no merged work is lost); :meth:`Workers.close` stops and joins them, idempotently.

A worker target is a module-level function ``target(worker_id, n_workers, inbox, outbox,
*args)`` (importable by the spawned interpreter); it should call :func:`lower_priority`, or
make a :class:`Priority` and lower it after its first result (what the window waits for).
"""

from __future__ import annotations

import multiprocessing as mp
import queue as _queue
import signal
import threading
import time
from multiprocessing.connection import wait as _wait_any

__all__ = ["WORKER_NICE", "Inbox", "Outbox", "Priority", "Workers", "describe_exit",
           "lower_priority"]

#: Niceness added to worker processes: on a busy machine the UI's frames (software OpenGL
#: wants every core) come before background work.
WORKER_NICE = 10


def lower_priority() -> None:
    """Called first in a worker: lower its priority (:data:`WORKER_NICE`) where allowed."""
    try:
        import os

        os.nice(WORKER_NICE)
    except (AttributeError, OSError):  # not POSIX, or not allowed: normal priority
        pass


class Priority:
    """Lowers this process's priority by :data:`WORKER_NICE` once: :meth:`lower` (a worker
    calls it after its first result: the window's first picture waits for that one), or a
    timer after ``seconds``, whichever comes first.

    On Linux a niceness belongs to a thread (``os.nice`` changes the caller's only, and threads
    started before keep theirs), so every thread of the process is lowered, the timer's
    included; elsewhere ``os.nice`` lowers the process.
    """

    def __init__(self, seconds: float):
        self._lock = threading.Lock()
        self.lowered = False
        self._timer = threading.Timer(float(seconds), self.lower)
        self._timer.daemon = True
        self._timer.start()

    def lower(self) -> None:
        import os

        with self._lock:
            if self.lowered:
                return
            self.lowered = True
        self._timer.cancel()
        try:
            tasks = os.listdir("/proc/self/task")
        except OSError:  # not Linux: os.nice lowers the whole process
            lower_priority()
            return
        try:
            target = min(os.getpriority(os.PRIO_PROCESS, os.getpid()) + WORKER_NICE, 19)
            for tid in tasks:
                try:
                    os.setpriority(os.PRIO_PROCESS, int(tid), target)
                except (OSError, ValueError):  # a thread that has just ended
                    pass
        except (AttributeError, OSError):  # no getpriority, or not allowed: as it is
            pass


def describe_exit(exitcode: int | None) -> str:
    """How a process ended, in words (``exitcode`` as ``multiprocessing`` reports it)."""
    if exitcode is None:
        return "its pipe broke"
    if exitcode < 0:
        try:
            name = signal.Signals(-exitcode).name
        except ValueError:
            name = f"signal {-exitcode}"
        why = " (perhaps out of memory)" if -exitcode == signal.SIGKILL else ""
        return f"killed by {name}{why}"
    return f"exited with code {exitcode}"


# --------------------------------------------------------------------------- worker side
class Inbox:
    """The worker's control pipe, read like a queue (``get(timeout)``, ``get_nowait()``,
    both raising ``queue.Empty``); a closed pipe reads as ``("stop",)``."""

    def __init__(self, conn):
        self.conn = conn

    def get(self, timeout: float | None = None):
        try:
            if not self.conn.poll(timeout):
                raise _queue.Empty
            return self.conn.recv()
        except (EOFError, OSError):  # the UI is gone: stop
            return ("stop",)

    def get_nowait(self):
        return self.get(0.0)


class Outbox:
    """The worker's results pipe: ``put(msg, timeout=None)`` hands ``msg`` to a sending
    thread through a buffer of ``maxsize`` (``queue.Full`` after ``timeout``)."""

    def __init__(self, conn, maxsize: int):
        self.conn = conn
        self.buffer: _queue.Queue = _queue.Queue(maxsize=max(int(maxsize), 1))
        self.thread = threading.Thread(target=self._send, daemon=True, name="outbox")
        self.thread.start()

    def _send(self) -> None:
        while True:
            msg = self.buffer.get()
            try:
                self.conn.send(msg)
            except (OSError, ValueError):  # the UI closed its end: nothing more to say
                return

    def put(self, msg, timeout: float | None = None) -> None:
        self.buffer.put(msg, timeout=timeout)


def _run_worker(target, worker_id, n, control, results, queue_size, args):
    """The spawned process's entry: wrap the pipes, run the target."""
    target(worker_id, n, Inbox(control), Outbox(results, queue_size), *args)


# --------------------------------------------------------------------------- UI side
class Workers:
    """``n`` background processes running ``target``.

    Parameters
    ----------
    target : callable
        ``target(worker_id, n_workers, inbox, outbox, *args)``, module level.
    n : int
        Number of processes (>= 1).
    name : str
        Process name prefix (``ps`` shows ``<name>-<i>``).
    queue_size : int
        Messages a worker buffers before it waits for the UI (back-pressure).
    args : tuple
        Extra arguments of ``target`` (picklable).
    """

    def __init__(self, target, n: int, name: str, queue_size: int, args: tuple = ()):
        if int(n) < 1:
            raise ValueError(f"need at least one worker process, got {n}")
        self.target, self.n, self.name = target, int(n), str(name)
        self.queue_size, self.args = int(queue_size), tuple(args)
        self.procs: list = []
        self.control: list = []
        self.results: list = []
        self._broken: set = set()
        self._next = 0
        #: Wall time of every restart (:meth:`restart`), for the owners' give-up rule.
        self.restart_times: list[float] = []
        self._start()

    def _start(self) -> None:
        ctx = mp.get_context("spawn")
        self.procs, self.control, self.results, self._broken = [], [], [], set()
        for w in range(self.n):
            c_read, c_write = ctx.Pipe(duplex=False)
            r_read, r_write = ctx.Pipe(duplex=False)
            p = ctx.Process(target=_run_worker,
                            args=(self.target, w, self.n, c_read, r_write, self.queue_size,
                                  self.args),
                            daemon=True, name=f"{self.name}-{w}")
            p.start()
            # The child has its own copies now: without ours, a child that dies leaves
            # pipes that read as closed.
            c_read.close()
            r_write.close()
            self.procs.append(p)
            self.control.append(c_write)
            self.results.append(r_read)

    # ------------------------------------------------------------------ messages
    def send(self, msg) -> None:
        """Send ``msg`` to every worker (a dead worker's pipe is skipped)."""
        for i, c in enumerate(self.control):
            try:
                c.send(msg)
            except (OSError, ValueError):
                self._broken.add(i)

    def get(self, timeout: float = 0.0):
        """One result message from any worker, or None when none is waiting, after waiting
        up to ``timeout`` seconds for one to begin (a message that has begun arriving is read
        whole; a worker that dies meanwhile ends it as a broken pipe, reported by
        :meth:`deaths`)."""
        msg = self._get_ready()
        if msg is None and timeout > 0:
            live = [c for i, c in enumerate(self.results) if i not in self._broken]
            if live and _wait_any(live, timeout):
                msg = self._get_ready()
        return msg

    def _get_ready(self):
        n = len(self.results)
        for k in range(n):
            i = (self._next + k) % n
            if i in self._broken:
                continue
            conn = self.results[i]
            try:
                if not conn.poll(0):
                    continue
                msg = conn.recv()
            except (EOFError, OSError, ValueError):
                self._broken.add(i)
                continue
            self._next = (i + 1) % n
            return msg
        return None

    # ------------------------------------------------------------------ health
    def deaths(self) -> list[tuple[int, int | None]]:
        """``(worker, exitcode)`` of every worker that exited or broke its pipe
        (``exitcode`` None: still running, but its pipe is closed)."""
        for i in self._broken:  # a broken pipe: the process is dying, learn how
            if self.procs[i].exitcode is None:
                self.procs[i].join(timeout=0.5)
        return [(i, p.exitcode) for i, p in enumerate(self.procs)
                if p.exitcode is not None or i in self._broken]

    @property
    def pids(self) -> list[int]:
        return [p.pid for p in self.procs]

    def recent_restarts(self, window: float) -> int:
        """Restarts in the last ``window`` seconds."""
        now = time.monotonic()
        return sum(1 for t in self.restart_times if now - t <= window)

    def restart(self) -> None:
        """Replace every process (the survivors too: the owner sends the new ones their work
        from what it already merged). The pipes are new as well, so nothing a dead worker
        half-wrote can arrive."""
        self._stop(join=1.0)
        self.restart_times.append(time.monotonic())
        self._start()

    # ------------------------------------------------------------------ stop
    def _stop(self, join: float) -> None:
        self.send(("stop",))
        for conn in self.control:
            conn.close()  # a worker blocked on its inbox reads "stop"
        for conn in self.results:
            conn.close()  # ... and one blocked sending a result gets a broken pipe
        deadline = time.monotonic() + join
        for p in self.procs:
            p.join(timeout=max(deadline - time.monotonic(), 0.05))
            if p.is_alive():
                p.terminate()
                p.join(timeout=1.0)
        self.procs, self.control, self.results = [], [], []

    def close(self) -> None:
        """Stop and join the processes (idempotent)."""
        if self.procs:
            self._stop(join=3.0)
