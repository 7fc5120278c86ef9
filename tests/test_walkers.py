"""The compiled walkers (``psurf_core.kernels``) against the numpy stages they are built from.

* For every technique with a compiled declaration, on every bundled scene, long and short,
  for pinhole rays and per-ray origins, in several chunks: the walker's hits are the stage
  path's (binning -> ``intersect``), with the same hit records and per-photon values
  (``evaluate``) to 1e-12; scenes with triangle meshes exercise the deferred exact tests.
* Without ``emit`` the walker adds to the per-ray sums what the emitted hits hold.
* The MIS weights composed from the members' compiled densities equal the numpy reference
  (``mis.mis_weights``), for the paper's presets, short members, the power heuristic, and
  sets with members switched off (``SPEC~A``), which compile nothing new.
* Threads, pieces and chunking change no hit and no image bit.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scene_support import scene_params

from psurf_core.camera import camera_rays
from psurf_core.estimators import parse_estimator
from psurf_core.geometry import Blockers, blockers_of
from psurf_core.kernels import fused as kfused
from psurf_core.kernels import spans as kspans
from psurf_core.kernels import walk as kwalk
from psurf_core.kernels.fused import MisSet, fused_pass
from psurf_core.mis import mis_weights
from psurf_core.render import (
    RenderSettings,
    member_shares,
    photons_used,
    render_pass,
    stage_chunks,
)
from psurf_core.scene_io import load_scene
from psurf_core.techniques import REGISTRY, get_technique
from psurf_core.techniques.base import PassContext
from psurf_core.trace import trace

SCENES = sorted((Path(__file__).resolve().parent.parent / "scenes").glob("*.toml"))


def _compiled_names():
    names = []
    for name, entry in REGISTRY.items():
        for n in [name] + ([name + "-short"] if entry.has_short else []):
            tech = get_technique(n)
            if tech.compiled is not None and n != "planes":  # planes = plane-t1t2-short
                names.append(n)
    return names


NAMES = _compiled_names()


def _setup(path, pinhole, width=20, height=15, photons=150):
    scene = load_scene(path)
    scene = replace(scene, camera=replace(scene.camera, width=width, height=height))
    blockers = blockers_of(scene)
    rays = camera_rays(scene, 2, np.random.default_rng(1), blockers=blockers)
    if not pinhole:  # per-ray origins: nudge them so no ray starts at the camera
        rays = replace(rays, origin=None, o=rays.o + 1e-7 * np.arange(len(rays))[:, None])
    paths = trace(scene, photons, np.random.default_rng(2), blockers=blockers)
    return scene, blockers, rays, paths


def _flat(chunks):
    """Hits of all chunks sorted by (ray, prim, s): indices, float columns (``s`` and every
    hit field), values."""
    ray = np.concatenate([c[0].ray for c in chunks])
    prim = np.concatenate([c[0].prim for c in chunks])
    s = np.concatenate([c[0].s for c in chunks])
    data = np.concatenate([c[0].data for c in chunks])
    order = np.lexsort((s, prim, ray))
    cols = [s] + [data[k].reshape(len(s), -1) for k in data.dtype.names]
    vals = np.concatenate([c[1] for c in chunks])
    return (ray[order], prim[order]), [c[order] for c in cols], vals[order], data.dtype.names


def test_every_compiled_family_is_covered():
    """The tests below run over the registry's compiled techniques: all of them."""
    assert {"plane-t1t2", "plane-t1t2-short", "plane-t1t3", "plane-t2t3-short", "cone",
            "cylinder-short", "ss-sphere", "ss-cone-short", "ss-disk", "ss-plane-uv",
            "ss-plane-ut-short", "ss-plane-vt"} <= set(NAMES)


#: The families checked on scenes with triangles in make test: one per module of visibility
#: twins (planes, generalized planes, cones, revolutions, single-scattering planes and
#: cones). Triangles change only the type of the shadow argument every visibility twin hands
#: to ``kernels.shadow.status``, so each family's walker compiles again for them (~5 s each
#: on a fresh clone); every family on them runs in make test-slow.
ON_TRIANGLES = ["plane-t1t2", "plane-t1t3", "cone", "hyperboloid", "ss-plane-uv", "ss-disk"]


def _has_triangles(path) -> bool:
    return blockers_of(load_scene(path)).triangles.shape[0] > 0


