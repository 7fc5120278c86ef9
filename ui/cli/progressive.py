"""Progressive rendering that never blocks the UI: passes render in a background process.

Usage (the window)::

    from ui.cli.progressive import Progressive
    from ui.views.image_panels import PanelView, next_mode, MODES, MODE_HELP

    prog = Progressive(scene, ["planes", "paper-multi"], RenderSettings(photons=2000),
                       seed=0, workers=1, breakdown=True)  # spawns the worker (~1 s to start)
    panels = PanelView()                                   # keeps the panel actors
    mode = "render"                                        # "techniques", "bounces"

    # every timer tick (100-200 ms): poll never waits; draw only when passes arrived
    if prog.poll():
        panels.draw(plotter, [(0, 1), (0, 2)], prog, mode, pixel_xy,
                    reference=None,          # (H, W, 3) image: relMSE per estimator
                    estimator=None,          # which run techniques/bounces break down
                    technique=None, k=None)  # bounces: one technique per K, or one K
        plotter.render()                     # draw() holds rendering; render once after it
    # 'm': mode = next_mode(mode); panels.draw(...); plotter.render()
    # play / pause: prog.pause() / prog.resume()
    # sliders, estimator toggles, new pixel pass, 'r': prog.reset(scene=..., estimators=[...],
    #     settings=..., seed=...)   (drops the passes; stale worker results are ignored)
    # prog.runs[i].acc (Welford), .seconds, .breakdown (BreakdownAccumulator or None);
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
one pass). Pass ``i`` of an estimator is seeded by ``SeedSequence([seed, i])`` (as every
render), and ``poll()`` merges each estimator's passes in pass order into a
:class:`~psurf_core.accumulate.Welford`, so the accumulated images are bit-identical to
``render(..., passes=n, seed=seed)``. With ``workers=N > 1`` worker ``w`` renders passes
``w, w + N, ...`` of every estimator; out-of-order arrivals wait until their predecessors came.

The worker is a separate process (``multiprocessing`` ``spawn`` context: safer beside VTK than
``fork``, and it uses the second core). Results come back through a bounded queue, so a UI that
stops polling stops the worker after a few passes instead of filling memory.
"""

from __future__ import annotations

import multiprocessing as mp
import queue as _queue
import time
import traceback
from dataclasses import dataclass, field

import numpy as np

from psurf_core.accumulate import Welford
from psurf_core.breakdown import (
    DEFAULT_K_MAX,
    BreakdownAccumulator,
    BreakdownLayout,
    render_pass_breakdown,
)
from psurf_core.estimators import parse_estimator
from psurf_core.geometry import blockers_of
from psurf_core.render import RenderSettings, render_pass

__all__ = ["EstimatorRun", "Progressive", "Job"]

#: Results waiting in the queue before the worker pauses (back-pressure).
QUEUE_SIZE = 6
#: Seconds ``poll`` spends at most unpacking results (keeps the UI frame short).
POLL_BUDGET = 0.03
#: Niceness added to worker processes: on a busy machine the UI's frames (software OpenGL
#: wants every core) come before background passes.
WORKER_NICE = 10


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
        Also send per-technique / per-K breakdown stacks (photon estimators only).
    k_max : int
        Breakdown scatter-count bins (see :mod:`psurf_core.breakdown`).
    max_passes : int or None
        Passes per estimator after which it stops.
    max_seconds : float or None
        Wall seconds per estimator after which it stops (equal time).
    """

    scene: object
    specs: tuple
    settings: RenderSettings
    seed: int = 0
    breakdown: bool = False
    k_max: int = DEFAULT_K_MAX
    max_passes: int | None = None
    max_seconds: float | None = None


@dataclass
class EstimatorRun:
    """The UI side of one estimator: its accumulated passes.

    Attributes
    ----------
    spec : str
    estimator : Estimator
    acc : Welford
        (H, W, 3) mean and per-pass variance over the merged passes.
    seconds : float
        Wall seconds the worker(s) spent on the merged passes.
    breakdown : BreakdownAccumulator or None
        When breakdowns were asked for and the estimator has techniques.
    """

    spec: str
    estimator: object
    acc: Welford
    seconds: float = 0.0
    breakdown: BreakdownAccumulator | None = None
    pending: dict = field(default_factory=dict)  # pass index -> (image, seconds, stacks)

    @property
    def passes(self) -> int:
        return self.acc.n

    @property
    def label(self) -> str:
        return self.spec


class _Engine:
    """Renders the passes of a :class:`Job` one at a time (in a worker or in the UI)."""

    def __init__(self, job: Job, first: int = 0, stride: int = 1):
        self.job = job
        scene = job.scene
        self.ests = [parse_estimator(s, scene) for s in job.specs]
        self.blockers = blockers_of(scene)
        self.layouts = [BreakdownLayout.of(scene, e, job.k_max)
                        if job.breakdown and not e.reference else None for e in self.ests]
        self.next = [int(first)] * len(self.ests)
        self.stride = int(stride)
        self.spent = [0.0] * len(self.ests)

    def choose(self) -> int | None:
        """The estimator to render next: least time spent among those not finished."""
        j = self.job
        ok = [e for e in range(len(self.ests))
              if (j.max_passes is None or self.next[e] < j.max_passes)
              and (j.max_seconds is None or self.spent[e] < j.max_seconds)]
        return min(ok, key=lambda e: (self.spent[e], e)) if ok else None

    def render(self, e: int):
        """Render estimator ``e``'s next pass: ``(e, pass_index, seconds, image, stacks)``."""
        j = self.job
        i = self.next[e]
        t0 = time.perf_counter()
        if self.layouts[e] is not None:
            img, b = render_pass_breakdown(j.scene, self.ests[e], i, j.seed, j.settings,
                                           blockers=self.blockers, layout=self.layouts[e])
            stacks = (b.unweighted, b.weighted)
        else:
            img = render_pass(j.scene, self.ests[e], i, j.seed, j.settings,
                              blockers=self.blockers)
            stacks = None
        dt = time.perf_counter() - t0
        self.spent[e] += dt
        self.next[e] += self.stride
        return e, i, dt, img, stacks


