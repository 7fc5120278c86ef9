"""``benchmarks/bench_compare.py``: ``make bench``'s headline against the previous run's.

The documents here are made up; nothing is timed.
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
spec = importlib.util.spec_from_file_location("bench_compare",
                                              ROOT / "benchmarks" / "bench_compare.py")
bench_compare = importlib.util.module_from_spec(spec)
spec.loader.exec_module(bench_compare)


def _doc(planes_hits, planes_ns, trace, ratio, extra=None):
    head = {"hits_per_second": {"planes": planes_hits, **(extra or {})},
            "cpu_ns_per_hit": {"planes": planes_ns},
            "photon_vertices_per_second": trace, "hit_cost_ratio": ratio}
    return {"command": "python benchmarks/run.py", "headline": head,
            "machine": {"load_average": [1.0, 1.0, 1.0]}}


def test_session_23s_regression_is_flagged_and_the_idle_spread_is_not():
    previous = _doc(1.87e7, 90.0, 9.07e6, 1.34)
    # Run d of 2026-12-04 (the tuple regression) and the spread of idle runs (0.70x).
    regressed = bench_compare.compare(_doc(1.16e7, 150.0, 9.0e6, 1.30), previous)
    noisy = bench_compare.compare(_doc(0.72 * 1.87e7, 90.0 / 0.72, 9.9e6, 1.2), previous)
    worse = {r["figure"] for r in regressed if r["worse"]}
    assert worse == {"hits_per_second.planes", "cpu_ns_per_hit.planes"}
    assert not any(r["worse"] for r in noisy)


def test_direction_of_each_figure():
    previous = _doc(2e7, 100.0, 1e7, 1.0)
    # Faster everywhere: nothing flagged, even by large factors.
    assert not any(r["worse"] for r in bench_compare.compare(_doc(8e7, 25.0, 4e7, 0.5),
                                                             previous))
    # The cost ratio and the CPU per hit are worse when they grow, the rates when they fall.
    rows = {r["figure"]: r for r in bench_compare.compare(_doc(2e7, 100.0, 0.5e7, 1.6),
                                                          previous)}
    assert rows["hit_cost_ratio"]["worse"] and rows["photon_vertices_per_second"]["worse"]
    assert rows["photon_vertices_per_second"]["ratio"] == 0.5
    assert not rows["hits_per_second.planes"]["worse"]


def test_figures_missing_from_either_run_are_left_out(tmp_path):
    rows = bench_compare.compare(_doc(2e7, 100.0, 1e7, 1.0, {"cone": 1e7}),
                                 _doc(2e7, 100.0, 1e7, 1.0))
    assert "hits_per_second.cone" not in {r["figure"] for r in rows}
    text = bench_compare.report(rows, _doc(2e7, 100.0, 1e7, 1.0))
    assert "no figure worse" in text
    p = tmp_path / "bench.json"
    assert bench_compare.load_previous(p) is None
    p.write_text("{ half a document")
    assert bench_compare.load_previous(p) is None
    p.write_text(json.dumps(_doc(1, 1, 1, 1)))
    assert bench_compare.load_previous(p)["headline"]["hit_cost_ratio"] == 1
