"""Passes on a Dask distributed cluster, merged in pass order: the same image as one process.

Passes are independent (pass ``i`` draws all its randomness from ``SeedSequence([seed, i])``),
so they can run anywhere. :func:`render_distributed` submits
``render_pass(scene, parse_estimator(spec, scene), i, seed, settings)`` per pass to a Dask
scheduler, gathers the pass images and adds them to one :class:`~psurf_core.accumulate.Welford`
**in pass order** with ``acc.add`` (the sequential Welford update, not the pairwise merge), so
``mean`` and ``var`` are bit-identical to :func:`psurf_core.render.render` with the same seed,
settings and pass count, whatever the number of workers or the order in which passes finish.

Only this module imports ``dask.distributed``, and only when called: the default render stays
single-process with no Dask running. ``address`` connects to an existing scheduler (its
workers must be able to import the same psurf version); ``workers=N`` starts a local cluster
of N single-threaded worker processes on 127.0.0.1 for the duration of the call.

Time-budget mode keeps at most ``2 x workers`` passes in flight, stops submitting once
``time_budget`` seconds are spent, and lets the passes in flight finish; they are all merged
(the analogue of "the pass in flight finishes"), so the result is always passes ``0..n-1``.

A worker that dies mid-run loses nothing: the scheduler runs its passes again elsewhere (or
on the worker its nanny restarts), and since a pass is a pure function of its index the image
stays bit-identical (``tests/test_worker_loss.py``). What cannot be recovered ends the run
with :class:`WorkersLostError` (one line): no worker left for :data:`NO_WORKER_TIMEOUT`
seconds, a pass whose workers died too often (Dask's ``KilledWorker``), or the scheduler gone.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from contextlib import contextmanager

import numpy as np

from .accumulate import Welford
from .estimators import Estimator, parse_estimator
from .parallel import merge_in_pass_order
from .render import RenderResult, RenderSettings, render_pass, warm_up
from .scene import Scene

__all__ = ["DistributedError", "WorkersLostError", "cluster_client", "render_distributed"]

#: Seconds to wait for a scheduler (``address``) to answer.
CONNECT_TIMEOUT = 10.0

#: How a local cluster (``workers=N``, and the tests' clusters) is started: worker processes
#: of one thread on the loopback. The scheduler's HTTP server always starts (``None`` means
#: its default port, 8787); on a free port of the loopback instead, two clusters at once (two
#: runs, two test workers) do not race for 8787 (the loser retried on another port and left
#: an unclosed socket: a ResourceWarning, an error under pytest).
LOCAL_CLUSTER = {"processes": True, "threads_per_worker": 1, "host": "127.0.0.1",
                 "dashboard_address": "127.0.0.1:0"}

#: Seconds a run waits with no worker at all (a nanny's restart or a new worker may come)
#: before it gives up with :class:`WorkersLostError`.
NO_WORKER_TIMEOUT = 30.0

#: Passes a run submits again after a worker loss cancelled them (while workers live), at
#: most: each loss cancels up to the window of passes in flight.
RESUBMITS = 64

#: Seconds between checks for live workers while passes are in flight.
_POLL = 1.0


class DistributedError(RuntimeError):
    """Dask is missing, the scheduler cannot be reached, or its workers cannot run psurf."""


class WorkersLostError(DistributedError):
    """Mid-run, the cluster lost what the run needs: every worker, a pass (with its worker,
    too often), or the scheduler. The passes merged before it are intact."""


def _pass_task(scene: Scene, spec: str, pass_index: int, seed: int,
               settings: RenderSettings) -> np.ndarray:
    """Run on a worker: one pass's (H, W, 3) float64 image."""
    return render_pass(scene, parse_estimator(spec, scene), pass_index, seed, settings)


def _warm_worker(scene: Scene, spec: str, settings: RenderSettings) -> None:
    """Run on each worker by ``client.run``: :func:`~psurf_core.render.warm_up`."""
    warm_up(scene, parse_estimator(spec, scene), settings)


def _worker_version() -> str:
    from . import __version__

    return __version__


