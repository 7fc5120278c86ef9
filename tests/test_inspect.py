"""The pixel inspector (psurf_core.inspect): the evaluate table sums to the pixel's pass value,
MIS weights are the ones the pass applied, Reconstruct is consistent, primitive coverage."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from psurf_core.estimators import parse_estimator
from psurf_core.inspect import inspect_pixel, primitive_pixels, reconstruct_hit
from psurf_core.render import RenderSettings, render_pass
from psurf_core.scene_io import load_scene

SCENES = Path(__file__).resolve().parents[1] / "scenes"
SEED, PASS, PIXEL = 1, 0, (32, 24)
SETTINGS = RenderSettings(photons=200)


@pytest.fixture(scope="module", params=["point.toml", "area_occluder.toml"])
def scene(request):
    return load_scene(SCENES / request.param)


@pytest.mark.parametrize("spec", ["planes", "mis:planes+plane-t1t2"])
def test_table_sums_to_pixel_pass_value(scene, spec):
    ins = inspect_pixel(scene, spec, SEED, PASS, PIXEL, SETTINGS)
    t = ins.table
    assert len(t) > 0, "the fixed pixel should be hit at this budget"
    assert np.allclose(t.contribution.sum(axis=0), ins.pixel_value, rtol=1e-9, atol=0)
    assert ins.sum_matches
    # ... and that is the value the full pass has at that pixel.
    full = render_pass(scene, parse_estimator(spec, scene), PASS, SEED, SETTINGS)
    assert np.allclose(full[PIXEL[1], PIXEL[0]], ins.pixel_value, rtol=1e-12, atol=0)
    # Table columns are consistent with each other.
    n = SETTINGS.photons * SETTINGS.spp
    assert np.allclose(t.value * t.mis_weight[:, None] / n, t.contribution, rtol=1e-9,
                       atol=1e-300)
    assert np.all((t.mis_weight >= 0) & (t.mis_weight <= 1))
    assert np.allclose(t.f, t.value * t.n_dot_psi[:, None], rtol=1e-12)
    nd = np.abs(np.einsum("ij,ij->i", t.normal, t.psi))
    assert np.allclose(nd, t.n_dot_psi, rtol=1e-9)
    ray_o = ins.rays.o[t.ray]
    assert np.allclose(t.point, ray_o + t.s[:, None] * t.psi)
    if spec == "planes":
        assert np.all(t.mis_weight == 1.0)
    else:
        assert set(np.unique(t.technique)) == {"plane-t1t2-short", "plane-t1t2"}
        assert np.any(t.mis_weight < 1.0)


def test_reconstruct_mis_members_and_path(scene):
    ins = inspect_pixel(scene, "mis:planes+plane-t1t2", SEED, PASS, PIXEL, SETTINGS)
    t = ins.table
    for k in t.by_contribution()[:5]:
        r = reconstruct_hit(ins, int(k))
        assert r["available"] and r["technique"] == t.technique[k]
        names = [m[0] for m in r["members"]]
        assert names == ["plane-t1t2-short", "plane-t1t2"]
        w = np.array([m[2] for m in r["members"]])
        assert np.isclose(w.sum(), 1.0)
        assert np.isclose(w[names.index(r["technique"])], t.mis_weight[k], rtol=1e-12)
        poly = r["polyline"]
        assert r["labels"][-1] == "camera" and r["labels"][-2] == "x0"
        assert np.allclose(poly[-2], t.point[k]) and np.allclose(poly[-1], ins.rays.o[t.ray[k]])
        assert len(poly) == int(t.K[k]) + 2  # light .. x0 (K + 1 vertices) + camera
        lt = scene.lights[0]
        if lt.kind == "point":
            assert np.allclose(poly[0], lt.position)


def test_reconstruct_single_technique_has_weight_one(scene):
    ins = inspect_pixel(scene, "planes", SEED, PASS, PIXEL, SETTINGS)
    r = reconstruct_hit(ins, int(ins.table.by_contribution()[0]))
    assert len(r["members"]) == 1 and r["members"][0][2] == 1.0 and r["members"][0][1] > 0
    with pytest.raises(IndexError):
        reconstruct_hit(ins, len(ins.table))


@pytest.mark.parametrize("settings", [SETTINGS, RenderSettings(
    photons=200, pixel_sampler="r2", photon_sampler="sobol-seq")], ids=["default", "seq"])
def test_primitive_pixels_contains_the_picked_pixel(scene, settings):
    """The primitive of the pixel's largest contribution reaches that pixel: coverage
    traces the pass's own photons and rays, whatever its samplers (until 2026-12-06 it
    took independent ones, another primitive under ``sobol``)."""
    ins = inspect_pixel(scene, "planes", SEED, 3, PIXEL, settings)
    t = ins.table
    k = int(t.by_contribution()[0])
    assert np.mean(t.contribution[k]) > 0
    mask = primitive_pixels(scene, "planes", SEED, 3, str(t.technique[k]), int(t.prim[k]),
                            settings, batch=int(t.batch[k]))
    assert mask.shape == (scene.camera.height, scene.camera.width) and mask.dtype == bool
    assert mask[PIXEL[1], PIXEL[0]]
    assert 1 <= mask.sum() < mask.size


def test_kernel_estimator_rows_have_no_normal():
    sc = load_scene(SCENES / "point.toml")
    ins = inspect_pixel(sc, "beams", SEED, PASS, PIXEL, SETTINGS)
    t = ins.table
    assert len(t) > 0 and ins.sum_matches
    assert np.all(np.isnan(t.n_dot_psi)) and not t.near_singular.any()
    r = reconstruct_hit(ins, 0)
    assert not r["available"] and "kernel" in r["note"]


def test_bad_input():
    sc = load_scene(SCENES / "point.toml")
    with pytest.raises(ValueError, match="outside"):
        inspect_pixel(sc, "planes", SEED, PASS, (64, 0), SETTINGS)
    with pytest.raises(ValueError, match="reference"):
        inspect_pixel(sc, "reference", SEED, PASS, PIXEL, SETTINGS)
    with pytest.raises(ValueError, match="not part of"):
        primitive_pixels(sc, "planes", SEED, PASS, "plane-t1t2", 0, SETTINGS)


def test_inspect_imports_no_ui():
    code = ("import sys, psurf_core.inspect; "
            "bad = [m for m in sys.modules if m.split('.')[0] in ('pyvista', 'vtk', "
            "'vtkmodules')]; print(bad); sys.exit(1 if bad else 0)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       cwd=Path(__file__).resolve().parents[1])
    assert r.returncode == 0, r.stdout + r.stderr


@pytest.mark.parametrize("name, spec", [
    ("area_occluder", "paper-multi"), ("point", "paper-single"), ("area", "paper-single"),
    ("mesh_light", "paper-multi"), ("area", "mis:sphere+disk+hyperboloid+torus+plane-t1t2"),
])
def test_member_primitives_pass_through_the_hit(name, spec):
    """Reconstruct's picture: every MIS member's surface swept from the path a hit implies
    contains that path's ``x0``: the hit's own camera ray meets it at the hit's ``s``
    (members that cannot make the path's K give no primitive)."""
    from psurf_core.inspect import member_primitives

    scene = load_scene(SCENES / f"{name}.toml")
    ins = inspect_pixel(scene, spec, 0, 0, (30, 20), RenderSettings(photons=500))
    order = ins.table.by_contribution()[:4]
    assert len(order) > 0
    checked = 0
    for k in order:
        recon = reconstruct_hit(ins, int(k))
        members = member_primitives(ins, recon)
        assert set(members) == {m[0] for m in recon["members"]}
        ray, s = int(ins.table.ray[k]), float(ins.table.s[k])
        own = members[recon["technique"]]
        assert own[2].size == 1  # the hit's own technique re-makes its primitive
        for mname, (tech, prims, rows) in members.items():
            for row in rows:
                hits = tech.intersect(prims, ins.rays, np.array([ray]), np.array([row]),
                                      ins.context(mname))
                assert len(hits) and np.min(np.abs(hits.s - s)) < 1e-6, (mname, hits.s, s)
                checked += 1
    assert checked >= 2 * len(order)


@pytest.mark.parametrize("spec", ["fast-multi", "mis:planes+cone-short@0.3"])
def test_members_with_a_share_weigh_with_sample_counts(spec):
    """A member that sweeps a share ``n_i`` of the photons (``NAME@0.3``, the ``fast-*``
    presets) has the balance weight with sample counts ``n_i Q_i / sum_j n_j Q_j`` (at most 1)
    and stands for all the photons: its contribution is ``value w / (n_i photons spp)``."""
    scene = load_scene(SCENES / "area_occluder.toml")
    settings = RenderSettings(photons=400)
    ins = inspect_pixel(scene, spec, SEED, PASS, PIXEL, settings)
    t = ins.table
    assert ins.sum_matches and len(t) > 0
    assert np.all((t.mis_weight >= 0) & (t.mis_weight <= 1))
    n = settings.photons * settings.spp
    assert np.allclose(t.value * (t.mis_weight / t.share)[:, None] / n, t.contribution,
                       rtol=1e-9, atol=1e-300)
    partial = t.share < 1
    assert np.any(partial) and np.all(t.share[partial] < 0.5)
    # The reconstructed path's member weights: the same sample counts, summing to 1.
    for k in t.by_contribution()[:4]:
        r = reconstruct_hit(ins, int(k))
        names = [m[0] for m in r["members"]]
        w = np.array([m[2] for m in r["members"]])
        assert np.isclose(w.sum(), 1.0)
        assert np.isclose(w[names.index(r["technique"])], t.mis_weight[k], rtol=1e-12)
