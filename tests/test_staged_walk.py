"""Staged walkers (``Compiled.staged``: the roots of a block of a span's rays first, those
inside their ray's interval kept, then those shaded) against the same family walked unstaged:
the same hits in the same order, bit for bit, and the same image bits, with blocks that cut
spans into pieces (a few rays) and blocks that hold whole spans."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from psurf_core.camera import camera_rays
from psurf_core.geometry import blockers_of
from psurf_core.kernels import walk as kwalk
from psurf_core.kernels.fused import fused_pass
from psurf_core.scene_io import load_scene
from psurf_core.techniques import get_technique
from psurf_core.techniques.base import PassContext
from psurf_core.trace import trace

ROOT = Path(__file__).resolve().parent.parent


def _walk(tech, prims, paths, rays, ctx):
    """Every emitted hit's columns (in the walker's order) and the image of a pass that
    emits nothing."""
    cols = []
    for hits, val, _ in fused_pass(tech, prims, paths, rays, ctx):
        cols.append((hits.ray.copy(), hits.prim.copy(), hits.s.copy(), np.array(hits.data),
                     val.copy()))
    out = np.zeros((len(rays), 3))
    assert not list(fused_pass(tech, prims, paths, rays, ctx, emit=False, out=out))
    return cols, out


@pytest.mark.parametrize(("name", "block"), [("cone", 3), ("ss-sphere", 5), ("cylinder", 256)])
def test_staged_walk_is_the_unstaged_walk(name, block, monkeypatch):
    scene = load_scene(ROOT / "scenes" / "area_occluder.toml")
    scene = replace(scene, camera=replace(scene.camera, width=32, height=24))
    blockers = blockers_of(scene)
    # Two rays a pixel: a span of a 32-pixel row holds up to 64 rays, so a block of 3 or 5
    # rays cuts most spans, 256 holds each whole.
    rays = camera_rays(scene, 2, np.random.default_rng(1), blockers=blockers)
    paths = trace(scene, 300, np.random.default_rng(2), blockers=blockers)
    ctx = PassContext(scene, blockers, 0.0, 0, 1 << 20)
    tech = get_technique(name)
    fam = type(tech).compiled
    assert fam.staged, f"{name} is expected to be a staged family"
    prims = tech.create(paths, ctx)
    monkeypatch.setattr(kwalk, "STAGE_BLOCK", block)
    runs = []
    for staged in (True, False):
        # A new declaration: a walker of its own (walk.walker keys them by the record).
        monkeypatch.setattr(type(tech), "compiled", replace(fam, staged=staged))
        runs.append(_walk(tech, prims, paths, rays, ctx))
    (cols_a, img_a), (cols_b, img_b) = runs
    assert len(cols_a) == len(cols_b) >= 1
    n = 0
    for a, b in zip(cols_a, cols_b, strict=True):
        for x, y in zip(a, b, strict=True):
            np.testing.assert_array_equal(x, y)
        n += len(a[0])
    assert n > 1000, n  # enough hits for the order to mean something
    np.testing.assert_array_equal(img_a, img_b)
    assert np.count_nonzero(img_a) > 100
