"""Passes in two local worker processes give the single-process image, bit for bit (by pass
count, by time budget, continuing an accumulator, and through ``render --jobs 2``)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from psurf_core import load_scene, parse_estimator
from psurf_core.parallel import pass_pool, render_parallel
from psurf_core.render import RenderSettings, render

ROOT = Path(__file__).resolve().parent.parent
SETTINGS = RenderSettings(photons=400)


@pytest.fixture(scope="module")
def pool():
    with pass_pool(2) as p:
        yield p


@pytest.fixture(scope="module")
def scene():
    sc = load_scene(str(ROOT / "scenes" / "area_occluder.toml"))
    return replace(sc, camera=replace(sc.camera, width=24, height=18))


def _same(a, b):
    assert a.passes == b.passes
    assert np.array_equal(a.mean, b.mean)
    assert np.array_equal(a.var, b.var)
    assert a.sum_var is not None and np.array_equal(a.sum_var, b.sum_var)  # the image sums'


@pytest.mark.parametrize("spec", ["planes", "paper-multi"])
def test_passes_bit_identical(pool, scene, spec):
    single = render(scene, parse_estimator(spec, scene), SETTINGS, passes=4, seed=7)
    par = render_parallel(scene, spec, SETTINGS, passes=4, seed=7, pool=pool)
    _same(single, par)
    assert par.var.max() > 0


def test_time_budget_merges_a_prefix_in_pass_order(pool, scene):
    seen = []
    par = render_parallel(scene, "planes", SETTINGS, time_budget=0.3, seed=3, pool=pool,
                          on_pass=lambda i, acc, t: seen.append(i))
    assert par.passes >= 1 and seen == list(range(par.passes))
    single = render(scene, parse_estimator("planes", scene), SETTINGS, passes=par.passes, seed=3)
    _same(single, par)


def test_continues_an_accumulator_and_stops_on_request(pool, scene):
    est = parse_estimator("planes", scene)
    first = render(scene, est, SETTINGS, passes=2, seed=5)
    par = render_parallel(scene, "planes", SETTINGS, passes=5, seed=5, pool=pool,
                          accumulator=first.accumulator,
                          on_pass=lambda i, acc, t: i < 3)  # stop after pass 3
    single = render(scene, est, SETTINGS, passes=4, seed=5)
    _same(single, par)


def test_render_hook_jobs(scene):
    """``render --jobs 2`` goes through ``maybe_distributed``; ``--jobs 1`` stays in-process."""
    import argparse

    from ui.cli.parallel import maybe_distributed

    est = parse_estimator("planes", scene)
    args = argparse.Namespace(dask=None, workers=None, jobs=2)
    par = maybe_distributed(args, scene, est, SETTINGS, passes=3, seed=11)
    _same(render(scene, est, SETTINGS, passes=3, seed=11), par)
    assert maybe_distributed(argparse.Namespace(dask=None, workers=None, jobs=1), scene, est,
                             SETTINGS, passes=3, seed=11) is None


def test_a_failing_pass_is_reraised_and_the_workers_stopped(scene):
    """A pass that raises in a worker re-raises in the caller; the pool it started ends."""
    from psurf_core.techniques import UnknownTechnique

    with pytest.raises(UnknownTechnique):  # parsed, and refused, in the worker
        render_parallel(scene, "no-such-estimator", SETTINGS, passes=2, seed=0, jobs=2)
