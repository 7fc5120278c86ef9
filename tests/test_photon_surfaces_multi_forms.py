"""Multiple-scattering photon surfaces (ESTIMATORS.md 3.1, 3.3 and 4): the exact checks.

* Scaled normals against finite-difference Jacobians of ``x0(xi1, xi2)`` built from the
  spec's coordinates (azimuth frame of section 1), for every technique.
* Evaluate, Reconstruct and Density agree: on every hit ``X * Q(rec) = f(rec) / q_shared``,
  a technique-independent function of the reconstructed path, and the record is a
  consistent path (``x_{k-1} = x_k + t_k w_k``).
* MIS weights sum to one on reconstructed paths, and every member's density is positive.
* Bounds are conservative: binning finds exactly the hits of all ray x primitive pairs.
* Names, variants and scatter counts of the techniques.

Unbiasedness is in ``test_photon_surfaces_multi_unbiased.py``, root finding and degenerate
configurations in ``test_photon_surfaces_multi_roots.py``.
"""

from __future__ import annotations

import numpy as np
import pytest
from photon_surfaces_multi_support import (
    MINE_K2,
    MINE_K3,
    MINE_LIGHT,
    SCENES,
    area_scene,
    point_scene,
    unit,
)

from psurf_core.binning import candidate_pairs
from psurf_core.camera import camera_rays
from psurf_core.geometry import blockers_of
from psurf_core.mis import member_densities, weights_from_densities
from psurf_core.path_record import Pdfs
from psurf_core.sampling import phase_value, sample_uniform_sphere
from psurf_core.techniques import (
    cones,
    cylinders,
    disks,
    generalized_planes,
    get_technique,
    spheres,
)
from psurf_core.techniques.base import PassContext
from psurf_core.techniques.hyperboloids import scaled_normal as hyperboloid_normal
from psurf_core.techniques.tori import Torus
from psurf_core.techniques.tori import scaled_normal as torus_normal
from psurf_core.trace import trace


# ------------------------------------------------------------------------------ normals
def _dot(a, b):
    return np.einsum("ij,ij->i", a, b)




def direction(axis, ref, c, ph):
    """``w`` at polar cosine ``c`` and azimuth ``ph`` about ``axis``, azimuth measured from
    ``e_x = normalize(ref - (ref . axis) axis)`` (spec section 1's frame when ``ref = w3``)."""
    ex = unit(ref - _dot(ref, axis)[:, None] * axis)
    ey = np.cross(axis, ex)
    s = np.sqrt(1.0 - c * c)
    return c[:, None] * axis + s[:, None] * (np.cos(ph)[:, None] * ex + np.sin(ph)[:, None] * ey)


def build_path(base, dims):
    """x0 and the path's pieces as functions of all photon dimensions (w3 = A3)."""
    A3 = base["A3"]
    w2 = direction(A3, base["ref"], dims["c2"], dims["ph2"])
    w1 = direction(w2, A3, dims["c1"], dims["ph1"])
    x2 = base["x3"] + dims["t3"][:, None] * A3
    x1 = x2 + dims["t2"][:, None] * w2
    return x1 + dims["t1"][:, None] * w1, dict(w2=w2, w1=w1, x2=x2, x1=x1)


NORMALS = {
    "plane-t1t3": (("t1", "t3"), lambda b, p, d: generalized_planes.scaled_normal(
        "t1t3", b["A3"], p["w2"], p["w1"])),
    "plane-t2t3": (("t2", "t3"), lambda b, p, d: generalized_planes.scaled_normal(
        "t2t3", b["A3"], p["w2"], p["w1"])),
    "sphere": (("c1", "ph1"), lambda b, p, d: spheres.scaled_normal(p["w1"], d["t1"])),
    "cone": (("t1", "ph1"), lambda b, p, d: cones.scaled_normal(p["w2"], p["w1"], d["t1"])),
    "cylinder": (("t2", "ph1"),
                 lambda b, p, d: cylinders.scaled_normal(p["w2"], p["w1"], d["t1"])),
    "disk": (("t1", "c1"), lambda b, p, d: disks.scaled_normal(p["w2"], p["w1"], d["t1"])),
    "hyperboloid": (("t1", "ph2"),
                    lambda b, p, d: hyperboloid_normal(p["w1"], b["A3"], p["x0"] - p["x2"])),
    "torus": (("c1", "ph2"), lambda b, p, d: torus_normal(p["w2"], p["w1"], d["t1"], b["A3"],
                                                          p["x0"] - p["x2"])),
}


