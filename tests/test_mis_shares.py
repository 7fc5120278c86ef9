"""MIS with sample counts (``mis:A+B@0.25``): a member that sweeps a share of the photons.

The balance and power heuristics weigh ``n_i Q_i`` and a hit's value is divided by its
member's share ``n_i`` (Veach's multi-sample MIS), which keeps the set unbiased whatever the
shares; the weights of all members still sum to one on every path.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from psurf_core.estimators import parse_estimator
from psurf_core.mis import weights_from_densities
from psurf_core.render import RenderSettings, render_pass
from psurf_core.scene_io import load_scene
from psurf_core.techniques import UnknownTechnique

SCENES = Path(__file__).resolve().parent.parent / "scenes"


def test_the_grammar_takes_a_share_per_member():
    est = parse_estimator("mis:planes+cone-short@0.25+cylinder@1")
    assert [(t.name, t.share) for t in est.techniques] == [
        ("plane-t1t2-short", 1.0), ("cone-short", 0.25), ("cylinder", 1.0)]
    assert [t.label for t in est.techniques] == ["plane-t1t2-short", "cone-short@0.25",
                                                 "cylinder"]
    for bad in ("mis:planes+cone@0", "mis:planes+cone@1.5", "mis:planes+cone@x",
                "mis:planes+cone@"):
        with pytest.raises(UnknownTechnique, match="share after '@'"):
            parse_estimator(bad)
    with pytest.raises(UnknownTechnique, match="listed twice"):
        parse_estimator("mis:cone+cone@0.5")
    # Leaving a member out of an allocated set by name.
    assert [t.name for t in parse_estimator("mis:planes+cone@0.5+cylinder~cone").techniques] \
        == ["plane-t1t2-short", "cylinder"]


def test_weights_with_shares_sum_to_one():
    rng = np.random.default_rng(0)
    q = rng.exponential(size=(3, 50))
    q[1, :5] = 0.0
    for weighting in ("balance", "power"):
        w = weights_from_densities(q, weighting, np.array([1.0, 0.25, 0.5]))
        np.testing.assert_allclose(w.sum(axis=0), 1.0, rtol=1e-14)


def _sums(scene, spec, passes, photons=600):
    est = parse_estimator(spec, scene)
    return np.array([render_pass(scene, est, i, 11, RenderSettings(photons=photons)).sum()
                     for i in range(passes)])


def _z(a, b):
    se = np.hypot(a.std(ddof=1) / np.sqrt(a.size), b.std(ddof=1) / np.sqrt(b.size))
    return (a.mean() - b.mean()) / se


def _scene():
    scene = load_scene(SCENES / "study_medium.toml")
    return replace(scene, min_scatter=2, max_scatter=3,
                   camera=replace(scene.camera, width=16, height=12))


def test_allocated_set_is_unbiased_and_the_test_can_tell(monkeypatch):
    """Against the same set with every share 1: the image sums of pooled passes agree
    within 4 standard errors. The same comparison catches weights that ignore the shares
    (members that swept a fifth of the photons counted as if they had swept all)."""
    import psurf_core.render as rmod

    scene = _scene()
    full = _sums(scene, "mis:planes+cone-short+cylinder-short", 30)
    alloc = _sums(scene, "mis:planes+cone-short@0.2+cylinder-short@0.3", 30)
    assert abs(_z(alloc, full)) < 4.0, (alloc.mean(), full.mean())
    real = rmod.MisSet
    monkeypatch.setattr(rmod, "MisSet", lambda g, f, w, shares: real(g, f, w, None))
    wrong = _sums(scene, "mis:planes+cone-short@0.2+cylinder-short@0.3", 30)
    assert abs(_z(wrong, full)) > 4.0, (wrong.mean(), full.mean())


@pytest.mark.slow
def test_allocated_set_with_a_numpy_member_is_unbiased():
    """The numpy MIS weights (a member without a compiled density) take shares too."""
    scene = _scene()
    full = _sums(scene, "mis-power:planes+cone-short+hyperboloid", 30)
    alloc = _sums(scene, "mis-power:planes@0.5+cone-short+hyperboloid@0.4", 30)
    assert abs(_z(alloc, full)) < 4.0, (alloc.mean(), full.mean())


@pytest.mark.parametrize("name,k,fast,paper", [
    ("study_occluder", (2, 3), "fast-multi", "paper-multi"),
    ("study_area", (1, 1), "fast-single", "paper-single"),
    ("point", (1, 1), "fast-single", "paper-single"),
    ("mesh_light", (1, 1), "fast-single", "paper-single"),
    # fast-full's single-scattering set for each light kind, every member on a share
    # (FULL_SINGLE_SHARES); its multiple-scattering set is left out (nothing at K = 1).
    ("mesh_light", (1, 1), "fast-full~plane-t1t2-short~plane-t2t3-short~cone-short",
     "paper-single"),
    ("point", (1, 1), "fast-full~plane-t1t2-short~plane-t2t3-short~cone-short",
     "paper-single"),
    ("study_area", (1, 1), "fast-full~plane-t1t2-short~plane-ut-short~cone-short",
     "paper-single"),
    # A share the pilot may choose (share_pilot.SHARE_RANGE's floor is 0.03).
    ("point", (1, 1), "fast-full@0.05~plane-t1t2-short~plane-t2t3-short~cone-short",
     "paper-single"),
    # A point light with an HG phase and a box occluder (its walkers compile: make test-slow).
    pytest.param("hg", (1, 1), "fast-full~plane-t1t2-short~plane-t2t3-short~cone-short",
                 "paper-single", marks=pytest.mark.slow),
    # 2 s warm, but ~85 s of numba compiling on a fresh clone (walkers for a mesh and a
    # point light together): make test-slow.
    pytest.param("mesh_light+point", (1, 1), "fast-single", "paper-single",
                 marks=pytest.mark.slow),
    # An area light beside a point light: the disk and the sphere sweep every photon of
    # both (estimators._fast_single), the area light's planes only its own.
    pytest.param("study_area+point", (1, 1), "fast-single", "paper-single",
                 marks=pytest.mark.slow),
])
def test_fast_presets_agree_with_the_papers(name, k, fast, paper):
    """The presets tuned for equal time (short members, sample counts, per-light members)
    estimate what the paper's presets do: pooled image sums within 4 standard errors.
    ``mesh_light+point``: the mesh light and ``point``'s point light in one scene, where
    ``ss-sphere`` serves both lights and each light has its own cone and disk."""
    first, _, second = name.partition("+")
    scene = load_scene(SCENES / f"{first}.toml")
    if second:
        scene = replace(scene, lights=(*scene.lights,
                                       *load_scene(SCENES / f"{second}.toml").lights))
    scene = replace(scene, min_scatter=k[0], max_scatter=k[1],
                    camera=replace(scene.camera, width=16, height=12))
    a, b = _sums(scene, fast, 30, 800), _sums(scene, paper, 30, 400)
    assert abs(_z(a, b)) < 4.0, (a.mean(), b.mean())


def test_fast_full_gives_single_scattering_a_share_per_light_kind():
    """``fast-full`` sums two sets; its single-scattering members sweep
    :data:`FULL_SINGLE_SHARES` of the photons by light kind (they cost most of a pass for
    little of the error, docs/vs_mitsuba.md), an area light's disk and sphere their
    ``fast-single`` shares scaled alike; ``fast-single`` keeps its own. A member several
    kinds share sweeps the largest share any of them asks for."""
    from psurf_core.estimators import AREA_DISK_SHARE, AREA_SPHERE_SHARE, FULL_SINGLE_SHARES

    def at(x):
        return "" if x == 1.0 else f"@{x:g}"

    m, p, a = (FULL_SINGLE_SHARES[k] for k in ("mesh", "point", "area"))
    mesh = load_scene(SCENES / "mesh_light.toml")
    full = parse_estimator("fast-full", mesh)
    assert [t.label for t in full.groups[0]] == [
        "ss-sphere" + at(m), "ss-cone" + at(m), "ss-disk-short" + at(m)]
    assert [t.label for t in full.groups[1]] == [  # the multiple-scattering set as before
        "plane-t1t2-short", "plane-t2t3-short@0.3", "cone-short@0.2"]
    assert [t.label for t in parse_estimator("fast-single", mesh).techniques] == [
        "ss-sphere", "ss-cone", "ss-disk-short"]
    area = load_scene(SCENES / "area.toml")
    assert [t.label for t in parse_estimator("fast-full", area).groups[0]] == [
        "ss-plane-uv" + at(a), "ss-plane-ut-short" + at(a), "ss-plane-vt-short" + at(a),
        "ss-sphere" + at(AREA_SPHERE_SHARE * a), "ss-disk" + at(AREA_DISK_SHARE * a)]
    both = replace(mesh, lights=(*mesh.lights,
                                 *load_scene(SCENES / "point.toml").lights))
    labels = [t.label for t in parse_estimator("fast-full", both).groups[0]]
    assert labels == ["ss-sphere" + at(max(m, p)), "ss-cone-short" + at(p), "ss-cone" + at(m),
                      "ss-disk" + at(p), "ss-disk-short" + at(m)]
