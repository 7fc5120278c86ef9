"""Single-scattering photon surfaces (``ss-*``, spec 3.2 and 4): normals, unbiasedness, MIS.

* Every scaled normal against a central-difference Jacobian of ``x0(xi1, xi2)``.
* Evaluate against the closed forms of the 3.2 table, hit by hit, in a scene with a point,
  a parallelogram and a mesh light (so ``1/P_L`` is included); reconstructed records are
  consistent paths on the light.
* Every technique (long and short) and the MIS sets against oracles, through the technique
  stages (trace -> create -> candidate pairs -> intersect -> evaluate [-> MIS weight]) on
  *unjittered* pixel-centre rays: the 1D quadrature for point lights, the reference path
  tracer for a parallelogram and closed mesh lights. The statistic is the z-score of the
  image mean (every estimator) and of the four quadrants' means (MIS sets), with standard
  errors from independent passes; single techniques have heavy tails (spec 5), so photons
  are pooled over 10-16 passes. A triangle strip using the joint pdf must fail the check.
* MIS weights sum to one on reconstructed paths; grazing configurations stay finite (the
  project turns numpy RuntimeWarnings into errors, so a 0/0 fails here too).

Fixed seeds only.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
import trimesh

from psurf_core.binning import candidate_pairs
from psurf_core.camera import Rays, camera_rays, project
from psurf_core.estimators import Estimator, parse_estimator
from psurf_core.geometry import blockers_of
from psurf_core.mis import member_densities, mis_weights, weights_from_densities
from psurf_core.path_record import KIND_CODE, PathRecord
from psurf_core.reference import reference_pass, single_scatter_quadrature
from psurf_core.sampling import direction_about, phase_value
from psurf_core.scene import (
    AreaLight,
    Camera,
    Medium,
    MeshLight,
    Phase,
    PointLight,
    Scene,
    SphereOccluder,
)
from psurf_core.techniques import get_technique
from psurf_core.techniques.base import PassContext, dot
from psurf_core.techniques.single_planes import SinglePlane
from psurf_core.trace import trace

Z_MAX = 4.0
W, H = 8, 6
SINGLE = ("ss-sphere", "ss-cone", "ss-cone-short", "ss-disk", "ss-disk-short")
PLANES = ("ss-plane-uv", "ss-plane-ut", "ss-plane-ut-short", "ss-plane-vt", "ss-plane-vt-short")


def _scene(lights, occluders=(), g=0.0, sigma_s=0.8, sigma_a=0.2):
    cam = Camera(np.array([0.0, 0.0, -4.0]), np.zeros(3), np.array([0.0, 1.0, 0.0]), 40.0, W, H)
    phase = Phase("hg", g) if g else Phase()
    med = Medium(-np.ones(3), np.ones(3), sigma_s, sigma_a, phase)
    return Scene(cam, med, tuple(lights), tuple(occluders), 1, 1)


POINT = PointLight(np.array([0.3, 0.4, 0.1]), np.array([4.0, 2.0, 1.0]), np.array([0.0, 1.0, 0.0]))
AREA = AreaLight(corner=np.array([-0.3, 0.95, -0.3]), edge_u=np.array([0.6, 0.0, 0.0]),
                 edge_v=np.array([0.0, 0.0, 0.6]), radiance=np.array([3.0, 3.0, 3.0]))
_ICO = trimesh.creation.icosphere(subdivisions=1, radius=0.2)
MESH = MeshLight(_ICO.vertices[_ICO.faces] + np.array([0.2, -0.1, 0.2]), np.array([2.0, 2.0, 2.0]))
# The parallelogram as two triangles (counter-clockwise about its downward normal).
_C, _U, _V = AREA.corner, AREA.edge_u, AREA.edge_v
QUAD = MeshLight(np.array([[_C, _C + _U, _C + _U + _V], [_C, _C + _U + _V, _C + _V]]),
                 np.array([3.0, 3.0, 3.0]))
LIGHTS = {"area": (AREA,), "mesh": (MESH,), "quad": (QUAD,), "mixed": (POINT, AREA, MESH)}


def test_mesh_lights_face_as_intended():
    tri = MESH.triangles
    assert tri.shape == (80, 3, 3) and _ICO.is_watertight
    assert np.all(dot(MESH.normals, tri.mean(axis=1) - np.array([0.2, -0.1, 0.2])) > 0)
    np.testing.assert_allclose(QUAD.normals, np.tile(AREA.normal, (2, 1)))
    assert np.isclose(QUAD.area, AREA.area)


# ------------------------------------------------------------------------- stage runner
def _pass(scene, est: Estimator, rays: Rays, paths, bl) -> np.ndarray:
    """Sum of per-photon contributions per ray (R, 3): the renderer's photon pass, by hand."""
    out = np.zeros((len(rays), 3))
    for group in est.groups:
        for tech in group:
            ctx = PassContext(scene, bl)
            prims = tech.create(paths, ctx)
            for ray, prim in candidate_pairs(scene.camera, rays, prims.lo, prims.hi, 1 << 19):
                hits = tech.intersect(prims, rays, ray, prim, ctx)
                if len(hits) == 0:
                    continue
                val = tech.evaluate(hits, prims, paths, rays, ctx)
                assert np.all(np.isfinite(val))
                if len(group) > 1:
                    val = val * mis_weights(tech, group, est.weighting, hits, prims, paths,
                                            rays, ctx)[:, None]
                for c in range(3):
                    out[:, c] += np.bincount(hits.ray, weights=val[:, c], minlength=len(rays))
    return out


