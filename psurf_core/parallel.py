"""Passes in local worker processes, merged in pass order: the same image as one process.

numpy's elementwise work runs on one core, and passes are independent (pass ``i`` draws all
its randomness from ``SeedSequence([seed, i])``), so the simplest way to use several cores
is to run whole passes in worker processes. :func:`render_parallel` keeps at most
``2 x jobs`` passes in flight in a :class:`concurrent.futures.ProcessPoolExecutor` and adds
the finished pass images to one :class:`~psurf_core.accumulate.Welford` **in pass order**
(``acc.add``), so ``mean`` and ``var`` are bit-identical to :func:`psurf_core.render.render`
with the same seed, settings and pass count, whichever worker ran which pass and whenever it
finished. It is the local, dependency-free sibling of :mod:`psurf_core.distributed` (Dask).

Workers are started with ``spawn`` (no state inherited from a parent that may hold GUI or
numba threads) and ignore SIGINT: Ctrl-C reaches the parent only, which cancels what is
queued and re-raises.
"""

from __future__ import annotations

import multiprocessing
import signal
import time
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, Executor, ProcessPoolExecutor, wait

import numpy as np

from .accumulate import Welford
from .estimators import Estimator, parse_estimator
from .render import RenderResult, RenderSettings, render_pass, warm_up
from .scene import Scene

__all__ = ["pass_pool", "render_parallel", "warm_pool"]


def _worker_init() -> None:
    """Worker start-up: ignore SIGINT (Ctrl-C reaches the parent only) and run the compiled
    kernels on one thread, since the pool's processes already fill the cores (numba would
    otherwise start ``NUMBA_NUM_THREADS`` per worker)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    import numba

    numba.set_num_threads(1)


def pass_pool(jobs: int) -> ProcessPoolExecutor:
    """A pool of ``jobs`` worker processes for :func:`render_parallel` (reuse it across
    renders to pay the process start-up once; close it with ``shutdown`` or ``with``)."""
    if jobs < 1:
        raise ValueError(f"the number of jobs must be >= 1, got {jobs}")
    return ProcessPoolExecutor(max_workers=int(jobs),
                               mp_context=multiprocessing.get_context("spawn"),
                               initializer=_worker_init)


def _stop(pool: ProcessPoolExecutor) -> None:
    """Cancel queued passes and end the workers now (their passes are discarded)."""
    procs = list((getattr(pool, "_processes", None) or {}).values())  # before shutdown
    pool.shutdown(wait=False, cancel_futures=True)
    for proc in procs:
        proc.terminate()


def _pass_task(scene: Scene, spec: str, pass_index: int, seed: int,
               settings: RenderSettings) -> np.ndarray:
    """Run in a worker: one pass's (H, W, 3) float64 image."""
    return render_pass(scene, parse_estimator(spec, scene), pass_index, seed, settings)


def _warm_task(scene: Scene, spec: str, settings: RenderSettings) -> None:
    """Run in a worker: :func:`~psurf_core.render.warm_up` (imports, compiled kernels)."""
    warm_up(scene, parse_estimator(spec, scene), settings)
    time.sleep(0.05)  # hold this worker so the next warm-up task goes to another one


def warm_pool(pool: Executor, scene: Scene, spec: str, settings: RenderSettings) -> None:
    """Start ``pool``'s workers and warm each up for ``spec`` before a time budget starts.

    Spawned workers import numpy and psurf_core (about a second) and compile or load the
    estimator's compiled kernels; one task per worker pays that outside the clock (a task
    goes to whichever worker is idle, so a worker may rarely be warmed twice and another
    left to warm itself on its first pass).
    """
    n = max(1, getattr(pool, "_max_workers", 1))
    for f in [pool.submit(_warm_task, scene, spec, settings) for _ in range(n)]:
        f.result()


