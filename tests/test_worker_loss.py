"""A worker that dies mid-run: the image stays bit-identical, or the run fails clearly.

* A local Dask cluster of two workers (with nannies, as ``--workers 2`` starts): one worker
  process is SIGKILLed while passes are in flight; its passes run again (on the other worker
  or on the one its nanny restarts) and the merged image equals the single-process render
  bit for bit.
* Every worker gone (killed, nannies told not to restart them): the run stops after
  ``no_worker_timeout`` with :class:`~psurf_core.distributed.WorkersLostError`, one line
  saying so; the passes merged before are intact.
* The command line: a lost cluster is one line, exit code 1, the completed passes saved to
  the checkpoint; a ``--jobs`` worker process killed mid-run is replaced by a new pool and the
  image stays bit-identical, until workers died ``JOB_RESTARTS + 1`` times (then one line).

Skipped, with the reason, only when Dask cannot start a local cluster here.
"""

from __future__ import annotations

import logging
import os
import signal
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from dask.distributed import Client, LocalCluster

import app
from psurf_core import checkpoint as ck
from psurf_core import load_scene, parse_estimator
from psurf_core.distributed import LOCAL_CLUSTER, WorkersLostError, render_distributed
from psurf_core.render import RenderSettings, render

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")

ROOT = Path(__file__).resolve().parent.parent
#: The path tracer: its passes need no compiled kernels, so a worker (and a restarted one)
#: starts rendering at once; 8 rays per pixel make a pass long enough to be in flight.
SPEC = "reference"
SETTINGS = RenderSettings(spp=16)
PASSES = 12


def cluster_and_client():
    try:
        cluster = LocalCluster(n_workers=2, **LOCAL_CLUSTER, silence_logs=logging.CRITICAL)
    except Exception as e:  # no processes, no loopback sockets, ...
        pytest.skip(f"dask cannot start a local cluster of 2 worker processes on 127.0.0.1 "
                    f"here: {type(e).__name__}: {e}")
    client = Client(cluster, set_as_default=False)
    client.wait_for_workers(2, timeout=60)
    return cluster, client


@pytest.fixture(scope="module")
def scene():
    sc = load_scene(str(ROOT / "scenes" / "area.toml"))
    return replace(sc, camera=replace(sc.camera, width=32, height=24))


def worker_pids(client) -> dict:
    return client.run(os.getpid)


def test_a_worker_killed_mid_run_leaves_the_image_bit_identical(scene):
    single = render(scene, parse_estimator(SPEC, scene), SETTINGS, passes=PASSES, seed=3)
    cluster, client = cluster_and_client()
    try:
        pids = worker_pids(client)
        lost, victims = [], []

        def on_pass(i, acc, elapsed):
            if victims:
                return
            # The first worker seen running a pass (the scheduler is in this process).
            busy = [(a, [ts.key for ts in ws.processing])
                    for a, ws in list(cluster.scheduler.workers.items()) if ws.processing]
            if busy and busy[0][0] in pids:
                address, keys = busy[0]
                lost.extend(keys)
                victims.append(pids[address])
                os.kill(pids[address], signal.SIGKILL)

        dist = render_distributed(scene, SPEC, SETTINGS, passes=PASSES, seed=3,
                                  client=client, on_pass=on_pass, max_in_flight=4)
        assert victims and lost, "no worker was killed with a pass in flight"
        assert victims[0] not in worker_pids(client).values()
    finally:
        client.close()
        cluster.close()
    assert dist.passes == PASSES
    np.testing.assert_array_equal(dist.mean, single.mean)
    np.testing.assert_array_equal(dist.var, single.var)