def _worker_main(worker_id: int, n_workers: int, control, results) -> None:
    """Worker process: waits for ``("job", gen, Job)``, renders, sends ``("pass", gen, ...)``.

    Messages in: ``("job", gen, job)``, ``("pause", bool)``, ``("stop",)``. Out: ``("pass",
    gen, e, i, seconds, image, stacks)``, ``("idle", gen, worker_id)`` when the job is done,
    ``("error", gen, text)``.
    """
    engine, gen, paused = None, -1, False
    try:
        import os

        os.nice(WORKER_NICE)
    except (AttributeError, OSError):  # not POSIX, or not allowed: run at normal priority
        pass

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
                engine = _Engine(msg[2], worker_id, n_workers)
            except Exception as ex:  # bad job: report, wait for the next one
                engine = None
                results.put(("error", gen, f"{type(ex).__name__}: {ex}"))
        return True

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
            out = ("pass", my_gen, *engine.render(e))
        except Exception as ex:
            results.put(("error", my_gen, f"{type(ex).__name__}: {ex}\n"
                                          f"{traceback.format_exc(limit=4)}"))
            engine = None
            continue
        # Bounded queue: wait for the UI, but stay responsive to stop / a new job.
        while True:
            try:
                results.put(out, timeout=0.1)
                break
            except _queue.Full:
                try:
                    msg = control.get_nowait()
                except _queue.Empty:
                    continue
                if not handle(msg):
                    return
                if gen != my_gen:
                    break  # a new job: this pass is stale, drop it


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
        self._procs: list = []
        self._control: list = []
        self._results = None
        self._gen = 0
        self._idle: set = set()
        self.errors: list[str] = []
        self._dead_reported = False
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
            b = None
            if job.breakdown and not est.reference:
                b = BreakdownAccumulator(BreakdownLayout.of(job.scene, est, job.k_max))
            self.runs.append(EstimatorRun(spec, est, Welford.empty((cam.height, cam.width, 3)),
                                          breakdown=b))
        self._idle = set()
        if self.workers == 0:
            self._engine = _Engine(job)
            return
        if not self._procs:
            ctx = mp.get_context("spawn")
            self._results = ctx.Queue(maxsize=QUEUE_SIZE * self.workers)
            for w in range(self.workers):
                c = ctx.Queue()
                p = ctx.Process(target=_worker_main, args=(w, self.workers, c, self._results),
                                daemon=True, name=f"psurf-progressive-{w}")
                p.start()
                self._procs.append(p)
                self._control.append(c)
        self._gen += 1
        for c in self._control:
            c.put(("job", self._gen, job))
            if self.paused:
                c.put(("pause", True))

    def reset(self, scene=None, estimators=None, settings: RenderSettings | None = None,
              seed: int | None = None, **changes) -> None:
        """Start over (new scene, estimators, settings, seed, or the same ones): the
        accumulated passes are dropped; workers get the new job (stale passes are ignored).

        ``changes`` may also set ``breakdown``, ``k_max``, ``max_passes``, ``max_seconds``.
        """
        j = self.job
        from dataclasses import replace

        job = replace(j, scene=j.scene if scene is None else scene,
                      specs=j.specs if estimators is None else tuple(estimators),
                      settings=j.settings if settings is None else settings,
                      seed=j.seed if seed is None else int(seed), **changes)
        self.errors = []
        self._start(job)

    def pause(self) -> None:
        """Stop rendering after the pass in flight (``resume`` continues)."""
        self.paused = True
        for c in self._control:
            c.put(("pause", True))

    def resume(self) -> None:
        self.paused = False
        for c in self._control:
            c.put(("pause", False))

    def close(self) -> None:
        """Stop and join the worker processes (idempotent)."""
        for c in self._control:
            try:
                c.put(("stop",))
            except (OSError, ValueError):
                pass
        for p in self._procs:
            p.join(timeout=3.0)
            if p.is_alive():
                p.terminate()
                p.join(timeout=1.0)
        for q in [*self._control, self._results]:
            if q is not None:
                q.cancel_join_thread()  # unread results must not hold up the exit
                q.close()
        self._procs, self._control, self._results = [], [], None

    def __enter__(self) -> Progressive:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __del__(self):  # a forgotten close() must not leave processes behind
        try:
            self.close()
        except Exception:
            pass

    # ------------------------------------------------------------------ results
    @property
    def passes(self) -> list[int]:
        """Merged passes per estimator."""
        return [r.acc.n for r in self.runs]

    @property
    def done(self) -> bool:
        """Every estimator reached ``max_passes`` / ``max_seconds`` (never without limits)."""
        j = self.job
        if j.max_passes is None and j.max_seconds is None:
            return False
        if self.workers == 0:
            return self._engine.choose() is None
        if j.max_passes is not None and all(r.acc.n >= j.max_passes for r in self.runs):
            return True
        return len(self._idle) == self.workers and not any(r.pending for r in self.runs)

    def _take(self, e: int, i: int, dt: float, img, stacks) -> None:
        run = self.runs[e]
        run.pending[i] = (img, dt, stacks)
        while run.acc.n in run.pending:  # merge in pass order
            img, dt, stacks = run.pending.pop(run.acc.n)
            run.acc.add(img)
            run.seconds += dt
            if stacks is not None and run.breakdown is not None:
                run.breakdown.add_arrays(*stacks)

    def poll(self, budget: float = POLL_BUDGET) -> int:
        """Merge the passes that arrived; never waits (``workers=0``: render one pass).

        Parameters
        ----------
        budget : float
            Seconds after which unpacking stops (the rest waits for the next poll).

        Returns
        -------
        int
            Passes received (0: nothing new to draw).
        """
        if self.workers == 0:
            if self.paused:
                return 0
            e = self._engine.choose()
            if e is None:
                return 0
            self._take(*self._engine.render(e))
            return 1
        got = 0
        t0 = time.perf_counter()
        while time.perf_counter() - t0 < budget:
            try:
                msg = self._results.get_nowait()
            except _queue.Empty:
                break
            if msg[1] != self._gen:
                continue  # from before the last reset
            if msg[0] == "pass":
                self._take(*msg[2:])
                got += 1
            elif msg[0] == "idle":
                self._idle.add(msg[2])
            elif msg[0] == "error":
                self.errors.append(msg[2])
        if not got and not self._dead_reported and any(p.exitcode is not None
                                                        for p in self._procs):
            self._dead_reported = True  # killed (out of memory, a signal): say so once
            self.errors.append("a progressive worker process exited unexpectedly")
        return got

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
                self._take(*self._engine.render(e))
            else:
                if not self.poll(budget=1.0):
                    time.sleep(0.01)
                if any(not p.is_alive() for p in self._procs):
                    raise RuntimeError("a progressive worker process died")
            if self.errors:
                raise RuntimeError(f"progressive worker failed: {self.errors[0]}")
            if time.perf_counter() - t0 > timeout:
                raise RuntimeError(f"progressive render: no result after {timeout:g} s")

    # ------------------------------------------------------------------ comparisons
    def summary(self, reference: np.ndarray | None = None) -> list[dict]:
        """One row per estimator (see :func:`compare_rows`)."""
        return compare_rows(self.runs, reference)