@pytest.mark.parametrize("name", list(NORMALS))
def test_scaled_normal_matches_finite_differences(name):
    rng = np.random.default_rng(11)
    n = 1000
    base = dict(A3=sample_uniform_sphere(rng, n), ref=sample_uniform_sphere(rng, n),
                x3=rng.normal(size=(n, 3)))
    dims = dict(t3=rng.uniform(0.2, 2, n), t2=rng.uniform(0.2, 2, n), t1=rng.uniform(0.2, 2, n),
                c2=rng.uniform(-0.95, 0.95, n), c1=rng.uniform(-0.95, 0.95, n),
                ph2=rng.uniform(0, 2 * np.pi, n), ph1=rng.uniform(0, 2 * np.pi, n))
    (a, b), normal = NORMALS[name]
    h = 1e-6

    def partial(key):
        up, dn = dict(dims), dict(dims)
        up[key], dn[key] = dims[key] + h, dims[key] - h
        return (build_path(base, up)[0] - build_path(base, dn)[0]) / (2 * h)

    n_fd = np.cross(partial(a), partial(b))
    x0, parts = build_path(base, dims)
    n_t = normal(base, dict(parts, x0=x0), dims)
    err = np.minimum(np.linalg.norm(n_fd - n_t, axis=1), np.linalg.norm(n_fd + n_t, axis=1))
    assert np.max(err / np.linalg.norm(n_fd, axis=1)) < 1e-5



# ------------------------------------------------------------------------------ X * Q = F
def all_hits(tech, scene, paths, rays):
    """Yield ``(hits, prims, values, records, ctx)`` per chunk of ``tech``'s binned hits."""
    ctx = PassContext(scene, blockers_of(scene))
    prims = tech.create(paths, ctx)
    for ray, prim in candidate_pairs(scene.camera, rays, prims.lo, prims.hi, 1 << 20):
        hits = tech.intersect(prims, rays, ray, prim, ctx)
        if len(hits):
            val = tech.evaluate(hits, prims, paths, rays, ctx)
            rec = tech.reconstruct(hits, prims, paths, rays, ctx)
            yield hits, prims, val, rec, ctx


def path_f(rec, beta, scene, rays, ray):
    """``f(path) / q_shared`` of the record: technique independent (see module docstring).

    ``beta`` is the photon's weight leaving ``x_K`` (K = 2) or ``x3`` (K = 3) along its first
    kept segment, so ``f / q_shared = beta * pdf(w2 | K=2) * rest`` or ``beta * E(t3) ss rho
    * rest``.
    """
    med = scene.medium
    st, ss, g = med.sigma_t, med.sigma_s, med.phase.g

    def E(t):
        return np.exp(-st * t)

    rest = (E(rec.t2) * ss * phase_value(_dot(rec.w2, rec.w1), g) * E(rec.t1) * ss
            * phase_value(-_dot(rec.w1, rec.psi), g) * E(rec.s - rays.s_min[ray]))
    k3 = rec.K >= 3
    w3 = np.where(k3[:, None], rec.w3, rec.w2)
    first = np.where(k3, E(np.where(k3, rec.t3, 0.0)) * ss * phase_value(_dot(w3, rec.w2), g),
                     Pdfs(rec, scene).w2)
    return beta[:, 0] * first * rest


CONSIST = [("area2", n) for n in MINE_K2] + [("point2", n) for n in MINE_K2] + \
          [("area3", n) for n in MINE_K3 + ["cone", "hyperboloid", "torus"]] + \
          [(k, n) for k in ("area2", "area3") for n in MINE_LIGHT]


@pytest.mark.parametrize(("scene_key", "name"), CONSIST)
def test_value_times_density_is_path_function(scene_key, name):
    scene = SCENES[scene_key]()
    blockers = blockers_of(scene)
    rays = camera_rays(scene, 1, np.random.default_rng(3), blockers=blockers)
    paths = trace(scene, 1500, np.random.default_rng(4), blockers=blockers)
    tech = get_technique(name)
    n_valid = 0
    for hits, prims, val, rec, ctx in all_hits(tech, scene, paths, rays):
        assert np.all(np.isfinite(val)) and np.all(val >= 0)
        # The record is one consistent path ending on the camera ray.
        np.testing.assert_allclose(rec.x2 + rec.t2[:, None] * rec.w2, rec.x1, atol=1e-9)
        np.testing.assert_allclose(rec.x1 + rec.t1[:, None] * rec.w1, rec.x0, atol=1e-9)
        np.testing.assert_allclose(np.linalg.norm(rec.w1, axis=1), 1.0, atol=1e-9)
        np.testing.assert_allclose(np.linalg.norm(rec.w2, axis=1), 1.0, atol=1e-9)
        if scene.max_scatter == 3:
            np.testing.assert_allclose(rec.x3 + rec.t3[:, None] * rec.w3, rec.x2, atol=1e-9)
        ph, K = prims.photon[hits.prim], prims.K[hits.prim]
        f = path_f(rec, paths.beta[ph, np.maximum(K - 3, 0)], scene, rays, hits.ray)
        v = val[:, 0] > 0
        n_valid += v.sum()
        q = tech.density(rec.select(v), ctx)
        np.testing.assert_allclose(val[v, 0] * q, f[v], rtol=1e-6 if name == "torus" else 1e-9)
    assert n_valid > 200


