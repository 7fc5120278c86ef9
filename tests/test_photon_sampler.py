"""The photon samplers (psurf_core/photon_sampler.py): the default keeps the tracer's draws bit
for bit; each ``sobol`` photon's numbers are uniform (every pass unbiased) while a batch
covers them evenly; both tracers read the same numbers; renders with either sampler agree;
the sampler is part of a checkpoint's identity."""

import numpy as np
import pytest
from scipy import stats
from tiny_scene import TINY

from psurf_core.checkpoint import identity_differences, render_identity
from psurf_core.estimators import parse_estimator
from psurf_core.photon_sampler import (
    SobolDraws,
    batch_draws,
    photon_dimensions,
    uniforms,
)
from psurf_core.render import RenderSettings, render
from psurf_core.scene_io import load_scene
from psurf_core.trace import trace, trace_depth


def test_independent_draws_are_the_generators_own():
    """From a generator, ``uniforms`` is ``rng.random(k m)``: with or without ``out``."""
    a, b = np.random.default_rng(3), np.random.default_rng(3)
    assert np.array_equal(uniforms(a, 3, 200), b.random(600))
    out = np.empty(600)
    assert uniforms(np.random.default_rng(3), 3, 200, out=out) is out
    assert np.array_equal(out, np.random.default_rng(3).random(600))
    assert batch_draws("independent", a, None, 5, 3) is a


def test_sobol_columns_stratify_each_dimension():
    """The first 2^k points of each dimension fall one in each interval of width 2^-k (the
    set's one-dimensional projections are (0, k, 1)-nets after scrambling)."""
    d = SobolDraws(np.random.default_rng(1), 1024, 6)
    cols = d.columns(6, 1024).reshape(6, 1024)
    for c in cols:
        assert np.array_equal(np.sort((c * 1024).astype(int)), np.arange(1024))
    iid = np.random.default_rng(1).random(1024)
    assert not np.array_equal(np.sort((iid * 1024).astype(int)), np.arange(1024))


@pytest.mark.parametrize("point", [0, 1, 517])
def test_each_sobol_point_is_uniform(point):
    """Across batches (seeds) one photon's numbers are uniform in each dimension (KS) and
    independent between dimensions (a 4x4 chi-square of two of them): each photon, so each
    pass, is sampled as with independent numbers. Unscrambled Sobol (point 0 at the origin
    in every batch) fails."""
    x = np.array([SobolDraws(np.random.default_rng(s), 1024, 5).points[point]
                  for s in range(400)])
    for dim in range(5):
        assert stats.kstest(x[:, dim], "uniform").pvalue > 1e-3
    cells = np.bincount((x[:, 1] * 4).astype(int) * 4 + (x[:, 4] * 4).astype(int),
                        minlength=16)
    assert stats.chisquare(cells).pvalue > 1e-3
    from scipy.stats import qmc

    bare = qmc.Sobol(5, scramble=False).random(1024)[point]
    assert stats.kstest(np.full(400, bare[0]), "uniform").pvalue < 1e-3


def test_columns_lay_out_as_the_stage_reads_them():
    """Dimension by dimension, the set's next dimensions each call; ``pairs`` interleaves
    the first two (an area light's ``(u, v)`` rows); past the set, independent numbers."""
    d = SobolDraws(np.random.default_rng(2), 64, 6)
    a = d.columns(4, 64, pairs=True)
    assert np.array_equal(a[:128].reshape(64, 2), d.points[:, :2])
    assert np.array_equal(a[128:192], d.points[:, 2]) and np.array_equal(a[192:], d.points[:, 3])
    b = d.columns(2, 40)
    assert np.array_equal(b, d.points[:40, 4:6].T.ravel())
    c = d.columns(3, 64)  # beyond the set's 6 dimensions
    assert c.shape == (192,) and np.all((c >= 0) & (c < 1))


@pytest.mark.parametrize("name", ["area", "point", "mesh_light", "area_occluder", "hg"])
def test_both_tracers_read_the_same_sobol_numbers(name):
    """The numpy reference and the compiled path trace the same photons from the same set,
    bit for bit (both draw through ``uniforms``, in the same order)."""
    scene = load_scene(f"scenes/{name}.toml")
    depth = trace_depth(scene)
    dims = photon_dimensions(scene, depth)
    a = trace(scene, 2000, SobolDraws(np.random.default_rng(4), 2000, dims))
    b = trace(scene, 2000, SobolDraws(np.random.default_rng(4), 2000, dims), reference=True)
    for f in ("x", "w", "t", "beta", "alive", "prefix_ok", "light", "light_uv"):
        assert np.array_equal(getattr(a, f), getattr(b, f)), f


