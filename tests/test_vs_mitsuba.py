"""The psurf -> Mitsuba 3 conversion of ``benchmarks/mitsuba_scene.py`` against psurf's oracles.

Before ``benchmarks/vs_mitsuba.py`` compares psurf with Mitsuba's ``volpath``, the converted
scene must render the same image: the same camera (vertical fov, image right = forward x up,
row 0 at the top, a pixel = the average over its area), the same units (point-light radiant
intensity, one-sided emitter radiance, sigma_t / albedo, HG g), black opaque emitters and
occluders, and the same scatter window (``max_depth`` and the difference of two renders).

* Point-light single scattering against psurf's deterministic quadrature, integrated over each
  pixel's area (Gauss-Legendre in the pixel, x the 1D quadrature along each ray), on an
  asymmetric scene, with the camera outside the medium and inside it (a wide view); the
  mirrored images must fail the same check (the check can fail).
* Area + mesh lights with occluders (K = 1, the window K = 2..3, and unlimited) against
  psurf's reference path tracer (itself checked against quadratures and an independent walk in
  ``test_reference.py``); per pixel only inside the medium box's silhouette
  (:func:`inside_silhouette`: on its edge Mitsuba's 32 passes are mostly 0, no standard error),
  in the aggregate everywhere. The K = 1 image mirrored left-right must fail; the window one
  also rejects the neighbouring window K = 2..2.

Every comparison is a z-score (per pixel and summed over the image) of Monte Carlo means
against their standard errors (fixed seeds). The Mitsuba tests skip when Mitsuba (the
optional ``bench`` extra) is not installed or no variant renders here; the conversion's
pure-numpy parts are tested always.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from psurf_core.camera import camera_rays, pixel_directions, project
from psurf_core.constants import MAX_TRACE_DEPTH
from psurf_core.geometry import blockers_of, ray_box
from psurf_core.reference import reference_image
from psurf_core.reference_quadrature import pixel_quadrature
from psurf_core.scene import BoxOccluder, Scene, SphereOccluder

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import mitsuba_scene as ms  # noqa: E402
from small_scenes import POINT, TETRA, make_scene  # noqa: E402
from small_scenes import TILTED_AREA as AREA  # noqa: E402 - benchmarks/mitsuba_conventions uses T.AREA

#: Aggregate (sum over the image, per channel) z bound, and the per-pixel bound: 192 pixels x 3
#: channels with standard errors from 32 passes (Student-t tails) need a wider per-pixel one.
Z_MAX = 4.0
Z_PIXEL = 5.0
W, H = 16, 12

OCCLUDERS = (
    SphereOccluder(np.array([-0.3, 0.0, -0.4]), 0.25),
    BoxOccluder(np.array([0.3, 0.2, -0.6]), np.array([0.6, 0.4, -0.3])),
)


def _scene(lights, occluders=(), g=0.0, sigma_s=0.8, sigma_a=0.2, kmin=1, kmax=1,
           camera=(-4.0, 40.0)):
    """The test scene at W x H; ``camera`` is (z of the position on the axis, vertical fov)."""
    z, fov = camera
    return make_scene(lights, occluders, g, sigma_s, sigma_a, kmin, kmax, size=(W, H),
                      position=(0.0, 0.0, z), fov=fov)


# --------------------------------------------------------------------------- no Mitsuba needed
def test_depths_of_scatter_windows():
    s = _scene([POINT])
    assert ms.depth_pair(s.with_scatter(1, 1)) == (2, None)
    assert ms.depth_pair(s.with_scatter(1, 3)) == (4, None)
    assert ms.depth_pair(s.with_scatter(2, 3)) == (4, 2)
    assert ms.depth_pair(s.with_scatter(2, 2)) == (3, 2)
    assert ms.depth_pair(s.with_scatter(1, -1)) == (MAX_TRACE_DEPTH + 1, None)
    assert ms.depth_pair(s.with_scatter(3, -1)) == (MAX_TRACE_DEPTH + 1, 3)


def test_look_at_matrix_is_mitsubas_frame():
    cam = _scene([POINT]).camera
    m = ms.look_at_matrix(cam.position, cam.look_at, cam.up)
    np.testing.assert_allclose(m[:3, :3].T @ m[:3, :3], np.eye(3), atol=1e-12)
    np.testing.assert_allclose(m[:3, 2], cam.forward)
    np.testing.assert_allclose(m[:3, 0], -cam.right)  # Mitsuba's local +x is image left
    np.testing.assert_allclose(m[:3, 1], cam.image_up, atol=1e-12)
    np.testing.assert_allclose(m[:3, 3], cam.position)


def test_parallelogram_triangles_face_the_emitting_side():
    tris = ms.parallelogram_triangles(AREA)
    n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    np.testing.assert_allclose(n / np.linalg.norm(n, axis=1, keepdims=True),
                               np.broadcast_to(AREA.normal, (2, 3)), atol=1e-12)
    assert np.isclose(0.5 * np.linalg.norm(n, axis=1).sum(), AREA.area)


def test_inside_silhouette_is_full_box_coverage():
    """The per-pixel mask of the emitter checks: exactly the pixels whose every ray (16 x 16
    per pixel) meets the medium box; the silhouette's edge pixels are partly covered."""
    scene = _scene([AREA, TETRA], OCCLUDERS)
    cam, med = scene.camera, scene.medium
    sub = (np.arange(16) + 0.5) / 16
    row, col = np.divmod(np.arange(cam.n_pixels), cam.width)
    px = (col[:, None, None] + sub[None, :, None] + 0.0 * sub[None, None, :]).ravel()
    py = (row[:, None, None] + 0.0 * sub[None, :, None] + sub[None, None, :]).ravel()
    d = pixel_directions(cam, px, py)
    te, tx = ray_box(np.broadcast_to(cam.position, d.shape), d, med.bounds_min, med.bounds_max)
    cover = (tx > np.maximum(te, 0.0)).reshape(H, W, 256).mean(axis=-1)
    inside = inside_silhouette(scene)
    np.testing.assert_array_equal(inside, cover == 1.0)
    assert inside.sum() == 100 and np.any((cover > 0) & ~inside)


