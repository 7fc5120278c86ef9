"""Parallel passes, shared by ``render`` and ``compare``: the ``--dask ADDRESS`` /
``--workers N`` / ``--jobs N`` flags (:func:`add_dask_flags`) and the render command's hook
(:func:`maybe_distributed`).

Passes are merged in pass order wherever they ran, so the image equals a single-process run.
Nothing of Dask is imported unless ``--dask``/``--workers`` is given (the cluster is
:mod:`psurf_core.distributed`, the local process pool :mod:`psurf_core.parallel`).
"""

from __future__ import annotations

import argparse
import os

from .common import note, positive_int

#: New pools a ``--jobs`` render starts after worker processes died, before it gives up.
JOB_RESTARTS = 3


class WorkersLost(Exception):
    """Mid-run, the workers a render needs are gone (every Dask worker, a pass lost with its
    workers, the scheduler, or a ``--jobs`` process killed): one line, exit code 1; the
    passes merged before it are kept (``render`` saves them to its checkpoint)."""


def _address(text: str) -> str:
    if not text.strip():
        raise argparse.ArgumentTypeError("must be a scheduler address, e.g. tcp://host:8786")
    return text.strip()


def jobs_count(text: str):
    """``--jobs``: a positive count, or ``auto`` (:func:`auto_jobs`)."""
    if text.strip().lower() == "auto":
        return "auto"
    try:
        return positive_int(text)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"must be an integer > 0 or 'auto', got {text!r}"
                                         ) from None


def usable_cores() -> int:
    """The cores this process may run on (its CPU affinity where the system tells it)."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def auto_jobs(args, fits) -> int:
    """What ``--jobs auto`` means for ``args``: one worker process a core this process may use
    (:func:`usable_cores`), fewer where ``fits(n)`` (the run's memory need with ``n``
    processes within the budget) says ``n`` would not fit; 1 (passes in this process) on one
    core, with ``--dask``/``--workers``, or with ``--clock cpu`` (which measures this process
    alone). Whole passes in processes use the cores where threads leave one idle: each
    pass's Create (numpy) and image accumulation run on one thread (``compare``'s runs used
    ~1.55 of 2 cores, docs/study.md)."""
    if getattr(args, "dask", None) is not None or getattr(args, "workers", None) is not None:
        return 1
    if getattr(args, "clock", "wall") == "cpu":
        return 1
    for n in range(usable_cores(), 1, -1):
        if fits(n):
            return n
    return 1


def add_dask_flags(parser: argparse.ArgumentParser, jobs_default="1") -> None:
    """``--dask ADDRESS`` / ``--workers N`` / ``--jobs N`` (mutually exclusive) on
    ``parser``; ``jobs_default`` is ``"1"`` or ``"auto"`` (:func:`auto_jobs`)."""
    g = parser.add_argument_group("parallel passes (local processes or Dask; default: one "
                                  "process, no Dask)")
    x = g.add_mutually_exclusive_group()
    x.add_argument("--dask", type=_address, default=None, metavar="ADDRESS",
                   help="send passes to the Dask scheduler at ADDRESS (e.g. tcp://host:8786; "
                        "its workers need the same psurf installed); passes are merged in "
                        "pass order, so the image equals a single-process run")
    x.add_argument("--workers", type=positive_int, default=None, metavar="N",
                   help="start a local Dask cluster of N single-threaded worker processes on "
                        "127.0.0.1 for this command")
    x.add_argument("--jobs", type=jobs_count, default=jobs_count(jobs_default),
                   metavar="N|auto",
                   help="run passes in N local worker processes (no Dask; e.g. 2 on a 2-core "
                        "machine); 'auto': one a core, as many as the memory holds; merged in "
                        "pass order, so the image equals a single-process run with as many "
                        f"passes (default {jobs_default}"
                        + (": this process)" if jobs_default == "1" else ")"))


def maybe_distributed(args, scene, estimator, settings, *, passes=None, time_budget=None,
                      seed=0, on_pass=None, accumulator=None, error=None):
    """The render command's hook: with ``--dask``/``--workers``, render the passes on Dask
    (:func:`psurf_core.distributed.render_distributed`) and return the ``RenderResult``; with
    ``--jobs N > 1``, in N local processes (:func:`psurf_core.parallel.render_parallel`);
    without them, return ``None`` (render in this process, nothing of Dask imported).

    ``error`` is the exception class to raise for a cluster that cannot be used (``app.py``
    passes its ``CliError``: one line, exit 2); ``DistributedError`` by default.
    """
    address, workers = getattr(args, "dask", None), getattr(args, "workers", None)
    jobs = getattr(args, "jobs", 1) or 1
    if address is None and workers is None and jobs > 1:
        return _render_jobs(scene, estimator, settings, jobs=jobs, passes=passes,
                            time_budget=time_budget, seed=seed, accumulator=accumulator,
                            on_pass=on_pass)
    if address is None and workers is None:
        return None
    from psurf_core.distributed import DistributedError, WorkersLostError, render_distributed

    try:
        return render_distributed(scene, estimator, settings, passes=passes,
                                  time_budget=time_budget, seed=seed, address=address,
                                  workers=workers, accumulator=accumulator, on_pass=on_pass)
    except WorkersLostError as e:
        flag = "--dask" if address is not None else "--workers"
        raise WorkersLost(f"{flag}: {e}") from None
    except DistributedError as e:
        flag = "--dask" if address is not None else "--workers"
        if error is None:
            raise
        raise error(f"{flag}: {e}") from None


def _render_jobs(scene, estimator, settings, *, jobs, passes, time_budget, seed, accumulator,
                 on_pass):
    """:func:`psurf_core.parallel.render_parallel`, continued in a new pool when a worker
    process dies (killed, out of memory): the passes merged so far are kept and the lost
    ones rendered again, so the image is the same bit for bit; after :data:`JOB_RESTARTS`
    new pools, :class:`WorkersLost`."""
    import time
    from concurrent.futures.process import BrokenProcessPool

    from psurf_core.accumulate import Welford
    from psurf_core.parallel import render_parallel

    cam = scene.camera
    acc = accumulator if accumulator is not None else Welford.empty((cam.height, cam.width, 3))
    t0 = time.perf_counter()
    for attempt in range(JOB_RESTARTS + 1):
        offset = time.perf_counter() - t0
        left = None if time_budget is None else max(time_budget - offset, 1e-9)

        def shifted(i, a, elapsed, offset=offset):
            return on_pass(i, a, offset + elapsed) if on_pass is not None else None

        try:
            result = render_parallel(scene, estimator, settings, passes=passes,
                                     time_budget=left, seed=seed, jobs=jobs, accumulator=acc,
                                     on_pass=shifted)
        except BrokenProcessPool:
            if attempt == JOB_RESTARTS:
                raise WorkersLost(f"--jobs: worker processes died {attempt + 1} times (killed, "
                                  f"or out of memory); {acc.n} passes were merged") from None
            note(f"--jobs: a worker process died (killed, or out of memory); a new pool "
                 f"continues from pass {acc.n}")
            continue
        result.seconds = time.perf_counter() - t0
        return result
    raise AssertionError("unreachable")
