"""The reference path tracer against deterministic oracles and against itself (ESTIMATORS.md 4).

Oracles: the 1D quadrature along unjittered rays (point-light single scattering), a
brute-force 3D quadrature (ray x emitter surface) for area and mesh lights, an independent
bounded-weight random walk for two and three events, and agreement between the reference's
own strategies, scatter-count windows and roulette settings. Every comparison is a
z-score of a Monte Carlo mean against its standard error, with fixed seeds.
"""

from __future__ import annotations

import numpy as np
import pytest
from small_scenes import POINT, TETRA, TETRA_VERTICES, TILTED_AREA, H, W, make_scene

from psurf_core.camera import camera_rays, project
from psurf_core.constants import MAX_TRACE_DEPTH
from psurf_core.geometry import blockers_of, ray_box, ray_parallelogram
from psurf_core.reference import reference_image, reference_pass, single_scatter_quadrature
from psurf_core.reference_quadrature import gauss_legendre_panels
from psurf_core.sampling import phase_value, sample_uniform_sphere
from psurf_core.scene import AreaLight, PointLight, SphereOccluder

Z_MAX = 4.0
# Large and facing (slightly tilted) down from the top: phase-sampled rays hit it often.
BIG_AREA = AreaLight(
    corner=np.array([-0.7, 0.9, -0.7]),
    edge_u=np.array([1.4, 0.0, 0.0]),
    edge_v=np.array([0.0, 0.1, 1.4]),
    radiance=np.array([1.0, 1.5, 2.0]),
)


def test_tetra_faces_outward():
    out = TETRA.triangles.mean(axis=1) - TETRA_VERTICES.mean(axis=0)
    assert np.all(np.einsum("ij,ij->i", TETRA.normals, out) > 0)


def _stats(est: np.ndarray, n_rays: int):
    """Per-ray-group mean and standard error of ``est`` (n_rays * M, 3), groups contiguous."""
    e = est.reshape(n_rays, -1, 3)
    return e.mean(axis=1), e.std(axis=1, ddof=1) / np.sqrt(e.shape[1])


def _z(a, se_a, b, se_b=0.0):
    se = np.sqrt(se_a**2 + se_b**2)
    return (a - b) / np.where(se > 0, se, np.inf)


def _assert_agree(m, se, ref, ref_se=0.0, mask=None, label=""):
    """Per pixel and aggregate |z| <= Z_MAX; zero-variance entries must match exactly."""
    mask = np.ones(m.shape[0], bool) if mask is None else mask
    ref = np.broadcast_to(ref, m.shape)
    ref_se = np.broadcast_to(ref_se, m.shape)
    z = _z(m[mask], se[mask], ref[mask], ref_se[mask])
    assert np.all(np.abs(z) <= Z_MAX), f"{label}: max |z| {np.abs(z).max():.2f}"
    zero = (se[mask] == 0) & (ref_se[mask] == 0)
    np.testing.assert_allclose(m[mask][zero], ref[mask][zero], atol=1e-12)
    agg = _z(m[mask].sum(0), np.sqrt((se[mask] ** 2).sum(0)),
             ref[mask].sum(0), np.sqrt((ref_se[mask] ** 2).sum(0)))
    assert np.all(np.abs(agg) <= Z_MAX), f"{label}: aggregate z {agg}"
    # The test must have had something to compare.
    assert np.any(m[mask] > 0)


# --------------------------------------------------------------------------- point lights
@pytest.mark.parametrize(
    "g, occluders",
    [
        (0.0, ()),
        (0.5, ()),
        (0.5, (SphereOccluder(np.array([-0.1, 0.0, -0.3]), 0.3),)),
        (0.0, (SphereOccluder(np.array([0.2, -0.1, 0.3]), 0.25),)),
    ],
    ids=["iso", "hg", "hg-sphere", "iso-sphere-behind"],
)
def test_point_single_scatter_matches_quadrature(g, occluders, seed=11):
    scene = make_scene([POINT], occluders, g=g)
    bl = blockers_of(scene)
    m_per = 8000
    rays = camera_rays(scene, spp=m_per, jitter=False, blockers=bl)
    est = reference_pass(scene, rays, np.random.default_rng(seed), bl)
    m, se = _stats(est, W * H)
    one = camera_rays(scene, spp=1, jitter=False, blockers=bl)
    quad = single_scatter_quadrature(scene, one.o, one.d, one.s_min, one.s_max, blockers=bl)
    px, py, _ = project(scene.camera, POINT.position[None])
    mask = np.ones(W * H, bool)
    mask[int(py[0]) * W + int(px[0])] = False  # NEE to a point light: infinite variance there
    _assert_agree(m, se, quad, mask=mask, label=f"g={g}")
    # Colour comes from the light only (grey medium).
    np.testing.assert_allclose(quad[:, 1], 0.5 * quad[:, 0], rtol=1e-12)


