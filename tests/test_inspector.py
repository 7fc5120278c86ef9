"""The window's stage inspections off the UI thread (``ui.cli.inspector``): the background
process answers what ``inspect_pixel`` / ``primitive_pixels`` answer in this process, only the
newest request of a kind is answered, a failure comes back as one line, and a killed
inspector is restarted and asked again."""

from __future__ import annotations

import os
import signal
import time

import numpy as np
import pytest

from psurf_core.inspect import inspect_pixel, primitive_pixels
from psurf_core.render import RenderSettings
from psurf_core.scene_io import load_scene
from ui.cli.background import WORKER_NICE
from ui.cli.inspector import CoverageRequest, Inspector, PixelRequest

SETTINGS = RenderSettings(photons=150)
SPEC = "mis:plane-t1t2+sphere"


@pytest.fixture(scope="module")
def scene():
    return load_scene("scenes/point.toml").with_scatter(max_scatter=3)


def _wait(insp, timeout=120.0):
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < timeout:
        got = insp.poll()
        if got:
            return got
        time.sleep(0.02)
    raise AssertionError("no answer from the inspector")


def test_background_answers_equal_the_inspection_here(scene):
    want = inspect_pixel(scene, SPEC, 2, 1, (32, 24), SETTINGS)
    with_proc = Inspector(workers=1)
    try:
        ticket = with_proc.submit(PixelRequest(scene, SPEC, 2, 1, (32, 24), SETTINGS))
        assert with_proc.busy("pixel") is not None
        (res,) = _wait(with_proc)
        assert res.kind == "pixel" and res.ticket == ticket and res.error is None
        got = res.value
        assert len(got.table) == len(want.table) > 0
        assert np.array_equal(got.table.contribution, want.table.contribution)
        assert np.array_equal(got.pixel_value, want.pixel_value) and got.sum_matches
        t = want.table
        k = int(t.by_contribution()[0])
        args = (str(t.technique[k]), int(t.prim[k]))
        with_proc.submit(CoverageRequest(scene, SPEC, 2, 1, *args, int(t.batch[k]), SETTINGS))
        (cov,) = _wait(with_proc)
        mask = primitive_pixels(scene, SPEC, 2, 1, *args, SETTINGS, batch=int(t.batch[k]))
        assert cov.kind == "coverage" and np.array_equal(cov.value, mask) and mask[24, 32]
        assert with_proc.busy("pixel") is None and with_proc.busy("coverage") is None
        # its first answer at the starting priority, then the background's (issue 13)
        want_nice = min(os.getpriority(os.PRIO_PROCESS, 0) + WORKER_NICE, 19)
        assert os.getpriority(os.PRIO_PROCESS, with_proc.pids[0]) == want_nice
    finally:
        with_proc.close()


def test_only_the_newest_request_is_answered(scene):
    insp = Inspector(workers=1)
    try:
        for x in (10, 11, 12):  # the pixel moved three times quickly
            last = insp.submit(PixelRequest(scene, SPEC, 0, 0, (x, 20), SETTINGS))
        got = []
        t0 = time.perf_counter()
        while time.perf_counter() - t0 < 120 and insp.busy("pixel") is not None:
            got += insp.poll()
            time.sleep(0.02)
        assert [r.ticket for r in got] == [last]
        assert got[0].value.pixel_xy == (12, 20)
    finally:
        insp.close()


def test_synchronous_inspector_and_one_line_errors(scene):
    insp = Inspector(workers=0)
    insp.submit(PixelRequest(scene, "planes", 0, 0, (500, 3), SETTINGS))
    (res,) = insp.poll()
    assert res.value is None and "\n" not in res.error and "outside" in res.error
    insp.submit(PixelRequest(scene, "planes", 0, 0, (5, 3), SETTINGS))
    (res,) = insp.poll()
    assert res.error is None and res.value.pixel_xy == (5, 3)
    assert insp.poll() == []


def test_a_killed_inspector_is_restarted_and_asked_again(scene):
    insp = Inspector(workers=1)
    try:
        insp.submit(PixelRequest(scene, "planes", 0, 0, (3, 3), SETTINGS))
        _wait(insp)  # started and warm
        old = insp.pids[0]
        os.kill(old, signal.SIGKILL)
        insp._pool.procs[0].join(timeout=10)
        ticket = insp.submit(PixelRequest(scene, "planes", 0, 0, (4, 3), SETTINGS))
        (res,) = _wait(insp)
        assert res.ticket == ticket and res.value.pixel_xy == (4, 3)
        assert insp.restarts == 1 and insp.pids[0] != old
        assert any("inspector process died" in n for n in insp.take_notices())
    finally:
        insp.close()