def _estimate(scene, ests: dict, n: int, passes: int, seed: int):
    """Per-pass images (passes, R, 3) of every estimator, all fed the same photons."""
    bl = blockers_of(scene)
    rays = camera_rays(scene, 1, jitter=False, blockers=bl)
    out = {k: [] for k in ests}
    for i in range(passes):
        rng = np.random.default_rng(np.random.SeedSequence([seed, i]))
        paths = trace(scene, n, rng, blockers=bl)
        for k, est in ests.items():
            out[k].append(_pass(scene, est, rays, paths, bl) / n)
    return rays, {k: np.array(v) for k, v in out.items()}


def _regions(rays: Rays) -> list[np.ndarray]:
    """Pixel masks (R,) of the whole image and of its four quadrants."""
    row, col = np.divmod(rays.pixel, W)
    quads = [((row < H // 2) == a) & ((col < W // 2) == b) for a in (0, 1) for b in (0, 1)]
    return [np.ones(len(rays), bool), *quads]


def _z_scores(per_pass: np.ndarray, oracle: np.ndarray, oracle_se: np.ndarray, masks) -> np.ndarray:
    """z of each region's mean (channel 0) against the oracle's (mean, se) per pixel (R,)."""
    z = []
    for m in masks:
        x = per_pass[:, m, 0].mean(axis=1)
        se = np.hypot(x.std(ddof=1) / np.sqrt(x.size), np.sqrt((oracle_se[m] ** 2).sum()) / m.sum())
        z.append((x.mean() - oracle[m].mean()) / se)
    return np.array(z)


def _check(name, z, mis=False):
    """|z| <= Z_MAX for the image mean; MIS sets (tame tails) also for every quadrant.

    Single techniques have heavy tails (spec 5): their sample standard error is itself
    noisy, and too often low in a quadrant of a few pixels, so only their image mean is held
    to the bound (their per-hit values are checked exactly against the closed forms).
    """
    z = z if mis else z[:1]
    assert np.all(np.isfinite(z)) and np.all(np.abs(z) <= Z_MAX), f"{name}: z = {np.round(z, 2)}"


# ------------------------------------------------------------------------- 1. normals
def _record(x1, w1, t1, axis, eu, ev, uv, kind):
    n = x1.shape[0]
    nan3, nan = np.full((n, 3), np.nan), np.full(n, np.nan)
    psi = np.tile([0.0, 0.0, 1.0], (n, 1))
    return PathRecord(K=np.ones(n, np.int64), light=np.zeros(n, np.int64),
                      kind=np.full(n, KIND_CODE[kind]), tri=np.full(n, -1), uv=uv, axis=axis,
                      eu=eu, ev=ev, x3=nan3, x2=nan3, x1=x1, x0=x1 + t1[:, None] * w1,
                      w3=nan3, w2=nan3, w1=w1, t3=nan, t2=nan, t1=t1, psi=psi, s=nan)


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


@pytest.mark.parametrize("name", ["ss-sphere", "ss-cone", "ss-disk", "ss-plane-uv",
                                  "ss-plane-ut", "ss-plane-vt"])
def test_scaled_normal_matches_finite_differences(name, n=300):
    rng = np.random.default_rng(3)
    axis = _unit(rng.normal(size=(n, 3)))
    eu, ev = rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
    corner = rng.normal(size=(n, 3))
    c0 = rng.uniform(-0.95, 0.95, n)
    ph0 = rng.uniform(0.0, 2.0 * np.pi, n)
    t0, u0, v0 = rng.uniform(0.2, 3.0, n), rng.uniform(0.0, 1.0, n), rng.uniform(0.0, 1.0, n)
    # x0 as a function of the technique's two integrated dimensions (the others fixed).
    light = lambda u, v: corner + u[:, None] * eu + v[:, None] * ev  # noqa: E731
    ray = lambda x, c, ph, t: x + t[:, None] * direction_about(axis, c, ph)  # noqa: E731
    w_of = lambda c, ph: direction_about(axis, c, ph)  # noqa: E731
    wp = w_of(c0, ph0)
    f, p0 = {
        "ss-sphere": (lambda a, b: ray(corner, a, b, t0), (c0, ph0)),
        "ss-cone": (lambda a, b: ray(corner, c0, b, a), (t0, ph0)),
        "ss-disk": (lambda a, b: ray(corner, b, ph0, a), (t0, c0)),
        "ss-plane-uv": (lambda a, b: light(a, b) + t0[:, None] * wp, (u0, v0)),
        "ss-plane-ut": (lambda a, b: light(a, v0) + b[:, None] * wp, (u0, t0)),
        "ss-plane-vt": (lambda a, b: light(u0, a) + b[:, None] * wp, (v0, t0)),
    }[name]
    h = 1e-6
    a, b = p0
    da = (f(a + h, b) - f(a - h, b)) / (2 * h)
    db = (f(a, b + h) - f(a, b - h)) / (2 * h)
    n_fd = np.cross(da, db)
    rec = _record(light(u0, v0) if "plane" in name else corner, wp, t0, axis, eu, ev,
                  np.stack([u0, v0], 1), "area")
    n_code = get_technique(name).scaled_normal(rec)
    err = np.minimum(np.linalg.norm(n_fd - n_code, axis=1), np.linalg.norm(n_fd + n_code, axis=1))
    assert np.max(err / np.linalg.norm(n_code, axis=1)) < 1e-5


# ------------------------------------------------------------------------- 2a. point light
def _point_case(g, occluders, n, passes, seed):
    scene = _scene([POINT], occluders, g=g)
    ests = {s: parse_estimator(s, scene) for s in SINGLE}
    ests["mis"] = parse_estimator("mis:ss-sphere+ss-cone+ss-disk", scene)
    rays, res = _estimate(scene, ests, n, passes, seed)
    quad = single_scatter_quadrature(scene, rays.o, rays.d, rays.s_min, rays.s_max)[:, 0]
    masks = _regions(rays)
    for k, v in res.items():
        _check(f"{k} g={g}", _z_scores(v, quad, np.zeros_like(quad), masks), mis=k == "mis")
    assert quad.sum() > 0


def test_point_light_matches_quadrature_hg_occluder():
    _point_case(0.5, (SphereOccluder(np.array([-0.1, 0.0, -0.3]), 0.3),), 5000, 16, 1)


def test_point_light_matches_quadrature_iso():
    _point_case(0.0, (), 5000, 16, 4)


@pytest.mark.slow
@pytest.mark.parametrize("g, occ", [(0.0, False), (0.5, False), (0.0, True)])
def test_point_light_matches_quadrature_matrix(g, occ):
    occluders = (SphereOccluder(np.array([0.2, -0.1, 0.3]), 0.25),) if occ else ()
    _point_case(g, occluders, 20000, 16, 2)


# ------------------------------------------------------------------------- 2b. area / mesh
class JointPdfStrip(SinglePlane):
    """The spec's known bug: a triangle strip divided by the joint density ``2 P_k``."""

    def sampled_position_pdf(self, kind, p_uv, p_u, p_v):
        return p_uv


def _compared_pixels(scene) -> np.ndarray:
    """Flat pixels whose centre ray sees medium and does not end on an emitter.

    A ray ending on the emitter gets scattering vertices arbitrarily close to it, where
    the sphere's ``1/T^2`` (and the reference's light sampling) has infinite variance; so
    does the reference's NEE in a point light's pixel (spec 4).
    """
    rays = camera_rays(scene, 1, jitter=False)
    ends = np.isfinite(blockers_of(scene).first_hit(rays.o, rays.d, np.zeros(len(rays)), None))
    keep = (rays.s_max > rays.s_min + 0.1) & ~ends
    for lt in scene.lights:  # and NEE to a point light, in the light's own pixel
        if lt.kind == "point":
            px, py, _ = project(scene.camera, lt.position[None])
            keep &= rays.pixel != int(py[0]) * W + int(px[0])
    return rays.pixel[keep]


@functools.cache
def _reference(light_name: str, g: float, spp: int, seed: int):
    """Reference mean and standard error per pixel (R,), channel 0; NaN where not compared."""
    scene = _scene(LIGHTS[light_name], g=g)
    bl = blockers_of(scene)
    pix = _compared_pixels(scene)
    rays = camera_rays(scene, spp, jitter=False, pixels=pix, blockers=bl)
    est = reference_pass(scene, rays, np.random.default_rng(seed), bl)[:, 0].reshape(-1, spp)
    mean, se = np.full(W * H, np.nan), np.full(W * H, np.nan)
    mean[pix], se[pix] = est.mean(axis=1), est.std(axis=1, ddof=1) / np.sqrt(spp)
    return mean, se


def _emitter_case(light_name, g, n, passes, seed, spp, names=(*SINGLE, *PLANES, "paper-single"),
                  extra=()):
    """z-scores (5,) of techniques ``names`` and ``extra`` (name, instance) vs the reference.

    Returns ``(z by name, per-pass images by name, reference (R,), compared pixels (R,))``.
    """
    scene = _scene(LIGHTS[light_name], g=g)
    ests = {s: parse_estimator(s, scene) for s in names}
    for k, tech in extra:
        ests[k] = Estimator(k, groups=((tech,),))
    rays, res = _estimate(scene, ests, n, passes, seed)
    ref, ref_se = _reference(light_name, g, spp, seed + 1000)
    use = np.isfinite(ref)
    assert use.sum() >= 20
    masks = [m & use for m in _regions(rays)]
    return {k: _z_scores(v, ref, ref_se, masks) for k, v in res.items()}, res, ref, use


def test_area_light_matches_reference():
    zs, *_ = _emitter_case("area", 0.0, 3000, 16, 5, 30000)
    for k, z in zs.items():
        _check(f"area {k}", z, mis=k == "paper-single")


def test_mesh_light_matches_reference():
    zs, *_ = _emitter_case("mesh", 0.5, 2500, 16, 6, 12000)
    for k, z in zs.items():
        _check(f"mesh {k}", z, mis=k == "paper-single")


def test_triangle_strips_need_the_marginal_pdf():
    """Spec 3.2: a strip over triangles divided by the joint ``2 P_k`` instead of the
    marginal ``2 P_k (1 - v)`` is biased by ``E[1 - v] = 2/3``; the same check that passes
    the marginal strips must reject it. A two-triangle light (the parallelogram split) keeps
    the strips' tails light, so the bias stands out clearly."""
    bad = [("joint-ut", JointPdfStrip(False, "ut")), ("joint-vt", JointPdfStrip(False, "vt"))]
    names = ("ss-plane-ut", "ss-plane-ut-short", "ss-plane-vt", "ss-plane-vt-short")
    zs, res, ref, use = _emitter_case("quad", 0.5, 2000, 10, 9, 20000, names=names, extra=bad)
    for k in names:
        _check(f"quad-mesh {k}", zs[k], mis=True)
    for k, _ in bad:
        ratio = res[k][:, use, 0].mean() / ref[use].mean()
        assert zs[k][0] < -3 * Z_MAX and 0.55 < ratio < 0.78, f"{k}: z {zs[k]}, ratio {ratio:.3f}"


@pytest.mark.slow
@pytest.mark.parametrize("light, g", [("area", 0.5), ("mesh", 0.0)])
def test_emitter_matrix(light, g):
    zs, *_ = _emitter_case(light, g, 10000, 16, 7, 40000)
    for k, z in zs.items():
        _check(f"{light} g={g} {k}", z, mis=k == "paper-single")


@pytest.mark.slow
def test_three_light_kinds_share_light_selection():
    """Point, parallelogram and mesh lights in one scene (photon weight 1/P_L). Only
    techniques that apply to every light kind estimate the whole image."""
    names = ("ss-sphere", "ss-cone", "ss-disk-short", "paper-single")
    zs, *_ = _emitter_case("mixed", 0.5, 8000, 16, 8, 20000, names=names)
    for k, z in zs.items():
        _check(f"mixed {k}", z, mis=k == "paper-single")


# ------------------------------------------------------------------------- 3. records, MIS
MIXED = _scene([POINT, AREA, MESH], g=0.5)


def _hits_of(scene, name, n=1500, seed=8, paths=None, rays=None):
    """One pass of one technique (a name or an instance), every ray against every primitive.

    Returns ``(tech, prims, hits, values, rec, paths, rays, ctx)``.
    """
    bl = blockers_of(scene)
    ctx = PassContext(scene, bl)
    rays = camera_rays(scene, 1, jitter=False, blockers=bl) if rays is None else rays
    paths = trace(scene, n, np.random.default_rng(seed), blockers=bl) if paths is None else paths
    tech = get_technique(name) if isinstance(name, str) else name
    prims = tech.create(paths, ctx)
    ray = np.repeat(np.arange(len(rays)), len(prims))
    prim = np.tile(np.arange(len(prims)), len(rays))
    hits = tech.intersect(prims, rays, ray, prim, ctx)
    val = tech.evaluate(hits, prims, paths, rays, ctx)
    rec = tech.reconstruct(hits, prims, paths, rays, ctx)
    return tech, prims, hits, val, rec, paths, rays, ctx


def _closed_form(name, rec, scene, paths, prims, hits, rays):
    """The per-photon contributions of the table of spec 3.2 (closed forms), channel 0."""
    med = scene.medium
    st, ss = med.sigma_t, med.sigma_s
    light = rec.light
    pl = scene.light_pmf[light]
    lt = [scene.lights[i] for i in light]
    I = np.array([x.intensity[0] if x.kind == "point" else np.nan for x in lt])
    Le = np.array([np.nan if x.kind == "point" else x.radiance[0] for x in lt])
    area = np.array([np.nan if x.kind == "point" else x.area for x in lt])
    w, a, t = rec.w1, rec.axis, rec.t1
    psi = rec.psi
    c = dot(w, a)
    sin = np.sqrt(1.0 - c * c)
    eph = np.cross(a, w) / sin[:, None]
    rho0 = phase_value(-dot(w, psi), med.phase.g)
    cam = np.exp(-st * (rec.s - rays.s_min[hits.ray])) * ss * rho0
    e_t = 1.0 if name.endswith("short") else np.exp(-st * t)
    T = paths.t[prims.photon[hits.prim], 0]
    kind = rec.kind
    point, para = kind == KIND_CODE["point"], kind == KIND_CODE["area"]
    phi = np.where(point, 4 * np.pi * I, np.pi * area * Le)
    # |e_u x e_v| is A for the parallelogram and 2 A_k for a triangle (spec: A -> 2 A_k).
    a_patch = np.linalg.norm(np.cross(rec.eu, rec.ev), axis=1)
    p_uv = np.where(para, 1.0, a_patch / area)  # 1, or 2 P_k = 2 A_k / A_tot
    le_term = np.where(point, I, a_patch * Le * c)  # I, A Le cos, 2 A_k Le cos
    a_k = np.where(para, a_patch, 0.5 * a_patch)
    base = name.removesuffix("-short")
    out = {
        "ss-sphere": lambda: np.where(point, I, le_term / p_uv) / (st * T**2 * np.abs(dot(w, psi))),
        "ss-cone": lambda: np.where(point, 2 * I, area * Le / 2) * e_t
        / (t * np.abs(dot(a - c[:, None] * w, psi))),
        "ss-disk": lambda: 2 * np.pi * np.where(point, I, le_term / p_uv) * e_t * sin
        / (t * np.abs(dot(eph, psi))),
        "ss-plane-uv": lambda: phi / a_k / (st * np.abs(dot(a, psi))),
        "ss-plane-ut": lambda: phi / np.where(para, 1.0, 1.0 - rec.uv[:, 1]) * e_t
        / np.abs(dot(np.cross(rec.eu, w), psi)),
        "ss-plane-vt": lambda: phi / np.where(para, 1.0, 1.0 - rec.uv[:, 0]) * e_t
        / np.abs(dot(np.cross(rec.ev, w), psi)),
    }[base]()
    return out * cam / pl


@pytest.mark.parametrize("name", [*SINGLE, *PLANES])
def test_evaluate_matches_closed_forms_and_records(name):
    """Evaluate = the table's closed forms (incl. 1/P_L, three light kinds in one scene);
    the reconstructed record is a consistent path on the light."""
    tech, prims, hits, val, rec, paths, rays, ctx = _hits_of(MIXED, name, n=4000)
    assert len(hits) > 50
    ok = val[:, 0] > 0
    assert ok.mean() > 0.8
    want = _closed_form(name, rec, MIXED, paths, prims, hits, rays)
    np.testing.assert_allclose(val[ok, 0], want[ok], rtol=1e-8)
    np.testing.assert_allclose(rec.x1 + rec.t1[:, None] * rec.w1, rec.x0, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(rec.w1, axis=1), 1.0, atol=1e-12)
    assert np.all(rec.K == 1) and np.all(np.isnan(rec.x2)) and np.all(np.isnan(rec.t2))
    emitter = rec.kind != KIND_CODE["point"]
    uv = rec.uv[emitter]
    corner = np.where((rec.kind[emitter] == KIND_CODE["area"])[:, None], AREA.corner,
                      MESH.triangles[np.maximum(rec.tri[emitter], 0), 0])
    np.testing.assert_allclose(corner + uv[:, :1] * rec.eu[emitter] + uv[:, 1:] * rec.ev[emitter],
                               rec.x1[emitter], atol=1e-9)
    tri = rec.kind[emitter] == KIND_CODE["mesh"]
    assert np.all(uv >= -1e-12) and np.all(np.where(tri, uv.sum(1), uv.max(1)) <= 1 + 1e-12)


def test_mis_weights_sum_to_one_on_reconstructed_paths():
    group = parse_estimator("paper-single", MIXED).groups[0]
    kinds = set()
    for tech in group:
        _, prims, hits, val, rec, paths, rays, ctx = _hits_of(MIXED, tech, n=800)
        q = member_densities(rec, group, ctx)
        w = weights_from_densities(q, "balance")
        assert np.all(np.isfinite(q)) and np.all(np.isfinite(w)) and np.all(w >= 0)
        me = group.index(tech)
        ok = val[:, 0] > 0
        assert np.all(q[me, ok] > 0)  # the hit's own technique has density on its path
        np.testing.assert_allclose(w[:, ok].sum(axis=0), 1.0, rtol=1e-12)
        # Only techniques that can produce the path's light kind take part.
        for j, m in enumerate(group):
            assert np.all(q[j, ~m.can_produce(rec.K, rec.kind)] == 0)
        kinds |= set(np.unique(rec.kind[ok]).tolist())
    assert kinds == {0, 1, 2}


# ------------------------------------------------------------------------- 3b. grazing
ALL = [*SINGLE, *PLANES]


def _finite_everywhere(scene, paths, rays, names):
    """Run every stage and every member density; all must be finite (and warning-free)."""
    group = [get_technique(n) for n in names]
    total = 0
    for tech in group:
        if not any(tech.applies_to(lt) for lt in scene.lights):
            continue
        _, prims, hits, val, rec, *_, ctx = _hits_of(scene, tech, paths=paths, rays=rays)
        assert np.all(np.isfinite(prims.lo) | np.isinf(prims.lo)) and not np.isnan(prims.hi).any()
        assert np.all(np.isfinite(val)) and np.all(val >= 0)
        q = member_densities(rec, group, ctx)
        assert np.all(np.isfinite(q)) and np.all(np.isfinite(weights_from_densities(q, None)))
        total += len(hits)
    return total


def _rays(scene, o, d):
    from psurf_core.camera import clip_rays

    d = _unit(np.asarray(d, float))
    o = np.broadcast_to(np.asarray(o, float), d.shape).copy()
    s_min, s_max = clip_rays(scene, o, d)
    return Rays(o, d, s_min, s_max, np.zeros(len(d), np.int64), 1)


def test_cones_disks_on_and_off_axis_stay_finite():
    """theta -> 0 or pi (w = +-a, and 1e-9 away) and theta = pi/2 for cones and disks."""
    import dataclasses

    scene = _scene([POINT], g=0.5)
    paths = trace(scene, 12, np.random.default_rng(2))
    a = POINT.axis
    tilt = _unit(a + np.array([1e-9, 0.0, 0.0]))
    w = np.array([a, -a, tilt, -tilt, [1.0, 0, 0], [0, 0, 1.0], _unit([1.0, 1e-300, 0.0]),
                  *_unit(np.random.default_rng(0).normal(size=(5, 3)))])
    paths = dataclasses.replace(paths, w=w[:, None, :].copy())
    rays = camera_rays(scene, 1, jitter=False)
    assert _finite_everywhere(scene, paths, rays, SINGLE) > 0
    # The disk drops the exactly axial photons (their half-plane is undefined).
    prims = get_technique("ss-disk").create(paths, PassContext(scene, blockers_of(scene)))
    made = set(prims.photon.tolist())
    assert made >= {2, 3, 4, 5, 6, 7} and not {0, 1} & made
    # Area light: w = n_L exactly and nearly tangent to the light (c -> 0).
    sa = _scene([AREA])
    pa = trace(sa, 6, np.random.default_rng(3))
    n = AREA.normal
    wa = np.array([n, _unit(n + [0.0, 0, 1e-9]), _unit([1.0, -1e-12, 0.0]),
                   _unit([0.0, -1e-7, 1.0]), _unit([1.0, -1.0, 1.0]), _unit([0.2, -1.0, 0.0])])
    pa = dataclasses.replace(pa, w=wa[:, None, :].copy())
    assert _finite_everywhere(sa, pa, camera_rays(sa, 1, jitter=False), ALL) > 0


def test_spheres_with_vanishing_radius_stay_finite():
    import dataclasses

    for scene in (_scene([POINT]), _scene([AREA]), _scene([MESH])):
        paths = trace(scene, 7, np.random.default_rng(4))
        t = np.array([[0.0], [1e-300], [1e-160], [1e-12], [1e-6], [0.3], [1.0]])
        paths = dataclasses.replace(paths, t=t)
        # Rays through the light points themselves (where a tiny sphere can be hit).
        o = np.array([0.0, 0.0, -4.0])
        rays = _rays(scene, o, paths.x[:, 0] - o)
        _finite_everywhere(scene, paths, rays, ["ss-sphere", "ss-cone", "ss-plane-uv"])


def test_rays_parallel_to_translated_light_and_strips():
    """psi in the plane of the translated light ([u,v]) or of a strip ([u,t], [v,t])."""
    import dataclasses

    scene = _scene([AREA])
    paths = trace(scene, 8, np.random.default_rng(5))
    w = np.tile(_unit([0.3, -1.0, 0.2]), (8, 1))
    t = np.linspace(0.2, 1.5, 8)[:, None]
    paths = dataclasses.replace(paths, w=w[:, None, :], t=t)
    y = paths.x[:, 0, 1] + t[:, 0] * w[:, 1]  # heights of the translated lights
    o = np.stack([np.full(8, -0.1), y, np.full(8, -4.0)], axis=1)
    d = np.array([[0.0, 0.0, 1.0], [0.0, 1e-13, 1.0], [0.0, -1e-17, 1.0]])
    o_all, d_all = np.repeat(o, 3, axis=0), np.tile(d, (8, 1))
    # Rays lying in the strips' planes: along e_u (resp. e_v) and w.
    ou = paths.x[:, 0] - 4.0 * _unit(AREA.edge_u)
    o_all = np.concatenate([o_all, ou, ou, paths.x[:, 0] + 0.1 * w - 4.0 * _unit(AREA.edge_v)])
    d_all = np.concatenate([d_all, np.tile(_unit(AREA.edge_u), (8, 1)),
                            np.tile(_unit(AREA.edge_u + 1e-14 * w[0]), (8, 1)),
                            np.tile(_unit(AREA.edge_v), (8, 1))])
    rays = Rays(o_all, d_all, np.zeros(len(d_all)), np.full(len(d_all), 10.0),
                np.zeros(len(d_all), np.int64), 1)
    _finite_everywhere(scene, paths, rays, ALL)
    uv = _hits_of(scene, "ss-plane-uv", paths=paths, rays=rays)[2]
    assert not np.isin(uv.ray, np.arange(0, 24, 3)).any()  # exactly parallel: no hit
