"""``benchmarks/pass_phases.py`` on a small pass: a ``planes`` pass's phases in order (the
spans' two thread jobs, the walk's, Python between), their medians adding up to about the
pass, ``on_threads`` put back; bad flags exit 2. Nothing here is timed beyond being there."""

from __future__ import annotations

import json
import math

from benchmark_support import ROOT, load_benchmark

from psurf_core.kernels import fused, spans

pass_phases = load_benchmark("pass_phases")


def test_phases_in_order_and_put_back(tmp_path, capsys):
    patched = (fused.on_threads, spans.on_threads)
    out = tmp_path / "ph.json"
    rc = pass_phases.main([str(ROOT / "scenes" / "point.toml"), "--photons", "300",
                           "--rounds", "3", "--threads", "1", "--json", str(out)])
    assert rc == 0
    assert "plane-t1t2-short" in capsys.readouterr().out
    res = json.loads(out.read_text())
    assert list(res) == ["plane-t1t2-short"]
    names = [n for n, _ in res["plane-t1t2-short"]]
    assert names == ["serial", "project", "serial", "fill", "serial", "piece", "serial"]
    assert all(math.isfinite(ms) and ms >= 0 for _, ms in res["plane-t1t2-short"])
    assert (fused.on_threads, spans.on_threads) == patched


def test_bad_flags_exit_2(capsys):
    assert pass_phases.main([str(ROOT / "scenes" / "point.toml"), "--rounds", "1"]) == 2
    assert "pass_phases: --rounds" in capsys.readouterr().err
