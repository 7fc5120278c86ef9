"""The window's stage inspections, off the UI thread: one pixel of one pass replayed
(:func:`psurf_core.inspect.inspect_pixel`) and the coverage of one primitive
(:func:`psurf_core.inspect.primitive_pixels`) computed in a background process.

Usage (the window)::

    from ui.cli.inspector import Inspector, PixelRequest, CoverageRequest

    insp = Inspector(workers=1)                  # 0: compute in submit() (screenshots, tests)
    insp.submit(PixelRequest(scene, "paper-multi", seed, pass_index, (x, y), settings))
    # every timer tick: never waits
    for res in insp.poll():                      # Result(kind, ticket, value, error)
        if res.kind == "pixel": state.inspection = res.value ...
    insp.busy("pixel")                           # seconds the newest request has waited, or None
    insp.close()

Only the newest request of each kind matters (moving the pixel three times quickly asks for
three inspections; the worker skips the two it has not started, and :meth:`Inspector.poll`
drops any answer to a request that has been replaced), so the window shows "computing..."
and stays responsive however long an inspection takes (an MIS set on a cold numba cache
compiles its kernels first). A worker that dies is restarted and asked again
(:meth:`Inspector.take_notices` says so).

Both requests are plain picklable records; the worker parses the estimator spec against the
scene it was sent (an :class:`~psurf_core.inspect.PixelInspection` comes back whole: rays,
photon paths, primitives, hits and the hit table).
"""

from __future__ import annotations

import queue as _queue
import time
import traceback
from dataclasses import dataclass

from psurf_core.render import RenderSettings

from .background import Priority, Workers, describe_exit

__all__ = ["CoverageRequest", "Inspector", "PixelRequest", "Result", "compute"]

#: A request waiting longer than this is probably compiling kernels (first run).
SLOW_AFTER = 3.0
#: The worker stays at its starting priority at most this many seconds (its first answer).
FIRST_ANSWER_SECONDS = 15.0


@dataclass(frozen=True)
class PixelRequest:
    """Replay pass ``pass_index`` for pixel ``pixel_xy`` (``inspect_pixel``'s arguments)."""

    scene: object
    spec: str
    seed: int
    pass_index: int
    pixel_xy: tuple
    settings: RenderSettings
    kind = "pixel"


@dataclass(frozen=True)
class CoverageRequest:
    """The pixels primitive ``prim`` (batch ``batch``) of ``technique`` reaches in the pass
    (``primitive_pixels``'s arguments)."""

    scene: object
    spec: str
    seed: int
    pass_index: int
    technique: str
    prim: int
    batch: int
    settings: RenderSettings
    kind = "coverage"


@dataclass(frozen=True)
class Result:
    """An answer: ``value`` (a ``PixelInspection`` or an (H, W) bool mask), or ``error``
    (one line) when the computation failed."""

    kind: str
    ticket: int
    value: object = None
    error: str | None = None
    seconds: float = 0.0


def compute(request):
    """Run one request here (what the worker does; ``workers=0`` calls it directly)."""
    from psurf_core.estimators import parse_estimator
    from psurf_core.inspect import inspect_pixel, primitive_pixels

    est = parse_estimator(request.spec, request.scene)
    if request.kind == "pixel":
        return inspect_pixel(request.scene, est, request.seed, request.pass_index,
                             request.pixel_xy, request.settings)
    return primitive_pixels(request.scene, est, request.seed, request.pass_index,
                            request.technique, request.prim, request.settings,
                            batch=request.batch)


def _answer(kind: str, ticket: int, request) -> Result:
    t0 = time.perf_counter()
    try:
        value = compute(request)
    except Exception as ex:  # reported to the window as one line, never raised there
        last = traceback.format_exception_only(type(ex), ex)[-1].strip()
        return Result(kind, ticket, error=last, seconds=time.perf_counter() - t0)
    return Result(kind, ticket, value, seconds=time.perf_counter() - t0)