# --------------------------------------------------------------------------- with Mitsuba
@pytest.fixture(scope="module")
def variant():
    if ms.import_mitsuba() is None:
        pytest.skip("mitsuba is not installed (optional extra: pip install -e '.[bench]')")
    try:
        return ms.pick_variant()
    except RuntimeError as e:
        pytest.skip(f"no Mitsuba variant renders on this machine ({e}); see make bench-mitsuba")


def _mitsuba(scene, passes, spp, seed):
    r = ms.MitsubaRenderer(scene, spp=spp).render(passes=passes, seed=seed, warmup=False)
    return r.mean, np.sqrt(r.var / r.passes)


def _psurf_reference(scene, passes, spp, seed):
    """Per-pixel mean and standard error of ``passes`` jittered reference passes."""
    bl = blockers_of(scene)
    rng = np.random.default_rng(seed)
    imgs = np.array([reference_image(scene, camera_rays(scene, spp, rng, blockers=bl), rng, bl)
                     for _ in range(passes)])
    return imgs.mean(axis=0), imgs.std(axis=0, ddof=1) / np.sqrt(passes)


def _z(a, se_a, b, se_b=0.0, mask=None):
    """Per-pixel |z| (masked) and the aggregate z per channel of ``a`` against ``b``."""
    mask = np.ones(a.shape[:2], bool) if mask is None else mask
    se = np.sqrt(se_a**2 + se_b**2)[mask]
    diff = (a - b)[mask]
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(se > 0, diff / se, np.where(diff == 0, 0.0, np.inf))
    agg = diff.sum(axis=0) / np.sqrt((se**2).sum(axis=0))
    return np.abs(z), agg


def _assert_agree(a, se_a, b, se_b=0.0, mask=None, label="", pixels=None):
    """Per-pixel |z| <= Z_PIXEL (on ``pixels`` if given, else on ``mask``) and the aggregate
    |z| <= Z_MAX per channel (over ``mask``)."""
    z, agg = _z(a, se_a, b, se_b, mask)
    if pixels is not None:
        z, _ = _z(a, se_a, b, se_b, pixels if mask is None else pixels & mask)
    assert z.max() <= Z_PIXEL, f"{label}: max |z| {z.max():.2f}"
    assert np.all(np.abs(agg) <= Z_MAX), f"{label}: aggregate z {agg}"
    assert np.any(b[mask if mask is not None else ...] > 0), f"{label}: nothing to compare"


