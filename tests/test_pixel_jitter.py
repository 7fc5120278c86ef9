"""The pixel samplers (psurf_core/pixel_jitter.py): each pass's points uniform over the pixel
(so every pass stays unbiased), the r2 points of one pixel even over the passes, the same
points for the same (seed, pass) anywhere, and renders with either sampler agreeing."""

import numpy as np
import pytest
from scipy import stats
from tiny_scene import TINY

from psurf_core.checkpoint import identity_differences, render_identity
from psurf_core.estimators import parse_estimator
from psurf_core.pixel_jitter import pass_jitter, r2_points, rotation
from psurf_core.render import RenderSettings, render
from psurf_core.scene_io import load_scene


def _r2(seed, i, n_pixels=4096, spp=1):
    return np.stack(pass_jitter("r2", n_pixels, spp, seed, i, None), axis=1)


def test_independent_draws_what_camera_rays_drew():
    """The default sampler takes the two draws camera_rays always took: images keep their
    bits."""
    a = np.random.default_rng(5)
    jx, jy = pass_jitter("independent", 300, 2, 0, 7, np.random.default_rng(5))
    assert np.array_equal(jx, a.random(600)) and np.array_equal(jy, a.random(600))


@pytest.mark.parametrize("i", [0, 1, 37, 1000])
def test_r2_pass_points_are_uniform_over_the_pixel(i):
    """Across pixels (independent rotations) pass i's points are uniform in [0, 1)^2: each
    pass alone is an unbiased box-filter sample. KS on each axis and a 4x4 cell chi-square;
    a sequence without its rotation (all pixels at one point) fails both."""
    p = _r2(11, i)
    for axis in range(2):
        assert stats.kstest(p[:, axis], "uniform").pvalue > 1e-3
    cells = np.bincount((p[:, 0] * 4).astype(int) * 4 + (p[:, 1] * 4).astype(int),
                        minlength=16)
    assert stats.chisquare(cells).pvalue > 1e-3
    bare = r2_points(np.full(4096, i), np.zeros((4096, 2)))
    assert stats.kstest(bare[:, 0], "uniform").pvalue < 1e-6


def test_r2_points_of_a_pixel_cover_it_evenly():
    """Over P passes one pixel's points integrate a smooth function of the pixel position with
    far less error than P independent points: the pixel-area noise of the mean falls faster
    than 1 / P (the squared error over 2000 pixels, P = 64: under a tenth)."""
    def f(x, y):
        return np.sin(3.0 * x) * (1.0 + y * y)

    exact = (1.0 - np.cos(3.0)) / 3.0 * (4.0 / 3.0)
    passes = 64
    r2 = np.mean([f(*_r2(3, i, 2000).T) for i in range(passes)], axis=0)
    rng = np.random.default_rng(3)
    ind = np.mean([f(rng.random(2000), rng.random(2000)) for _ in range(passes)], axis=0)
    assert np.mean((r2 - exact) ** 2) < 0.1 * np.mean((ind - exact) ** 2)


def test_r2_points_are_fixed_by_seed_and_pass():
    assert np.array_equal(_r2(4, 9), _r2(4, 9))
    assert not np.array_equal(_r2(4, 9), _r2(5, 9))
    assert not np.array_equal(_r2(4, 9), _r2(4, 10))
    # spp rays of a pixel in pass i are consecutive points of its sequence
    two = _r2(4, 3, n_pixels=10, spp=2)
    rot = rotation(4, 20)
    assert np.allclose(two[1], r2_points([7], rot[1:2])[0])


def test_unknown_sampler_is_refused():
    with pytest.raises(ValueError, match="unknown pixel sampler 'sobol'"):
        RenderSettings(pixel_sampler="sobol")


def test_renders_with_either_sampler_agree(tmp_path):
    """Photon planes on the tiny area-light scene at K = 2, 4 seeds x 60 passes of each
    sampler: the images' totals agree within 5 standard errors (taken from the seeds' spread,
    which the r2 passes' correlation cannot fool)."""
    path = tmp_path / "tiny.toml"
    path.write_text(TINY + "\n[render]\nmin_scatter = 2\nmax_scatter = 2\n")
    scene = load_scene(str(path))
    est = parse_estimator("planes", scene)
    totals = {}
    for sampler in ("independent", "r2"):
        st = RenderSettings(photons=300, pixel_sampler=sampler)
        totals[sampler] = np.array([render(scene, est, st, passes=60, seed=s).mean.sum()
                                    for s in range(4)])
    a, b = totals["independent"], totals["r2"]
    se = np.sqrt(a.var(ddof=1) / len(a) + b.var(ddof=1) / len(b))
    assert abs(a.mean() - b.mean()) < 5.0 * se
    assert a.mean() > 0.0


def test_checkpoint_identity_names_the_sampler(tmp_path):
    """A checkpoint rendered with r2 does not resume with the default sampler (nor the
    reverse); a default checkpoint's identity has no sampler key (older files resume)."""
    path = tmp_path / "tiny.toml"
    path.write_text(TINY)
    scene = load_scene(str(path))
    est = parse_estimator("planes", scene)
    plain = render_identity(str(path), scene, est, RenderSettings(), 0)
    r2 = render_identity(str(path), scene, est, RenderSettings(pixel_sampler="r2"), 0)
    assert "pixel_sampler" not in plain and r2["pixel_sampler"] == "r2"
    assert [d[0] for d in identity_differences(r2, plain)] == ["pixel_sampler"]
    from ui.cli.checkpoint import describe_difference

    said = describe_difference(*identity_differences(r2, plain)[0], str(path))
    assert said == ("the checkpoint was made with --pixel-sampler 'r2', the command line has "
                    "'independent'")
