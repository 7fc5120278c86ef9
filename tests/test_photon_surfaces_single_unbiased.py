"""Single-scattering photon surfaces (``ss-*``, spec 3.2 and 4): unbiasedness.

Every technique (long and short) and the MIS sets against oracles, through the technique
stages (trace -> create -> candidate pairs -> intersect -> evaluate [-> MIS weight]) on
*unjittered* pixel-centre rays: the 1D quadrature for point lights, the reference path
tracer for a parallelogram and closed mesh lights. The statistic is the z-score of the image
mean (every estimator) and of the four quadrants' means (MIS sets), with standard errors from
independent passes; single techniques have heavy tails (spec 5), so photons are pooled over
10-16 passes. A triangle strip using the joint pdf must fail the check.

Fixed seeds only.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
from photon_surfaces_single_support import LIGHTS, PLANES, SINGLE
from small_scenes import POINT, H, W, make_scene

from psurf_core.binning import candidate_pairs
from psurf_core.camera import Rays, camera_rays, project
from psurf_core.estimators import Estimator, parse_estimator
from psurf_core.geometry import blockers_of
from psurf_core.mis import mis_weights
from psurf_core.reference import reference_pass, single_scatter_quadrature
from psurf_core.scene import SphereOccluder
from psurf_core.techniques.base import PassContext
from psurf_core.techniques.single_planes import SinglePlane
from psurf_core.trace import trace

Z_MAX = 4.0


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


# ------------------------------------------------------------------------- point light
def _point_case(g, occluders, n, passes, seed):
    scene = make_scene([POINT], occluders, g=g)
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


# ------------------------------------------------------------------------- area / mesh lights
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
    scene = make_scene(LIGHTS[light_name], g=g)
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
    scene = make_scene(LIGHTS[light_name], g=g)
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
