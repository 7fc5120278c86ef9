"""Background worker processes for the window: spawn, talk, notice a death, restart, stop.

The window's progressive renderer (:mod:`ui.cli.progressive`) and its stage inspector
(:mod:`ui.cli.inspector`) each run their work in processes of their own so that the UI thread
never waits. :class:`Workers` is the machinery they share:

* processes come from the ``spawn`` context (safer beside VTK than ``fork``; a fresh
  interpreter per worker), as daemons, at a lower priority (:data:`WORKER_NICE`: the UI's
  frames come first on a busy machine);
* every worker gets its own control queue (messages in) and all share one bounded results
  queue (messages out; bounded so that a UI that stops reading stops the workers);
* :meth:`Workers.deaths` reports workers that exited without being asked to (killed by a
  signal, out of memory, a crash), :func:`describe_exit` words it, and :meth:`Workers.restart`
  replaces every process (the owners decide what the new ones are told, so no merged work is
  lost); :meth:`Workers.close` stops and joins them, idempotently.

A worker target is a module-level function ``target(worker_id, n_workers, control, results,
*args)`` (it must be importable by the spawned interpreter).
"""

from __future__ import annotations

import multiprocessing as mp
import queue as _queue
import signal
import time

__all__ = ["WORKER_NICE", "Workers", "describe_exit", "lower_priority"]

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


def describe_exit(exitcode: int | None) -> str:
    """How a process ended, in words (``exitcode`` as ``multiprocessing`` reports it)."""
    if exitcode is None:
        return "still running"
    if exitcode < 0:
        try:
            name = signal.Signals(-exitcode).name
        except ValueError:
            name = f"signal {-exitcode}"
        why = " (perhaps out of memory)" if -exitcode == signal.SIGKILL else ""
        return f"killed by {name}{why}"
    return f"exited with code {exitcode}"


class Workers:
    """``n`` background processes running ``target``.

    Parameters
    ----------
    target : callable
        ``target(worker_id, n_workers, control, results, *args)``, module level.
    n : int
        Number of processes (>= 1).
    name : str
        Process name prefix (``ps`` shows ``<name>-<i>``).
    queue_size : int
        Capacity of the shared results queue (back-pressure).
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
        self.results = None
        #: Wall time of every restart (:meth:`restart`), for the owners' give-up rule.
        self.restart_times: list[float] = []
        self._start()

    def _start(self) -> None:
        ctx = mp.get_context("spawn")
        self.results = ctx.Queue(maxsize=self.queue_size)
        self.procs, self.control = [], []
        for w in range(self.n):
            c = ctx.Queue()
            p = ctx.Process(target=self.target,
                            args=(w, self.n, c, self.results, *self.args), daemon=True,
                            name=f"{self.name}-{w}")
            p.start()
            self.procs.append(p)
            self.control.append(c)

    # ------------------------------------------------------------------ messages
    def send(self, msg) -> None:
        """Put ``msg`` on every worker's control queue."""
        for c in self.control:
            c.put(msg)

    def get(self):
        """One result message, or None when none is waiting (never blocks)."""
        if self.results is None:
            return None
        try:
            return self.results.get_nowait()
        except _queue.Empty:
            return None
        except (OSError, EOFError, ValueError):  # the queue broke with a dying worker
            return None

    # ------------------------------------------------------------------ health
    def deaths(self) -> list[tuple[int, int]]:
        """``(worker, exitcode)`` of every worker that is no longer running."""
        return [(i, p.exitcode) for i, p in enumerate(self.procs) if p.exitcode is not None]

    @property
    def pids(self) -> list[int]:
        return [p.pid for p in self.procs]

    def recent_restarts(self, window: float) -> int:
        """Restarts in the last ``window`` seconds."""
        now = time.monotonic()
        return sum(1 for t in self.restart_times if now - t <= window)

    def restart(self) -> None:
        """Replace every process (the survivors too: the owner sends the new ones their work
        from what it already merged). The results queue is new as well, so nothing a dead
        worker half-wrote can arrive."""
        self._stop(join=1.0)
        self.restart_times.append(time.monotonic())
        self._start()

    # ------------------------------------------------------------------ stop
    def _stop(self, join: float) -> None:
        for c in self.control:
            try:
                c.put(("stop",))
            except (OSError, ValueError):
                pass
        for p in self.procs:
            p.join(timeout=join)
            if p.is_alive():
                p.terminate()
                p.join(timeout=1.0)
        for q in [*self.control, self.results]:
            if q is not None:
                q.cancel_join_thread()  # unread messages must not hold up the exit
                q.close()
        self.procs, self.control, self.results = [], [], None

    def close(self) -> None:
        """Stop and join the processes (idempotent)."""
        if self.procs or self.results is not None:
            self._stop(join=3.0)