def test_quadrature_converged_and_point_only():
    scene = make_scene([POINT], (SphereOccluder(np.array([-0.1, 0.0, -0.3]), 0.3),), g=0.5)
    r = camera_rays(scene, spp=1, jitter=False)
    a = single_scatter_quadrature(scene, r.o, r.d, r.s_min, r.s_max, n=4096)
    b = single_scatter_quadrature(scene, r.o, r.d, r.s_min, r.s_max, n=16384)
    # Shadow edges cost accuracy (panel rule), but far below any test's standard error.
    np.testing.assert_allclose(a, b, rtol=2e-3, atol=1e-6)
    with pytest.raises(ValueError):
        sa = make_scene([TILTED_AREA])
        single_scatter_quadrature(sa, r.o, r.d, r.s_min, r.s_max)


# --------------------------------------------------------------------------- area / mesh
def _patches(light):
    """(origin, e1, e2, is_triangle, normal) of each emitting patch."""
    if isinstance(light, AreaLight):
        return [(light.corner, light.edge_u, light.edge_v, False, light.normal)]
    return [(t[0], t[1] - t[0], t[2] - t[0], True, n)
            for t, n in zip(light.triangles, light.normals, strict=True)]


def _light_points(light, n=9):
    """(P, 3) grid of points covering every patch of an emitter."""
    a, b = (g.ravel() for g in np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n)))
    out = []
    for p0, e1, e2, tri, _ in _patches(light):
        v = b * (1 - a) if tri else b
        out.append(p0 + a[:, None] * e1 + v[:, None] * e2)
    return np.concatenate(out)


def _brute_force_single(scene, light, o, d, s_min, s_max, n_s=256, n_uv=16):
    """Tensor Gauss-Legendre over the ray (s) and each emitting patch (u, v), area measure.

    Independent of the reference's sampling: L = int ds exp(-st (s - s_min)) ss
    int dA rho(mu) Le cos_L exp(-st r) / r^2, no occluders (valid for one convex emitter).
    """
    med = scene.medium
    us, ws = gauss_legendre_panels(n_s)
    ua, wa = gauss_legendre_panels(n_uv, order=8)
    s = s_min + (s_max - s_min) * us
    x = o + s[:, None] * d  # (n_s, 3)
    cam = np.exp(-med.sigma_t * (s - s_min)) * med.sigma_s * ws * (s_max - s_min)
    total = 0.0
    for p0, e1, e2, tri, nrm in _patches(light):
        a, b = np.meshgrid(ua, ua, indexing="ij")
        wgt = np.outer(wa, wa)
        if tri:  # collapsed square: u = a, v = b (1 - a), Jacobian (1 - a) |e1 x e2|
            u, v, jac = a, b * (1 - a), (1 - a) * np.linalg.norm(np.cross(e1, e2))
        else:
            u, v, jac = a, b, np.linalg.norm(np.cross(e1, e2))
        y = p0 + u.ravel()[:, None] * e1 + v.ravel()[:, None] * e2  # (n_uv^2, 3)
        dA = (wgt * jac).ravel()
        vec = y[None] - x[:, None]  # vertex -> light
        r = np.linalg.norm(vec, axis=-1)
        cos_l = np.clip(-(vec @ nrm) / r, 0.0, None)
        rho = phase_value((vec @ d) / r, med.phase.g)
        f = rho * cos_l * np.exp(-med.sigma_t * r) / r**2
        total += cam @ (f @ dA)
    return total * light.radiance


