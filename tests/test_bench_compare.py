"""``benchmarks/bench_compare.py``: ``make bench``'s headline against the previous run's.

The documents here are made up; nothing is timed.
"""

from __future__ import annotations

import json

from benchmark_support import load_benchmark

bench_compare = load_benchmark("bench_compare")


def _doc(planes_hits, planes_ns, trace, ratio, extra=None):
    head = {"hits_per_second": {"planes": planes_hits, **(extra or {})},
            "cpu_ns_per_hit": {"planes": planes_ns},
            "photon_vertices_per_second": trace, "hit_cost_ratio": ratio}
    return {"command": "python benchmarks/run.py", "headline": head,
            "machine": {"load_average": [1.0, 1.0, 1.0]}}


def test_the_machines_drift_is_not_a_regression_and_one_path_slower_is():
    previous = _doc(1.87e7, 90.0, 9.07e6, 1.34, {"cone": 1.5e7, "beams": 2e5})
    # 2026-12-04 11:12: the same commit twice, every figure 0.57-0.75x in the second run.
    drift = bench_compare.compare(_doc(0.72 * 1.87e7, 90.0 / 0.70, 0.70 * 9.07e6, 1.34,
                                       {"cone": 0.70 * 1.5e7, "beams": 0.63 * 2e5}), previous)
    assert not any(r["worse"] for r in drift)
    assert all(r["slower"] for r in drift if r["figure"] != "hit_cost_ratio")
    # One path 2x slower, the rest as before: only its figures are worse.
    one = bench_compare.compare(_doc(0.5 * 1.87e7, 180.0, 9.07e6, 1.34,
                                     {"cone": 1.5e7, "beams": 2e5}), previous)
    assert {r["figure"] for r in one if r["worse"]} == {"hits_per_second.planes",
                                                       "cpu_ns_per_hit.planes"}
    text = bench_compare.report(one, previous)
    assert "2 figure(s) worse" in text


def test_direction_of_each_figure():
    previous = _doc(2e7, 100.0, 1e7, 1.0)
    # Faster everywhere: nothing flagged, even by large factors.
    faster = bench_compare.compare(_doc(8e7, 25.0, 4e7, 0.5), previous)
    assert not any(r["worse"] or r["slower"] for r in faster)
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