@contextmanager
def cluster_client(address: str | None = None, workers: int | None = None):
    """A ``dask.distributed.Client`` on ``address`` or on a new local cluster of ``workers``
    single-threaded processes (loopback only); both are closed on exit.

    Raises
    ------
    DistributedError
        Dask is not installed, both or neither of ``address``/``workers`` given, the
        scheduler does not answer, it has no workers, or its workers cannot import psurf or
        run a different psurf version.
    """
    if (address is None) == (workers is None):
        raise DistributedError("give exactly one of a scheduler address or a worker count")
    try:
        from dask.distributed import Client, LocalCluster
    except ImportError as e:
        raise DistributedError(f"dask.distributed is not installed ({e}); "
                               "pip install 'dask[distributed]'") from None
    cluster = client = None
    try:
        if address is not None:
            try:
                client = Client(address, timeout=CONNECT_TIMEOUT, set_as_default=False)
            except (OSError, TimeoutError, ValueError) as e:
                raise DistributedError(f"cannot connect to the Dask scheduler at {address}: "
                                       f"{' '.join(str(e).split()) or type(e).__name__}") from None
        else:
            if workers < 1:
                raise DistributedError(f"the worker count must be >= 1, got {workers}")
            try:
                cluster = LocalCluster(n_workers=workers, **LOCAL_CLUSTER,
                                       silence_logs=logging.ERROR)
                client = Client(cluster, set_as_default=False)
            except (OSError, TimeoutError, RuntimeError) as e:
                raise DistributedError(f"cannot start a local Dask cluster of {workers} "
                                       f"workers: {type(e).__name__}: {e}") from None
        _check_workers(client, address)
        yield client
    finally:
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()


def _check_workers(client, address) -> None:
    from . import __version__

    where = f"the scheduler at {address}" if address else "the local cluster"
    try:
        client.wait_for_workers(1, timeout=CONNECT_TIMEOUT)
    except (TimeoutError, OSError):
        raise DistributedError(f"{where} has no workers (waited {CONNECT_TIMEOUT:g} s)") from None
    try:
        versions = client.run(_worker_version)
    except Exception as e:  # an import failure on a worker comes back as any exception
        raise DistributedError(f"the workers of {where} cannot import psurf_core "
                               f"({type(e).__name__}: {e}); install psurf on them") from None
    bad = {w: v for w, v in versions.items() if v != __version__}
    if bad:
        w, v = next(iter(bad.items()))
        raise DistributedError(f"worker {w} of {where} runs psurf {v}, this is {__version__}")


def _n_workers(client) -> int:
    info = client.scheduler_info()
    return max(1, sum(int(w.get("nthreads", 1)) for w in info.get("workers", {}).values()))


