"""``benchmarks/pass_breakdown.py`` on a small pass: its tables' keys, ablated walkers that find
the same hits as the walker they come from, and everything it patches put back.

Nothing here is timed: the times it measures are only checked to be there and finite.
"""

from __future__ import annotations

import json
import math

from benchmark_support import ROOT, load_benchmark

from psurf_core.kernels import fused
from psurf_core.techniques import get_technique

pass_breakdown = load_benchmark("pass_breakdown")

ROW_KEYS = {"pass_ms", "pass_cpu_ms", "spans_ms", "spans_cpu_ms", "walker_ms", "walker_cpu_ms",
            "other_ms", "hits", "candidates", "hits_per_second", "threads_used",
            "hits_each_round"}


def test_tables_and_ablated_hits(tmp_path, capsys):
    patched = (fused._Run.spans, fused._Run.walk_chunk, fused.thread_count)
    out = tmp_path / "pb.json"
    rc = pass_breakdown.main([str(ROOT / "scenes" / "point.toml"), "--photons", "300",
                              "--rounds", "2", "--ablate", "--scaling", "--json", str(out)])
    assert rc == 0
    printed = capsys.readouterr().out
    assert "hits: the same in every variant and round" in printed
    assert "walker CPU ns a hit, per technique" in printed
    res = json.loads(out.read_text())
    assert set(res["breakdown"]) == {"plane-t1t2-short", "total"}
    assert set(res["ablate"]) == set(pass_breakdown.VARIANTS)
    assert set(res["scaling"]) == {"1", "2", "walker_wall_ratio_1_to_2"}
    rows = [*res["breakdown"].values(), *res["ablate"].values(), res["scaling"]["1"],
            res["scaling"]["2"]]
    for row in rows:
        assert set(row) - {"techniques"} == ROW_KEYS
    for row in [*res["ablate"].values(), res["scaling"]["1"], res["scaling"]["2"]]:
        # each variant's pass, technique by technique too
        assert set(row["techniques"]) == {"plane-t1t2-short"}
        assert set(row["techniques"]["plane-t1t2-short"]) == ROW_KEYS
        assert all(math.isfinite(row[k]) and row[k] >= 0 for k in ROW_KEYS
                   if k.endswith("_ms") and k != "other_ms")
    base = res["breakdown"]["total"]
    assert base["hits"] > 0 and base["candidates"] >= base["hits"]
    # Leaving out the shadow tests or the contribution changes the work per hit, never
    # which pairs are hits: every variant and thread count, every round, the same hits.
    for row in rows:
        assert row["hits_each_round"] == [base["hits"]] * 2
        assert row["candidates"] == base["candidates"]
    assert res["scaling"]["walker_wall_ratio_1_to_2"] > 0
    # The timing hooks and the techniques' compiled records are put back.
    assert (fused._Run.spans, fused._Run.walk_chunk, fused.thread_count) == patched


def test_compiled_record_put_back():
    # ``planes`` holds its record on the instance, ``sphere`` inherits its class's.
    for name in ("planes", "sphere"):
        tech = get_technique(name)
        own, fam = dict(vars(tech)).get("compiled"), tech.compiled
        novis = pass_breakdown.ablated(fam)["novis"]
        assert novis is not fam and novis.visibility is not fam.visibility
        with pass_breakdown.compiled_as(tech, novis):
            assert tech.compiled is novis
        assert tech.compiled is fam and vars(tech).get("compiled") is own


def test_uncompiled_technique_is_one_line_exit_2(capsys):
    rc = pass_breakdown.main([str(ROOT / "scenes" / "point.toml"), "--spec", "points",
                              "--photons", "50", "--rounds", "2"])
    err = capsys.readouterr().err
    assert rc == 2
    assert err.count("\n") == 1 and "'points' has no compiled walker" in err