@pytest.mark.parametrize("pinhole", [True, False], ids=["pinhole", "per-ray-origin"])
@pytest.mark.parametrize("path", scene_params())
def test_walker_equals_stages(path, pinhole, monkeypatch):
    _walker_equals_stages(path, pinhole, monkeypatch,
                          ON_TRIANGLES if _has_triangles(path) else NAMES)


@pytest.mark.slow
@pytest.mark.parametrize("path", [p for p in SCENES if _has_triangles(p)],
                         ids=lambda p: p.stem)
def test_every_walker_equals_stages_on_triangles(path, monkeypatch):
    _walker_equals_stages(path, True, monkeypatch, NAMES)


def _walker_equals_stages(path, pinhole, monkeypatch, names):
    scene, blockers, rays, paths = _setup(path, pinhole)
    ctx = PassContext(scene, blockers, 0.0, 0, 1500)  # a small budget: several chunks
    # ... of at most max_pairs (a walk's rows would let a chunk hold ~10x as many pairs)
    monkeypatch.setattr(kfused, "CHUNK_BYTES", 1)
    numpy_tests = []  # calls of Blockers.occluded while a walker runs
    real = Blockers.occluded
    monkeypatch.setattr(Blockers, "occluded",
                        lambda self, *a: numpy_tests.append(1) or real(self, *a))
    covered = 0
    for name in names:
        tech = get_technique(name)
        if not any(tech.applies_to(lt) for lt in scene.lights):
            continue
        prims = tech.create(paths, ctx)
        stage = list(stage_chunks(tech, prims, paths, rays, ctx))
        n_before = len(numpy_tests)
        st = {}
        fused = list(fused_pass(tech, prims, paths, rays, ctx, stats=st))
        # The walker tests every segment itself, triangle meshes included (no hand-back).
        assert len(numpy_tests) == n_before, name
        if not stage:
            assert not fused, name
            continue
        covered += 1
        # several chunks (a chunk is yielded where it has hits), where there are enough
        # hits and candidate pairs for the budget to split them (the dense scene's optical
        # depth leaves some techniques a handful; a hull cut to where hits count, a few
        # candidates)
        assert (len(fused) > 1 or sum(len(c[0].ray) for c in fused) < 100
                or st["candidates"] <= 2 * ctx.max_pairs), name
        (a_idx, a_cols, a_val, a_keys), (b_idx, b_cols, b_val, b_keys) = (_flat(stage),
                                                                          _flat(fused))
        assert a_keys == b_keys, name
        for x, y in zip(a_idx, b_idx, strict=True):
            np.testing.assert_array_equal(y, x, err_msg=name)
        for k, x, y in zip(["s", *a_keys], a_cols, b_cols, strict=True):
            np.testing.assert_allclose(y, x, rtol=1e-12, atol=1e-12, err_msg=f"{name} {k}")
        np.testing.assert_allclose(b_val, a_val, rtol=1e-12, atol=1e-12 * np.abs(a_val).max(),
                                   err_msg=name)
    assert covered >= 4


def test_walkers_find_hits_and_nonzero_values_somewhere():
    """The equality above is not vacuous: every family has hits with values, and occluded
    ones, on a scene with an occluder."""
    path = SCENES[[p.stem for p in SCENES].index("area_occluder")]
    scene, blockers, rays, paths = _setup(path, True, photons=400)
    ctx = PassContext(scene, blockers, 0.0, 0, 1 << 20)
    for name in NAMES:
        tech = get_technique(name)
        vals = np.concatenate([v for _, v, _ in
                               fused_pass(tech, tech.create(paths, ctx), paths, rays, ctx)])
        assert vals.shape[0] > 50 and np.count_nonzero(vals[:, 0]) > 20, name
        assert np.count_nonzero(vals[:, 0] == 0) > 0, name


# Each family once and each kind of shadow argument once (the table alone, the tuple with
# triangles) in make test; the two other pairs, ~40 s of compilation each on a fresh clone,
# in make test-slow.
@pytest.mark.parametrize("name, spec", [
    ("area_occluder", "paper-single"), ("mesh_light", "paper-multi"),
    pytest.param("area_occluder", "paper-multi", marks=pytest.mark.slow),
    pytest.param("mesh_light", "paper-single", marks=pytest.mark.slow)])
