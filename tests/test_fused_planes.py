"""The fused photon-plane kernel (``planes_fused``) finds exactly the stage path's hits
(binning -> ``intersect``) with the same per-photon values (``evaluate``), on every bundled
scene, long and short, for pinhole rays and for per-ray origins."""

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
from psurf_core.techniques.base import PassContext
from psurf_core.techniques.planes import PhotonPlane
from psurf_core.trace import trace

SCENES = sorted((Path(__file__).resolve().parent.parent / "scenes").glob("*.toml"))


def _stage(tech, prims, paths, rays, ctx):
    return list(stage_chunks(tech, prims, paths, rays, ctx))


def _flat(chunks):
    """Hits of all chunks, sorted by (ray, prim): ray, prim, s, t1, t2, n_dot_psi, values."""
    cols = [np.concatenate([h.ray for h, _ in chunks]), np.concatenate([h.prim for h, _ in chunks])]
    cols += [np.concatenate([h.s for h, _ in chunks])]
    cols += [np.concatenate([h.data[k] for h, _ in chunks]) for k in ("t1", "t2", "n_dot_psi")]
    vals = np.concatenate([v for _, v in chunks])
    order = np.lexsort((cols[1], cols[0]))
    return [c[order] for c in cols], vals[order]


@pytest.mark.parametrize("short", [True, False], ids=["short", "long"])
@pytest.mark.parametrize("pinhole", [True, False], ids=["pinhole", "per-ray-origin"])
@pytest.mark.parametrize("path", SCENES, ids=[p.stem for p in SCENES])
def test_fused_equals_stages(path, short, pinhole):
    scene = load_scene(path)
    scene = replace(scene, camera=replace(scene.camera, width=32, height=24))
    blockers = blockers_of(scene)
    rays = camera_rays(scene, 2, np.random.default_rng(1), blockers=blockers)
    if not pinhole:
        rays = replace(rays, origin=None)
    paths = trace(scene, 300, np.random.default_rng(2), blockers=blockers)
    tech = PhotonPlane(short)
    # A small pair budget so that several chunks are made.
    ctx = PassContext(scene, blockers, 0.0, 0, 5000)
    prims = tech.create(paths, ctx)
    stage = _stage(tech, prims, paths, rays, ctx)
    fused = list(tech.fused_pass(prims, paths, rays, ctx))
    assert len(fused) > 1
    (a_cols, a_val), (b_cols, b_val) = _flat(stage), _flat(fused)
    assert a_cols[0].size > 100
    np.testing.assert_array_equal(a_cols[0], b_cols[0])
    np.testing.assert_array_equal(a_cols[1], b_cols[1])
    # Sums of products may round differently (numpy's einsum may fuse multiply-adds): s, t1,
    # t2 and n_dot_psi agree to 1e-12 relative or 1e-12 scene units (near cancellation).
    for x, y in zip(a_cols[2:], b_cols[2:], strict=True):
        np.testing.assert_allclose(y, x, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(b_val, a_val, rtol=1e-12, atol=1e-12 * np.abs(a_val).max())
    assert np.count_nonzero(a_val[:, 0]) > 0


def test_render_pass_uses_fused_and_matches_stages(monkeypatch):
    """A whole pass through ``photon_pass`` (fused) equals the same pass with the fused path
    disabled; the tally hook sees every hit either way."""
    scene = load_scene(SCENES[[p.stem for p in SCENES].index("area_occluder")])
    scene = replace(scene, camera=replace(scene.camera, width=24, height=16))
    est = parse_estimator("planes", scene)
    settings = RenderSettings(photons=200)
    seen = []

    def tally(tech, hits, prims, rays, raw, val):
        seen.append(len(hits))

    fused = render_pass(scene, est, 0, 3, settings, tally=tally)
    n_fused = sum(seen)
    seen.clear()
    monkeypatch.setattr(PhotonPlane, "fused_pass", lambda self, *a: None)
    stage = render_pass(scene, est, 0, 3, settings, tally=tally)
    assert n_fused == sum(seen) > 0
    np.testing.assert_allclose(fused, stage, rtol=1e-12, atol=1e-300)


def test_compiled_screen_rects_equal_binning():
    """The compiled pixel rectangles equal ``binning.screen_rects`` on finite boxes (what
    clipped primitive bounds are), including empty boxes and boxes reaching behind the
    camera."""
    from psurf_core.binning import screen_rects
    from psurf_core.techniques.fused_spans import _camera_vector, _screen_rects

    for path in SCENES:
        cam = load_scene(path).camera
        rng = np.random.default_rng(5)
        lo = cam.position + rng.uniform(-8, 8, (500, 3))
        hi = lo + rng.uniform(-0.5, 4, (500, 3))
        want = screen_rects(cam, lo, hi)
        got = _screen_rects(lo, hi, _camera_vector(cam))
        assert np.any(want[1] > want[0]) and np.any(want[1] == want[0])
        for w, g in zip(want, got, strict=True):
            np.testing.assert_array_equal(g, w)


def test_ctrl_c_inside_the_kernel_stays_a_keyboard_interrupt():
    """A SIGINT handled while numba boxes a result arrives as a chain of SystemErrors caused
    by the KeyboardInterrupt (seen with ``render --checkpoint``); the fused path turns it back
    into the KeyboardInterrupt, other SystemErrors pass through."""
    from psurf_core.compiled import interrupted

    def chain(root):
        try:
            try:
                try:
                    raise root
                except BaseException as e:
                    raise SystemError("returned a result with an exception set") from e
            except SystemError as e:
                raise SystemError("returned a result with an exception set") from e
        except SystemError as e:
            return e

    assert interrupted(chain(KeyboardInterrupt()))
    assert not interrupted(chain(ValueError("x")))
    assert not interrupted(SystemError("plain"))


def test_a_time_budget_warms_the_kernel_up_first_without_changing_the_image(monkeypatch):
    """``render(time_budget=...)`` compiles/loads the kernel before its clock starts (a cold
    numba compile took the whole 1 s budget of an equal-time comparison on CI), through a
    throw-away pass that changes nothing in the image; ``passes=`` renders skip it."""
    import psurf_core.render as rmod

    scene = load_scene(SCENES[[p.stem for p in SCENES].index("area_occluder")])
    scene = replace(scene, camera=replace(scene.camera, width=24, height=16))
    est = parse_estimator("planes", scene)
    settings = RenderSettings(photons=200)
    warmed_passes = []
    real_pass = rmod.render_pass

    def counting_pass(sc, *a, **k):
        warmed_passes.append((sc.camera.width, sc.camera.height))
        return real_pass(sc, *a, **k)

    monkeypatch.setattr(rmod, "_WARMED", set())
    monkeypatch.setattr(rmod, "render_pass", counting_pass)
    plain = rmod.render(scene, est, settings, passes=1, seed=4)
    assert warmed_passes == [(24, 16)] and rmod._WARMED == set()
    timed = rmod.render(scene, est, settings, time_budget=1e-9, seed=4)
    assert warmed_passes[1:] == [rmod._WARM_SIZE, (24, 16)]
    assert rmod._WARMED == {"planes"}
    assert timed.passes == 1 and np.array_equal(timed.mean, plain.mean)
    rmod.render(scene, est, settings, time_budget=1e-9, seed=4)  # warmed once per process
    assert warmed_passes[3:] == [(24, 16)]
    reference = parse_estimator("reference", scene)
    rmod.warm_up(scene, reference, settings)
    assert len(warmed_passes) == 4


@pytest.mark.parametrize("name", ["area_occluder", "mesh_light"])
def test_threads_change_nothing(name, monkeypatch):
    """The chunks shared among threads (count, prefix sum, fill; spans by pieces of
    primitives) hold the same hits in the same order with the same values as one thread's,
    deferred mesh shadow tests included."""
    from psurf_core.techniques import fused_spans, planes_fused

    monkeypatch.setattr(planes_fused, "_THREADED_MIN_PAIRS", 0)
    monkeypatch.setattr(fused_spans, "_THREADED_MIN_PRIMS", 0)
    scene = load_scene(SCENES[[p.stem for p in SCENES].index(name)])
    scene = replace(scene, camera=replace(scene.camera, width=32, height=24))
    blockers = blockers_of(scene)
    rays = camera_rays(scene, 2, np.random.default_rng(1), blockers=blockers)
    paths = trace(scene, 300, np.random.default_rng(2), blockers=blockers)
    tech = PhotonPlane(True)
    ctx = PassContext(scene, blockers, 0.0, 0, 20000)
    runs = []
    for threads in (1, 3):  # pieces on 3 threads, whatever the machine has
        for mod in (planes_fused, fused_spans):
            monkeypatch.setattr(mod, "thread_count", lambda t=threads: t)
        prims = tech.create(paths, ctx)
        runs.append([(h, v.copy()) for h, v in tech.fused_pass(prims, paths, rays, ctx)])
    (one, many) = runs
    assert len(one) == len(many) > 1
    for (ha, va), (hb, vb) in zip(one, many, strict=True):
        for a, b in [(ha.ray, hb.ray), (ha.prim, hb.prim), (ha.s, hb.s), (va, vb)]:
            np.testing.assert_array_equal(a, b)
        for k in ha.data:
            np.testing.assert_array_equal(ha.data[k], hb.data[k])


def test_output_buffers_are_reused_only_when_released():
    """Hits of a chunk that something still references (even through a view of a view) are
    never overwritten; released ones are reused."""
    from psurf_core.techniques.planes_fused import _HitBuffers

    pool = _HitBuffers()
    first = pool.take(100)
    first[0][:] = 7
    kept = first[0][10:20][::2]  # a view of a view keeps the lease alive
    del first
    second = pool.take(100)  # slot 0 is leased: slot 1
    third = pool.take(100)  # both leased: fresh memory
    for out in (second, third):
        out[0][:] = -1
    np.testing.assert_array_equal(kept, 7)
    s1 = pool.storage[1].__array_interface__["data"][0]
    assert second[0].__array_interface__["data"][0] == s1
    del second, third
    fourth = pool.take(50)  # slot 0 still leased (kept), slot 1 released: reused
    assert fourth[0].__array_interface__["data"][0] == s1
    np.testing.assert_array_equal(kept, 7)


def test_threads_only_on_cores_other_processes_leave_free(monkeypatch):
    """numba's thread count, lowered to the cores the rest of the machine leaves idle."""
    from psurf_core.techniques import fused_threads

    monkeypatch.setattr(fused_threads, "get_num_threads", lambda: 2)
    monkeypatch.setattr(fused_threads.os, "cpu_count", lambda: 2)
    for others, want in [(0.0, 2), (0.4, 2), (0.7, 1), (1.0, 1), (3.0, 1)]:
        monkeypatch.setattr(fused_threads, "_OTHER_LOAD", lambda o=others: o)
        assert fused_threads.thread_count() == want
    monkeypatch.setattr(fused_threads, "get_num_threads", lambda: 1)
    monkeypatch.setattr(fused_threads, "_OTHER_LOAD", lambda: 0.0)
    assert fused_threads.thread_count() == 1
    load = fused_threads._OtherLoad()
    monkeypatch.setattr(fused_threads, "_LOAD_REFRESH", 0.0)
    assert load() >= 0.0 and load() >= 0.0
