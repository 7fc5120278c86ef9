"""The fused cone / cylinder / generalized-plane kernels (``surfaces_fused``) find exactly the
stage path's hits (binning -> ``intersect``) with the same ``data`` fields and per-photon
values (``evaluate``), on every bundled scene, long and short, for pinhole rays and for
per-ray origins; a whole ``paper-multi`` pass (fused hits inside the MIS group) equals the
same pass on the stage path."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from psurf_core.camera import camera_rays
from psurf_core.estimators import parse_estimator
from psurf_core.geometry import blockers_of
from psurf_core.render import RenderSettings, render_pass, stage_chunks
from psurf_core.scene_io import load_scene
from psurf_core.techniques import get_technique
from psurf_core.techniques.base import PassContext, Technique
from psurf_core.trace import trace

SCENES = sorted((Path(__file__).resolve().parent.parent / "scenes").glob("*.toml"))
NAMES = ["cone", "cylinder", "plane-t1t3", "plane-t2t3"]


def _stage(tech, prims, paths, rays, ctx):
    return list(stage_chunks(tech, prims, paths, rays, ctx))


def _flat(chunks):
    """Hits of all chunks sorted by (ray, prim, s): index columns, float columns (every
    ``data`` field, 2D ones flattened), values; and the ``data`` keys."""
    keys = sorted(chunks[0][0].data)
    ray = np.concatenate([h.ray for h, _ in chunks])
    prim = np.concatenate([h.prim for h, _ in chunks])
    s = np.concatenate([h.s for h, _ in chunks])
    order = np.lexsort((s, prim, ray))
    cols = [s] + [np.concatenate([h.data[k] for h, _ in chunks]) for k in keys]
    vals = np.concatenate([v for _, v in chunks])
    return (ray[order], prim[order]), [c[order] for c in cols], vals[order], keys


def _setup(path, pinhole, width=20, height=15, photons=150):
    scene = load_scene(path)
    scene = replace(scene, camera=replace(scene.camera, width=width, height=height))
    blockers = blockers_of(scene)
    rays = camera_rays(scene, 2, np.random.default_rng(1), blockers=blockers)
    if not pinhole:
        rays = replace(rays, origin=None)
    paths = trace(scene, photons, np.random.default_rng(2), blockers=blockers)
    return scene, blockers, rays, paths


@pytest.mark.parametrize("short", [True, False], ids=["short", "long"])
@pytest.mark.parametrize("pinhole", [True, False], ids=["pinhole", "per-ray-origin"])
@pytest.mark.parametrize("path", SCENES, ids=[p.stem for p in SCENES])
def test_fused_equals_stages(path, short, pinhole, monkeypatch):
    import psurf_core.techniques.surfaces_fused as sf

    scene, blockers, rays, paths = _setup(path, pinhole)
    # A small pair budget so that several chunks are made.
    ctx = PassContext(scene, blockers, 0.0, 0, 1500)
    deferred = []
    real_resolve = sf._resolve

    def resolve(kind, blockers, rays, prims, hits, st, val):
        deferred.append(kind)
        return real_resolve(kind, blockers, rays, prims, hits, st, val)

    monkeypatch.setattr(sf, "_resolve", resolve)
    for name in NAMES:
        tech = get_technique(name + ("-short" if short else ""))
        if not any(tech.applies_to(lt) for lt in scene.lights):
            continue
        prims = tech.create(paths, ctx)
        stage = _stage(tech, prims, paths, rays, ctx)
        fused = list(tech.fused_pass(prims, paths, rays, ctx))
        if not stage:
            assert not fused, name
            continue
        assert len(fused) > 1, name
        (a_idx, a_cols, a_val, a_keys), (b_idx, b_cols, b_val, b_keys) = (_flat(stage),
                                                                          _flat(fused))
        assert a_keys == b_keys, name
        for x, y in zip(a_idx, b_idx, strict=True):
            np.testing.assert_array_equal(y, x, err_msg=name)
        # Sums of products may round differently (numpy's einsum): 1e-12 relative or 1e-12
        # scene units (near cancellation).
        for k, x, y in zip(["s", *a_keys], a_cols, b_cols, strict=True):
            np.testing.assert_allclose(y, x, rtol=1e-12, atol=1e-12, err_msg=f"{name} {k}")
        np.testing.assert_allclose(b_val, a_val, rtol=1e-12,
                                   atol=1e-12 * np.abs(a_val).max(), err_msg=name)
    # Scenes with triangle meshes hand segments to Blockers.occluded (the exact test).
    assert bool(deferred) == (blockers.triangles.shape[0] > 0)


def test_fused_finds_hits_and_nonzero_values_somewhere():
    """The equality test above is not vacuous: every family has hits with values on the
    default scene, occluded ones included."""
    path = SCENES[[p.stem for p in SCENES].index("area_occluder")]
    scene, blockers, rays, paths = _setup(path, True, photons=400)
    ctx = PassContext(scene, blockers, 0.0, 0, 1 << 20)
    for name in NAMES:
        tech = get_technique(name)
        chunks = list(tech.fused_pass(tech.create(paths, ctx), paths, rays, ctx))
        vals = np.concatenate([v for _, v in chunks])
        assert vals.shape[0] > 100 and np.count_nonzero(vals[:, 0]) > 50, name
        assert np.count_nonzero(vals[:, 0] == 0) > 0, name


@pytest.mark.parametrize("name", ["plane-t1t2", "planes"])
def test_fused_plane_hits_carry_the_stage_data(name):
    """``photon_pass`` hands fused hits to the MIS weights (``reconstruct``) and the UI: the
    photon plane's fused hits have the stage path's ``data`` fields, with the same shapes."""
    path = SCENES[[p.stem for p in SCENES].index("area_occluder")]
    scene, blockers, rays, paths = _setup(path, True)
    ctx = PassContext(scene, blockers, 0.0, 0, 1 << 20)
    tech = get_technique(name)
    prims = tech.create(paths, ctx)
    (a, _), = _stage(tech, prims, paths, rays, ctx)
    (b, _), = list(tech.fused_pass(prims, paths, rays, ctx))
    assert sorted(a.data) == sorted(b.data)
    for k in a.data:
        assert a.data[k].shape == b.data[k].shape and a.data[k].dtype == b.data[k].dtype, k


def test_paper_multi_pass_with_fused_members_equals_stages(monkeypatch):
    """A whole ``paper-multi`` pass, every member fused inside the MIS group, equals the same
    pass with every fused path switched off; the tally hook sees the same hits."""
    scene = load_scene(SCENES[[p.stem for p in SCENES].index("area_occluder")])
    scene = replace(scene, camera=replace(scene.camera, width=24, height=16))
    est = parse_estimator("paper-multi", scene)
    settings = RenderSettings(photons=150)
    seen = {}

    def tally(tech, hits, prims, rays, raw, val):
        seen[tech.name] = seen.get(tech.name, 0) + len(hits)

    used = set()

    def spy(real):
        def fused_pass(self, *a):
            out = real(self, *a)
            if out is not None:
                used.add(self.name)
            return out
        return fused_pass

    kinds = {type(t) for t in est.groups[0]}
    for kind in kinds:
        monkeypatch.setattr(kind, "fused_pass", spy(kind.fused_pass))
    fused = render_pass(scene, est, 0, 3, settings, tally=tally)
    assert used == {t.name for t in est.groups[0]} and len(used) == 5
    n_fused = dict(seen)
    seen.clear()
    for kind in kinds:
        monkeypatch.setattr(kind, "fused_pass", Technique.fused_pass)
    stage = render_pass(scene, est, 0, 3, settings, tally=tally)
    assert n_fused == seen and len(seen) == 5 and min(seen.values()) > 0
    np.testing.assert_allclose(fused, stage, rtol=1e-12, atol=1e-300)
