"""Passes on a Dask cluster (two worker processes on loopback) give the single-process image,
bit for bit, by pass count and by time budget; ``--dask`` on ``compare`` and the render hook.

Skipped, with the reason, only when Dask cannot start a local cluster on this machine (dask is a
declared dependency: a missing install fails).
"""

from __future__ import annotations

import argparse
import gc
import json
import logging
import socket
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from app_support import run_app
from dask.distributed import LocalCluster

from psurf_core import load_scene, parse_estimator
from psurf_core.distributed import (
    LOCAL_CLUSTER,
    DistributedError,
    cluster_client,
    render_distributed,
)
from psurf_core.render import RenderSettings, render
from ui.cli.parallel import maybe_distributed

ROOT = Path(__file__).resolve().parent.parent
SETTINGS = RenderSettings(photons=400)


@pytest.fixture(scope="module")
def cluster():
    try:
        c = LocalCluster(n_workers=2, **LOCAL_CLUSTER, silence_logs=logging.ERROR)
    except Exception as e:  # no processes, no loopback sockets, ...
        pytest.skip(f"dask cannot start a local cluster of 2 worker processes on 127.0.0.1 "
                    f"here: {type(e).__name__}: {e}")
    with c:
        yield c


@pytest.fixture(scope="module")
def client(cluster):
    from dask.distributed import Client

    with Client(cluster, set_as_default=False) as c:
        c.wait_for_workers(2, timeout=30)
        yield c


@pytest.fixture(scope="module")
def scene():
    sc = load_scene(str(ROOT / "scenes" / "area_occluder.toml"))
    return replace(sc, camera=replace(sc.camera, width=24, height=18))


def _same(a, b):
    assert a.passes == b.passes
    assert np.array_equal(a.mean, b.mean)
    assert np.array_equal(a.var, b.var)
    assert a.accumulator.n == b.accumulator.n and np.array_equal(a.accumulator.m2,
                                                                 b.accumulator.m2)
    assert a.sum_var is not None and np.array_equal(a.sum_var, b.sum_var)  # the image sums'


@pytest.mark.parametrize("spec", ["planes", "beams"])
def test_four_passes_bit_identical(client, scene, spec):
    single = render(scene, parse_estimator(spec, scene), SETTINGS, passes=4, seed=7)
    dist = render_distributed(scene, spec, SETTINGS, passes=4, seed=7, client=client)
    _same(single, dist)
    assert dist.var.max() > 0


def test_time_budget_merges_a_prefix_in_pass_order(client, scene):
    seen = []
    dist = render_distributed(scene, "planes", SETTINGS, time_budget=0.5, seed=3, client=client,
                              on_pass=lambda i, acc, t: seen.append(i))
    assert dist.passes >= 1 and seen == list(range(dist.passes))
    single = render(scene, parse_estimator("planes", scene), SETTINGS, passes=dist.passes, seed=3)
    _same(single, dist)


def test_resume_from_an_accumulator(client, scene):
    est = parse_estimator("planes", scene)
    first = render(scene, est, SETTINGS, passes=2, seed=5)
    dist = render_distributed(scene, "planes", SETTINGS, passes=5, seed=5, client=client,
                              accumulator=first.accumulator)
    _same(render(scene, est, SETTINGS, passes=5, seed=5), dist)


def test_render_hook_with_dask_address(cluster, scene):
    args = argparse.Namespace(dask=cluster.scheduler_address, workers=None)
    est = parse_estimator("planes", scene)
    dist = maybe_distributed(args, scene, est, SETTINGS, passes=3, seed=1)
    _same(render(scene, est, SETTINGS, passes=3, seed=1), dist)


def test_unreachable_scheduler_is_one_clear_error(monkeypatch):
    import psurf_core.distributed as d

    monkeypatch.setattr(d, "CONNECT_TIMEOUT", 1.0)
    with pytest.raises(DistributedError, match="cannot connect to the Dask scheduler"):
        with cluster_client("tcp://127.0.0.1:9", None):
            pass
    with pytest.raises(DistributedError, match="exactly one"):
        with cluster_client(None, None):
            pass


def test_compare_cli_on_the_cluster(cluster, tmp_path):
    sc = tmp_path / "tiny.toml"
    text = (ROOT / "scenes" / "area.toml").read_text().replace("[64, 48]", "[16, 12]")
    sc.write_text(text + "\n[render]\nmin_scatter = 2\nmax_scatter = 2\n")
    r = run_app("compare", sc, "--estimators", "planes,points", "--time", "1", "--photons",
                "300", "--reference-time", "1", "--dask", cluster.scheduler_address,
                "--out", tmp_path / "o", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    data = json.loads((tmp_path / "o" / "compare.json").read_text())
    assert data["results"][0]["ratio"] == 1.0
    assert all(x["passes"] >= 1 for x in data["results"])


def test_a_local_cluster_does_not_race_for_the_dashboard_port():
    """Two clusters at once (two runs with --workers, two test workers) must not both ask for
    the scheduler's default HTTP port: the loser retried on another and left an unclosed
    socket behind (a ResourceWarning, an error under this suite's warning filter)."""
    held = socket.socket()
    try:
        held.bind(("0.0.0.0", 8787))  # the default port, as another cluster would hold it
        held.listen()
    except OSError:
        pass  # already held by something else: the same situation
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            with LocalCluster(n_workers=0, **LOCAL_CLUSTER, silence_logs=logging.CRITICAL) as c:
                link = c.dashboard_link
            gc.collect()
    finally:
        held.close()
    assert link.startswith("http://127.0.0.1:") and ":8787/" not in link, link
    leaks = [w for w in caught if issubclass(w.category, ResourceWarning)]
    assert not leaks, [str(w.message) for w in leaks]