@pytest.mark.parametrize("name", MINE_K2 + MINE_K3 + MINE_LIGHT)
def test_bounds_are_conservative(name):
    """Binning by the primitives' bounds finds exactly the hits with a value of all ray x
    primitive pairs (a light strip's bounds leave out where its rebuilt vertices leave the
    box: ``techniques.bounds.hit_boxes``), and no hit those pairs do not have."""
    scene = area_scene(3) if name in MINE_K3 + MINE_LIGHT else point_scene(2)
    blockers = blockers_of(scene)
    rays = camera_rays(scene, 1, np.random.default_rng(13), blockers=blockers)
    paths = trace(scene, 600, np.random.default_rng(14), blockers=blockers)
    tech = get_technique(name)

    def keys(h, val=None):
        k = zip(h.ray.tolist(), h.prim.tolist(), h.s.tolist(), strict=True)
        return sorted(k) if val is None else sorted(x for x, v in zip(k, np.any(
            val != 0.0, axis=1), strict=True) if v)

    found = [(h, val) for h, _, val, *_ in all_hits(tech, scene, paths, rays)]
    binned = sorted(x for h, val in found for x in keys(h, val))
    ctx = PassContext(scene, blockers)
    prims = tech.create(paths, ctx)
    ray, prim = np.divmod(np.arange(len(rays) * len(prims)), len(prims))
    h = tech.intersect(prims, rays, ray, prim, ctx)
    every = keys(h, tech.evaluate(h, prims, paths, rays, ctx))
    assert len(every) > 50 and binned == every
    assert set(x for h, _ in found for x in keys(h)) <= set(keys(h))


def test_mis_weights_sum_to_one_on_reconstructed_paths():
    scene = area_scene(2)
    group = [get_technique(n) for n in ["plane-t1t2", *MINE_K2, "plane-ut-short", "plane-vt"]]
    blockers = blockers_of(scene)
    rays = camera_rays(scene, 1, np.random.default_rng(5), blockers=blockers)
    paths = trace(scene, 800, np.random.default_rng(6), blockers=blockers)
    for i, tech in enumerate(group):
        for _hits, _prims, val, rec, ctx in all_hits(tech, scene, paths, rays):
            q = member_densities(rec, group, ctx)
            w = weights_from_densities(q, "balance")
            v = val[:, 0] > 0
            # Every technique of the right K can produce every valid path (spec 4).
            assert np.all(q[:, v] > 0) and np.all(np.isfinite(q))
            np.testing.assert_allclose(w[:, v].sum(axis=0), 1.0, rtol=1e-12)
            assert np.all(w[i, v] > 0)



@pytest.mark.parametrize("k", [2, 3])
def test_short_members_densities_are_their_short_ratios_times_shared_pdfs(k):
    # For short (track-length) members every integrated flight's E(t*) / p(t*) is 1 / st and
    # an integrated azimuth's 1 / p(ph) is 2 pi, so on any path Q_j = P(path) short_ratio_j:
    # the pdfs P every member shares cancel from an all-short set's weights, which
    # kernels.mis then takes from the short ratios (study_medium: st = 0.75; HG g = 0.3).
    # The constants by hand: planes |n.psi| / st^2, the strip's / st, the cone's 2 pi / st.
    from pathlib import Path

    from psurf_core.scene import Phase
    from psurf_core.scene_io import load_scene

    scene = load_scene(Path(__file__).resolve().parent.parent / "scenes" / "study_medium.toml")
    scene = scene.with_scatter(k, k).with_medium(phase=Phase("hg", 0.3))
    st = scene.medium.sigma_t
    group = [get_technique(n) for n in ["plane-t1t2-short", "plane-ut-short", "cone-short"]]
    by_hand = np.array([1.0 / st**2, 1.0 / st, 2.0 * np.pi / st])
    blockers = blockers_of(scene)
    rays = camera_rays(scene, 1, np.random.default_rng(5), blockers=blockers)
    paths = trace(scene, 150, np.random.default_rng(6), blockers=blockers)
    for tech in group:
        n = 0
        for _hits, _prims, val, rec, ctx in all_hits(tech, scene, paths, rays):
            q = member_densities(rec, group, ctx)
            r = np.array([m.compiled.short_ratio(rec) for m in group])
            ndp = np.array([np.abs(_dot(m.scaled_normal(rec), rec.psi)) for m in group])
            v = val[:, 0] > 0
            shared = q[:, v] / r[:, v]  # P(path): the same for every member
            np.testing.assert_allclose(shared / shared[0], 1.0, rtol=1e-9)
            hand = q[:, v] / (by_hand[:, None] * ndp[:, v])
            np.testing.assert_allclose(hand / hand[0], 1.0, rtol=1e-9)
            n += int(v.sum())
        assert n > 50, (tech.name, n)


# ------------------------------------------------------------------------------ contract
def test_names_and_variants():
    for name in MINE_K2 + MINE_K3:
        tech = get_technique(name)
        assert tech.name == name and tech.short == name.endswith("-short")
        assert tech.min_k == (3 if name.startswith("plane-t") else 2)
    with pytest.raises(ValueError):
        Torus(short=True)
    with pytest.raises(ValueError):
        spheres.PhotonSphere(short=True)