def test_accumulating_walker_adds_what_it_would_emit(name, spec):
    scene, blockers, rays, paths = _setup(SCENES[[p.stem for p in SCENES].index(name)], True)
    ctx = PassContext(scene, blockers, 0.0, 0, 1500)
    est = parse_estimator(spec, scene)
    (group,) = est.groups
    mis = MisSet(group, group, "balance")
    for tech in group:
        prims = tech.create(paths, ctx)
        want = np.zeros((len(rays), 3))
        for hits, val, w in fused_pass(tech, prims, paths, rays, ctx, mis):
            np.add.at(want, hits.ray, val * w[:, None])
        got = np.zeros((len(rays), 3))
        assert not list(fused_pass(tech, prims, paths, rays, ctx, mis, emit=False, out=got))
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12 * np.abs(want).max())


# Sets whose walkers nothing else compiles run in make test-slow (each costs ~15-40 s of
# numba compilation on a fresh clone).
_SLOW = pytest.mark.slow
MIS_SPECS = ["paper-multi",
             pytest.param("mis-power:plane-t1t2-short+cone-short+cylinder+plane-t2t3",
                          marks=_SLOW),
             pytest.param("mis:planes+cone+cylinder-short", marks=_SLOW), "paper-multi~cone",
             "paper-multi~plane-t1t2~cylinder",
             pytest.param("mis:planes+cone-short@0.3+cylinder@0.5", marks=_SLOW),
             "mis-power:planes@0.6+cone@0.2", "paper-single", "paper-single~ss-sphere",
             pytest.param("mis-power:ss-plane-uv+ss-plane-ut-short+ss-plane-vt+ss-cone-short"
                          "+ss-disk+ss-sphere", marks=_SLOW), "fast-single", "fast-multi"]


#: (scene, set) pairs in make test-slow: a scene with triangles compiles every set's walkers
#: again (the shadow argument is another type), ~20-50 s each on a fresh clone. The mesh
#: light keeps ``paper-multi`` and ``fast-single`` (its presets' sets) in make test; the other
#: sets' MIS weights on it are the same functions on other data (the light's pdfs are read
#: from the photon table at run time), checked on the three scenes without triangles.
_SLOW_ON_MESH = {"paper-single", "paper-single~ss-sphere", "fast-multi",
                 "mis-power:planes@0.6+cone@0.2"}


def _scene_set_pairs():
    for name in ["area_occluder", "hg", "mesh_light", "point"]:
        for spec in MIS_SPECS:
            marks, value = [], spec
            if hasattr(spec, "marks"):  # a pytest.param
                marks, value = list(spec.marks), spec.values[0]
            if name == "mesh_light" and value in _SLOW_ON_MESH:
                marks = [*marks, _SLOW]
            yield pytest.param(value, name, marks=marks, id=f"{name}-{value}")


@pytest.mark.parametrize(("spec", "name"), list(_scene_set_pairs()))
def test_compiled_mis_weights_equal_numpy(spec, name):
    scene, blockers, rays, paths = _setup(SCENES[[p.stem for p in SCENES].index(name)], True)
    ctx = PassContext(scene, blockers, 0.0, 0, 1 << 20)
    est = parse_estimator(spec, scene)
    n = 0
    for group, full in est.sets:
        if len(group) < 2:
            continue
        shares = member_shares(group, len(paths), full)
        for tech in group:
            prims = tech.create(paths.subset(np.arange(photons_used(tech, len(paths)))), ctx)
            for hits, _, w in fused_pass(tech, prims, paths, rays, ctx,
                                         MisSet(group, full, est.weighting, shares)):
                ref = mis_weights(tech, full, est.weighting, hits, prims, paths, rays, ctx,
                                  shares)
                np.testing.assert_allclose(w, ref, rtol=1e-12, atol=1e-14,
                                           err_msg=f"{spec} {tech.name}")
                n += len(hits)
    assert n > 100


def test_switching_members_off_compiles_nothing_new():
    """``SPEC~A`` runs the walkers built for ``SPEC`` (a window toggle compiles nothing)."""
    path = SCENES[[p.stem for p in SCENES].index("area_occluder")]
    scene = replace(load_scene(path), camera=replace(load_scene(path).camera, width=24,
                                                       height=16))
    settings = RenderSettings(photons=100)
    render_pass(scene, parse_estimator("paper-multi", scene), 0, 1, settings)
    before = set(kwalk._WALKERS)
    render_pass(scene, parse_estimator("paper-multi~cone~plane-t2t3", scene), 0, 1, settings)
    assert set(kwalk._WALKERS) == before


