"""``--jobs auto`` (``compare``'s default, ``render``'s on request): one worker process a core
this process may use, as many as the memory holds, and passes in this process wherever
processes cannot be used or measured (``--dask``/``--workers``, ``--clock cpu``, one core)."""

from __future__ import annotations

import argparse
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from app_support import run_app

from ui.cli import parallel
from ui.cli.limits import resolve_jobs

ROOT = Path(__file__).resolve().parent.parent


def _args(**kw):
    base = dict(jobs="auto", dask=None, workers=None, clock="wall", memory_budget=None)
    base.update(kw)
    return SimpleNamespace(**base)


def test_jobs_flag_reads_a_count_or_auto():
    assert parallel.jobs_count("auto") == "auto"
    assert parallel.jobs_count(" AUTO ") == "auto"
    assert parallel.jobs_count("3") == 3
    for bad in ("0", "-1", "two", ""):
        with pytest.raises(argparse.ArgumentTypeError, match="> 0 or 'auto'"):
            parallel.jobs_count(bad)


@pytest.mark.parametrize("cores, fit, expected", [
    (4, 4, 4),   # every core
    (4, 3, 3),   # the memory holds three processes
    (4, 1, 1),   # not even two: this process
    (1, 8, 1),   # one core: this process
])
def test_auto_is_one_process_a_core_that_fits(monkeypatch, cores, fit, expected):
    monkeypatch.setattr(parallel, "usable_cores", lambda: cores)
    asked = []

    def fits(n):
        asked.append(n)
        return n <= fit

    assert parallel.auto_jobs(_args(), fits) == expected
    assert all(2 <= n <= cores for n in asked)  # never more than the cores, never 1 asked


@pytest.mark.parametrize("kw", [dict(dask="tcp://127.0.0.1:8786"), dict(workers=2),
                                dict(clock="cpu")])
def test_auto_is_this_process_where_processes_do_not_apply(monkeypatch, kw):
    monkeypatch.setattr(parallel, "usable_cores", lambda: 8)
    assert parallel.auto_jobs(_args(**kw), lambda n: True) == 1


def test_resolve_checks_the_need_of_each_count_against_the_budget(monkeypatch):
    """``resolve_jobs`` asks the memory model for each count and keeps the most that fits
    ``--memory-budget``; a given count is left alone."""
    from psurf_core.budget import Need

    monkeypatch.setattr(parallel, "usable_cores", lambda: 4)
    mib = 1 << 20

    def need_of(n):  # 100 MiB a process
        return Need(width=1, height=1, spp=1, photons=0, triangles=0, per_pixel=0.0,
                    per_ray=0.0, per_photon=0.0, per_triangle=0.0, workers=100.0 * mib * n,
                    processes=n)

    args = _args(memory_budget=350)
    resolve_jobs(args, need_of)
    assert args.jobs == 3
    args = _args(jobs=2, memory_budget=10)
    resolve_jobs(args, need_of)
    assert args.jobs == 2


def test_render_jobs_auto_gives_the_single_process_image(tmp_path):
    """``render --jobs auto`` (one process a core, or this process on one core) renders the
    image of ``--jobs 1`` bit for bit (passes merged in pass order)."""
    outs = []
    for jobs in ("auto", "1"):
        out = tmp_path / f"jobs_{jobs}.npz"
        r = run_app("render", ROOT / "scenes" / "area.toml", "--estimator", "planes",
                    "--resolution", "16,12", "--passes", "4", "--photons", "300", "--seed", "5",
                    "--jobs", jobs, "--out", out, cwd=tmp_path)
        assert r.returncode == 0, r.stderr
        assert "Traceback" not in r.stderr
        with np.load(out) as d:
            outs.append({k: d[k] for k in ("mean", "var")})
    for key in ("mean", "var"):
        assert np.array_equal(outs[0][key], outs[1][key]), key
    assert outs[0]["mean"].max() > 0
