"""Background progressive rendering (``ui.cli.progressive``): merged passes equal a serial render
bit for bit, whichever process rendered them and in whatever order they arrived; compiling
kernels is not render time; a killed worker is restarted and nothing merged is lost."""

from __future__ import annotations

import os
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from psurf_core.accumulate import Welford
from psurf_core.breakdown import BreakdownAccumulator, BreakdownLayout, render_pass_breakdown
from psurf_core.estimators import parse_estimator
from psurf_core.render import RenderSettings, render
from psurf_core.scene_io import load_scene
from psurf_core.techniques import UnknownTechnique
from ui.cli.progressive import Job, Progressive, compare_rows
from ui.cli.progressive_worker import Engine

SETTINGS = RenderSettings(photons=150)
ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def scene():
    return load_scene("scenes/point.toml").with_scatter(max_scatter=3)


def _serial(scene, spec, passes, seed):
    return render(scene, parse_estimator(spec, scene), SETTINGS, passes=passes,
                  seed=seed).accumulator


def _serial_breakdown(scene, spec, passes, seed):
    est = parse_estimator(spec, scene)
    acc = BreakdownAccumulator(BreakdownLayout.of(scene, est))
    for i in range(passes):
        acc.add(render_pass_breakdown(scene, est, i, seed, SETTINGS, layout=acc.layout)[1])
    return acc


def _same(a: Welford, b: Welford) -> bool:
    return a.n == b.n and np.array_equal(a.mean, b.mean) and np.array_equal(a.m2, b.m2)


def test_worker_process_equals_serial_render(scene):
    specs = ["planes", "mis:plane-t1t2+sphere"]
    with Progressive(scene, specs, SETTINGS, seed=5, workers=1, breakdown=True,
                     max_passes=3) as prog:
        prog.run(timeout=600)
        assert prog.done and prog.passes == [3, 3] and not prog.errors
        for run in prog.runs:
            assert _same(run.acc, _serial(scene, run.spec, 3, 5)), run.spec
            assert run.seconds > 0
        b = prog.runs[1].breakdown
        ref = _serial_breakdown(scene, "mis:plane-t1t2+sphere", 3, 5)
        assert _same(b.weighted, ref.weighted) and _same(b.unweighted, ref.unweighted)


def test_one_worker_merges_the_breakdowns_and_sends_their_means(scene):
    """Issue 13 (never freeze): with one worker the breakdowns are merged where the passes are
    rendered; the UI gets their float32 means with every pass, equal to a serial render's
    (``ShownBreakdown``), and the worker has stepped back to the background priority once
    its first pass arrived."""
    import time

    from ui.cli.background import WORKER_NICE
    from ui.cli.progressive import ShownBreakdown

    spec = "mis:plane-t1t2+sphere"
    with Progressive(scene, ["planes", spec], SETTINGS, seed=6, workers=1,
                     breakdown=True) as prog:
        assert isinstance(prog.runs[1].breakdown, ShownBreakdown)
        assert prog.runs[1].breakdown.n == 0 and not prog.runs[1].breakdown.image.any()
        t0 = time.perf_counter()
        while prog.passes[1] < 2 and time.perf_counter() - t0 < 120:
            prog.poll()
            time.sleep(0.02)
        prog.pause()
        run = prog.runs[1]
        b = run.breakdown
        assert isinstance(b, ShownBreakdown) and not prog.done
        assert b.n == run.acc.n >= 2 and b.weighted.mean.dtype == np.float32
        ref = _serial_breakdown(scene, spec, b.n, 6)
        for got, want in ((b.weighted, ref.weighted), (b.unweighted, ref.unweighted)):
            assert got.n == want.n
            assert np.array_equal(got.mean, want.mean.astype(np.float32))
        assert b.technique_images().shape == ref.technique_images().shape
        with pytest.raises(TypeError, match="read-only"):  # the worker merges, not the UI
            b.add_arrays(ref.unweighted.mean, ref.weighted.mean)
        ours = os.getpriority(os.PRIO_PROCESS, 0)
        assert os.getpriority(os.PRIO_PROCESS, prog.pids[0]) == min(ours + WORKER_NICE, 19)


