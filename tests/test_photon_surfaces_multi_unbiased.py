"""Multiple-scattering photon surfaces (ESTIMATORS.md 4): unbiasedness.

Image means (per-pass mean and standard error) of every technique and of MIS sets agree with
``planes`` within ``Z_MAX`` combined standard errors; escaped photons are needed (dropping
them makes the long plane and the cylinder disagree with z > 5). The references are rendered
once per module and shared (:func:`image_mean`).
"""

from __future__ import annotations

import dataclasses
import importlib

import numpy as np
import pytest
from photon_surfaces_multi_support import MINE_K2, MINE_K3, MINE_LIGHT, SCENES, area_scene

from psurf_core.estimators import parse_estimator
from psurf_core.render import RenderSettings, render_pass

# The module (not its render() function) is patched in the escape test.
render_mod = importlib.import_module("psurf_core.render")
Z_MAX = 4.0


_cache: dict = {}


def pass_means(scene, name, photons, passes, seed):
    """Mean and standard error of the per-pass image means (red channel)."""
    est = parse_estimator(name, scene)
    settings = RenderSettings(photons=photons, spp=1)
    v = np.array([render_pass(scene, est, i, seed, settings)[..., 0].mean()
                  for i in range(passes)])
    return v.mean(), v.std(ddof=1) / np.sqrt(passes)


def image_mean(scene_key, name, photons, passes, seed):
    """:func:`pass_means`, cached across tests (the references are shared)."""
    key = (scene_key, name, photons, passes, seed)
    if key not in _cache:
        _cache[key] = pass_means(SCENES[scene_key](), name, photons, passes, seed)
    return _cache[key]


def zscore(a, b):
    return (a[0] - b[0]) / np.hypot(a[1], b[1])


REF = dict(photons=6000, passes=16, seed=101)


def reference(scene_key):
    return image_mean(scene_key, "planes", **REF)


@pytest.mark.parametrize("name", MINE_K2)
def test_k2_technique_agrees_with_planes(name):
    photons = 1500 if name == "torus" else 3000
    got = image_mean("area2", name, photons, 8, 7)
    z = zscore(got, reference("area2"))
    assert abs(z) < Z_MAX, (name, got, reference("area2"), z)
    assert got[1] < 0.1 * got[0]  # the test has power: SE well below a 10 % error


@pytest.mark.parametrize("name", MINE_K3)
def test_k3_generalized_planes_agree_with_planes(name):
    got = image_mean("area3", name, 3000, 8, 8)
    z = zscore(got, reference("area3"))
    assert abs(z) < Z_MAX, (name, got, reference("area3"), z)
    assert got[1] < 0.1 * got[0]


@pytest.mark.parametrize(("scene_key", "name"),
                         [(k, n) for k in ("area2", "area3") for n in MINE_LIGHT])
def test_light_strips_agree_with_planes(scene_key, name):
    """The strips move the light point and the whole later path (area3: HG g = 0.3)."""
    got = image_mean(scene_key, name, 3000, 8, 10)
    z = zscore(got, reference(scene_key))
    assert abs(z) < Z_MAX, (name, got, reference(scene_key), z)
    assert got[1] < 0.1 * got[0]


# paper-multi is this explicit set; at K = 2 the generalized planes drop out of it.
MIS_SETS = [("area2", "paper-multi"),
            ("area3", "mis:plane-t1t2+plane-t1t3+plane-t2t3+cone+cylinder"),
            ("point2", "paper-multi"),
            # ~75 s of a fresh clone's make test: make test-slow (the short set below and
            # area3's long set cover the same members).
            pytest.param("point2", "mis:plane-t1t2+sphere+cone+cylinder+disk+hyperboloid",
                         marks=pytest.mark.slow),
            ("point2", "mis:planes+cone-short+cylinder-short+disk-short+hyperboloid-short"),
            # Light strips with shares, and at a point light (where they make nothing).
            ("area2", "mis:planes+plane-ut-short+plane-vt-short@0.3+cone-short@0.2"),
            ("area3", "mis:planes+plane-ut@0.5+plane-vt-short+plane-t2t3-short@0.3"),
            ("point2", "mis:planes+plane-ut-short")]


@pytest.mark.parametrize(("scene_key", "name"), MIS_SETS)
def test_mis_sets_agree_with_planes(scene_key, name):
    got = image_mean(scene_key, name, 3000, 8, 9)
    z = zscore(got, reference(scene_key))
    assert abs(z) < Z_MAX, (name, got, reference(scene_key), z)


@pytest.mark.parametrize("name", ["plane-t1t2", "cylinder"])
def test_dropping_escaped_photons_biases(monkeypatch, name):
    """Techniques that rebuild x1 need photons whose own x1 left the box (spec 4)."""
    ref = reference("area2")  # before patching: the cached reference must stay honest
    real = render_mod.trace

    def dropping(*args, **kw):
        paths = real(*args, **kw)
        keep = paths.prefix_ok[:, 1][:, None, None]
        return dataclasses.replace(paths, beta=paths.beta * keep)

    monkeypatch.setattr(render_mod, "trace", dropping)
    got = pass_means(area_scene(2), name, 3000, 8, 12)
    z = zscore(got, ref)
    assert z < -5.0, (name, got, ref, z)



# ------------------------------------------------------------------------------ slow matrix
SLOW = ([("area2", n) for n in MINE_K2 + MINE_LIGHT] + [("point2", n) for n in MINE_K2]
        + [("area3", n) for n in MINE_K3 + MINE_K2 + MINE_LIGHT]
        + [(k, "mis:plane-t1t2+plane-t1t3-short+plane-t2t3+sphere+disk+hyperboloid+torus")
           for k in ("area2", "point2", "area3")])


@pytest.mark.slow
@pytest.mark.parametrize(("scene_key", "name"), SLOW)
def test_slow_matrix_agrees_with_planes(request, scene_key, name):
    if "slow" not in (request.config.getoption("markexpr") or ""):
        pytest.skip("slow matrix: select it with -m slow")
    ref = image_mean(scene_key, "planes", 20000, 24, 202)
    got = image_mean(scene_key, name, 10000, 16, 203)
    z = zscore(got, ref)
    assert abs(z) < Z_MAX, (scene_key, name, got, ref, z)