def render_distributed(
    scene: Scene,
    estimator: str | Estimator,
    settings: RenderSettings,
    *,
    passes: int | None = None,
    time_budget: float | None = None,
    seed: int = 0,
    address: str | None = None,
    workers: int | None = None,
    client=None,
    accumulator: Welford | None = None,
    on_pass: Callable[[int, Welford, float], bool | None] | None = None,
    max_in_flight: int | None = None,
    no_worker_timeout: float | None = None,
) -> RenderResult:
    """Progressive render whose passes run on Dask workers; the result equals
    :func:`psurf_core.render.render` with the same arguments.

    Parameters
    ----------
    scene : Scene
        Sent to the workers once (scattered), not re-read from its file.
    estimator : str or Estimator
        The spec (an ``Estimator`` is sent as its ``spec``); each pass parses it on its worker
        exactly as the single-process path does.
    settings : RenderSettings
    passes, time_budget : int, float
        Stop after ``passes`` passes in total, or stop submitting after ``time_budget``
        seconds (passes in flight finish and count; at least one pass). One pass when neither.
    seed : int
    address, workers
        An existing scheduler, or a local cluster of ``workers`` processes to start; or pass a
        connected ``client`` (left open).
    accumulator : Welford, optional
        Continue an earlier render (its ``n`` passes are skipped).
    on_pass : callable(i, acc, elapsed) -> bool or None
        Called after each pass is merged (in pass order); ``False`` stops (passes in flight
        are cancelled and not merged).
    max_in_flight : int, optional
        Passes submitted but not merged; default ``2 x`` the cluster's worker threads.
    no_worker_timeout : float, optional
        Seconds without any worker before giving up (default :data:`NO_WORKER_TIMEOUT`).

    Raises
    ------
    DistributedError
        See :func:`cluster_client`. A pass that fails on a worker re-raises its exception.
    WorkersLostError
        No worker for ``no_worker_timeout`` seconds, a pass lost with its workers too often,
        or the scheduler gone; ``accumulator`` (when given) holds the passes merged before.
    """
    if client is None:
        with cluster_client(address, workers) as c:
            return render_distributed(scene, estimator, settings, passes=passes,
                                      time_budget=time_budget, seed=seed, client=c,
                                      accumulator=accumulator, on_pass=on_pass,
                                      max_in_flight=max_in_flight,
                                      no_worker_timeout=no_worker_timeout)

    spec = estimator.spec if isinstance(estimator, Estimator) else str(estimator)
    if passes is None and time_budget is None:
        passes = 1
    cam = scene.camera
    acc = accumulator if accumulator is not None else Welford.empty((cam.height, cam.width, 3))
    window = max_in_flight if max_in_flight is not None else 2 * _n_workers(client)
    window = max(1, int(window))

    scattered = client.scatter(scene, broadcast=True, hash=False)
    if time_budget is not None:
        # Every worker compiles/loads the estimator's compiled kernels before the clock runs.
        client.run(_warm_worker, scene, spec, settings)

    timeout = NO_WORKER_TIMEOUT if no_worker_timeout is None else float(no_worker_timeout)
    retries, used = 0, {}  # resubmissions so far; pass -> the scattered copy it was given

    def submit(i: int):
        used[i] = scattered
        return client.submit(_pass_task, scattered, spec, i, seed, settings, pure=False)

    def resubmit(i: int, e: Exception) -> bool:
        # A killed worker can take the scattered scene with it: the scheduler then forgets
        # it and cancels every pass that needs it (dask/distributed#3149), though the other
        # workers live. Scatter again (once per loss: the first pass cancelled with the
        # current copy) and resubmit, a bounded number of times.
        from concurrent.futures import CancelledError

        nonlocal scattered, retries
        if not isinstance(e, CancelledError) or retries >= RESUBMITS:
            return False
        if _live_workers(client) == 0:
            return False
        retries += 1
        if used.get(i) is scattered:
            scattered = client.scatter(scene, broadcast=True, hash=False)
        return True

    try:
        return merge_in_pass_order(
            submit,
            _waiter(client, timeout, acc), acc, window, spec, seed, settings, passes=passes,
            time_budget=time_budget, on_pass=on_pass, resubmit=resubmit)
    except WorkersLostError:
        raise
    except Exception as e:
        if not _is_loss(e):
            raise
        if _live_workers(client) == 0:
            raise WorkersLostError(f"no Dask worker is left (the passes in flight and the "
                                   f"scene sent to the workers went with them); {acc.n} "
                                   f"passes were merged") from None
        why = " ".join(str(e).split())
        raise WorkersLostError(f"the cluster lost pass {acc.n} with its workers "
                               f"({type(e).__name__}: {why[:160]}{'...' if len(why) > 160 else ''}"
                               f"); {acc.n} passes were merged") from None


def _is_loss(e: Exception) -> bool:
    """A worker or the scheduler gone (not an error of the pass itself)."""
    from concurrent.futures import CancelledError

    from distributed import KilledWorker
    from distributed.comm.core import CommClosedError

    return isinstance(e, (KilledWorker, CommClosedError, CancelledError))


def _live_workers(client) -> int:
    try:
        return len(client.scheduler_info(n_workers=-1).get("workers", {}))
    except Exception as e:  # the scheduler does not answer
        raise WorkersLostError(f"lost the Dask scheduler ({type(e).__name__}: "
                               f"{' '.join(str(e).split())[:200]})") from None


def _waiter(client, timeout: float, acc: Welford):
    """``wait_any(futures)`` for :func:`merge_in_pass_order`: returns when one is done, and
    raises :class:`WorkersLostError` once the cluster has had no worker for ``timeout``
    seconds."""
    from concurrent.futures import CancelledError

    from dask.distributed import wait

    def wait_any(futures):
        alone_since = None
        while True:
            try:
                with client.as_current():  # wait() looks for a current client
                    wait(futures, timeout=_POLL, return_when="FIRST_COMPLETED")
                return
            except CancelledError:
                return  # cancelled futures are done: their result() says why, per pass
            except TimeoutError:
                pass
            if _live_workers(client):
                alone_since = None
                continue
            now = time.monotonic()
            alone_since = now if alone_since is None else alone_since
            if now - alone_since >= timeout:
                raise WorkersLostError(f"no Dask worker is left (none for {timeout:g} s); "
                                       f"{acc.n} passes were merged")

    return wait_any