def _clear_rays(scene, pts, bl, count=5):
    """Pixel-centre rays passing farther than 0.25 from every point of ``pts`` (P, 3) and
    seeing at least 0.5 of medium (the brute force's 1/r^2 needs r bounded below)."""
    one = camera_rays(scene, spp=1, jitter=False, blockers=bl)
    rel = pts[None] - one.o[:, None]
    along = np.einsum("rvk,rk->rv", rel, one.d)
    dist = np.linalg.norm(rel - along[..., None] * one.d[:, None], axis=-1).min(axis=1)
    pick = np.flatnonzero((dist > 0.25) & (one.s_max > one.s_min + 0.5))[::3][:count]
    assert pick.size >= 3
    return one, pick


def test_pixel_quadrature_of_some_pixels_and_jittered():
    """``pixel_quadrature``: the pixels asked for are those of the whole image (the others
    0); jittered sub-pixel points agree with the product rule on smooth pixels."""
    from psurf_core.reference_quadrature import pixel_quadrature

    scene = make_scene([POINT], g=0.4)
    full = pixel_quadrature(scene, 4, 256)
    pick = np.array([0, 5, W + 3, H * W - 1])
    part = pixel_quadrature(scene, 4, 256, pixels=pick)
    np.testing.assert_array_equal(part.reshape(-1, 3)[pick], full.reshape(-1, 3)[pick])
    rest = np.ones(H * W, bool)
    rest[pick] = False
    assert not part.reshape(-1, 3)[rest].any()
    jit = pixel_quadrature(scene, 16, 256, rng=np.random.default_rng(3))
    # Away from the light's 3x3 pixels (its 1/r^2 peak, where rules converge slowly).
    px, py, _ = project(scene.camera, POINT.position[None])
    lit = full[..., 0] > 1e-3 * full.max()
    lit[max(int(py[0]) - 1, 0):int(py[0]) + 2, max(int(px[0]) - 1, 0):int(px[0]) + 2] = False
    np.testing.assert_allclose(jit[lit], full[lit], rtol=0.05)
    assert lit.sum() > 20


@pytest.mark.parametrize("light", [TILTED_AREA, TETRA], ids=["parallelogram", "tetra-mesh"])
@pytest.mark.parametrize("g", [0.0, 0.5], ids=["iso", "hg"])
def test_emitter_single_scatter_matches_brute_force(light, g, seed=5):
    scene = make_scene([light], g=g)
    bl = blockers_of(scene)
    one, pick = _clear_rays(scene, _light_points(light), bl)
    rays = camera_rays(scene, spp=40000, jitter=False, pixels=one.pixel[pick], blockers=bl)
    m, se = _stats(reference_pass(scene, rays, np.random.default_rng(seed), bl), pick.size)
    brute = np.array([_brute_force_single(scene, light, one.o[i], one.d[i], one.s_min[i],
                                          one.s_max[i]) for i in pick])
    _assert_agree(m, se, brute, label=f"{type(light).__name__} g={g}")


@pytest.mark.parametrize("strategy", ["equiangular", "mis-free-flight", "mis-directions"])
def test_each_strategy_matches_brute_force_dense(strategy, seed=8):
    """Single scattering from the tetrahedron in a dense medium (st = 4.5), where the
    guided distances and the equiangular vertices differ most from free flight: every
    strategy against the quadrature (the default one in the test above)."""
    scene = make_scene([TETRA], g=0.3, sigma_s=4.0, sigma_a=0.5)
    bl = blockers_of(scene)
    one, pick = _clear_rays(scene, _light_points(TETRA), bl)
    rays = camera_rays(scene, spp=20000, jitter=False, pixels=one.pixel[pick], blockers=bl)
    m, se = _stats(reference_pass(scene, rays, np.random.default_rng(seed), bl,
                                  strategy=strategy), pick.size)
    brute = np.array([_brute_force_single(scene, TETRA, one.o[i], one.d[i], one.s_min[i],
                                          one.s_max[i]) for i in pick])
    _assert_agree(m, se, brute, label=strategy)


# --------------------------------------------------------------------------- sampler densities
def _vertices(n=4000, seed=0):
    """Points spread over the box, a few very close to the lights' centres."""
    rng = np.random.default_rng(seed)
    x = rng.uniform(-0.95, 0.95, (n, 3))
    x[:50] = TETRA.triangles.mean(axis=(0, 1)) + rng.normal(0, 0.02, (50, 3))
    x[50:60] = POINT.position + rng.normal(0, 1e-3, (10, 3))
    return x


