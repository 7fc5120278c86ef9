"""Progressive rendering that never blocks the UI: passes render in a background process.

Usage (the window)::

    from ui.cli.progressive import Progressive
    from ui.views.image_panels import PanelView, next_mode, MODES, MODE_HELP

    prog = Progressive(scene, ["planes", "paper-multi"], RenderSettings(photons=2000),
                       seed=0, workers=1, breakdown=True)  # spawns the worker (~1 s to start)
    panels = PanelView()                                   # keeps the panel actors
    mode = "render"                                        # "techniques", "bounces"

    # every timer tick (100-200 ms): poll never waits; draw only when something arrived
    if prog.poll():
        panels.draw(plotter, [(0, 1), (0, 2)], prog, mode, pixel_xy,
                    reference=None,          # (H, W, 3) image: relMSE per estimator
                    estimator=None,          # which run techniques/bounces break down
                    technique=None, k=None)  # bounces: one technique per K, or one K
        plotter.render()                     # draw() holds rendering; render once after it
    for text in prog.take_notices(): ...     # a worker died and was restarted, kernels compiled
    # 'm': mode = next_mode(mode); panels.draw(...); plotter.render()
    # play / pause: prog.pause() / prog.resume()
    # the breakdown modes need breakdowns: prog.set_breakdown(mode != "render") (keeps passes)
    # sliders, estimator toggles, 'r': prog.reset(scene=..., estimators=[...],
    #     settings=..., seed=...)   (drops the passes; stale worker results are ignored)
    # prog.runs[i].acc (Welford), .seconds, .breakdown (its means, ShownBreakdown, while a
    #     worker renders; the exact BreakdownAccumulator when the job is done, or for
    #     workers=0 or N > 1; None without breakdowns),
    #     .note(now) ("compiling kernels (first run)...", "" once passes arrive)
    # prog.summary(reference) -> rows with "ratio" (Var at equal time) and "relmse"
    # window closed: prog.close()

``panels.draw`` rebuilds its actors by itself when the mode, the layout or the window size
changed, or when ``compose()`` cleared the subplots; otherwise it only updates pixel values,
colour ranges and texts (~3 ms; a rebuild ~15-60 ms). The tiles are ``ImageData`` with an
origin and a spacing, so ``ui.views.controls.pick_pixel`` finds the clicked pixel on any of them.
In software OpenGL (no GPU) VTK's default 4x multisampling makes every ``plotter.render()``
of the 1600 x 900 window ~200 ms instead of ~60 ms: the window may want
``plotter.ren_win.SetMultiSamples(0)`` (``benchmarks/ui_frames.py`` measures both).

``workers=0`` is the synchronous fallback (screenshots, tests, no multiprocessing): ``poll()``
then renders one pass itself (blocking) and ``run(passes=N)`` renders N passes of every
estimator.

Scheduling: the worker renders whole passes, each time for the estimator that has spent the
least wall time so far (ties: list order), so the estimators are compared at equal time (up to
one pass). Compiling an estimator's kernels (numba; a minute or more for an MIS preset on a
cold cache) happens before its first pass and is not render time: the panels say "compiling
kernels (first run)" meanwhile, and its seconds are reported apart (:attr:`EstimatorRun.
compile_seconds`). Pass ``i`` of an estimator is seeded by ``SeedSequence([seed, i])`` (as
every render), and ``poll()`` merges each estimator's passes in pass order into a
:class:`~psurf_core.accumulate.Welford`, so the accumulated images are bit-identical to
``render(..., passes=n, seed=seed)``. With ``workers=N > 1`` worker ``w`` renders passes
``w, w + N, ...`` of every estimator; out-of-order arrivals wait until their predecessors came.

A dying worker loses nothing merged: when a worker process exits unasked (killed, out of
memory, a crash) ``poll()`` restarts the workers on a job that continues after the merged
passes (and the seconds spent), so the images stay bit-identical to a serial render, and
:meth:`Progressive.take_notices` says what happened. After :data:`MAX_RESTARTS` deaths within
:data:`RESTART_WINDOW` seconds it stops restarting and reports an error instead.

The worker processes (:mod:`ui.cli.background`, ``spawn`` context, lower priority, a pipe
pair each) run :func:`ui.cli.progressive_worker.worker_main`; results come back through a
bounded buffer, so a UI that stops polling stops the worker after a few passes instead of
filling memory.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from psurf_core.accumulate import Welford
from psurf_core.breakdown import DEFAULT_K_MAX, BreakdownAccumulator, BreakdownLayout
from psurf_core.estimators import parse_estimator
from psurf_core.render import RenderSettings

from .background import Workers, describe_exit
from .equal_time import compare_rows
from .estimator_run import COMPILE_NOTE_AFTER, EstimatorRun
from .progressive_worker import BreakdownMeans, Engine, Job, ShownBreakdown, worker_main

__all__ = ["COMPILE_NOTE_AFTER", "EstimatorRun", "Job", "Progressive", "ShownBreakdown",
           "compare_rows"]

#: Results waiting in the queue per worker before it pauses (back-pressure).
QUEUE_SIZE = 6
#: Seconds ``poll`` spends at most unpacking results (keeps the UI frame short).
POLL_BUDGET = 0.03
#: Seconds ``poll`` waits, after a result, for the next one a worker is sending.
STREAM_WAIT = 0.005
#: A warm-up that took this many CPU seconds was a compilation (a busy machine stretches wall
#: time, not CPU time); see also ``estimator_run.COMPILE_NOTE_AFTER``.
COMPILE_CPU = 4.0
#: Give up restarting after this many worker deaths within :data:`RESTART_WINDOW` seconds.
MAX_RESTARTS, RESTART_WINDOW = 3, 120.0


class Progressive:
    """Progressive renders of one or more estimators at equal time, without blocking the UI.

    Parameters
    ----------
    scene : Scene
    estimators : list of str
        Estimator specs in display order (ratios are relative to the first).
    settings : RenderSettings, optional
    seed : int
    workers : int
        0: synchronous (``poll``/``run`` render in the calling thread); N >= 1: N worker
        processes.
    breakdown : bool
        Accumulate per-technique / per-K breakdowns (:mod:`psurf_core.breakdown`) too.
    k_max : int
        Breakdown scatter-count bins.
    max_passes : int, optional
        Stop each estimator after this many passes.
    max_seconds : float, optional
        Stop each estimator after this many wall seconds of rendering.

    Raises
    ------
    SceneError, UnknownTechnique
        For specs that do not parse (checked here, before any process starts).
    """

    def __init__(self, scene, estimators, settings: RenderSettings | None = None, *,
                 seed: int = 0, workers: int = 1, breakdown: bool = False,
                 k_max: int = DEFAULT_K_MAX, max_passes: int | None = None,
                 max_seconds: float | None = None):
        if int(workers) < 0:
            raise ValueError(f"workers must be >= 0, got {workers}")
        self.workers = int(workers)
        self._pool: Workers | None = None
        self._gen = 0
        self._idle: set = set()
        self.errors: list[str] = []
        self._notices: list[str] = []
        #: Worker processes restarted after a death, since this object was made.
        self.restarts = 0
        self.stopped = False  # gave up restarting
        self.paused = False
        self._start(Job(scene, tuple(estimators), settings or RenderSettings(), int(seed),
                        bool(breakdown), int(k_max), max_passes, max_seconds))

    # ------------------------------------------------------------------ set-up
    def _start(self, job: Job) -> None:
        if not job.specs:
            raise ValueError("no estimator to render")
        ests = [parse_estimator(s, job.scene) for s in job.specs]  # errors here, in the UI
        self.job = job
        cam = job.scene.camera
        self.runs = []
        for spec, est in zip(job.specs, ests, strict=True):
            self.runs.append(EstimatorRun(spec, est, Welford.empty((cam.height, cam.width, 3)),
                                          breakdown=self._new_breakdown(est)))
        self._idle = set()
        self.stopped = False
        if self.workers == 0:
            self._engine = Engine(job)
            self._use_engine_breakdowns()
            return
        if self._pool is None:
            self._pool = Workers(worker_main, self.workers, "psurf-progressive", QUEUE_SIZE)
        self._send_job(job)

    def _new_breakdown(self, est):
        """The UI's side of an estimator's breakdown for the current job (None without one):
        one worker merges it and sends its means (:class:`ShownBreakdown`); several send
        every pass's stacks, merged here; ``workers=0``: the engine's own (set after)."""
        j = self.job
        if not j.breakdown or est.reference:
            return None
        layout = BreakdownLayout.of(j.scene, est, j.k_max)
        return ShownBreakdown(layout) if self.workers <= 1 else BreakdownAccumulator(layout)

    def _use_engine_breakdowns(self) -> None:
        """``workers=0``: the runs' breakdowns are the engine's accumulators themselves."""
        for run, acc in zip(self.runs, self._engine.breakdowns, strict=True):
            if acc is not None:
                run.breakdown = acc

    def _send_job(self, job: Job) -> None:
        self._gen += 1
        self._pool.send(("job", self._gen, job))
        if self.paused:
            self._pool.send(("pause", True))

    def reset(self, scene=None, estimators=None, settings: RenderSettings | None = None,
              seed: int | None = None, **changes) -> None:
        """Start over (new scene, estimators, settings, seed, or the same ones): the
        accumulated passes are dropped; workers get the new job (stale passes are ignored).

        ``changes`` may also set ``breakdown``, ``k_max``, ``max_passes``, ``max_seconds``.
        """
        j = self.job
        job = replace(j, scene=j.scene if scene is None else scene,
                      specs=j.specs if estimators is None else tuple(estimators),
                      settings=j.settings if settings is None else settings,
                      seed=j.seed if seed is None else int(seed), start=None, spent=None,
                      **changes)
        self.errors = []
        if self._pool is not None and (self.stopped or self._pool.deaths()):
            self._pool.restart()  # 'r' after the workers gave up: fresh processes
        self._start(job)

    def set_breakdown(self, on: bool) -> None:
        """Start or stop accumulating the per-technique / per-K breakdowns, keeping every
        merged pass.

        A breakdown roughly doubles the cost of a pass (measured: 1.9x for ``planes``, 2.0x
        for ``paper-multi``), so the window asks for it only while a mode shows it. The
        workers get a job that continues after the merged passes (and the seconds spent),
        as after a restart: the images stay bit-identical to a serial render; a breakdown
        switched on counts the passes from then on (its own ``n``).
        """
        on = bool(on)
        if on == self.job.breakdown:
            return
        job = replace(self.job, breakdown=on, start=tuple(r.acc.n for r in self.runs),
                      spent=tuple(r.seconds for r in self.runs))
        self.job = job
        for run in self.runs:
            run.pending.clear()  # out of order, from the replaced job: rendered again
            run.warming_since = None
            run.breakdown = self._new_breakdown(run.estimator)
        self._idle = set()
        if self.workers == 0:
            warmed = self._engine.warmed
            self._engine = Engine(job)
            self._engine.warmed = warmed  # compiled in this process already
            self._use_engine_breakdowns()
            return
        self._send_job(job)

    def pause(self) -> None:
        """Stop rendering after the pass in flight (``resume`` continues)."""
        self.paused = True
        if self._pool is not None:
            self._pool.send(("pause", True))

    def resume(self) -> None:
        self.paused = False
        if self._pool is not None:
            self._pool.send(("pause", False))

    def close(self) -> None:
        """Stop and join the worker processes (idempotent)."""
        if self._pool is not None:
            self._pool.close()
            self._pool = None

    def __enter__(self) -> Progressive:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __del__(self):  # a forgotten close() must not leave processes behind
        try:
            self.close()
        except Exception:
            pass

    @property
    def pids(self) -> list[int]:
        """Process ids of the workers (empty for ``workers=0``)."""
        return self._pool.pids if self._pool is not None else []

    # ------------------------------------------------------------------ results
    @property
    def passes(self) -> list[int]:
        """Merged passes per estimator."""
        return [r.acc.n for r in self.runs]

    @property
    def done(self) -> bool:
        """Every estimator reached ``max_passes`` / ``max_seconds`` (never without limits),
        and with one worker its exact breakdowns arrived."""
        j = self.job
        if j.max_passes is None and j.max_seconds is None:
            return False
        if self.workers == 0:
            return self._engine.choose() is None
        if any(isinstance(r.breakdown, ShownBreakdown) for r in self.runs):
            return False  # the worker's exact accumulators follow its last pass (module doc)
        if j.max_passes is not None and all(r.acc.n >= j.max_passes for r in self.runs):
            return True
        return len(self._idle) == self.workers and not any(r.pending for r in self.runs)

    def take_notices(self) -> list[str]:
        """What happened since the last call, for the status line (a worker died and was
        restarted, an estimator's kernels were compiled); each notice is returned once."""
        out, self._notices = self._notices, []
        return out

    def _take(self, e: int, i: int, dt: float, img, stacks) -> None:
        run = self.runs[e]
        run.pending[i] = (img, dt, stacks)
        while run.acc.n in run.pending:  # merge in pass order
            img, dt, stacks = run.pending.pop(run.acc.n)
            run.acc.add(img)
            run.seconds += dt
            if stacks is None or run.breakdown is None:
                continue
            if isinstance(stacks, BreakdownMeans):  # one worker merged it (module doc)
                run.breakdown = ShownBreakdown(run.breakdown.layout, stacks)
            elif isinstance(stacks, BreakdownAccumulator):  # workers=0: the engine's own
                run.breakdown = stacks
            else:  # several workers: this pass's (unweighted, weighted) stacks
                run.breakdown.add_arrays(*stacks)

    def _warmed(self, e: int, seconds: float, cpu: float) -> None:
        run = self.runs[e]
        run.warming_since = None
        run.compile_seconds += seconds
        if cpu >= COMPILE_CPU:
            self._notices.append(f"{run.spec}: kernels compiled in {seconds:.0f} s (first "
                                 "run; not counted as render time)")
        elif seconds >= COMPILE_NOTE_AFTER:
            self._notices.append(f"{run.spec}: kernels loaded in {seconds:.0f} s (not "
                                 "counted as render time)")

    def _render_here(self, e: int) -> None:
        """``workers=0``: warm up (compile) estimator ``e`` if needed, render its next pass."""
        if not self._engine.warmed[e]:
            self._warmed(e, *self._engine.warm(e))
        self._take(*self._engine.render(e))

    def poll(self, budget: float = POLL_BUDGET) -> int:
        """Merge what arrived; never waits (``workers=0``: render one pass).

        Parameters
        ----------
        budget : float
            Seconds after which unpacking stops (the rest waits for the next poll).

        Returns
        -------
        int
            Passes received plus status changes (0: nothing new to draw).
        """
        if self.workers == 0:
            if self.paused:
                return 0
            e = self._engine.choose()
            if e is None:
                return 0
            self._render_here(e)
            return 1
        if self._pool is None:
            return 0
        got = 0
        t0 = time.perf_counter()
        while (left := budget - (time.perf_counter() - t0)) > 0:
            # After a message, wait a little for the next: a worker's outbox sends its
            # buffered results one after another, and the next is rarely there the instant
            # the last is read (returning then merged ~2 results a 200 ms tick, and the
            # worker, held back by its full buffer, rendered ~20 % of the time: docs/study.md,
            # "The window's worker waited for the UI").
            msg = self._pool.get(min(left, STREAM_WAIT) if got else 0.0)
            if msg is None:
                break
            if msg[1] != self._gen:
                continue  # from before the last reset or restart
            kind = msg[0]
            if kind == "pass":
                self._take(*msg[2:])
            elif kind == "warming":
                self.runs[msg[2]].warming_since = time.monotonic()
            elif kind == "warmed":
                self._warmed(msg[2], msg[3], msg[4])
            elif kind == "breakdowns":  # the job is done: the exact accumulators
                for run, acc in zip(self.runs, msg[2], strict=True):
                    if acc is not None and run.breakdown is not None:
                        run.breakdown = acc
            elif kind == "idle":
                self._idle.add(msg[2])
            elif kind == "error":
                self.errors.append(msg[2])
            got += 1
        if not got and not self.stopped:
            got += self._check_workers()
        return got

    def _check_workers(self) -> int:
        """Restart dead workers on the merged passes (1: something to redraw)."""
        dead = self._pool.deaths()
        if not dead:
            return 0
        how = describe_exit(dead[0][1])
        merged = sum(r.acc.n for r in self.runs)
        if self._pool.recent_restarts(RESTART_WINDOW) >= MAX_RESTARTS:
            self.stopped = True
            self.errors.append(f"the background render process keeps dying ({how}, "
                               f"{MAX_RESTARTS + 1} times in {RESTART_WINDOW:.0f} s): rendering "
                               f"stopped with the {merged} passes merged (r starts over)")
            return 1
        for run in self.runs:  # out-of-order passes died with their worker's successors
            run.pending.clear()
            run.warming_since = None
        self._pool.restart()
        self.restarts += 1
        self._idle = set()
        job = replace(self.job, start=tuple(r.acc.n for r in self.runs),
                      spent=tuple(r.seconds for r in self.runs))
        self._send_job(job)
        self._notices.append(f"the background render process died ({how}); restarted it, "
                             f"keeping the {merged} passes already merged")
        return 1

    def run(self, passes: int | None = None, timeout: float = 600.0) -> None:
        """Block until every estimator has ``passes`` merged passes (default: until
        :attr:`done`). For scripts and tests; the window calls :meth:`poll` instead.

        Raises
        ------
        RuntimeError
            A worker reported an error, or ``timeout`` seconds passed.
        """
        t0 = time.perf_counter()

        def finished() -> bool:
            if passes is not None:
                return all(r.acc.n >= passes for r in self.runs)
            return self.done

        while not finished():
            if self.workers == 0:
                e = self._engine.choose() if passes is None else \
                    min((k for k, r in enumerate(self.runs) if r.acc.n < passes),
                        key=lambda k: (self._engine.spent[k], k))
                if e is None:
                    break
                self._render_here(e)
            elif not self.poll(budget=1.0):
                time.sleep(0.01)
            if self.errors:
                raise RuntimeError(f"progressive worker failed: {self.errors[0]}")
            if time.perf_counter() - t0 > timeout:
                raise RuntimeError(f"progressive render: no result after {timeout:g} s")

    # ------------------------------------------------------------------ comparisons
    def summary(self, reference: np.ndarray | None = None) -> list[dict]:
        """One row per estimator (see :func:`compare_rows`)."""
        return compare_rows(self.runs, reference)
