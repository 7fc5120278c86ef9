"""``benchmarks/blocked_hits.py`` on a small pass: the statuses it reads are the walk's (a hit
is blocked exactly where its value is 0), a strip's hits outside the box are among its
blocked ones, and the script prints a row per member."""

from __future__ import annotations

import numpy as np
from benchmark_support import ROOT, load_benchmark

from psurf_core.camera import camera_rays
from psurf_core.estimators import parse_estimator
from psurf_core.geometry import blockers_of
from psurf_core.kernels.fused import MisSet
from psurf_core.kernels.shadow import BLOCKED
from psurf_core.render import RenderSettings, pass_generators
from psurf_core.scene_io import load_scene
from psurf_core.techniques.base import PassContext
from psurf_core.trace import trace

blocked_hits = load_benchmark("blocked_hits")


def test_statuses_are_the_walks(capsys):
    scene = load_scene(ROOT / "scenes" / "area_occluder.toml").with_scatter(2, 3)
    est = parse_estimator("mis:planes+plane-ut-short", scene)
    blockers = blockers_of(scene)
    ray_rng, photon_ss = pass_generators(0, 0)
    rays = camera_rays(scene, 1, ray_rng, blockers=blockers)
    paths = trace(scene, 150, np.random.default_rng(photon_ss.spawn(1)[0]), blockers=blockers)
    group, full = est.sets[0]
    for tech in group:
        ctx = PassContext(scene, blockers, 0.0, 0, RenderSettings().max_pairs)
        prims = tech.create(paths, ctx)
        hits, status, vals = blocked_hits.walk_statuses(tech, prims, paths, rays, ctx,
                                                        MisSet(group, full, est.weighting))
        blocked = (status == BLOCKED).any(axis=1)
        assert blocked.sum() > 10 and (~blocked).sum() > 100, tech.name
        np.testing.assert_array_equal(blocked, np.all(vals == 0.0, axis=1))
        out = np.concatenate([blocked_hits.outside(tech, prims, h, scene) for h in hits])
        assert not np.any(out & ~blocked), tech.name
    assert blocked_hits.main([str(ROOT / "scenes" / "area_occluder.toml"), "2", "3",
                              "mis:planes+plane-ut-short", "--photons", "100",
                              "--outside"]) == 0
    rows = capsys.readouterr().out.splitlines()
    assert rows[0].startswith("# python benchmarks/blocked_hits.py")
    assert [r.split()[0] for r in rows[2:]] == ["plane-t1t2-short", "plane-ut-short"]
