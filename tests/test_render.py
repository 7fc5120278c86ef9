"""The render pass and the progressive renderer: determinism, replay, Welford, the core/UI wall."""

import subprocess
import sys

import numpy as np
import pytest

from psurf_core.accumulate import Welford
from psurf_core.estimators import parse_estimator
from psurf_core.render import RenderSettings, kernel_radius, render, render_pass
from psurf_core.scene import AreaLight, Camera, Medium, Phase, Scene
from psurf_core.techniques import get_technique


def area_scene(res=(12, 9), k=(2, 2)):
    cam = Camera(np.array([0, 0, -4.0]), np.zeros(3), np.array([0, 1.0, 0]), 40.0, *res)
    med = Medium(-np.ones(3), np.ones(3), 0.8, 0.2, Phase())
    light = AreaLight(np.array([-0.3, 0.95, -0.3]), np.array([0.6, 0, 0]), np.array([0, 0, 0.6]),
                      np.full(3, 3.0))
    return Scene(cam, med, (light,), (), *k)


def test_same_seed_same_image_and_pixel_replay():
    sc = area_scene()
    est = parse_estimator("planes")
    st = RenderSettings(photons=3000)
    a = render_pass(sc, est, 3, 42, st)
    b = render_pass(sc, est, 3, 42, st)
    c = render_pass(sc, est, 3, 43, st)
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    # One pixel of pass 3 replayed alone gives exactly the full pass's value there.
    p = 4 * sc.camera.width + 6
    one = render_pass(sc, est, 3, 42, st, pixels=np.array([p]))
    assert np.allclose(one.reshape(-1, 3)[p], a.reshape(-1, 3)[p], rtol=1e-12, atol=0)
    assert np.count_nonzero(one.reshape(-1, 3).sum(1)) <= 1
    # The memory budget changes chunking, never the image.
    small = render_pass(sc, est, 3, 42, RenderSettings(photons=3000, memory_budget_mib=1))
    assert np.allclose(small, a, rtol=1e-12, atol=1e-18)


def test_welford_merge_matches_sequential():
    rng = np.random.default_rng(0)
    xs = rng.normal(size=(9, 4, 3, 3))
    seq = Welford.empty((4, 3, 3))
    for x in xs:
        seq.add(x)
    a, b = Welford.empty((4, 3, 3)), Welford.empty((4, 3, 3))
    for x in xs[:4]:
        a.add(x)
    for x in xs[4:]:
        b.add(x)
    a.merge(b)
    assert a.n == 9
    assert np.allclose(a.mean, xs.mean(0)) and np.allclose(seq.mean, xs.mean(0))
    assert np.allclose(a.variance, xs.var(0, ddof=1)) and np.allclose(seq.variance, a.variance)
    with pytest.raises(FloatingPointError):
        seq.add(np.full((4, 3, 3), np.nan))


def test_progressive_render_budget_and_resume():
    sc = area_scene()
    est = parse_estimator("planes")
    st = RenderSettings(photons=1000)
    full = render(sc, est, st, passes=4, seed=5)
    assert full.passes == 4 and full.var.shape == full.mean.shape
    part = render(sc, est, st, passes=2, seed=5)
    resumed = render(sc, est, st, passes=4, seed=5, accumulator=part.accumulator)
    assert np.array_equal(resumed.mean, full.mean) and np.array_equal(resumed.var, full.var)
    timed = render(sc, est, st, time_budget=1e-6, seed=5)
    assert timed.passes == 1 and np.all(timed.var == 0)


def test_kernel_radius_schedule():
    sc = area_scene()
    tech = get_technique("beams")
    st = RenderSettings(radius=0.1, radius_shrink=0.5)
    assert kernel_radius(tech, sc, st, 0) == pytest.approx(0.1)
    # gamma_3 = (1 + a)/2 * (2 + a)/3 with a = 0.5; beams are 1D: r = r0 gamma.
    assert kernel_radius(tech, sc, st, 2) == pytest.approx(0.1 * 0.75 * 2.5 / 3)
    assert kernel_radius(get_technique("planes"), sc, st, 5) == 0.0


def test_core_never_imports_the_ui():
    code = ("import sys, psurf_core, psurf_core.render, psurf_core.mis, psurf_core.scene_io;"
            "bad = [m for m in sys.modules if m.split('.')[0] in ('pyvista', 'vtk', 'vtkmodules',"
            " 'ui')]; print(bad); sys.exit(1 if bad else 0)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