def inside_silhouette(scene) -> np.ndarray:
    """(H, W) bool: pixels wholly inside the medium box's silhouette (all four corner rays
    meet the box; the box is convex, so then every ray of the pixel does).

    The others, on the silhouette's edge, are at most half covered and their rays see
    0.03-0.08 of medium on average (optical depth <= 0.11 in the emitter scene). Mitsuba's
    free-flight samples there are rarely non-zero, so most of its 32 pass means are 0 and
    their spread is no standard error: at K = 1, pixel (1, 13) had none of its 32 passes
    non-zero (mean 0, s.e. 0; |z| 7.7 against the reference) where psurf's reference gives
    5.8e-6 +- 0.3e-6 (0.2 % of the image mean) and 32 x 512 Mitsuba spp 5.5e-6 +- 1.6e-6
    (docs/vs_mitsuba.md, "Why not per pixel on the silhouette's edge"). The edge pixels stay
    in the aggregate z.
    """
    cam, med = scene.camera, scene.medium
    row, col = np.divmod(np.arange(cam.n_pixels), cam.width)
    hit = np.ones(cam.n_pixels, bool)
    for dx, dy in ((0, 0), (1, 0), (0, 1), (1, 1)):
        d = pixel_directions(cam, (col + dx).astype(float), (row + dy).astype(float))
        te, tx = ray_box(np.broadcast_to(cam.position, d.shape), d, med.bounds_min,
                         med.bounds_max)
        hit &= tx > np.maximum(te, 0.0)
    return hit.reshape(cam.height, cam.width)


#: Point-light cases: (g, occluders, camera, (sigma_s, sigma_a)). Inside the medium the camera
#: sees through dense medium (sigma_t = 2): Mitsuba's default near clip (0.01, where its rays
#: start) would make the image 2 % too bright, which this check rejects.
POINT_CASES = {
    "iso": (0.0, (), (-4.0, 40.0), (0.8, 0.2)),
    "hg-sphere": (0.5, (SphereOccluder(np.array([-0.1, 0.0, -0.3]), 0.3),), (-4.0, 40.0),
                  (0.8, 0.2)),
    "camera-inside": (0.0, (), (-0.9, 70.0), (1.6, 0.4)),
}


#: Mitsuba samples per pixel per pass: twice as many inside, where the rejected near-clip
#: error (2 %) must stand well clear of the noise.
POINT_SPP = {"iso": 128, "hg-sphere": 128, "camera-inside": 256}


def point_scene(case: str) -> Scene:
    """The point-light scene of :data:`POINT_CASES` ``[case]`` (K = 1)."""
    g, occluders, camera, (ss, sa) = POINT_CASES[case]
    return _scene([POINT], occluders, g=g, sigma_s=ss, sigma_a=sa, camera=camera)


@pytest.mark.parametrize("case", list(POINT_CASES))
def test_point_single_scatter_matches_pixel_quadrature(variant, case):
    scene = point_scene(case)
    g = scene.medium.phase.g
    fine, coarse = pixel_quadrature(scene, 8), pixel_quadrature(scene, 4)
    # The light's pixel holds the 1/r singularity (NEE to a point: infinite variance there,
    # and the pixel quadrature converges slowly); its neighbours are left out too.
    px, py, _ = project(scene.camera, POINT.position[None])
    mask = np.ones((H, W), bool)
    mask[max(int(py[0]) - 1, 0) : int(py[0]) + 2, max(int(px[0]) - 1, 0) : int(px[0]) + 2] = False
    m, se = _mitsuba(scene, passes=32, spp=POINT_SPP[case], seed=3)
    # The quadrature's own error (fine vs coarse) counts as a standard error.
    q_err = np.abs(fine - coarse)
    _assert_agree(m, se, fine, q_err, mask=mask, label=f"point {case} g={g}")
    # The check has power: the image mirrored left-right or top-bottom is rejected.
    for flip in (np.fliplr, np.flipud):
        z, agg = _z(flip(m), flip(se), fine, q_err, mask=mask)
        assert z.max() > Z_PIXEL, f"{flip.__name__} image not rejected"


