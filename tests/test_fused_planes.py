"""The fused photon-plane kernel (``planes_fused``) finds exactly the stage path's hits
(binning -> ``intersect``) with the same per-photon values (``evaluate``), on every bundled
scene, long and short, for pinhole rays and for per-ray origins."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from psurf_core.binning import candidate_pairs
from psurf_core.camera import camera_rays
from psurf_core.estimators import parse_estimator
from psurf_core.geometry import blockers_of
from psurf_core.render import RenderSettings, render_pass
from psurf_core.scene_io import load_scene
from psurf_core.techniques.base import PassContext
from psurf_core.techniques.planes import PhotonPlane
from psurf_core.trace import trace

SCENES = sorted((Path(__file__).resolve().parent.parent / "scenes").glob("*.toml"))


def _stage(tech, prims, paths, rays, ctx):
    box = (ctx.scene.medium.bounds_min, ctx.scene.medium.bounds_max)
    out = []
    for ray, prim in candidate_pairs(ctx.scene.camera, rays, prims.lo, prims.hi,
                                     ctx.max_pairs, prims.hull, box):
        hits = tech.intersect(prims, rays, ray, prim, ctx)
        if len(hits):
            out.append((hits, tech.evaluate(hits, prims, paths, rays, ctx)))
    return out


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
    from psurf_core.techniques.planes_fused import _camera_vector, _screen_rects

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
    from psurf_core.techniques.planes_fused import _interrupted

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

    assert _interrupted(chain(KeyboardInterrupt()))
    assert not _interrupted(chain(ValueError("x")))
    assert not _interrupted(SystemError("plain"))


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
