"""Compiled MIS weights (``psurf_core.mis_fused``) against the numpy reference path.

* On every bundled scene (small images, few photons), for the paper's presets and for MIS
  sets with short members, balance and power heuristics: the kernel's weights equal
  ``reconstruct`` -> ``member_densities`` -> ``weights_from_densities`` to rounding, on
  every hit of every member.
* The weights of all members on one reconstructed path sum to one (where any member has a
  density).
* A member the kernel does not know (``hyperboloid``) sends the whole set to the numpy path.
* Rendered images with the kernel equal those of the numpy path.
* ``photon_record``'s compiled gather equals numpy's fancy indexing, bit for bit.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

import psurf_core.render as render_mod
from psurf_core.binning import candidate_pairs
from psurf_core.camera import camera_rays
from psurf_core.compiled import ctrl_c_kept
from psurf_core.estimators import parse_estimator
from psurf_core.geometry import blockers_of
from psurf_core.mis import member_densities, mis_weights, weights_from_densities
from psurf_core.mis_fused import fast_weights, member_table
from psurf_core.path_record import KIND_CODE, photon_record
from psurf_core.render import RenderSettings, render_pass
from psurf_core.scene import AreaLight, MeshLight, Phase
from psurf_core.scene_io import load_scene
from psurf_core.techniques.base import PassContext
from psurf_core.trace import trace

SCENES = sorted((Path(__file__).resolve().parent.parent / "scenes").glob("*.toml"))
SPECS = ["paper-multi", "paper-single", "mis-power:plane-t1t2+plane-t1t3-short+plane-t2t3"
         "+cone-short+cylinder-short+plane-t1t2-short",
         "mis:ss-plane-uv+ss-plane-ut-short+ss-plane-vt-short+ss-cone-short+ss-disk-short"
         "+ss-sphere+cone+plane-t2t3",
         "mis-power:sphere+disk+disk-short+cone+plane-t1t3"]
RTOL, ATOL = 1e-12, 1e-15


def _small(scene, w=20, h=15):
    return dataclasses.replace(scene, camera=dataclasses.replace(scene.camera, width=w,
                                                                  height=h))


def _chunks(scene, spec, photons=400, seed=3):
    """Every (tech, group, weighting, hits, prims, paths, rays, ctx) chunk of one pass."""
    est = parse_estimator(spec, scene)
    blockers = blockers_of(scene)
    rays = camera_rays(scene, 1, np.random.default_rng(seed), blockers=blockers)
    paths = trace(scene, photons, np.random.default_rng(seed + 1), blockers=blockers)
    box = (scene.medium.bounds_min, scene.medium.bounds_max)
    for group in est.groups:
        if len(group) < 2:
            continue
        for tech in group:
            ctx = PassContext(scene, blockers)
            prims = tech.create(paths, ctx)
            for ray, prim in candidate_pairs(scene.camera, rays, prims.lo, prims.hi,
                                             1 << 20, prims.hull, box):
                hits = tech.intersect(prims, rays, ray, prim, ctx)
                if len(hits):
                    yield tech, group, est.weighting, hits, prims, paths, rays, ctx


@pytest.fixture(scope="module", params=[s.stem for s in SCENES])
def scene(request):
    return _small(load_scene(next(s for s in SCENES if s.stem == request.param)))


@pytest.mark.parametrize("spec", SPECS)
def test_fast_weights_equal_numpy_path(scene, spec):
    n = 0
    for tech, group, weighting, hits, prims, paths, rays, ctx in _chunks(scene, spec):
        assert member_table(group) is not None
        fast = fast_weights(tech, group, weighting, hits, prims, paths, rays, ctx)
        ref = mis_weights(tech, group, weighting, hits, prims, paths, rays, ctx, fast=False)
        np.testing.assert_allclose(fast, ref, rtol=RTOL, atol=ATOL, err_msg=tech.name)
        n += len(hits)
    assert n > 0 or spec.startswith("paper-single")


@pytest.mark.parametrize("weighting", ["balance", "power"])
def test_fast_weights_of_all_members_sum_to_one(scene, weighting):
    for spec in ("paper-multi", "paper-single"):
        for tech, group, _, hits, prims, paths, rays, ctx in _chunks(scene, spec, photons=200):
            w = np.array([fast_weights(tech, group, weighting, hits, prims, paths, rays, ctx,
                                       member=j) for j in range(len(group))])
            rec = tech.reconstruct(hits, prims, paths, rays, ctx)
            q = member_densities(rec, group, ctx)
            np.testing.assert_allclose(w, weights_from_densities(q, weighting), rtol=RTOL,
                                       atol=ATOL)
            some = q.sum(axis=0) > 0
            np.testing.assert_allclose(w[:, some].sum(axis=0), 1.0, rtol=1e-12)
            assert np.all(w[:, ~some] == 0.0)


def test_negative_hg_and_power_heuristic():
    """``phase_value``'s ``g < 0`` branch (no bundled scene has one)."""
    sc = _small(load_scene(SCENES[0]))
    sc = dataclasses.replace(sc, medium=dataclasses.replace(sc.medium, phase=Phase("hg", -0.4)))
    spec = SPECS[2]
    n = 0
    for tech, group, weighting, hits, prims, paths, rays, ctx in _chunks(sc, spec):
        fast = fast_weights(tech, group, weighting, hits, prims, paths, rays, ctx)
        ref = mis_weights(tech, group, weighting, hits, prims, paths, rays, ctx, fast=False)
        np.testing.assert_allclose(fast, ref, rtol=RTOL, atol=ATOL, err_msg=tech.name)
        n += len(hits)
    assert n > 0


