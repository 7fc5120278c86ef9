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


#: Within the fast set, the scenes whose light kind, phase function and occluder types other
#: fast scenes also have: ``point`` (a point light, isotropic: ``hg`` has a point light,
#: ``area`` the isotropic phase), ``mesh_light`` (``dense_mesh_light`` has a mesh light with
#: triangles) and ``area_occluder`` (an area light, HG, a sphere: ``area``, ``hg`` and
#: ``dense_mesh_light`` have them). Tests that compare formulas one hit at a time from Python
#: (``test_twins.py``) run them in make test-slow: ~20-26 s each.
COVERED_SCENES = frozenset({"point", "mesh_light", "area_occluder"})


def scene_params(scenes=SCENES, slow=SLOW_SCENES) -> list:
    """``scenes`` as ``pytest.param``s with the scene's stem as id; those in ``slow`` (the
    repeats) marked slow."""
    return [pytest.param(p, id=p.stem, marks=[pytest.mark.slow] if p.stem in slow else [])
            for p in scenes]