def render_parallel(
    scene: Scene,
    estimator: str | Estimator,
    settings: RenderSettings,
    *,
    passes: int | None = None,
    time_budget: float | None = None,
    seed: int = 0,
    jobs: int = 2,
    pool: Executor | None = None,
    accumulator: Welford | None = None,
    on_pass: Callable[[int, Welford, float], bool | None] | None = None,
) -> RenderResult:
    """Progressive render whose passes run in ``jobs`` local processes; the result equals
    :func:`psurf_core.render.render` with the same arguments and the same pass count.

    Parameters
    ----------
    scene : Scene
    estimator : str or Estimator
        Sent as its spec; each pass parses it in its worker as the single-process path does.
    settings : RenderSettings
    passes, time_budget : int, float
        Stop after ``passes`` passes in total, or stop submitting after ``time_budget``
        seconds (the passes in flight finish and count; at least one pass). One pass when
        neither is given.
    seed : int
    jobs : int
        Worker processes of the pool this call starts (ignored with ``pool``).
    pool : Executor, optional
        A pool from :func:`pass_pool` (left open).
    accumulator : Welford, optional
        Continue an earlier render (its ``n`` passes are skipped).
    on_pass : callable(i, acc, elapsed) -> bool or None
        Called after each pass is merged (in pass order); ``False`` stops (queued passes are
        cancelled and nothing more is merged).
    """
    if pool is None:
        p = pass_pool(jobs)
        try:
            result = render_parallel(scene, estimator, settings, passes=passes,
                                     time_budget=time_budget, seed=seed, pool=p,
                                     accumulator=accumulator, on_pass=on_pass)
        except BaseException:
            # Ctrl-C or a failed pass: do not wait for the passes still running.
            _stop(p)
            raise
        p.shutdown(wait=True)
        return result
    spec = estimator.spec if isinstance(estimator, Estimator) else str(estimator)
    if passes is None and time_budget is None:
        passes = 1
    cam = scene.camera
    acc = accumulator if accumulator is not None else Welford.empty((cam.height, cam.width, 3))
    window = 2 * max(1, getattr(pool, "_max_workers", jobs))
    if time_budget is not None:
        warm_pool(pool, scene, spec, settings)
    return merge_in_pass_order(
        lambda i: pool.submit(_pass_task, scene, spec, i, seed, settings),
        lambda fs: wait(fs, return_when=FIRST_COMPLETED), acc, window, spec, seed, settings,
        passes=passes, time_budget=time_budget, on_pass=on_pass)


def merge_in_pass_order(submit, wait_any, acc: Welford, window: int, spec: str, seed: int,
                        settings: RenderSettings, *, passes=None, time_budget=None,
                        on_pass=None, resubmit=None) -> RenderResult:
    """Keep up to ``window`` passes in flight and add them to ``acc`` in pass order (the
    local pool here, Dask in :mod:`psurf_core.distributed`): the result equals a serial
    render with the same seed, whatever order the passes finish in.

    ``submit(i)`` starts pass ``i`` and returns a future; ``wait_any(futures)`` blocks until
    one of them is done. A worker's exception is re-raised, unless ``resubmit(i, e)`` (when
    given) returns True: then pass ``i`` is submitted again (a pass is a function of its
    index, so its image is the same bits). Pending futures are cancelled on the way out.
    """
    t0 = time.perf_counter()
    done_before = next_i = acc.n
    in_flight: dict[int, object] = {}
    finished: dict[int, np.ndarray] = {}
    submitting = True
    try:
        while True:
            while submitting and len(in_flight) < window and (passes is None or next_i < passes):
                in_flight[next_i] = submit(next_i)
                next_i += 1
            if not in_flight:
                break
            wait_any(list(in_flight.values()))
            for i in sorted(in_flight):
                if in_flight[i].done():
                    try:
                        finished[i] = in_flight[i].result()  # re-raises a worker's exception
                    except Exception as e:
                        if resubmit is None or not resubmit(i, e):
                            raise
                        in_flight[i] = submit(i)
                        continue
                    del in_flight[i]
            stop = False
            while acc.n in finished:
                i = acc.n
                acc.add(finished.pop(i))
                if on_pass is not None and on_pass(i, acc, time.perf_counter() - t0) is False:
                    stop = True
                    break
            if stop:
                break
            elapsed = time.perf_counter() - t0
            if time_budget is not None and elapsed >= time_budget and next_i > done_before:
                submitting = False
            if passes is not None and acc.n >= passes:
                break
    finally:
        for f in in_flight.values():
            f.cancel()
    return RenderResult(acc.mean.copy(), acc.variance, acc.n, settings.photons, settings.spp,
                        time.perf_counter() - t0, spec, seed, acc)