def test_priority_lowers_every_thread_once_or_after_its_time(tmp_path):
    """``Priority`` (the worker renders its first pass at the starting priority): ``lower``
    lowers every thread of the process by WORKER_NICE, once; the timer does it by itself.
    In a child process: a niceness cannot be raised back."""
    import subprocess
    import sys

    if not os.path.isdir("/proc/self/task"):
        pytest.skip("per-thread niceness: Linux")
    code = """if True:
        import os, threading, time
        from ui.cli.background import WORKER_NICE
        from ui.cli.background import Priority
        stop = threading.Event()
        threading.Thread(target=stop.wait, daemon=True).start()
        start = os.getpriority(os.PRIO_PROCESS, 0)
        want = min(start + WORKER_NICE, 19)
        p = Priority(seconds=600)
        assert not p.lowered and os.getpriority(os.PRIO_PROCESS, 0) == start
        p.lower()
        p.lower()
        tids = [int(t) for t in os.listdir("/proc/self/task")]
        assert len(tids) >= 2, tids
        got = {os.getpriority(os.PRIO_PROCESS, t) for t in tids}
        assert got == {want}, (start, got)
        q = Priority(seconds=0.05)  # the timer: lowered by then (19 at most)
        t0 = time.monotonic()
        while not q.lowered and time.monotonic() - t0 < 60:
            time.sleep(0.01)
        assert q.lowered
        print("ok", start, want)
    """
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0 and out.stdout.startswith("ok"), out.stderr


def test_two_workers_merge_in_pass_order(scene):
    with Progressive(scene, ["planes"], SETTINGS, seed=8, workers=2, max_passes=5) as prog:
        prog.run(timeout=600)
        assert prog.passes == [5]
        assert _same(prog.runs[0].acc, _serial(scene, "planes", 5, 8))


def test_out_of_order_passes_wait_for_their_predecessors(scene):
    prog = Progressive(scene, ["planes"], SETTINGS, seed=1, workers=0)
    eng = Engine(prog.job, first=0, stride=1)
    outs = [eng.render(0) for _ in range(3)]
    prog._take(*outs[2])
    prog._take(*outs[1])
    assert prog.passes == [0]
    prog._take(*outs[0])
    assert prog.passes == [3]
    assert _same(prog.runs[0].acc, _serial(scene, "planes", 3, 1))


def test_synchronous_fallback(scene):
    prog = Progressive(scene, ["planes", "beams"], SETTINGS, seed=2, workers=0)
    assert prog.poll() == 1 and sum(prog.passes) == 1  # poll renders one pass itself
    prog.run(passes=3)
    assert min(prog.passes) >= 3
    for run in prog.runs:
        assert _same(run.acc, _serial(scene, run.spec, run.acc.n, 2))
    prog.pause()
    assert prog.poll() == 0
    prog.close()


def test_reset_drops_passes_and_restarts(scene):
    with Progressive(scene, ["planes"], SETTINGS, seed=0, workers=1, max_passes=2) as prog:
        prog.run(timeout=600)
        prog.reset(estimators=["beams", "planes"], seed=4, max_passes=2)
        assert prog.passes == [0, 0]
        prog.run(timeout=600)
        assert [r.spec for r in prog.runs] == ["beams", "planes"]
        assert _same(prog.runs[0].acc, _serial(scene, "beams", 2, 4))
        assert _same(prog.runs[1].acc, _serial(scene, "planes", 2, 4))


def test_bad_spec_fails_before_any_process(scene):
    with pytest.raises(UnknownTechnique):
        Progressive(scene, ["no-such-thing"], SETTINGS, workers=1)
    with pytest.raises(ValueError):
        Progressive(scene, [], SETTINGS, workers=0)


