"""The cheap rejects in ``Blockers.occluded`` (segment box vs blocker boxes, emitter-plane
crossing) never change an answer: random segments, many touching or leaving an emitter, give
the same result with and without them, in every bundled scene with blockers."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from psurf_core.geometry import blockers_of
from psurf_core.scene_io import load_scene

ROOT = Path(__file__).resolve().parent.parent
SCENES = sorted(p.name for p in (ROOT / "scenes").glob("*.toml"))


@pytest.mark.parametrize("name", SCENES)
def test_rejects_keep_every_answer(name):
    scene = load_scene(ROOT / "scenes" / name)
    fast = blockers_of(scene)
    if fast.empty:
        pytest.skip("no blockers")
    exact = replace(fast, bounds=None, planes=None)
    rng = np.random.default_rng(0)
    lo, hi = scene.medium.bounds_min - 0.2, scene.medium.bounds_max + 0.2
    n = 4000
    a = rng.uniform(lo, hi, size=(n, 3))
    b = rng.uniform(lo, hi, size=(n, 3))
    # Segments starting on (or just off) the blockers' boxes' faces, as photons leaving an
    # emitter do, and short segments near them.
    for blo, bhi in fast.bounds:
        k = n // 4
        p = rng.uniform(blo, bhi, size=(k, 3))
        a = np.concatenate([a, p, p])
        b = np.concatenate([b, rng.uniform(lo, hi, size=(k, 3)),
                            p + rng.normal(scale=1e-3, size=(k, 3))])
    got = fast.occluded(a, b)
    want = exact.occluded(a, b)
    assert want.any() and not want.all()
    np.testing.assert_array_equal(got, want)
