"""Numerics: no estimator lets a NaN or an infinity reach an image of a traced pass.

Property-based (hypothesis, derandomized, fixed example counts) over every registered
technique and its ``-short`` variant, every MIS-capable technique in one set, and the
reference path tracer: **traced photons** in scenes with extreme parameters (media from
``st = 1e-6`` to ``1e4``, ``|g|`` up to ``1 - 1e-9``, lights on the box boundary and at its
corners), one whole render pass each (binning included); every recorded per-hit value and
the image must be finite. Also the phase function itself as ``|g| -> 1``. Crafted photons and
rays are in ``test_numerics_crafted.py``.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numerics_support import (  # noqa: F401 - fixed_constant_pool is an autouse fixture
    MIS_NAMES,
    NAMES,
    TRACED,
    build_scene,
    fixed_constant_pool,
    traced_media,
)

from psurf_core.estimators import Estimator
from psurf_core.render import PassRecord, RenderSettings, render_pass
from psurf_core.scene import Scene
from psurf_core.techniques import get_technique


def _render_checked(scene: Scene, est: Estimator, seed: int, photons: int) -> int:
    rec = PassRecord()
    img = render_pass(scene, est, 0, seed, RenderSettings(photons=photons), record=rec)
    assert img.dtype == np.float64 and np.all(np.isfinite(img)), est.spec
    n = 0
    for chunks in rec.hits.values():
        for hits, val in chunks:
            assert np.all(np.isfinite(val)) and np.all(np.isfinite(hits.s)), est.spec
            n += len(hits)
    return n


@pytest.mark.parametrize("name", NAMES)
def test_traced_extreme_scenes_give_finite_images(name):
    hits = []

    @TRACED
    @given(medium=traced_media, seed=st.integers(0, 2**31 - 1))
    def run(medium, seed):
        est = Estimator(name, groups=((get_technique(name),),))
        hits.append(_render_checked(build_scene(**medium), est, seed, 200))

    run()
    assert sum(hits) > 0, f"{name}: no traced example produced a hit (vacuous test)"


@pytest.mark.parametrize("weighting", ["balance", "power"])
def test_traced_mis_of_every_technique_gives_finite_images(weighting):
    @settings(TRACED, max_examples=4)
    @given(medium=traced_media, seed=st.integers(0, 2**31 - 1))
    def run(medium, seed):
        group = tuple(get_technique(n) for n in MIS_NAMES)
        est = Estimator(f"mis:{'+'.join(MIS_NAMES)}", groups=(group,), weighting=weighting)
        _render_checked(build_scene(**medium, res=(4, 3)), est, seed, 100)

    run()


@pytest.mark.parametrize("g", [1 - 1e-9, -(1 - 1e-9), 1 - 1e-15, 0.999, -0.5, 1e-4])
def test_phase_function_is_finite_and_exact_as_g_approaches_one(g):
    """``1 + g^2 - 2 g mu`` cancelled to 0 at ``mu = +-1`` for ``|g|`` near 1 (an infinite
    rho, then ``0 * inf = NaN`` in every contribution with ``ss = 0`` or a zero weight)."""
    from psurf_core.sampling import phase_value

    mu = np.array([1.0, -1.0, 0.0, 1.0 - 1e-12])
    rho = phase_value(mu, g)
    assert np.all(np.isfinite(rho)) and np.all(rho > 0)
    exact = (1 - g) * (1 + g) / (4 * np.pi * np.array([(1 - g) ** 3, (1 + g) ** 3]))
    np.testing.assert_allclose(rho[:2], exact, rtol=1e-6)


def test_traced_extreme_scenes_reference_gives_finite_images():
    """The path tracer too: dense/thin media, |g| -> 1, lights touching the box."""
    nonzero = []

    @settings(TRACED, max_examples=6)
    @given(medium=traced_media, seed=st.integers(0, 2**31 - 1))
    def run(medium, seed):
        img = render_pass(build_scene(**medium, res=(6, 4)), Estimator("reference", reference=True),
                          0, seed, RenderSettings(spp=4))
        assert img.dtype == np.float64 and np.all(np.isfinite(img)) and np.all(img >= 0)
        nonzero.append(bool(img.sum() > 0))

    run()
    assert any(nonzero), "reference: every extreme scene rendered black (vacuous test)"