def test_equal_time_schedule(scene):
    eng = Engine(Job(scene, ("planes", "beams", "sphere"), SETTINGS, max_seconds=1.0))
    eng.spent = [0.5, 0.2, 0.2]
    assert eng.choose() == 1  # least time, ties by list order
    eng.spent = [0.5, 1.0, 0.7]
    assert eng.choose() == 0
    eng.spent = [1.0, 1.0, 1.0]
    assert eng.choose() is None


def test_compare_rows_ratio_and_relmse():
    rng = np.random.default_rng(0)

    def run(label, scale, seconds):
        acc = Welford.empty((4, 5, 3))
        for _ in range(4):
            acc.add(1.0 + scale * rng.standard_normal((4, 5, 3)))
        return SimpleNamespace(label=label, acc=acc, seconds=seconds)

    a, b = run("a", 1.0, 2.0), run("b", 0.5, 1.0)
    rows = compare_rows([a, b], reference=np.ones((4, 5, 3)))
    mv = [float(np.mean(r.acc.variance) / 4) for r in (a, b)]
    assert rows[0]["ratio"] == 1.0
    assert np.isclose(rows[1]["ratio"], mv[1] * 1.0 / (mv[0] * 2.0))
    assert rows[1]["relmse"] > 0
    assert rows[1]["equal"] == "time"
    one = SimpleNamespace(label="c", acc=Welford.empty((4, 5, 3)), seconds=0.0)
    assert compare_rows([one])[0]["ratio"] is None
    # Untimed (screenshots): equal passes, so the ratio is the plain variance ratio.
    a.seconds = b.seconds = 0.0
    rows = compare_rows([a, b])
    assert rows[1]["equal"] == "passes"
    assert np.isclose(rows[1]["ratio"], mv[1] / mv[0])


def test_a_killed_worker_is_restarted_keeping_the_merged_passes(scene):
    """Issue 15: the window's background render process dies (SIGKILL, as the OOM killer
    does): it is restarted on the passes already merged, says so once, and the image stays
    bit-identical to a serial render."""
    import os
    import signal
    import time

    with Progressive(scene, ["planes"], SETTINGS, seed=3, workers=1, max_passes=6) as prog:
        t0 = time.perf_counter()
        while prog.passes[0] < 2 and time.perf_counter() - t0 < 120:
            prog.poll()
            time.sleep(0.02)
        kept = prog.passes[0]
        assert kept >= 2
        old = prog.pids[0]
        os.kill(old, signal.SIGKILL)
        notices, seen = [], []
        while not (prog.done and notices) and time.perf_counter() - t0 < 180:
            prog.poll()
            notices += prog.take_notices()
            seen.append(prog.passes[0])
            time.sleep(0.02)
        assert prog.restarts == 1 and prog.pids[0] != old and not prog.errors
        assert any("died (killed by SIGKILL" in n and "restarted" in n for n in notices)
        assert min(seen) >= kept  # nothing merged was lost
        assert prog.passes == [6]
        assert _same(prog.runs[0].acc, _serial(scene, "planes", 6, 3))


def test_workers_that_keep_dying_stop_with_a_message(scene):
    """After MAX_RESTARTS deaths within the window the renderer stops restarting and says
    what happened (and how to start over) instead of looping."""
    from ui.cli import progressive as pg

    class Dead:
        def deaths(self):
            return [(0, -9)]

        def recent_restarts(self, window):
            return pg.MAX_RESTARTS

        def get(self, timeout=0.0):
            return None

    prog = Progressive(scene, ["planes"], SETTINGS, workers=0)
    prog.workers, prog._pool = 1, Dead()
    assert prog.poll() == 1
    assert prog.stopped and "keeps dying" in prog.errors[0] and "r starts over" in prog.errors[0]
    assert prog.poll() == 0  # no restart loop


