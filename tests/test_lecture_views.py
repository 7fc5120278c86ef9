"""Issue 13 ("Lecture-grade app"), what the window looks like: the layout's parts never
overlap and every text fits its part at any window size (defect 5), a technique keeps its
colour (defect 6), the variance maps share one fixed, lockable scale (also across the lecture
states that compare them). Each defect's test failed on the code the issue was filed
against.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pv = pytest.importorskip("pyvista")
pv.OFF_SCREEN = True

ROOT = Path(__file__).resolve().parents[1]
POINT = str(ROOT / "scenes" / "point.toml")
OCCLUDER = str(ROOT / "scenes" / "area_occluder.toml")
MIS = "mis:plane-t1t2+planes"


# --------------------------------------------------------------------------- defect 5
SIZES = [(1024, 768), (1280, 1024), (1280, 720), (1600, 900), (1920, 1080), (3840, 2160)]


@pytest.mark.parametrize("size", SIZES)
def test_defect5_layout_parts_never_overlap(size):
    from ui.views.layout import FOCI, window_layout

    for focus in FOCI:
        for sliders in (False, True):
            for rows in (0, 2, 3):
                for lines in (6, 16, 40):
                    lay = window_layout(size, focus=focus, footer_rows=rows, sliders=sliders,
                                        panel_lines=lines)
                    parts = list(lay.parts().items())
                    for _name, r in parts:
                        assert not r.empty and 0 <= r.x0 < r.x1 <= 1 and 0 <= r.y0 < r.y1 <= 1
                    for i, (a, ra) in enumerate(parts):
                        for b, rb in parts[i + 1:]:
                            assert not ra.overlaps(rb), (size, focus, a, b)
                    why = (size, focus, sliders, rows, lines)
                    assert lay.view3d.pixels(size)[1] >= 0.2 * size[1], why


@pytest.mark.parametrize("size", [(1024, 768), (1920, 1080)])
def test_defect5_texts_fit_their_parts(size):
    """At 1024x768 the caption was clipped under the panels and labels were cut ("16 passes,
    1.2...", "paper-multi~plane-t..."): every text stays inside its part, none is cut."""
    from ui.views.image_panels import PanelView
    from ui.views.window import CELL_PANEL, CELL_TITLE, build_state, compose, make_plotter

    state = build_state(OCCLUDER, seed=1, pixel_xy=(32, 24), photons=100, passes=1,
                        render_passes=False, stage="evaluate",
                        estimators=["planes", "mis:plane-t1t2+cone+cylinder~cone"])
    from ui.cli.progressive import Progressive

    state.prog = Progressive(state.scene, list(state.specs), state.settings, workers=0)
    state.prog.run(passes=2)
    state.panels, state.acc = PanelView(), state.prog.runs[state.inspected].acc
    state.message = "a status line"
    plotter = make_plotter(size, off_screen=True)
    try:
        compose(plotter, state)
        plotter.render()
        for cell in (CELL_TITLE, CELL_PANEL):
            ren = plotter.renderers[plotter.renderers.loc_to_index(cell)]
            x0, y0, x1, y1 = ren.GetViewport()
            w, h = (x1 - x0) * size[0], (y1 - y0) * size[1]
            for name, actor in ren.actors.items():
                bb = [0.0] * 4
                actor.GetBoundingBox(ren, bb)
                px, py = actor.GetPositionCoordinate().GetComputedViewportValue(ren)
                left, right = px + bb[0], px + bb[1]
                bottom, top = py + bb[2], py + bb[3]
                assert left >= -1 and right <= w + 1, (cell, name, left, right, w)
                assert bottom >= -1 and top <= h + 1, (cell, name, bottom, top, h)
        for ren in plotter.renderers:
            for name, actor in ren.actors.items():
                if name.endswith("-title") or name.endswith("-header"):
                    assert "\u2026" not in actor.GetInput(), name
    finally:
        plotter.close()


# --------------------------------------------------------------------------- defect 6
def test_defect6_a_technique_keeps_its_colour():
    """Colours came from a member's position (a toggle changed them) and green meant both
    "cone" and "member on"."""
    from psurf_core.estimators import parse_estimator
    from psurf_core.scene_io import load_scene
    from ui.views import controls
    from ui.views.footer import member_chip_label
    from ui.views.palette import OKABE_ITO, chip_colours, technique_colour

    scene = load_scene(POINT)
    full = controls.members(parse_estimator("paper-multi", scene))
    less = controls.members(controls.estimator_with("paper-multi", scene, {"plane-t1t2"}))
    assert {n: technique_colour(n) for n in less} == {n: technique_colour(n) for n in full
                                                      if n in less}
    assert len({technique_colour(n) for n in full}) == len(full)  # all different
    single = controls.members(parse_estimator("paper-single", scene))
    assert len({technique_colour(n) for n in single}) == len(single)
    assert technique_colour("plane-t1t2-short") == technique_colour("plane-t1t2")
    for name in full:
        on, off = chip_colours(name, True), chip_colours(name, False)
        assert on[0] == technique_colour(name) and off[0] == "#FFFFFF"
        assert "on " in member_chip_label(0, name, True)
        assert "off" in member_chip_label(0, name, False)
    assert set(OKABE_ITO.values()) >= {technique_colour(n) for n in full}


def test_defect6_reconstruct_legend_keeps_colours_after_a_toggle():
    from psurf_core.inspect import inspect_pixel, member_primitives, reconstruct_hit
    from psurf_core.render import RenderSettings
    from psurf_core.scene_io import load_scene
    from ui.views.hits_view import add_member_surfaces
    from ui.views.palette import technique_colour
    from ui.views.stage_text import hit_order

    scene = load_scene(OCCLUDER)
    for spec in ("mis:plane-t1t2+cone+cylinder", "mis:plane-t1t2+cone+cylinder~plane-t1t2"):
        ins = inspect_pixel(scene, spec, 0, 0, (32, 24), RenderSettings(photons=200))
        recon = reconstruct_hit(ins, int(hit_order(ins)[0]))
        p = pv.Plotter(off_screen=True)
        try:
            entries = add_member_surfaces(p, ins, recon, member_primitives(ins, recon))
        finally:
            p.close()
        for label, colour in entries:
            name = label.lstrip("> ").split()[0].rstrip(":")
            if "cannot make" not in label:
                assert colour == technique_colour(name), (spec, label)


# --------------------------------------------------------------------------- needs
def test_variance_scale_is_shared_fixed_over_time_and_lockable():
    from psurf_core.render import RenderSettings
    from psurf_core.scene_io import load_scene
    from ui.cli.progressive import Progressive
    from ui.views.panel_modes import VarScale, mode_areas

    scene = load_scene(POINT)
    prog = Progressive(scene, ["planes", MIS], RenderSettings(photons=100), workers=0)
    scale = VarScale()
    prog.run(passes=2)
    first = mode_areas(prog, "render", scale=scale)[1]
    clims = {t.clim for t in first.tiles}
    assert len(clims) == 1  # one scale for every map
    prog.run(passes=5)
    later = mode_areas(prog, "render", scale=scale)[1]
    assert {t.clim for t in later.tiles} == clims  # fixed: a converging map darkens
    assert all(t.title.startswith(("planes", MIS)) for t in later.tiles)  # named
    assert not scale.toggle()  # unlocked: follows the data
    auto = mode_areas(prog, "render", scale=scale)[1].tiles[0].clim
    assert auto != next(iter(clims))
    assert scale.toggle() and mode_areas(prog, "render", scale=scale)[1].tiles[0].clim == auto


def test_lecture_states_that_compare_share_one_variance_range():
    from ui.views.lecture_states import STATES

    pair = [s for s in STATES if s.tutorial == 7]
    assert len(pair) == 2 and pair[0].var_clim is not None
    assert pair[0].var_clim == pair[1].var_clim


def test_the_headers_say_equal_time_while_an_estimator_waits_for_its_first_pass():
    """Issue 12's check under Xvfb: at 30 s paper-multi (no pass yet) made the window's
    headers read "renders at equal passes" and "Var = variance x passes"."""
    from psurf_core.accumulate import Welford
    from ui.views.panel_modes import Entry, mode_areas

    done, waiting = Welford.empty((4, 5, 3)), Welford.empty((4, 5, 3))
    for v in (1.0, 2.0, 4.0):
        done.add(np.full((4, 5, 3), v))
    areas = mode_areas([Entry("planes", done, 2.5),
                        Entry("paper-multi", waiting, 0.0, note="compiling kernels")], "render")
    assert "equal time" in areas[0].header and "x time" in areas[1].header
    assert "compiling kernels" in areas[0].tiles[1].title
    cold = mode_areas([Entry("planes", Welford.empty((4, 5, 3)), 0.0,
                             note="compiling kernels (first run), 8 s..."),
                       Entry("paper-multi", waiting, 0.0, note="waiting for the first pass...")],
                      "render")
    assert "equal time" in cold[0].header  # a cold cache: nothing rendered yet, still timed
    untimed = mode_areas([Entry("planes", done, 0.0), Entry("b", done, 0.0)], "render")
    assert "equal passes" in untimed[0].header  # screenshots: every run 0 s
