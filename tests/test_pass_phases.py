"""``benchmarks/pass_phases.py`` on a small pass (in a child process: the script clocks
``render_pass``'s parts by replacing them in their modules): a line per phase, and the walks'
serial image addition (``fused.accumulate`` or ``fused.add_images``) printed beside them,
within their time."""

from __future__ import annotations

import re

from benchmark_support import ROOT, run_benchmark


def test_phases_and_accumulate():
    out = run_benchmark("pass_phases", ROOT / "scenes" / "area.toml", 2, 3, "planes",
                        "--photons", 400, "--passes", 3, "--resolution", "64,48").stdout
    wall = {m[0].strip(): float(m[1]) for m in
            re.findall(r"^  (\S.*?)\s+wall\s+(-?[\d.]+) ms", out, re.M)}
    assert {"trace", "create plane-t1t2-short", "walk plane-t1t2-short",
            "image addition (in the walks)"} <= set(wall), out
    # The image addition runs inside the walk phase: never longer than it, and not nothing
    # (a 400-photon pass's ~70k candidate pairs are walked in pieces with images of their
    # own, added to the pass's).
    assert 0.0 < wall["image addition (in the walks)"] <= wall["walk plane-t1t2-short"], out
