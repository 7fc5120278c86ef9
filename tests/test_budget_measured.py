"""The memory model is above what runs really use, and not far above (``make test-slow``).

Each configuration renders in a fresh subprocess (``benchmarks/memory_model.py --one``), which
measures its peak RSS growth after a warm-up render; :func:`psurf_core.budget.render_need`
must be at least that (a run the check lets through fits) and at most 3.5x (a run it refuses
would not have fitted in far less). One size is large in each: the image, spp, photons at an
unlimited and a small scatter range, an MIS set, a mesh light.
"""

from __future__ import annotations

import sys

import pytest
from benchmark_support import load_benchmark

memory_model = load_benchmark("memory_model")

CASES = [
    {"est": "planes", "res": [1024, 768], "photons": 100},
    {"est": "reference", "res": [384, 288], "spp": 4},
    {"est": "planes", "photons": 32768},
    {"est": "planes", "photons": 32768, "max_scatter": 3},
    {"est": "paper-multi", "photons": 4096, "budget": 16},
    {"est": "planes", "photons": 2000, "mesh": "ico6"},
]


@pytest.mark.slow
@pytest.mark.skipif(sys.platform != "linux", reason="VmHWM in /proc/self/status is Linux's")
@pytest.mark.parametrize("cfg", CASES, ids=lambda c: "-".join(f"{v}" for v in c.values()))
def test_model_is_above_the_measured_peak(cfg):
    row = memory_model.measure(cfg)
    print(f"\n{cfg}: measured {row['measured_mib']} MiB, model {row['model_mib']} MiB")
    assert 1.0 <= row["ratio"] <= 3.5, row