def test_sobol_photons_integrate_a_smooth_function_better():
    """The mean first scattering point of a batch (a smooth function of the light point,
    the emission direction and the first flight) varies far less from batch to batch with
    Sobol photons: below 0.2x the independent batches' variance over 40 batches of 1024."""
    scene = load_scene("scenes/area.toml")
    means = {}
    for sampler in ("independent", "sobol"):
        m = []
        for s in range(40):
            draws = batch_draws(sampler, np.random.default_rng(100 + s), scene, 1024, 3)
            p = trace(scene, 1024, draws, max_depth=3)
            m.append(p.x[:, 1].mean(axis=0))
        means[sampler] = np.array(m)
    ratio = means["sobol"].var(axis=0, ddof=1) / means["independent"].var(axis=0, ddof=1)
    assert np.all(ratio < 0.2), ratio


def test_photon_dimensions_count_every_stage():
    """The light choice (only where there are several lights), each light's emission
    (point 2, area 4, mesh 5), the first flight and four numbers per later segment."""
    for name, per_light in (("area", 4), ("point", 2), ("mesh_light", 5)):
        scene = load_scene(f"scenes/{name}.toml")
        assert all(type(lt).__name__.lower().startswith(name.split("_")[0])
                   for lt in scene.lights)
        choice = int(len(scene.lights) > 1)
        assert photon_dimensions(scene, 3) == choice + per_light * len(scene.lights) + 1 + 8


def _two_lights(tmp_path):
    """``area.toml`` with a point light added."""
    from pathlib import Path

    path = tmp_path / "two.toml"
    path.write_text(Path("scenes/area.toml").read_text() + '\n[[lights]]\ntype = "point"\n'
                    'position = [0.3, 0.4, 0.1]\nintensity = [4.0, 4.0, 4.0]\n')
    return load_scene(str(path))


def test_several_lights_choice_takes_the_first_dimension(tmp_path):
    """With two lights (area 4 + point 2) the choice is dimension 0; each light's photons
    read their own points' next dimensions, and both tracers the same numbers."""
    scene = _two_lights(tmp_path)
    dims = photon_dimensions(scene, 3)
    assert dims == 1 + 4 + 2 + 1 + 8
    d = SobolDraws(np.random.default_rng(4), 512, dims)
    p = trace(scene, 512, d, max_depth=3)
    area = p.light == 0
    assert 0 < area.sum() < 512
    assert np.array_equal(p.light_uv[area], d.points[area, 1:3])
    q = trace(scene, 512, SobolDraws(np.random.default_rng(4), 512, dims), max_depth=3,
              reference=True)
    for f in ("x", "w", "t", "light"):
        assert np.array_equal(getattr(p, f), getattr(q, f)), f


def test_one_lights_choice_takes_no_sobol_dimension():
    """With one light the light choice is a spare number: the emission's ``(u, v)`` are
    the set's first two dimensions (its most even projection), not dimensions 1 and 2."""
    scene = load_scene("scenes/area.toml")
    dims = photon_dimensions(scene, 3)
    d = SobolDraws(np.random.default_rng(4), 512, dims)
    p = trace(scene, 512, d, max_depth=3)
    assert np.array_equal(p.light_uv, d.points[:, :2])


def test_each_photon_keeps_its_own_point():
    """Rows: a stage of some photons reads their own points' next dimensions."""
    d = SobolDraws(np.random.default_rng(2), 64, 6)
    d.columns(2, 64)
    rows = np.array([3, 10, 11, 40])
    assert np.array_equal(d.columns(2, 4, rows=rows), d.points[rows, 2:4].T.ravel())
    assert d.columns(1, 4, spare=True).shape == (4,) and d.next == 4


def test_sequence_points_do_not_depend_on_what_was_asked_before():
    """``sobol-seq``: points ``start ..`` of a seed's sequence are its contiguous points,
    asked in order, out of order or again; another seed scrambles another sequence."""
    from psurf_core.photon_sampler import sequence_points

    whole = sequence_points(31, 5, 0, 3000)
    assert np.array_equal(sequence_points(31, 5, 1000, 500), whole[1000:1500])
    assert np.array_equal(sequence_points(31, 5, 1500, 700), whole[1500:2200])
    assert np.array_equal(sequence_points(31, 5, 200, 100), whole[200:300])
    assert not np.allclose(sequence_points(32, 5, 0, 100), whole[:100])


def test_sequence_passes_together_stratify_each_dimension():
    """The first four passes of 256 photons are the sequence's first 1024 points: one in
    each interval of width 1/1024 in every dimension (passes of ``sobol`` sets scrambled
    apart are not)."""
    from psurf_core.photon_sampler import sequence_points, sequence_start

    seq = np.concatenate([sequence_points(7, 6, sequence_start(i, 256, 0, 1 << 15), 256)
                          for i in range(4)])
    for c in seq.T:
        assert np.array_equal(np.sort((c * 1024).astype(int)), np.arange(1024))
    sets = np.concatenate([SobolDraws(np.random.default_rng(i), 256, 6).points
                           for i in range(4)])
    assert not all(np.array_equal(np.sort((c * 1024).astype(int)), np.arange(1024))
                   for c in sets.T)