def compare_rows(runs, reference: np.ndarray | None = None) -> list[dict]:
    """The equal-time comparison numbers shown above the panels.

    Parameters
    ----------
    runs : list of EstimatorRun (or objects with ``label``, ``acc``, ``seconds``)
    reference : (H, W, 3) ndarray, optional
        Ground truth for relMSE (``psurf_core.study.relmse``).

    Returns
    -------
    list of dict
        ``label``, ``passes``, ``seconds``, ``mean_variance`` (``mean(var / passes)``, the
        variance of the current mean image; None below two passes), ``ratio``
        (``mean_variance * seconds`` over the first estimator's: the variance ratio at equal
        time, corrected for the last pass's overshoot; at equal passes (``mean_variance *
        passes``) when some run reports 0 seconds; None when undefined), ``equal``
        (``'time'`` or ``'passes'``), ``relmse``.
    """
    from psurf_core.study import relmse

    rows = []
    for r in runs:
        n = r.acc.n
        mv = float(np.mean(r.acc.variance) / n) if n >= 2 else None
        rows.append({
            "label": r.label, "passes": n, "seconds": float(r.seconds), "mean_variance": mv,
            "relmse": (relmse(r.acc.mean, reference) if reference is not None and n else None),
        })
    base = rows[0] if rows else None
    # Untimed runs (screenshots: fixed passes, every second reported as 0 so the picture is
    # deterministic) are compared at equal passes instead of at equal time.
    timed = all(row["seconds"] > 0 for row in rows)
    for row in rows:
        ok = (base is not None and row["mean_variance"] is not None
              and bool(base["mean_variance"]))
        if not ok:
            row["ratio"] = None
        elif timed:
            row["ratio"] = (row["mean_variance"] * row["seconds"]
                            / (base["mean_variance"] * base["seconds"]))
        else:
            row["ratio"] = row["mean_variance"] * row["passes"] / (
                base["mean_variance"] * base["passes"])
        row["equal"] = "time" if timed else "passes"
    return rows