@pytest.mark.parametrize("name", ["area_occluder", "mesh_light"])
def test_threads_change_nothing(name, monkeypatch):
    """Pieces on 3 threads (whatever the machine has) give the same hits in the same order
    and the same image bits as one thread (each piece adding to its own image, then those
    in order: ``fused.CHUNK_PIECES``)."""
    monkeypatch.setattr(kfused, "THREADED_MIN_PAIRS", 0)
    monkeypatch.setattr(kspans, "_THREADED_MIN_PRIMS", 0)
    monkeypatch.setattr(kfused, "CHUNK_BYTES", 1)  # chunks of max_pairs: several
    scene, blockers, rays, paths = _setup(SCENES[[p.stem for p in SCENES].index(name)], True,
                                          width=32, height=24, photons=300)
    ctx = PassContext(scene, blockers, 0.0, 0, 20000)
    est = parse_estimator("paper-multi", scene)
    images, runs = [], []
    for threads in (1, 3):
        for mod in (kfused, kspans):
            monkeypatch.setattr(mod, "thread_count", lambda t=threads: t)
        tech = get_technique("planes")
        prims = tech.create(paths, ctx)
        runs.append([(h, v.copy()) for h, v, _ in fused_pass(tech, prims, paths, rays, ctx)])
        images.append(render_pass(scene, est, 0, 5, RenderSettings(photons=200)))
    (one, many) = runs
    assert len(one) == len(many) > 1
    for (ha, va), (hb, vb) in zip(one, many, strict=True):
        for a, b in [(ha.ray, hb.ray), (ha.prim, hb.prim), (ha.s, hb.s), (va, vb)]:
            np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(ha.data, hb.data)
    np.testing.assert_array_equal(images[0], images[1])


def test_images_with_and_without_hits_materialized_agree():
    """A pass that keeps its hits (``record``: the UI's) and one that does not (the walkers
    add to the image directly) give the same image to rounding."""
    from psurf_core.render import PassRecord

    scene = load_scene(SCENES[[p.stem for p in SCENES].index("area_occluder")])
    scene = replace(scene, camera=replace(scene.camera, width=24, height=16))
    for spec in ("planes", "paper-multi", "fast-multi", "paper-single"):
        est = parse_estimator(spec, scene)
        a = render_pass(scene, est, 0, 3, RenderSettings(photons=150))
        b = render_pass(scene, est, 0, 3, RenderSettings(photons=150), record=PassRecord())
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12 * np.abs(a).max(), err_msg=spec)


@pytest.mark.parametrize("photons, pieces_own_images", [(300, True), (8, False)])
def test_each_piece_its_own_image(photons, pieces_own_images, monkeypatch):
    """A chunk cut in ``CHUNK_PIECES`` pieces adds each piece's hits to an image of its own
    (the first to the pass's), those in piece order, where the images hold fewer cells than
    the chunk's compact rows would (``pieces_own_images``: 300 photons at 32x24), else
    compact rows added in order (8 photons): either way the image has the same bits on 1
    and 3 threads and whether the pass keeps its hits or not, and agrees to rounding with
    one piece (the rows added one after another)."""
    from psurf_core.render import PassRecord

    monkeypatch.setattr(kspans, "_THREADED_MIN_PRIMS", 0)
    added = []  # chunks whose compact rows were added (not their pieces' images)
    real = kfused.accumulate
    monkeypatch.setattr(kfused, "accumulate", lambda *a: added.append(1) or real(*a))
    scene = load_scene(SCENES[[p.stem for p in SCENES].index("area_occluder")])
    scene = replace(scene, camera=replace(scene.camera, width=32, height=24))
    settings = RenderSettings(photons=photons)
    for spec in ("planes", "paper-multi"):
        est = parse_estimator(spec, scene)
        monkeypatch.setattr(kfused, "THREADED_MIN_PAIRS", 1 << 40)  # one piece a chunk
        one_piece = render_pass(scene, est, 0, 3, settings)
        monkeypatch.setattr(kfused, "THREADED_MIN_PAIRS", 0)  # CHUNK_PIECES a chunk
        images = []
        for threads in (1, 3):
            for mod in (kfused, kspans):
                monkeypatch.setattr(mod, "thread_count", lambda t=threads: t)
            added.clear()
            images.append(render_pass(scene, est, 0, 3, settings))
            assert bool(added) != pieces_own_images, spec
        kept = render_pass(scene, est, 0, 3, settings, record=PassRecord())
        assert np.abs(images[0]).max() > 0, spec
        np.testing.assert_array_equal(images[0], images[1], err_msg=spec)
        np.testing.assert_array_equal(images[0], kept, err_msg=spec)
        np.testing.assert_allclose(images[0], one_piece, rtol=1e-12,
                                   atol=1e-12 * np.abs(one_piece).max(), err_msg=spec)