@pytest.mark.parametrize("sigma_t", [1.0, 4.5, 40.0])
def test_guided_direction_density_is_the_sampled_one(sigma_t):
    """E[rho / p] = 1 for directions drawn from the guided mixture iff p is its density (the
    weight is bounded by 1 / GUIDE_PHASE, so the mean has a finite variance)."""
    from psurf_core import reference_guide as R

    scene = make_scene([POINT, TETRA, TILTED_AREA], g=0.4, sigma_s=0.9 * sigma_t,
                       sigma_a=0.1 * sigma_t)
    plan = R.Plan.of(scene, "mis")
    assert plan.directions
    x = _vertices()
    rng = np.random.default_rng(1)
    w_in = sample_uniform_sphere(rng, x.shape[0])
    weights = []
    for _ in range(25):
        _, _, wt = R.scatter(scene, plan, x, w_in, rng)
        weights.append(wt)
    wt = np.concatenate(weights)
    assert wt.max() <= 1 / R.GUIDE_PHASE + 1e-9
    z = (wt.mean() - 1.0) / (wt.std(ddof=1) / np.sqrt(wt.size))
    assert abs(z) < 4, (wt.mean(), z)
    assert wt.min() < 0.2  # the guided lobe really concentrates somewhere


@pytest.mark.parametrize("sigma_t", [1.0, 4.5, 40.0])
def test_guided_distance_density_is_the_sampled_one(sigma_t):
    """E[st / dens; t < t_end] = 1 - exp(-st t_end) (the free-flight mass of the segment)
    for distances drawn from the guided mixture, iff dens is its density over Tr."""
    from psurf_core import reference_guide as R

    scene = make_scene([POINT, TETRA], sigma_s=0.9 * sigma_t, sigma_a=0.1 * sigma_t)
    plan = R.Plan.of(scene, "mis")
    assert plan.distances
    rng = np.random.default_rng(2)
    o = _vertices(2000, seed=3)
    w = sample_uniform_sphere(rng, o.shape[0])
    w[:200] = (plan.centres[1] - o[:200]) / np.linalg.norm(plan.centres[1] - o[:200],
                                                            axis=1)[:, None]  # at the mesh
    _, t_end = ray_box(o, w, scene.medium.bounds_min, scene.medium.bounds_max)
    vals = []
    for _ in range(20):
        t, dens = R.sample_distance(scene, plan, o, w, t_end, rng)
        np.testing.assert_allclose(dens, R.distance_density(scene, plan, o, w, t_end, t))
        vals.append(np.where(t < t_end, sigma_t / dens, 0.0) - (-np.expm1(-sigma_t * t_end)))
    v = np.concatenate(vals)
    assert np.max(v) <= 1 / R.GUIDE_FLIGHT
    assert abs(v.mean() / (v.std(ddof=1) / np.sqrt(v.size))) < 4


def test_point_and_area_light_together(seed=6):
    """Light choice by power and emitters blocking another light's NEE: the sum of the two
    single-light oracles (point quadrature with the parallelogram as a blocker)."""
    # Above the downward-facing parallelogram: its shadow falls across the medium below.
    point = PointLight(np.array([-0.05, 0.9, 0.25]), np.array([1.0, 2.0, 3.0]), POINT.axis)
    scene = make_scene([point, TILTED_AREA], g=0.3)
    bl = blockers_of(scene)
    one, pick = _clear_rays(
        scene, np.concatenate([_light_points(TILTED_AREA), point.position[None]]), bl)
    rays = camera_rays(scene, spp=40000, jitter=False, pixels=one.pixel[pick], blockers=bl)
    m, se = _stats(reference_pass(scene, rays, np.random.default_rng(seed), bl), pick.size)
    point_only = make_scene([point], g=0.3)
    quad = single_scatter_quadrature(point_only, one.o[pick], one.d[pick], one.s_min[pick],
                                     one.s_max[pick], blockers=bl)
    brute = np.array([_brute_force_single(scene, TILTED_AREA, one.o[i], one.d[i], one.s_min[i],
                                          one.s_max[i]) for i in pick])
    # The parallelogram really shadows the point light somewhere along these rays.
    unblocked = single_scatter_quadrature(point_only, one.o[pick], one.d[pick], one.s_min[pick],
                                          one.s_max[pick])
    assert np.any(quad[:, 0] < 0.99 * unblocked[:, 0])
    _assert_agree(m, se, quad + brute, label="point + area")


