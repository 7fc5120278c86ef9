"""``benchmarks/stages.py``: the CPU-per-hit ratio of ``make bench`` from passes run back to
back (the figures are timed, so only how they are combined is checked)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from benchmark_support import load_benchmark

from psurf_core.scene_io import load_scene

stages = load_benchmark("stages")


def test_paired_cost_ratio_is_the_median_of_back_to_back_rounds():
    scene = load_scene(Path(__file__).resolve().parents[1] / "scenes" / "area.toml")
    r = stages.paired_cost_ratio(scene, "planes", "plane-t1t2", 300, 3)
    a, b = r["cpu_ns_per_hit"]["planes"], r["cpu_ns_per_hit"]["plane-t1t2"]
    assert len(a) == len(b) == r["rounds"] == len(r["each_ratio"]) == 3
    np.testing.assert_allclose(r["each_ratio"], np.array(b) / np.array(a))
    assert r["ratio"] == float(np.median(r["each_ratio"])) > 0