def test_passes_cancelled_with_the_scattered_scene_run_again(scene):
    """What a killed worker sometimes does (dask/distributed#3149; seen once in ``make test``:
    "4 Futures cancelled ... already forgotten" although the other worker lived): the
    scheduler forgets the scene scattered to the workers and cancels every pass in flight.
    Here the scene's key is cancelled after the first merged pass; the run scatters it again,
    resubmits the cancelled passes and ends with the single-process image's bits."""
    from distributed import Future

    single = render(scene, parse_estimator(SPEC, scene), SETTINGS, passes=6, seed=5)
    cluster, client = cluster_and_client()
    forgotten = []
    try:
        def on_pass(i, acc, elapsed):
            if i == 0:
                keys = [k for k in cluster.scheduler.tasks if str(k).startswith("Scene-")]
                assert len(keys) == 1, keys
                Future(keys[0], client).cancel()
                forgotten.extend(keys)

        dist = render_distributed(scene, SPEC, SETTINGS, passes=6, seed=5, client=client,
                                  on_pass=on_pass, max_in_flight=4)
        scenes_now = [k for k in cluster.scheduler.tasks if str(k).startswith("Scene-")]
    finally:
        client.close()
        cluster.close()
    assert forgotten and forgotten[0] not in scenes_now  # a new scatter, not the old one
    assert dist.passes == 6
    np.testing.assert_array_equal(dist.mean, single.mean)
    np.testing.assert_array_equal(dist.var, single.var)


def test_no_worker_left_is_a_clear_failure(scene):
    """Two workers without nannies (as ``dask worker --no-nanny`` on other machines would
    be) both killed mid-run: nothing restarts them."""
    import subprocess

    try:
        cluster = LocalCluster(n_workers=0, **LOCAL_CLUSTER, silence_logs=logging.CRITICAL)
    except Exception as e:
        pytest.skip(f"dask cannot start a local scheduler here: {type(e).__name__}: {e}")
    workers = [subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker",
                                 cluster.scheduler_address, "--no-nanny", "--nthreads", "1",
                                 "--no-dashboard"], stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL) for _ in range(2)]
    client = Client(cluster, set_as_default=False)
    try:
        client.wait_for_workers(2, timeout=120)
        merged = []

        def on_pass(i, acc, elapsed):
            merged.append(acc.n)
            if i == 0:
                for w in workers:
                    w.send_signal(signal.SIGKILL)

        t0 = time.monotonic()
        with pytest.raises(WorkersLostError) as e:
            render_distributed(scene, SPEC, SETTINGS, passes=PASSES, seed=3,
                               client=client, on_pass=on_pass, no_worker_timeout=3.0)
        seconds = time.monotonic() - t0
    finally:
        for w in workers:
            w.kill()
            w.wait()
        client.close()
        cluster.close()
    msg = str(e.value)
    assert "no Dask worker is left" in msg and "\n" not in msg, msg
    assert f"{merged[-1]} passes were merged" in msg, msg
    assert seconds < 60, seconds


def test_waiting_with_no_worker_gives_up_after_the_timeout(monkeypatch):
    """The wait itself: passes in flight, no worker at all (none ever comes back)."""
    import contextlib

    import dask.distributed

    import psurf_core.distributed as dist
    from psurf_core.accumulate import Welford

    class NoWorkers:
        def scheduler_info(self, n_workers=-1):
            return {"workers": {}}

        def as_current(self):
            return contextlib.nullcontext()

    def never(futures, timeout=None, return_when=None):
        time.sleep(0.01)
        raise TimeoutError

    monkeypatch.setattr(dask.distributed, "wait", never)
    monkeypatch.setattr(dist, "_POLL", 0.01)
    acc = Welford.empty((2, 2, 3))
    t0 = time.monotonic()
    with pytest.raises(WorkersLostError, match=r"no Dask worker is left \(none for 0.3 s\); "
                                               r"0 passes were merged"):
        dist._waiter(NoWorkers(), 0.3, acc)(["a future"])
    assert 0.3 <= time.monotonic() - t0 < 5


# --------------------------------------------------------------------------- the command line