# --------------------------------------------------------------------------- self-consistency
def test_strategies_agree(seed=100):
    """NEE alone, phase-sampled hits alone, equiangular vertices alone and every MIS
    combination (guided or not) estimate the same integral."""
    scene = make_scene([BIG_AREA, TETRA], g=0.5)
    bl = blockers_of(scene)
    one = camera_rays(scene, spp=1, jitter=False, blockers=bl)
    # NEE by area has infinite variance where a vertex can approach an emitter: compare only
    # rays that do not end on one (no occluders here, so any blocker hit is an emitter).
    mask = ~np.isfinite(bl.first_hit(one.o, one.d, np.zeros(W * H), None))
    m_per = 6000
    rays = camera_rays(scene, spp=m_per, jitter=False, blockers=bl)
    res, nonzero = {}, []
    others = ("nee", "phase", "equiangular", "mis-free-flight", "mis-unguided",
              "mis-directions")
    for i, strat in enumerate(("mis", *others)):
        est = reference_pass(scene, rays, np.random.default_rng(seed + i), bl, strategy=strat)
        res[strat] = _stats(est, W * H)
        nonzero.append(np.count_nonzero(est[:, 0].reshape(W * H, -1), axis=1))
    # A sample standard error means little with a handful of (rare, large) phase hits.
    mask &= np.min(nonzero, axis=0) >= 100
    assert mask.sum() >= 12
    m0, s0 = res["mis"]
    for strat in others:
        m1, s1 = res[strat]
        _assert_agree(m1, s1, m0, s0, mask=mask, label=strat)
    # Two scattering events: NEE alone has infinite variance, so only MIS vs phase.
    s2 = scene.with_scatter(2, 2)
    a = _stats(reference_pass(s2, rays, np.random.default_rng(seed + 7), bl), W * H)
    b = _stats(reference_pass(s2, rays, np.random.default_rng(seed + 8), bl,
                              strategy="phase"), W * H)
    _assert_agree(*a, *b, label="K=2 mis vs phase")
    with pytest.raises(ValueError):
        reference_pass(scene, rays, np.random.default_rng(0), bl, strategy="bogus")


def _naive_walk(scene, rays, rng, k_events):
    """Independent estimator of exactly ``k_events`` scatterings from one parallelogram light.

    Deliberately unlike the reference: distances from the exponential truncated to each
    segment's free part (weight ``(1 - exp(-st t_end)) ss / st``), directions uniform on the
    sphere (weight ``4 pi rho``), no NEE; the last direction scores only when its first surface
    is the light's front side. Every weight is bounded, so its variance is finite.

    Returns
    -------
    (N, 3) float
    """
    med = scene.medium
    st, ss, g = med.sigma_t, med.sigma_s, med.phase.g
    (light,) = scene.lights
    bl = blockers_of(scene)
    n = len(rays)

    def flight(t_end):
        """Truncated-exponential distance on [0, t_end] and its weight Tr ss / pdf."""
        t_end = np.clip(t_end, 0.0, None)
        mass = -np.expm1(-st * t_end)
        t = -np.log1p(-rng.random(n) * mass) / st
        return t, mass * ss / st

    def turn(w_prev):
        w = sample_uniform_sphere(rng, n)
        return w, 4.0 * np.pi * phase_value(np.einsum("ij,ij->i", w, w_prev), g)

    s, wgt = flight(rays.s_max - rays.s_min)
    x = rays.o + (rays.s_min + s)[:, None] * rays.d
    w_prev = rays.d
    for _ in range(k_events - 1):
        w, f = turn(w_prev)
        _, t_box = ray_box(x, w, med.bounds_min, med.bounds_max)
        t, fw = flight(np.minimum(t_box, bl.first_hit(x, w)))
        wgt = wgt * f * fw
        x, w_prev = x + t[:, None] * w, w
    w, f = turn(w_prev)
    t_l = ray_parallelogram(x, w, light.corner, light.edge_u, light.edge_v)
    first = bl.first_hit(x, w)
    hit = (t_l > 0) & np.isfinite(t_l) & (t_l <= first * (1 + 1e-9)) & (w @ light.normal < 0)
    score = np.where(hit, wgt * f * np.exp(-st * np.where(hit, t_l, 0.0)), 0.0)
    return score[:, None] * light.radiance


