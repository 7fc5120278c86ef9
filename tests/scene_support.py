"""The bundled scenes as test parameters, with the area-light scenes that repeat a case
(``showcase`` and the three ``study_*`` scenes) in ``make test-slow``.

The fast set keeps one scene per light kind with and without occluders: ``area``,
``area_occluder`` (area light, HG, a sphere), ``mesh_light``, ``dense_mesh_light`` (mesh light,
HG, a sphere), ``point`` and ``hg`` (point light, HG, a box). Tests that run every technique on
every scene spend most of ``make test``'s time on the other four, which add no light kind, phase
function or occluder type the fast set lacks.
"""

from __future__ import annotations

from pathlib import Path

import pytest

SCENE_DIR = Path(__file__).resolve().parent.parent / "scenes"
SCENES = sorted(SCENE_DIR.glob("*.toml"))
SLOW_SCENES = frozenset({"showcase", "study_area", "study_medium", "study_occluder"})


def scene_params(scenes=SCENES) -> list:
    """``scenes`` as ``pytest.param``s with the scene's stem as id; the repeats marked slow."""
    return [pytest.param(p, id=p.stem,
                         marks=[pytest.mark.slow] if p.stem in SLOW_SCENES else [])
            for p in scenes]
