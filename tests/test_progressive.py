"""Background progressive rendering (``ui.cli.progressive``): merged passes equal a serial render
bit for bit, whichever process rendered them and in whatever order they arrived."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from psurf_core.accumulate import Welford
from psurf_core.breakdown import BreakdownAccumulator, BreakdownLayout, render_pass_breakdown
from psurf_core.estimators import parse_estimator
from psurf_core.render import RenderSettings, render
from psurf_core.scene_io import load_scene
from psurf_core.techniques import UnknownTechnique
from ui.cli.progressive import Job, Progressive, _Engine, compare_rows

SETTINGS = RenderSettings(photons=150)


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
        prog.run(timeout=120)
        assert prog.done and prog.passes == [3, 3] and not prog.errors
        for run in prog.runs:
            assert _same(run.acc, _serial(scene, run.spec, 3, 5)), run.spec
            assert run.seconds > 0
        b = prog.runs[1].breakdown
        ref = _serial_breakdown(scene, "mis:plane-t1t2+sphere", 3, 5)
        assert _same(b.weighted, ref.weighted) and _same(b.unweighted, ref.unweighted)


def test_two_workers_merge_in_pass_order(scene):
    with Progressive(scene, ["planes"], SETTINGS, seed=8, workers=2, max_passes=5) as prog:
        prog.run(timeout=120)
        assert prog.passes == [5]
        assert _same(prog.runs[0].acc, _serial(scene, "planes", 5, 8))


def test_out_of_order_passes_wait_for_their_predecessors(scene):
    prog = Progressive(scene, ["planes"], SETTINGS, seed=1, workers=0)
    eng = _Engine(prog.job, first=0, stride=1)
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
        prog.run(timeout=120)
        prog.reset(estimators=["beams", "planes"], seed=4, max_passes=2)
        assert prog.passes == [0, 0]
        prog.run(timeout=120)
        assert [r.spec for r in prog.runs] == ["beams", "planes"]
        assert _same(prog.runs[0].acc, _serial(scene, "beams", 2, 4))
        assert _same(prog.runs[1].acc, _serial(scene, "planes", 2, 4))


def test_bad_spec_fails_before_any_process(scene):
    with pytest.raises(UnknownTechnique):
        Progressive(scene, ["no-such-thing"], SETTINGS, workers=1)
    with pytest.raises(ValueError):
        Progressive(scene, [], SETTINGS, workers=0)


def test_equal_time_schedule(scene):
    eng = _Engine(Job(scene, ("planes", "beams", "sphere"), SETTINGS, max_seconds=1.0))
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


def test_a_killed_worker_is_reported(scene):
    import time

    with Progressive(scene, ["planes"], SETTINGS, seed=0, workers=1) as prog:
        prog._procs[0].kill()
        prog._procs[0].join(timeout=10)
        t0 = time.perf_counter()
        while not prog.errors and time.perf_counter() - t0 < 10:
            prog.poll()
        assert any("exited unexpectedly" in e for e in prog.errors)