def test_unknown_member_falls_back_to_numpy():
    sc = _small(load_scene(SCENES[0]))
    spec = "mis:cone+hyperboloid"
    chunks = list(_chunks(sc, spec, photons=150))
    assert chunks
    for tech, group, weighting, hits, prims, paths, rays, ctx in chunks:
        assert member_table(group) is None
        assert fast_weights(tech, group, weighting, hits, prims, paths, rays, ctx) is None
        np.testing.assert_array_equal(
            mis_weights(tech, group, weighting, hits, prims, paths, rays, ctx),
            mis_weights(tech, group, weighting, hits, prims, paths, rays, ctx, fast=False))


@pytest.mark.parametrize("spec", ["paper-multi", "paper-single"])
def test_images_equal_numpy_path(spec, monkeypatch):
    sc = _small(load_scene(SCENES[0]), 24, 18)
    est = parse_estimator(spec, sc)
    settings = RenderSettings(photons=300)
    fast = render_pass(sc, est, 0, 7, settings)
    slow_weights = render_mod.mis_weights

    def numpy_weights(*args, **kw):
        return slow_weights(*args, fast=False, **kw)

    monkeypatch.setattr(render_mod, "mis_weights", numpy_weights)
    ref = render_pass(sc, est, 0, 7, settings)
    assert np.any(ref > 0)
    np.testing.assert_allclose(fast, ref, rtol=1e-12, atol=1e-15 * np.abs(ref).max())


def _numpy_photon_record(paths, photon, K, scene, rays, ray, s):
    """The numpy ``photon_record`` the compiled gather replaced (fields as a dict)."""
    h = photon.shape[0]

    def gather(arr, k):
        j = K - k
        flat = arr.reshape(arr.shape[0] * arr.shape[1], -1)
        out = flat[photon * arr.shape[1] + np.maximum(j, 0)]
        if arr.ndim == 2:
            out = out[:, 0]
        out[j < 0] = np.nan
        return out

    light = paths.light[photon]
    eu, ev, kind = np.zeros((h, 3)), np.zeros((h, 3)), np.zeros(h, dtype=np.int64)
    for li, lt in enumerate(scene.lights):
        sel = light == li
        kind[sel] = KIND_CODE[lt.kind]
        if isinstance(lt, AreaLight):
            eu[sel], ev[sel] = lt.edge_u, lt.edge_v
        elif isinstance(lt, MeshLight):
            tr = lt.triangles[paths.tri[photon[sel]]]
            eu[sel], ev[sel] = tr[:, 1] - tr[:, 0], tr[:, 2] - tr[:, 0]
    psi = rays.d[ray]
    return dict(K=K, light=light, kind=kind, tri=paths.tri[photon], uv=paths.light_uv[photon],
                axis=paths.light_normal[photon], eu=eu, ev=ev, x3=gather(paths.x, 3),
                x2=gather(paths.x, 2), x1=gather(paths.x, 1),
                x0=rays.o[ray] + s[:, None] * psi, w3=gather(paths.w, 3),
                w2=gather(paths.w, 2), w1=gather(paths.w, 1), t3=gather(paths.t, 3),
                t2=gather(paths.t, 2), t1=gather(paths.t, 1), psi=psi, s=s)


@pytest.mark.parametrize("spec", ["paper-multi", "paper-single"])
def test_photon_record_equals_numpy_gather(scene, spec):
    for _, _, _, hits, prims, paths, rays, ctx in _chunks(scene, spec, photons=150):
        p = hits.prim
        args = (paths, prims.photon[p], prims.K[p], ctx.scene, rays, hits.ray, hits.s)
        rec = photon_record(*args)
        for name, ref in _numpy_photon_record(*args).items():
            np.testing.assert_array_equal(getattr(rec, name), ref, err_msg=name)


def test_ctrl_c_during_a_compiled_call_stays_a_keyboard_interrupt():
    """numba reports a SIGINT handled while it boxes a result as a SystemError caused by
    the KeyboardInterrupt: ``ctrl_c_kept`` gives callers the Ctrl-C back."""
    with pytest.raises(KeyboardInterrupt):
        with ctrl_c_kept():
            try:
                raise KeyboardInterrupt
            except KeyboardInterrupt as e:
                raise SystemError("returned a result with an exception set") from e
    with pytest.raises(SystemError):
        with ctrl_c_kept():
            raise SystemError("unrelated")