@pytest.mark.parametrize("window", [(1, 1), (1, -1)], ids=["K1", "unlimited"])
def test_emitters_and_occluders_match_reference(variant, window):
    scene = _scene([AREA, TETRA], OCCLUDERS, g=0.4, sigma_s=1.2, sigma_a=0.2,
                   kmin=window[0], kmax=window[1])
    ref, ref_se = _psurf_reference(scene, passes=32, spp=32, seed=11)
    m, se = _mitsuba(scene, passes=32, spp=128, seed=12)
    inside = inside_silhouette(scene)
    _assert_agree(m, se, ref, ref_se, label=f"K={window}", pixels=inside)
    # The check has power: the image mirrored left-right is rejected.
    z, _ = _z(np.fliplr(m), np.fliplr(se), ref, ref_se, inside)
    assert z.max() > Z_PIXEL, "fliplr image not rejected"


def test_scatter_window_is_a_difference_of_depths(variant):
    """K = 2..3 as I(max_depth 4) - I(max_depth 2); K = 2..2 (an off-by-one) is rejected."""
    scene = _scene([AREA, TETRA], OCCLUDERS, g=0.4, sigma_s=1.2, sigma_a=0.2, kmin=2, kmax=3)
    ref, ref_se = _psurf_reference(scene, passes=32, spp=32, seed=21)
    m, se = _mitsuba(scene, passes=32, spp=128, seed=22)
    _assert_agree(m, se, ref, ref_se, label="K=2..3", pixels=inside_silhouette(scene))
    two, two_se = _psurf_reference(scene.with_scatter(2, 2), passes=32, spp=32, seed=23)
    _, agg = _z(m, se, two, two_se)
    assert np.all(np.abs(agg) > Z_MAX), f"K=2..2 not rejected: aggregate z {agg}"


def test_pass_seeds_are_distinct_32_bit():
    seeds = {ms.pass_seed(s, n, t) for s in (0, 1, 4242, 10**9) for n in range(50) for t in (0, 1)}
    assert len(seeds) == 400 and all(0 <= x < 2**32 for x in seeds)


# --------------------------------------------------------------------------- vs_mitsuba.py's parts
import mitsuba_renders as mr  # noqa: E402
import vs_mitsuba  # noqa: E402

from psurf_core.metrics import var_relmse  # noqa: E402
from psurf_core.study_reference import load_reference  # noqa: E402


@pytest.mark.parametrize("window", [(1, 1), (1, 3), (1, -1), (2, 3), (2, -1), (3, 3)])
def test_composite_reference_parts_cover_the_window_once(window):
    """Mitsuba renders K = 1 (only), planes K >= 2 (only): each K of the window exactly once."""
    kmin, kmax = window
    parts = mr.reference_parts("composite", kmin, kmax)
    covered = []
    for renderer, a, b in parts:
        assert renderer == ("mitsuba" if a == 1 else "planes")
        assert renderer != "mitsuba" or b == 1
        covered += list(range(a, (b if b >= 0 else 9) + 1))
    top = kmax if kmax >= 0 else 9
    assert covered == list(range(kmin, top + 1))
    assert mr.reference_parts("psurf", kmin, kmax) == [("psurf", kmin, kmax)]


def test_recommended_estimator_per_window_and_override():
    assert vs_mitsuba.recommended(1, 1) == "fast-single"
    assert vs_mitsuba.recommended(2, 3) == "fast-multi"
    assert vs_mitsuba.recommended(1, -1) == "fast-full"
    cases = vs_mitsuba.CASES
    est = vs_mitsuba._estimators(["hg=paper-full"], cases)
    assert est["hg"] == "paper-full" and est["point"] == "fast-full"
    assert est["study_area_k1"] == "fast-single" and est["study_occluder_k23"] == "fast-multi"
    assert set(vs_mitsuba._estimators(["planes"], cases).values()) == {"planes"}
    with pytest.raises(SystemExit):
        vs_mitsuba._estimators(["nosuchcase=planes"], cases)