@pytest.mark.parametrize("k", [2, 3])
def test_multiple_scatter_matches_naive_walk(k, seed=40):
    """K = 2, 3 (where NEE to a point light is useless as an oracle): MIS reference vs a
    bounded-weight walk of different construction, with an occluder in the way.

    The walk gets eight times the reference's rays: bounded is not light-tailed, and at the
    reference's count its own standard error understates its error in the occluder's
    shadow (with 2500 rays one of 48 pixels sat 4.1 standard errors below the truth, which
    64 x 2500 rays pin down to 3.5 %; measured in issue 15's work).
    """
    occ = (SphereOccluder(np.array([0.1, 0.35, 0.2]), 0.25),)
    scene = make_scene([BIG_AREA], occ, g=0.4, sigma_s=1.2, sigma_a=0.2, kmin=k, kmax=k)
    bl = blockers_of(scene)
    rays = camera_rays(scene, spp=2500, jitter=False, blockers=bl)
    ref = _stats(reference_pass(scene, rays, np.random.default_rng(seed), bl), W * H)
    many = camera_rays(scene, spp=20000, jitter=False, blockers=bl)
    naive = _stats(_naive_walk(scene, many, np.random.default_rng(seed + 1), k), W * H)
    _assert_agree(*ref, *naive, label=f"K={k}")


def test_scatter_windows_add_up(seed=20):
    """Images of K=1 and K=2 alone sum to the [1, 2] image (and K=2 is not zero)."""
    base = make_scene([TILTED_AREA, TETRA], g=0.3, sigma_s=1.5, sigma_a=0.3)
    bl = blockers_of(base)
    m_per = 3000
    res = {}
    for i, (lo, hi) in enumerate([(1, 1), (2, 2), (1, 2)]):
        sc = base.with_scatter(lo, hi)
        rays = camera_rays(sc, spp=m_per, rng=np.random.default_rng(seed + i), blockers=bl)
        est = reference_pass(sc, rays, np.random.default_rng(seed + 10 + i), bl)
        res[lo, hi] = _stats(est, W * H)
    (m1, s1), (m2, s2), (m12, s12) = res[1, 1], res[2, 2], res[1, 2]
    _assert_agree(m1 + m2, np.hypot(s1, s2), m12, s12, label="K1+K2 vs [1,2]")
    assert (m2.sum() / m1.sum()) > 0.05


def test_roulette_unbiased_and_image(seed=1):
    """Unlimited depth (roulette from depth 8) matches the same depth cap without roulette.

    Only paths with at least 12 events are compared: the roulette weights act on all of them
    (dropping the ``1/q`` would cost them a factor ``0.9^4`` or less).
    """
    base = make_scene([BIG_AREA], sigma_s=2.85, sigma_a=0.15)  # albedo 0.95: deep paths matter
    bl = blockers_of(base)
    cap = MAX_TRACE_DEPTH  # the unlimited tracer stops there too
    rays = camera_rays(base, spp=4000, rng=np.random.default_rng(seed), blockers=bl)
    runs = [reference_pass(base.with_scatter(lo, hi), rays, np.random.default_rng(seed + i), bl)
            for i, (lo, hi) in enumerate([(12, -1), (12, cap), (1, 1)], start=1)]
    a, b = _stats(runs[0], W * H), _stats(runs[1], W * H)
    _assert_agree(*a, *b, label="roulette")
    assert a[0].sum() > 0.05 * runs[2].reshape(W * H, -1, 3).mean(axis=1).sum()
    # reference_image is the per-pixel mean of reference_pass (same generator state).
    few = camera_rays(base, spp=20, rng=np.random.default_rng(seed), blockers=bl)
    est = reference_pass(base, few, np.random.default_rng(9), bl)
    img = reference_image(base, few, np.random.default_rng(9), bl)
    assert img.shape == (H, W, 3) and np.all(np.isfinite(img)) and np.all(img >= 0)
    np.testing.assert_allclose(img.reshape(-1, 3), est.reshape(W * H, 20, 3).mean(axis=1))