def test_poll_waits_for_a_streaming_worker_within_its_budget(scene):
    """A worker's outbox sends its buffered results one after another, the next a moment
    after the last is read: ``poll`` waits up to ``STREAM_WAIT`` for it (within its budget)
    instead of returning after the first, so a 200 ms tick merges what the worker has ready
    (before, ~2 results a tick, and the worker, held by its full buffer, idled ~80 % of the
    time in the window)."""
    from ui.cli import progressive as pg

    prog = Progressive(scene, ["planes"], SETTINGS, workers=0)
    img = np.zeros((scene.camera.height, scene.camera.width, 3))
    waits = []

    class Streaming:  # the next message arrives only to a reader that waits for it
        def __init__(self, n):
            self.msgs = [("pass", prog._gen, 0, i, 0.01, img + i, None) for i in range(n)]

        def deaths(self):
            return []

        def get(self, timeout=0.0):
            waits.append(timeout)
            if self.msgs and (len(waits) == 1 or timeout > 0):
                return self.msgs.pop(0)
            return None

    prog.workers, prog._pool = 1, Streaming(5)
    assert prog.poll(budget=10.0) == 5
    assert prog.passes == [5] and prog.runs[0].acc.n == 5
    assert waits[0] == 0.0  # nothing received yet: no waiting when the worker is quiet
    assert all(0 < w <= pg.STREAM_WAIT for w in waits[1:])
    waits.clear()
    prog._pool = Streaming(0)
    assert prog.poll(budget=10.0) == 0 and waits == [0.0]  # an idle worker costs no wait


def test_compiling_is_not_render_time(scene, monkeypatch):
    """Defect 2 of issue 13: on a cold numba cache the first pass of an MIS set took the
    compile time (paper-multi "1 passes, 14.9 s" beside planes' 65): the engine compiles
    (warms up) before its first pass and reports those seconds apart."""
    import time

    import psurf_core.render as render_mod
    import ui.cli.progressive_worker as worker

    real = render_mod.render_pass
    compiled = set()

    def first_call_compiles(scene_, est, *a, **kw):  # numba: the first call compiles
        if est.spec not in compiled:
            compiled.add(est.spec)
            t0 = time.process_time()
            while time.process_time() - t0 < 0.6:  # compiling burns CPU
                pass
        return real(scene_, est, *a, **kw)

    monkeypatch.setattr(render_mod, "render_pass", first_call_compiles)
    monkeypatch.setattr(worker, "render_pass", first_call_compiles)
    monkeypatch.setattr(render_mod, "_WARMED", set())
    monkeypatch.setattr("ui.cli.progressive.COMPILE_CPU", 0.5)
    prog = Progressive(scene, ["planes", "mis:plane-t1t2+sphere"], SETTINGS, seed=1,
                       workers=0)
    prog.run(passes=2)
    for run in prog.runs:
        assert run.compile_seconds >= 0.6, run.spec
        assert run.seconds < 0.6 * run.acc.n, run.spec  # the passes alone
        assert _same(run.acc, _serial(scene, run.spec, run.acc.n, 1))
    notes = prog.take_notices()
    assert any("kernels compiled" in n and "not counted" in n for n in notes)


def test_the_panels_say_compiling_while_it_lasts(scene):
    from ui.cli.progressive import COMPILE_NOTE_AFTER, EstimatorRun

    run = EstimatorRun("paper-multi", None, Welford.empty((2, 2, 3)))
    assert run.note() == "waiting for the first pass..."
    run.warming_since = 100.0
    assert run.note(now=100.5) == "loading kernels..."
    assert run.note(now=100.0 + COMPILE_NOTE_AFTER + 10).startswith(
        "compiling kernels (first run)")
    run.acc.add(np.zeros((2, 2, 3)))
    assert run.note(now=1e9) == ""