def test_every_bundled_scene_is_a_case_with_its_own_window():
    """Issue 12 asks for every bundled scene: a scene added to scenes/ without a case fails
    here, and a bundled (non-study) scene's case renders the window of its [render] table."""
    from psurf_core.scene_io import load_scene

    root = Path(__file__).resolve().parents[1]
    bundled = {f"scenes/{p.name}" for p in (root / "scenes").glob("*.toml")}
    assert {c[1] for c in vs_mitsuba.CASES} == bundled
    for case, path, kmin, kmax in vs_mitsuba.CASES:
        if not case.startswith("study_"):
            sc = load_scene(root / path)
            assert (kmin, kmax) == (sc.min_scatter, sc.max_scatter), case


def test_photons_flag_is_auto_or_a_positive_count():
    assert vs_mitsuba._photons("auto") == "auto" and vs_mitsuba._photons("200") == 200
    for bad in ("0", "-3", "many", "2.5"):
        with pytest.raises(Exception, match="auto"):
            vs_mitsuba._photons(bad)


def test_summed_reference_is_a_compare_reference(tmp_path, monkeypatch):
    """reference() sums its parts (means and variances of the means) and writes the sum as a
    file ``app.py compare --reference`` loads, with the same floor."""
    scene = _scene([AREA], kmin=1, kmax=-1)
    rng = np.random.default_rng(3)
    parts = {}

    def fake_part(renderer, case, sc, path, a, b, args):
        d = {"mean": rng.random((H, W, 3)) + 0.5, "var": rng.random((H, W, 3)),
             "passes": 10 if renderer == "mitsuba" else 40, "spp": 1, "seconds": 2.0,
             "path": f"{renderer}.npz", "render_seconds": None}
        parts[renderer] = d
        return d

    monkeypatch.setattr(mr, "render_part", fake_part)
    args = type("A", (), {"reference": "composite", "work": str(tmp_path), "ref_time": 7.0})
    ref = mr.reference("c", scene, "x.toml", 1, -1, args)
    m, p = parts["mitsuba"], parts["planes"]
    np.testing.assert_allclose(ref["mean"], m["mean"] + p["mean"])
    np.testing.assert_allclose(ref["var_mean"], m["var"] / 10 + p["var"] / 40)
    assert ref["file"] == str(mr.composite_path(tmp_path, "c", "composite", 1, -1, 7.0))
    loaded = load_reference(ref["file"], scene)
    np.testing.assert_allclose(loaded.mean, ref["mean"])
    assert loaded.floor == pytest.approx(var_relmse(ref["var_mean"], ref["mean"]))
    with pytest.raises(Exception, match="scatter"):
        load_reference(ref["file"], scene.with_scatter(1, 1))


def test_reference_file_is_read_with_its_window(tmp_path):
    """``--reference-file CASE=PATH``: a render .npz becomes the case's reference (variance of
    the mean = var / passes); another scatter window, a missing file or an unknown case is one
    clear error."""
    rng = np.random.default_rng(5)
    mean, var = rng.random((H, W, 3)) + 0.5, rng.random((H, W, 3))
    path = tmp_path / "ref.npz"
    np.savez(path, mean=mean, var=var, passes=np.int64(8), spp=np.int64(1),
             seconds=np.float64(3.0), min_scatter=np.int64(2), max_scatter=np.int64(3),
             estimator=np.str_("paper-multi"), seed=np.int64(1000))
    ref = mr.reference_from_file(path, 2, 3)
    np.testing.assert_allclose(ref["mean"], mean)
    np.testing.assert_allclose(ref["var_mean"], var / 8)
    assert ref["parts"][0]["estimator"] == "paper-multi" and ref["parts"][0]["seed"] == 1000
    with pytest.raises(SystemExit, match="K=2..3, the case is K=1..1"):
        mr.reference_from_file(path, 1, 1)
    names = [c[0] for c in vs_mitsuba.CASES]
    assert vs_mitsuba._reference_files([f"hg={path}"], names) == {"hg": str(path)}
    for bad in (f"nosuch={path}", str(path), f"hg={tmp_path / 'missing.npz'}"):
        with pytest.raises(SystemExit, match="--reference-file"):
            vs_mitsuba._reference_files([bad], names)