@pytest.mark.parametrize("point", [0, 517, 5000])
def test_each_sequence_point_is_uniform(point):
    """Across seeds one point of the ``sobol-seq`` sequence is uniform in each dimension
    (KS): every pass is unbiased."""
    from psurf_core.photon_sampler import sequence_points

    x = np.array([sequence_points(s, 4, point, 1)[0] for s in range(300)])
    for dim in range(4):
        assert stats.kstest(x[:, dim], "uniform").pvalue > 1e-3


def _tiny_k2(tmp_path):
    """The tiny area-light scene at K = 2."""
    path = tmp_path / "tiny.toml"
    path.write_text(TINY + "\n[render]\nmin_scatter = 2\nmax_scatter = 2\n")
    return load_scene(str(path))


def test_renders_with_either_photon_sampler_agree(tmp_path):
    """`planes` and `fast-multi` on the tiny area-light scene at K = 2, 4 seeds x 40 passes
    of each sampler: the images' totals agree within 5 standard errors (from the seeds'
    spread)."""
    scene = _tiny_k2(tmp_path)
    for spec in ("planes", "fast-multi"):
        est = parse_estimator(spec, scene)
        totals = {}
        for sampler in ("independent", "sobol", "sobol-seq"):
            st = RenderSettings(photons=300, photon_sampler=sampler)
            totals[sampler] = np.array([render(scene, est, st, passes=40, seed=s).mean.sum()
                                        for s in range(4)])
        a = totals["independent"]
        for sampler in ("sobol", "sobol-seq"):
            b = totals[sampler]
            se = np.sqrt(a.var(ddof=1) / len(a) + b.var(ddof=1) / len(b))
            assert abs(a.mean() - b.mean()) < 5.0 * se, (spec, sampler)
        assert a.mean() > 0.0


def test_sobol_renders_are_fixed_by_seed(tmp_path):
    """The same seed gives the same image; another sampler another one."""
    scene = _tiny_k2(tmp_path)
    est = parse_estimator("planes", scene)
    st = RenderSettings(photons=200, photon_sampler="sobol")
    a = render(scene, est, st, passes=3, seed=9).mean
    b = render(scene, est, st, passes=3, seed=9).mean
    c = render(scene, est, RenderSettings(photons=200), passes=3, seed=9).mean
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    sq = RenderSettings(photons=200, photon_sampler="sobol-seq")
    d = render(scene, est, sq, passes=3, seed=9).mean
    assert np.array_equal(d, render(scene, est, sq, passes=3, seed=9).mean)
    assert not np.array_equal(d, a)


def test_unknown_photon_sampler_is_refused():
    with pytest.raises(ValueError, match="unknown photon sampler 'r2'"):
        RenderSettings(photon_sampler="r2")


def test_checkpoint_identity_names_the_photon_sampler(tmp_path):
    """A checkpoint rendered with Sobol photons does not resume with the default sampler;
    a default checkpoint's identity has no such key (older files resume)."""
    path = tmp_path / "tiny.toml"
    path.write_text(TINY)
    scene = load_scene(str(path))
    est = parse_estimator("planes", scene)
    plain = render_identity(str(path), scene, est, RenderSettings(), 0)
    sob = render_identity(str(path), scene, est, RenderSettings(photon_sampler="sobol"), 0)
    assert "photon_sampler" not in plain and sob["photon_sampler"] == "sobol"
    assert [d[0] for d in identity_differences(sob, plain)] == ["photon_sampler"]
    from ui.cli.checkpoint import describe_difference

    said = describe_difference(*identity_differences(sob, plain)[0], str(path))
    assert said == ("the checkpoint was made with --photon-sampler 'sobol', the command line "
                    "has 'independent'")


def test_sequence_render_resumes_bit_for_bit(tmp_path):
    """``sobol-seq``: two passes, then two more continuing the accumulator, give the image of
    four passes in one go (pass ``i``'s points depend on the seed, ``i`` and the pass size
    alone), also when another seed's sequence was drawn in between."""
    scene = _tiny_k2(tmp_path)
    est = parse_estimator("fast-multi", scene)
    st = RenderSettings(photons=150, photon_sampler="sobol-seq")
    whole = render(scene, est, st, passes=4, seed=5).mean
    first = render(scene, est, st, passes=2, seed=5)
    render(scene, est, st, passes=3, seed=6)
    from psurf_core.accumulate import Welford

    acc = Welford.empty(whole.shape)
    render(scene, est, st, passes=2, seed=5, accumulator=acc)
    again = render(scene, est, st, passes=4, seed=5, accumulator=acc).mean
    assert np.array_equal(again, whole)
    assert not np.array_equal(first.mean, whole)
