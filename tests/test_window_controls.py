"""The window's controls as pure functions (``ui.views.controls``, no window): picking a
pixel (panel <-> pixel <-> display coordinates, the viewport under the mouse), an estimator
without some of its members (``SPEC~A``), the medium / photon parameters and their debouncer,
and a coverage mask's outline.

The conversions are checked against VTK's own display -> world transform in
``test_window_controls_clicks.py`` (the actions in the off-screen window);
``test_window_controls_progressive.py`` holds the progressive window, its flags and a
reference.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

pv = pytest.importorskip("pyvista")
pv.OFF_SCREEN = True

from window_controls_support import POINT  # noqa: E402

from ui.views import controls  # noqa: E402


# --------------------------------------------------------------------------- pure picking
def test_panel_to_pixel_cell_layout():
    # pixel (X, Y) is the cell [X, X+1] x [H-Y-1, H-Y]
    assert controls.panel_to_pixel((0.2, 47.9), 64, 48) == (0, 0)
    assert controls.panel_to_pixel((63.99, 0.01), 64, 48) == (63, 47)
    assert controls.panel_to_pixel((10.5, 48 - 5 - 0.5), 64, 48) == (10, 5)
    for outside in ((-0.01, 10), (64.0, 10), (10, -0.5), (10, 48.0)):
        assert controls.panel_to_pixel(outside, 64, 48) is None


def test_display_panel_round_trip():
    vp = (0.5, 0.55, 0.75, 1.0)
    args = ((800, 450), vp, (32.0, 27.0), 30.0)
    for d in ((401.0, 248.0), (600.0, 300.0), (799.0, 449.0)):
        w = controls.display_to_panel(d, *args)
        back = controls.panel_to_display(w, *args)
        assert np.allclose(back, d)
    # the viewport centre is the focal point; the viewport's height spans 2 * parallel_scale
    assert np.allclose(controls.display_to_panel((500.0, 348.75), *args), (32.0, 27.0))
    top = controls.display_to_panel((500.0, 450.0), *args)
    assert np.isclose(top[1] - 27.0, 30.0)


def test_viewport_at():
    vps = [(0.0, 0.0, 0.5, 1.0), (0.5, 0.55, 0.75, 1.0), (0.75, 0.55, 1.0, 1.0),
           (0.5, 0.0, 1.0, 0.55)]
    assert controls.viewport_at((10, 10), (800, 450), vps) == 0
    assert controls.viewport_at((450, 400), (800, 450), vps) == 1
    assert controls.viewport_at((700, 400), (800, 450), vps) == 2
    assert controls.viewport_at((700, 100), (800, 450), vps) == 3
    assert controls.viewport_at((900, 100), (800, 450), vps) is None


# --------------------------------------------------------------------------- pure controls
def test_estimator_members_toggle():
    from psurf_core.estimators import parse_estimator
    from psurf_core.scene_io import load_scene

    scene = load_scene(POINT)
    est = controls.estimator_with("mis:plane-t1t2+plane-t1t3+planes", scene, {"plane-t1t3"})
    assert est.spec == "mis:plane-t1t2+plane-t1t3+planes~plane-t1t3"
    assert controls.members(est) == ("plane-t1t2", "plane-t1t2-short")  # 'planes' is short
    assert est.weighting == "balance" and len(est.groups) == 1
    one = controls.estimator_with("mis-power:plane-t1t2+plane-t1t3", scene, {"plane-t1t2"})
    assert controls.members(one) == ("plane-t1t3",) and est.groups[0] != one.groups[0]
    assert len(one.groups) == 1 and len(one.groups[0]) == 1  # alone: no MIS weight
    with pytest.raises(ValueError, match="at least one"):
        controls.estimator_with("mis:plane-t1t2+plane-t1t3", scene,
                                {"plane-t1t2", "plane-t1t3"})
    preset = controls.estimator_with("paper-multi", scene, {"cone"})
    assert preset.spec == "paper-multi~cone" and preset.weighting == "balance"
    assert controls.members(preset) == ("plane-t1t2", "plane-t1t3", "plane-t2t3", "cylinder")
    # paper-full keeps both MIS sets, and the preset's per-light choice (ss-disk: point only)
    full = controls.estimator_with("paper-full", scene, {"cone", "ss-sphere"})
    sizes = [len(g) for g in parse_estimator("paper-full", scene).groups]
    assert [len(g) for g in full.groups] == [sizes[0] - 1, sizes[1] - 1]
    assert not {"cone", "ss-sphere"} & set(controls.members(full))
    disk = [t for t in full.techniques if t.name == "ss-disk"][0]
    assert disk.lights == ("point",)
    assert controls.estimator_with("paper-full", scene, set()).spec == "paper-full"


def test_without_grammar_errors_and_image():
    """``SPEC~A``: errors name the spec and the member; ``fast-multi~cone-short`` renders
    exactly ``mis:`` of the remaining members with their shares (fast-multi restricts no
    light; its walkers are compiled for ``tests/test_walkers.py`` anyway, where
    ``paper-multi``'s four-member remainder would compile four walkers for this test alone)."""
    from psurf_core.estimators import parse_estimator
    from psurf_core.render import RenderSettings, render_pass
    from psurf_core.scene_io import load_scene
    from psurf_core.techniques import UnknownTechnique

    scene = load_scene(POINT)
    for spec, msg in [("paper-multi~ss-cone", "not a member of 'paper-multi'"),
                      ("paper-multi~", "malformed"), ("reference~cone", "path tracer"),
                      ("mis:cone+cylinder~cone~cylinder", "every member")]:
        with pytest.raises(UnknownTechnique, match=msg):
            parse_estimator(spec, scene)
    small = replace(scene, camera=replace(scene.camera, width=24, height=18))
    st = RenderSettings(photons=150)
    a = render_pass(small, parse_estimator("fast-multi~cone-short", small), 0, 3, st)
    b = render_pass(small, parse_estimator("mis:planes+plane-t2t3-short@0.3", small), 0, 3, st)
    assert np.array_equal(a, b) and a.max() > 0


def test_medium_params_and_scene():
    from psurf_core.scene_io import load_scene

    scene = load_scene(POINT)
    p = controls.MediumParams(-1.0, 99.0, 1.5, 10).clamped()
    lo_s, hi_a, hi_g = controls.RANGES["sigma_s"][0], controls.RANGES["sigma_a"][1], 0.9
    assert (p.sigma_s, p.sigma_a, p.g) == (lo_s, hi_a, hi_g)
    assert p.photons == controls.RANGES["photons"][0]
    new = controls.scene_with(scene, controls.MediumParams(1.5, 0.25, -0.3, 1000))
    assert new.medium.sigma_s == 1.5 and new.medium.sigma_a == 0.25
    assert new.medium.phase.kind == "hg" and new.medium.phase.g == -0.3
    assert scene.medium.sigma_s != 1.5  # the loaded scene is untouched (frozen copies)
    iso = controls.scene_with(scene, controls.MediumParams(1.0, 0.1, 0.0, 1000))
    assert iso.medium.phase.kind == "isotropic"


def test_debouncer_applies_the_last_value_once_quiet():
    d = controls.Debouncer(delay=0.3)
    assert d.due(0.0) is None
    d.push(1, now=0.0)
    d.push(2, now=0.2)  # a drag: each step restarts the wait
    assert d.due(0.4) is None
    assert d.due(0.5) == 2
    assert d.due(10.0) is None and not d.pending


def test_coverage_mesh_outline():
    from ui.views.coverage_view import coverage_mesh

    m = np.zeros((4, 5), bool)
    m[1, 1:3] = True  # two pixels side by side: 6 outline edges, 2 cells
    cells, outline = coverage_mesh(m)
    assert cells.n_cells == 2 and outline.n_lines == 6
    # pixel (1, 1) spans x in [1, 2], y in [H-Y-1, H-Y] = [2, 3]
    b = cells.bounds
    assert np.allclose([b[0], b[1], b[2], b[3]], [1, 3, 2, 3])
    assert coverage_mesh(np.zeros((3, 3), bool))[0].n_cells == 0
