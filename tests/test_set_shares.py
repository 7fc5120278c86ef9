"""``benchmarks/set_shares.py``: per-set costs and variances of a summed preset, and the
shares the cost model prefers; and the pixel weights it passes to
``pass_size.split_variances``."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
from benchmark_support import ROOT, load_benchmark

from psurf_core.estimators import FULL_SINGLE_SHARES, parse_estimator
from psurf_core.pass_size import split_variances
from psurf_core.render import RenderSettings
from psurf_core.scene_io import load_scene
from psurf_core.share_pilot import set_alone

set_shares = load_benchmark("set_shares")


def test_a_set_is_measured_on_its_own_allocation():
    """The single-scattering set of ``fast-full`` for a point light, alone, its members back
    on every photon; the preset's share is reported as the set's present share."""
    scene = load_scene(ROOT / "scenes" / "point.toml")
    alone, top = set_alone("fast-full", scene, 0)
    assert top == FULL_SINGLE_SHARES["point"]
    assert [t.label for t in alone.techniques] == ["ss-sphere", "ss-cone-short", "ss-disk"]
    assert len(alone.sets) == 1
    # The estimator parsed by anyone else keeps its shares.
    assert [t.label for t in parse_estimator("fast-full", scene).sets[0][0]] == [
        "ss-sphere@0.15", "ss-cone-short@0.15", "ss-disk@0.15"]


def test_the_best_shares_beat_the_present_ones_in_the_model(tmp_path):
    out = tmp_path / "shares.json"
    assert set_shares.main([str(ROOT / "scenes" / "point.toml"), "--resolution", "16,12",
                            "--photons", "200", "--passes", "2", "--split-passes", "4",
                            "--out", str(out)]) == 0
    r = json.loads(out.read_text())
    assert [s["present_share"] for s in r["sets"]] == [FULL_SINGLE_SHARES["point"], 1.0]
    best = [s["best_share"] for s in r["sets"]]
    assert max(best) == 1.0 and min(best) > 0.0
    for s in r["sets"]:
        assert s["c1_s_per_photon"] > 0.0 and s["v_rel_per_photon"] > 0.0
    # The best shares minimise the model: no other allocation, the present one included,
    # is below them.
    assert r["model_best_vs_all_on"] <= r["model_present_vs_all_on"] * (1 + 1e-12)
    assert r["model_best_vs_all_on"] <= 1.0 + 1e-12


def test_split_variances_weigh_pixels():
    """The same seeds with every pixel weighted 2 give exactly twice ``Vj`` and ``Vp``."""
    scene = load_scene(ROOT / "scenes" / "point.toml").with_scatter(1, 1)
    scene = replace(scene, camera=replace(scene.camera, width=8, height=6))
    est = parse_estimator("ss-sphere", scene)
    st = RenderSettings(photons=100)
    vj, vp = split_variances(scene, est, st, passes=3, seed=5)
    vj2, vp2 = split_variances(scene, est, st, weight=np.full((6, 8, 3), 2.0), passes=3,
                               seed=5)
    assert vp > 0.0
    np.testing.assert_allclose([vj2, vp2], [2 * vj, 2 * vp], rtol=1e-12)