@pytest.fixture
def work(tmp_path, monkeypatch):
    text = (ROOT / "scenes" / "area.toml").read_text().replace("[64, 48]", "[24, 18]")
    (tmp_path / "scene.toml").write_text(text)
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_render_saves_the_passes_when_the_cluster_is_lost(work, capsys, monkeypatch):
    import psurf_core.distributed as dist
    from psurf_core.accumulate import Welford

    def lost(scene, est, settings, *, on_pass=None, accumulator=None, **kw):
        acc = Welford.empty((18, 24, 3))
        for i in range(3):  # three passes merge, then the cluster is gone
            acc.add(np.full((18, 24, 3), float(i)))
            on_pass(i, acc, 0.1)
        raise WorkersLostError("no Dask worker is left (none for 30 s); 3 passes were merged")

    monkeypatch.setattr(dist, "render_distributed", lost)
    monkeypatch.setattr(dist, "cluster_client", None)
    code = app.main(["render", "scene.toml", "--estimator", "planes", "--photons", "100",
                     "--passes", "8", "--dask", "tcp://127.0.0.1:1", "--out", "o.npz",
                     "--checkpoint", "ck", "--checkpoint-every", "1000"])
    _, err = capsys.readouterr()
    lines = [ln for ln in err.strip().splitlines() if not ln.startswith("psurf: note:")]
    assert code == 1 and len(lines) == 1 and "Traceback" not in err, err
    assert "--dask: no Dask worker is left" in lines[0], lines[0]
    assert "ck holds the 3 completed passes" in lines[0], lines[0]
    assert ck.load_checkpoint(work / "ck").accumulator.n == 3
    assert not (work / "o.npz").exists()


def kill_a_pool_worker_when(monkeypatch, when):
    """After ``Welford.add`` in this process (the merge; workers are spawned fresh and do not
    see the patch), SIGKILL one of this process's worker processes if ``when(n)``."""
    import multiprocessing

    from psurf_core.accumulate import Welford

    real = Welford.add

    def add(self, x):
        real(self, x)
        if when(self.n):
            for proc in multiprocessing.active_children():
                os.kill(proc.pid, signal.SIGKILL)
                break

    monkeypatch.setattr(Welford, "add", add)


PLAIN = ["render", "scene.toml", "--estimator", SPEC, "--spp", "8", "--passes", "10"]
JOBS = [*PLAIN, "--jobs", "2", "--checkpoint-every", "0"]


def test_render_jobs_continues_in_a_new_pool_bit_identically(work, capsys, monkeypatch):
    with monkeypatch.context() as m:
        kill_a_pool_worker_when(m, lambda n: n == 2)
        code = app.main([*JOBS, "--out", "killed.npz", "--checkpoint", "ck"])
    _, err = capsys.readouterr()
    assert code == 0, err
    assert "a new pool continues from pass" in err and "Traceback" not in err, err
    assert app.main([*PLAIN, "--out", "plain.npz"]) == 0  # one process
    with np.load(work / "killed.npz") as a, np.load(work / "plain.npz") as b:
        assert int(a["passes"]) == int(b["passes"]) == 10
        np.testing.assert_array_equal(a["mean"], b["mean"])
        np.testing.assert_array_equal(a["var"], b["var"])


@pytest.mark.slow
def test_render_jobs_workers_dying_again_and_again_is_one_line(work, capsys, monkeypatch):
    import ui.cli.parallel

    with monkeypatch.context() as m:
        m.setattr(ui.cli.parallel, "JOB_RESTARTS", 1)  # two pools, not four: quicker
        kill_a_pool_worker_when(m, lambda n: True)
        code = app.main([*JOBS, "--out", "o.npz", "--checkpoint", "ck"])
    _, err = capsys.readouterr()
    lines = [ln for ln in err.strip().splitlines() if not ln.startswith("psurf: note:")]
    assert code == 1 and len(lines) == 1 and "Traceback" not in err, err
    assert "--jobs: worker processes died 2 times" in lines[0], lines[0]
    n = ck.load_checkpoint(work / "ck").accumulator.n
    assert 1 <= n < 10 and f"ck holds the {n} completed passes" in lines[0], lines[0]
    assert not (work / "o.npz").exists()