def worker_main(worker_id: int, n_workers: int, control, results) -> None:
    """The inspector process: answers the newest request of each kind, in arrival order.
    Its first answer (the stage the window opens on) at the priority it was started with,
    the rest at the background's (:class:`~ui.cli.background.Priority`)."""
    priority = Priority(FIRST_ANSWER_SECONDS)
    waiting: dict = {}  # kind -> (ticket, request), newest only
    while True:
        try:
            msg = control.get(timeout=0.2) if not waiting else control.get_nowait()
        except _queue.Empty:
            msg = None
        if msg is not None:
            if msg[0] == "stop":
                return
            _, ticket, request = msg
            waiting.pop(request.kind, None)
            waiting[request.kind] = (ticket, request)
            continue  # take every message already queued before computing
        if not waiting:
            continue
        kind = next(iter(waiting))
        ticket, request = waiting.pop(kind)
        answer = _answer(kind, ticket, request)
        priority.lower()
        results.put(answer)


class Inspector:
    """Stage inspections in ``workers`` background processes (0 or 1).

    Parameters
    ----------
    workers : int
        1: one background process; 0: :meth:`submit` computes at once (deterministic, for
        screenshots and tests), :meth:`poll` hands the answers out.
    """

    def __init__(self, workers: int = 1):
        if int(workers) not in (0, 1):
            raise ValueError(f"the inspector runs in 0 or 1 processes, got {workers}")
        self.workers = int(workers)
        self._pool = (Workers(worker_main, 1, "psurf-inspector", queue_size=4)
                      if self.workers else None)
        self._ticket = 0
        self._pending: dict = {}  # kind -> (ticket, request, submitted at)
        self._ready: list = []
        self._notices: list[str] = []
        #: Inspector processes restarted after a death.
        self.restarts = 0

    def submit(self, request) -> int:
        """Ask for ``request`` (:class:`PixelRequest` or :class:`CoverageRequest`); replaces
        any unanswered request of its kind. Returns the ticket its :class:`Result` carries."""
        self._ticket += 1
        t = self._ticket
        if self._pool is None:
            self._pending.pop(request.kind, None)
            self._ready = [r for r in self._ready if r.kind != request.kind]
            self._ready.append(_answer(request.kind, t, request))
            return t
        self._pending[request.kind] = (t, request, time.monotonic())
        self._pool.send(("request", t, request))
        return t

    def cancel(self, kind: str) -> None:
        """Forget the unanswered request of ``kind`` (its answer will be dropped)."""
        self._pending.pop(kind, None)
        self._ready = [r for r in self._ready if r.kind != kind]

    def busy(self, kind: str) -> float | None:
        """Seconds the unanswered request of ``kind`` has waited, or None."""
        p = self._pending.get(kind)
        return None if p is None else time.monotonic() - p[2]

    def poll(self, budget: float = 0.03) -> list[Result]:
        """The answers that arrived to the newest requests (never waits)."""
        out, self._ready = self._ready, []
        if self._pool is None:
            return out
        t0 = time.perf_counter()
        while time.perf_counter() - t0 < budget:
            res = self._pool.get()
            if res is None:
                break
            p = self._pending.get(res.kind)
            if p is None or p[0] != res.ticket:
                continue  # answer to a replaced request
            del self._pending[res.kind]
            out.append(res)
        if not out and self._pending:
            self._check_worker()
        return out

    def _check_worker(self) -> None:
        dead = self._pool.deaths()
        if not dead:
            return
        how = describe_exit(dead[0][1])
        self._pool.restart()
        self.restarts += 1
        for ticket, request, _ in self._pending.values():
            self._pool.send(("request", ticket, request))
        self._notices.append(f"the inspector process died ({how}); restarted it and asked "
                             "again")

    def take_notices(self) -> list[str]:
        """What happened since the last call (a restarted worker); each notice once."""
        out, self._notices = self._notices, []
        return out

    @property
    def pids(self) -> list[int]:
        return self._pool.pids if self._pool is not None else []

    def close(self) -> None:
        """Stop the worker process (idempotent)."""
        if self._pool is not None:
            self._pool.close()
            self._pool = None

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass
