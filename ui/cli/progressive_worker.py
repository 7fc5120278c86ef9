"""What the progressive renderer's background process does (:mod:`ui.cli.progressive` is its
UI side): :class:`Job` (what to render), :class:`Engine` (renders it pass by pass, in a worker
or in the UI for ``workers=0``) and :func:`worker_main` (the process's loop).

Messages in (one control queue per worker): ``("job", gen, Job)``, ``("pause", bool)``,
``("stop",)``. Messages out (the shared results queue): ``("warming", gen, e)`` before
estimator ``e``'s kernels are compiled or loaded, ``("warmed", gen, e, wall, cpu)`` after,
``("pass", gen, e, i, seconds, image, breakdown)``, ``("breakdowns", gen, accumulators)``
and ``("idle", gen, worker)`` when the job is done, ``("error", gen, text)``. ``gen`` is the
job's generation: the UI ignores messages of a job it has replaced.

Breakdowns (``Job.breakdown``) are merged where the passes are rendered: an engine that
renders every pass (one worker, or the UI's own engine) adds each pass's two ``(T, NK, H, W,
3)`` stacks to its :class:`~psurf_core.breakdown.BreakdownAccumulator` (in pass order: equal
to a serial run) and a worker sends with each pass only what the panels show of it,
:class:`BreakdownMeans` (the two means in float32), then the exact accumulators once the job
is done. Merging them in the UI thread made its slowest frame 535-676 ms (363-466 ms of CPU)
while ``paper-multi`` was inspected on the showcase with the breakdown modes on and off; with
the merge here 89-166 ms (79-84 ms of CPU, none over 100 ms) (``xvfb-run
benchmarks/ui_frames.py --quick [--frames 300]``, 2 cores at load 5.3-5.9). With several
workers each pass's stacks are sent (float64) and the UI merges them in pass order.

Compilation is never render time: before an estimator's first pass in a process the engine
calls :func:`psurf_core.render.warm_up` (numba compiles the kernels, or loads them from its
cache) and reports those seconds apart, so the equal-time schedule and the panels' seconds
count passes only.

Priority: a worker renders its first pass at the priority it was started with (the window's
first picture waits for that pass, and a busy machine gives a process at the background
priority a few percent of a core), then steps back to :data:`ui.cli.background.WORKER_NICE`
(:class:`~ui.cli.background.Priority`) so that the window's frames come first; at the latest
after :data:`FIRST_PASS_SECONDS` (a cold cache compiles kernels for minutes). With the
inspector doing the same, the showcase's first pass (``planes,paper-multi``) came 3.9-4.1 s
after the launch instead of 4.3-4.9 s (``xvfb-run benchmarks/ui_frames.py --first-picture
5 --roots BEFORE,AFTER``, 2 cores at load 7.3-7.7; the launches at load 6.9-7.5: 5.9 s and
6.4 s).
"""

from __future__ import annotations

import queue as _queue
import time
import traceback
from dataclasses import dataclass

import numpy as np

from psurf_core.breakdown import (
    DEFAULT_K_MAX,
    BreakdownAccumulator,
    BreakdownLayout,
    render_pass_breakdown,
)
from psurf_core.estimators import parse_estimator
from psurf_core.geometry import blockers_of
from psurf_core.render import RenderSettings, render_pass, warm_up

from .background import Priority

__all__ = ["BreakdownMeans", "Engine", "Job", "ShownBreakdown", "worker_main"]

#: A worker stays at its starting priority at most this many seconds (see the module doc).
FIRST_PASS_SECONDS = 15.0


@dataclass(frozen=True)
class Job:
    """What a worker renders (picklable: sent to the worker process).

    Attributes
    ----------
    scene : Scene
        The scene object itself (it may differ from the file: the window's sliders).
    specs : tuple of str
        Estimator specs, in display order (the first is the comparison's baseline).
    settings : RenderSettings
    seed : int
    breakdown : bool
        Also render per-technique / per-K breakdowns (photon estimators only).
    k_max : int
        Breakdown scatter-count bins (see :mod:`psurf_core.breakdown`).
    max_passes : int or None
        Passes per estimator after which it stops.
    max_seconds : float or None
        Wall seconds per estimator after which it stops (equal time).
    start : tuple of int, optional
        First pass of each estimator (a restarted worker continues after the merged
        passes); default 0 for all.
    spent : tuple of float, optional
        Seconds each estimator has already rendered (the equal-time schedule continues).
    """

    scene: object
    specs: tuple
    settings: RenderSettings
    seed: int = 0
    breakdown: bool = False
    k_max: int = DEFAULT_K_MAX
    max_passes: int | None = None
    max_seconds: float | None = None
    start: tuple | None = None
    spent: tuple | None = None


@dataclass(frozen=True)
class BreakdownMeans:
    """What the panels show of a worker's breakdown after ``n`` passes: the means of its
    ``weighted`` and ``unweighted`` ``(T, NK, H, W, 3)`` stacks, float32 (see the module
    doc)."""

    n: int
    weighted: np.ndarray
    unweighted: np.ndarray

    @classmethod
    def of(cls, acc: BreakdownAccumulator) -> BreakdownMeans:
        return cls(acc.n, acc.weighted.mean.astype(np.float32),
                   acc.unweighted.mean.astype(np.float32))


class ShownBreakdown(BreakdownAccumulator):
    """A worker's breakdown as the panels show it: the means it sent
    (:class:`BreakdownMeans`), read like the accumulator they come
    from (``weighted.mean``, ``technique_images()``, ...; no variance, nothing is added
    here). Before the first pass: ``n`` 0 and zero means."""

    def __init__(self, layout: BreakdownLayout, means: BreakdownMeans | None = None):
        self.layout = layout
        if means is None:  # zeros are allocated lazily by the OS: nothing is touched
            zeros = np.zeros(layout.stack_shape, dtype=np.float32)
            means = BreakdownMeans(0, zeros, zeros)
        self.weighted = _Means(means.n, means.weighted)
        self.unweighted = _Means(means.n, means.unweighted)

    def add(self, b) -> None:
        raise TypeError("a shown breakdown is read-only: the worker merges the passes")


@dataclass
class _Means:
    n: int
    mean: np.ndarray


class Engine:
    """Renders the passes of a :class:`Job` one at a time (in a worker or in the UI).

    Worker ``first`` of ``stride`` renders passes ``start + first, start + first + stride,
    ...`` of every estimator. With ``stride`` 1 it merges the breakdowns itself
    (:attr:`breakdowns`, one accumulator per estimator or None; the module doc).
    """

    def __init__(self, job: Job, first: int = 0, stride: int = 1):
        self.job = job
        scene = job.scene
        self.ests = [parse_estimator(s, scene) for s in job.specs]
        self.blockers = blockers_of(scene)
        self.layouts = [BreakdownLayout.of(scene, e, job.k_max)
                        if job.breakdown and not e.reference else None for e in self.ests]
        self.breakdowns = [BreakdownAccumulator(lay) if lay is not None and int(stride) == 1
                           else None for lay in self.layouts]
        n = len(self.ests)
        start = job.start if job.start is not None else (0,) * n
        self.next = [int(s) + int(first) for s in start]
        self.stride = int(stride)
        self.spent = [float(s) for s in (job.spent if job.spent is not None else (0.0,) * n)]
        self.warmed = [False] * n

    def choose(self) -> int | None:
        """The estimator to render next: least time spent among those not finished."""
        j = self.job
        ok = [e for e in range(len(self.ests))
              if (j.max_passes is None or self.next[e] < j.max_passes)
              and (j.max_seconds is None or self.spent[e] < j.max_seconds)]
        return min(ok, key=lambda e: (self.spent[e], e)) if ok else None

    def warm(self, e: int) -> tuple[float, float]:
        """Compile (or load) estimator ``e``'s kernels: ``(wall, cpu)`` seconds it took (0s
        when done already; CPU seconds tell compiling, tens of seconds, from loading a
        cached kernel, about one, on a busy machine too). Not counted in :attr:`spent`."""
        if self.warmed[e]:
            return 0.0, 0.0
        t0, c0 = time.perf_counter(), time.process_time()
        warm_up(self.job.scene, self.ests[e], self.job.settings)
        self.warmed[e] = True
        return time.perf_counter() - t0, time.process_time() - c0

    def render(self, e: int):
        """Render estimator ``e``'s next pass: ``(e, pass_index, seconds, image, breakdown)``.

        ``breakdown`` is None (no breakdown), this engine's accumulator of ``e`` with the pass
        added (stride 1), or the pass's ``(unweighted, weighted)`` stacks (stride > 1). The
        seconds are the pass's, not its breakdown's merge.
        """
        j = self.job
        i = self.next[e]
        t0 = time.perf_counter()
        if self.layouts[e] is not None:
            img, b = render_pass_breakdown(j.scene, self.ests[e], i, j.seed, j.settings,
                                           blockers=self.blockers, layout=self.layouts[e])
            dt = time.perf_counter() - t0
            acc = self.breakdowns[e]
            if acc is None:
                stacks = (b.unweighted, b.weighted)
            else:
                acc.add(b)
                stacks = acc
        else:
            img = render_pass(j.scene, self.ests[e], i, j.seed, j.settings,
                              blockers=self.blockers)
            dt = time.perf_counter() - t0
            stacks = None
        self.spent[e] += dt
        self.next[e] += self.stride
        return e, i, dt, img, stacks


def worker_main(worker_id: int, n_workers: int, control, results) -> None:
    """The worker process: waits for a job, renders it, sends its passes (module docstring)."""
    engine, gen, paused = None, -1, False
    priority = Priority(FIRST_PASS_SECONDS)  # the first pass at the starting priority

    def handle(msg) -> bool:
        """Apply a control message; False to stop."""
        nonlocal engine, gen, paused
        if msg[0] == "stop":
            return False
        if msg[0] == "pause":
            paused = bool(msg[1])
        elif msg[0] == "job":
            gen = msg[1]
            try:
                engine = Engine(msg[2], worker_id, n_workers)
            except Exception as ex:  # bad job: report, wait for the next one
                engine = None
                results.put(("error", gen, f"{type(ex).__name__}: {ex}"))
        return True

    def send(out, my_gen) -> bool:
        """Put ``out`` on the bounded queue, staying responsive to stop / a new job; False
        when the worker must stop, None-like (the job changed) ends the wait too."""
        while True:
            try:
                results.put(out, timeout=0.1)
                return True
            except _queue.Full:
                try:
                    msg = control.get_nowait()
                except _queue.Empty:
                    continue
                if not handle(msg):
                    return False
                if gen != my_gen:
                    return True  # a new job: this message is stale, drop it

    idle_sent = None
    while True:
        try:  # drain control messages without waiting while there is work
            wait = engine is None or paused
            msg = control.get(timeout=0.2) if wait else control.get_nowait()
            if not handle(msg):
                return
            continue
        except _queue.Empty:
            pass
        if engine is None or paused:
            continue
        e = engine.choose()
        if e is None:
            if idle_sent != gen:
                if any(b is not None for b in engine.breakdowns):  # exact, once: module doc
                    results.put(("breakdowns", gen, engine.breakdowns))
                results.put(("idle", gen, worker_id))
                idle_sent = gen
            try:
                if not handle(control.get(timeout=0.2)):
                    return
            except _queue.Empty:
                pass
            continue
        my_gen = gen
        try:
            if not engine.warmed[e]:
                results.put(("warming", my_gen, e))
                results.put(("warmed", my_gen, e, *engine.warm(e)))
            out = ("pass", my_gen, *engine.render(e))
            if isinstance(out[-1], BreakdownAccumulator):  # what the panels show of it
                out = (*out[:-1], BreakdownMeans.of(out[-1]))
        except Exception as ex:
            priority.lower()
            results.put(("error", my_gen, f"{type(ex).__name__}: {ex}\n"
                                          f"{traceback.format_exc(limit=4)}"))
            engine = None
            continue
        priority.lower()  # before the pass is sent: the UI that has it sees a lowered worker
        if not send(out, my_gen):
            return
