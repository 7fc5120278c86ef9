"""Samplers against their pdfs (chi-square and moments) and Trace's invariants."""

import numpy as np
import pytest

from psurf_core import sampling
from psurf_core.scene import AreaLight, Camera, Medium, MeshLight, Phase, PointLight, Scene
from psurf_core.trace import emit, trace


def chi2_uniformity(u, bins=50):
    """Chi-square statistic of samples that should be U(0, 1)."""
    h, _ = np.histogram(u, bins=bins, range=(0, 1))
    e = len(u) / bins
    return ((h - e) ** 2 / e).sum()


# 50 bins: chi2(49) has mean 49, sd ~10; 100 is beyond p = 1e-5.
CHI2_LIMIT = 100.0


@pytest.mark.parametrize("g", [0.0, 0.5, -0.7, 0.95])
def test_hg_chi2(g):
    rng = np.random.default_rng(11)
    mu = sampling.sample_phase_cos(g, rng.random(200_000))
    # Probability-integral transform with the HG cdf: trapezoid quadrature of 2 pi rho on a
    # grid graded towards the forward peak (independent of the sampler's inversion formula).
    grid = -np.cos(np.linspace(0, np.pi, 400_001))
    pdf = 2 * np.pi * sampling.phase_value(grid, g)
    cdf = np.concatenate([[0], np.cumsum((pdf[1:] + pdf[:-1]) / 2 * np.diff(grid))])
    assert cdf[-1] == pytest.approx(1.0, abs=1e-5)
    assert chi2_uniformity(np.interp(mu, grid, cdf / cdf[-1])) < CHI2_LIMIT
    assert abs(mu.mean() - g) < 5 * mu.std() / np.sqrt(mu.size)  # E[mu] = g


def test_hg_direction_has_the_sampled_cosine():
    rng = np.random.default_rng(2)
    w = sampling.sample_uniform_sphere(rng, 1000)
    w2 = sampling.sample_phase(w, 0.6, rng)
    assert np.allclose(np.linalg.norm(w2, axis=1), 1)
    mu = np.einsum("ij,ij->i", w, w2)
    assert abs(mu.mean() - 0.6) < 0.05


def test_cosine_hemisphere_and_sphere():
    rng = np.random.default_rng(3)
    n = np.tile([0.0, -1.0, 0.0], (100_000, 1))
    w = sampling.sample_cosine_hemisphere(n, rng)
    c = w @ np.array([0.0, -1.0, 0.0])
    assert np.all(c >= 0)
    assert chi2_uniformity(c**2) < CHI2_LIMIT  # p(cos) = 2 cos  =>  cos^2 ~ U(0, 1)
    s = sampling.sample_uniform_sphere(rng, 100_000)
    assert chi2_uniformity((s[:, 2] + 1) / 2) < CHI2_LIMIT
    phi = np.arctan2(s[:, 1], s[:, 0])
    assert chi2_uniformity((phi + np.pi) / (2 * np.pi)) < CHI2_LIMIT


def test_triangle_barycentric_uniform():
    rng = np.random.default_rng(4)
    b = sampling.sample_triangle_barycentric(rng, 200_000)
    assert np.all(b >= 0) and np.all(b.sum(1) <= 1 + 1e-12)
    # Marginal of v is 2 (1 - v): its cdf 1 - (1 - v)^2 must be uniform.
    assert chi2_uniformity(1 - (1 - b[:, 1]) ** 2) < CHI2_LIMIT
    assert chi2_uniformity(1 - (1 - b[:, 0]) ** 2) < CHI2_LIMIT


def scene_two_lights():
    cam = Camera(np.array([0, 0, -4.0]), np.zeros(3), np.array([0, 1.0, 0]), 40.0, 8, 6)
    med = Medium(-np.ones(3), np.ones(3), 0.8, 0.2, Phase("hg", 0.3))
    pt = PointLight(np.zeros(3), np.array([1.0, 2.0, 3.0]), np.array([0, 1.0, 0]))
    area = AreaLight(np.array([-0.3, 0.95, -0.3]), np.array([0.6, 0, 0]), np.array([0, 0, 0.6]),
                     np.full(3, 3.0))
    tri = np.array([[[0, 0, 0], [0.3, 0, 0], [0, 0.3, 0]], [[0, 0, 0.2], [0.6, 0, 0.2],
                                                                 [0, 0.2, 0.2]]], float)
    mesh = MeshLight(tri, np.full(3, 2.0))
    return Scene(cam, med, (pt, area, mesh), (), 1, 4)


def test_emission_power_and_light_choice():
    sc = scene_two_lights()
    rng = np.random.default_rng(5)
    n = 300_000
    e = emit(sc, rng, n)
    frac = np.bincount(e["light"], minlength=3) / n
    assert np.allclose(frac, sc.light_pmf, atol=4e-3)
    # Expected emitted power per photon equals the total power (per channel).
    total = sum(lt.power_rgb for lt in sc.lights)
    assert np.allclose(e["beta"].mean(0), total, rtol=0.02)
    # Mesh: triangles chosen by area, points on them, cosine-weighted about their normals.
    m = e["light"] == 2
    tri = e["tri"][m]
    areas = sc.lights[2].areas
    assert np.allclose(np.bincount(tri, minlength=2) / m.sum(), areas / areas.sum(), atol=0.01)
    cos = np.einsum("ij,ij->i", e["w1"][m], e["light_normal"][m])
    assert np.all(cos >= 0) and abs(cos.mean() - 2 / 3) < 0.01


def test_trace_infinite_medium_and_validity():
    sc = scene_two_lights()
    paths = trace(sc, 50_000, np.random.default_rng(6))
    st = sc.medium.sigma_t
    # Free flights are exponential whatever the box (infinite-medium sampling).
    t1 = paths.t[:, 0]
    assert abs(t1.mean() - 1 / st) < 4 / st / np.sqrt(t1.size)
    # Many photons leave the unit box on their first flight, and they are kept.
    outside = ~np.all(np.abs(paths.x[:, 1]) <= 1, axis=1)
    assert outside.mean() > 0.1
    assert np.all(paths.alive[:, 1][outside])  # a second segment is still sampled
    assert not np.any(paths.prefix_ok[:, 1][outside])
    # Segments chain: x_j = x_{j-1} + t_j w_j.
    a = paths.alive[:, 1]
    rebuilt = paths.x[a, 1] + paths.t[a, 1, None] * paths.w[a, 1]
    assert np.allclose(rebuilt, paths.x[a, 2])
    # beta leaving vertex j = beta leaving vertex j-1 times the albedo.
    assert np.allclose(paths.beta[a, 1], paths.beta[a, 0] * sc.medium.albedo)


def test_roulette_keeps_expected_weight():
    sc = scene_two_lights()
    sc = Scene(sc.camera, sc.medium, sc.lights[:1], (), 1, -1)  # unlimited: roulette
    big = Medium(-np.full(3, 1e3), np.full(3, 1e3), 0.8, 0.2, Phase())
    sc = Scene(sc.camera, big, sc.lights, (), 1, -1)
    paths = trace(sc, 200_000, np.random.default_rng(7))
    j = 11  # past ROULETTE_START
    expect = sc.lights[0].power_rgb[0] * sc.medium.albedo ** j
    got = paths.beta[:, j, 0]
    assert paths.alive[:, j].mean() < 0.9
    assert abs(got.mean() - expect) < 5 * got.std() / np.sqrt(got.size)
