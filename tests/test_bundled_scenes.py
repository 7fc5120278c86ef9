"""Every bundled scene renders with every baseline estimator: finite, non-negative, not black."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from psurf_core.estimators import parse_estimator
from psurf_core.render import RenderSettings, render_pass
from psurf_core.scene_io import load_scene

SCENES = sorted(str(p) for p in Path(__file__).parent.parent.glob("scenes/*.toml"))
BASELINES = ["reference", "points", "bre", "beams", "beams-long", "planes"]


def test_at_least_four_scenes():
    assert len(SCENES) >= 4


@pytest.mark.parametrize("scene_file", SCENES)
@pytest.mark.parametrize("spec", BASELINES)
def test_scene_renders(scene_file, spec):
    sc = load_scene(scene_file)
    sc = replace(sc, camera=replace(sc.camera, width=16, height=12))
    img = render_pass(sc, parse_estimator(spec, sc), 0, 1, RenderSettings(photons=400, spp=2))
    assert img.shape == (12, 16, 3)
    assert np.all(np.isfinite(img)) and np.all(img >= 0)
    assert img.sum() > 0
