"""What each part of the window shows for a :class:`ui.views.window.ViewState`: the layout
applied to the renderers, the title and caption, the 3D view of the stage, the stage panel and
the image panels (:func:`compose` draws them all; the window's timer redraws only the image
panels and the stage panel, :func:`compose_images` and :func:`compose_panel`).

Composition only: nothing here handles an event or waits for a computation (the state, a
:class:`ui.views.window.ViewState`, holds what the background processes computed), so the
window (:mod:`ui.views.interactive`), the off-screen screenshots and the browser version draw
the same pictures.

The plotter (:func:`make_plotter`) has five renderers; :data:`CELL_3D` .. :data:`CELL_TITLE`
are their subplot indices, placed by :func:`ui.views.layout.window_layout` for the window's
size at every compose.
"""

from __future__ import annotations

import numpy as np

from psurf_core.inspect import member_primitives, reconstruct_hit

from . import (
    controls,
    coverage_view,
    hits_view,
    image_panels,
    primitives_view,
    scene_view,
    stage_text,
)
from ._vtk import pv
from .layout import CAPTION_PT, window_layout
from .scene_view import FONT, FONT_SMALL, FONT_TITLE, add_text, fit_font, pt, wrap_to
from .stage_text import coverage_target
from .stepper import DEFAULT_SIZE, STAGES, stage_index

HELP = """keys
  n / p    next / previous stage
  e / E    inspect the next / previous estimator
  1 .. 9   switch an MIS member on / off
  space    play / pause rendering
  r        reset (stage, passes, camera)
  arrows   move the picked pixel
  [ / ]    previous / next hit
  , / .    previous / next inspected pass
  c        coverage of the hit's primitive
  x X a A  sigma_s / sigma_a down / up
  g G k K  HG g / photons down / up
  + / -    more / fewer photon subpaths
  m        panels: render/techniques/bounces
  l        variance scale: fixed / auto
  z        layout: split / images / 3D
  s        screenshot (PNG, current folder)
  v        record a GIF (v again: stop)
  w        show / hide the sliders
  h        this help      q  quit
mouse
  click a render or map: inspect that
    estimator at that pixel
  right click a primitive: its coverage
  chips and buttons at the bottom"""

#: The renderers (pyvista subplot indices) of the layout's parts.
CELL_3D, CELL_RENDER, CELL_VARIANCE, CELL_PANEL, CELL_TITLE = (0, 0), (0, 1), (0, 2), (0, 3), \
    (0, 4)
#: The stage panel is laid out for at least this many lines (most stages: the same layout).
PANEL_MIN_LINES = 12
_PARTS = ((CELL_TITLE, "title"), (CELL_3D, "view3d"), (CELL_PANEL, "panel"),
          (CELL_RENDER, "images"), (CELL_VARIANCE, "maps"))



def _recon(state):
    ins = state.inspection
    if ins is None or len(ins.table) == 0:
        return None, None
    order = stage_text.hit_order(ins)
    k = min(max(state.hit, 0), len(order) - 1)
    return reconstruct_hit(ins, int(order[k])), k


def panel_text(state) -> str:
    """The stage panel's text (see :func:`ui.views.stage_text.panel_text`)."""
    recon, k = _recon(state) if state.stage == "reconstruct" else (None, None)
    return stage_text.panel_text(state, recon, k)


def state_layout(plotter: pv.Plotter, state, text: str):
    """The layout of ``state`` in ``plotter``'s window (the panel sized for ``text``)."""
    return window_layout(plotter.window_size, focus=state.focus, footer_rows=state.footer_rows,
                         sliders=state.sliders_on,
                         panel_lines=max(text.count("\n") + 1, PANEL_MIN_LINES),
                         caption_chars=state.caption_chars)


def apply_layout(plotter: pv.Plotter, state, lay) -> None:
    """Place the renderers where ``lay`` says (``state.layout`` remembers it)."""
    parts = lay.parts()
    for cell, part in _PARTS:
        plotter.renderers[plotter.renderers.loc_to_index(cell)].SetViewport(
            *parts[part].viewport)
    state.layout = lay


def _viewport_px(plotter, cell) -> tuple:
    ren = plotter.renderers[plotter.renderers.loc_to_index(cell)]
    x0, y0, x1, y1 = ren.GetViewport()
    return (x1 - x0) * plotter.window_size[0], (y1 - y0) * plotter.window_size[1]


def compose_title(plotter: pv.Plotter, state) -> None:
    """Title (bold), hint (right) and caption (wrapped to the width, shrunk if it must be)."""
    plotter.subplot(*CELL_TITLE)
    w, h = _viewport_px(plotter, CELL_TITLE)
    n = stage_index(state.stage) + 1
    hint = state.hint or f"stage {n}/{len(STAGES)}   n / p: step   h: help"
    # Measuring and wrapping the caption is most of this part's cost, and it changes only
    # with the stage, the hint or the size: the same title is left as it is.
    key = (state.stepper.title, state.stepper.caption, hint, round(w), round(h),
           pt(FONT_SMALL))
    if getattr(state, "title_key", None) == key and "caption" in plotter.renderer.actors:
        return
    state.title_key = key
    plotter.renderer.clear_actors()
    plotter.renderer.set_background("white")
    hw = scene_view.text_extent(hint, pt(FONT_SMALL))[0]
    title_px = fit_font(state.stepper.title, pt(FONT_TITLE), (0.97 * w - hw - 20, h),
                        bold=True)
    with_hint = title_px >= 0.7 * pt(FONT_TITLE)
    if not with_hint:  # a narrow column: the title first (the stage number is in it)
        title_px = fit_font(state.stepper.title, pt(FONT_TITLE), (0.97 * w, h), bold=True)
    add_text(plotter, state.stepper.title, 0.015, 0.97, FONT_SMALL, size_px=title_px,
             bold=True, name="title")
    if with_hint:
        add_text(plotter, hint, 0.985, 0.97, FONT_SMALL, name="stage-hint",
                 colour="#555555", align="right")
    cap_px = pt(CAPTION_PT)
    room = (0.97 * w, h - 1.35 * title_px - 12)
    text = wrap_to(state.stepper.caption, room[0], cap_px)
    while cap_px > 8 and scene_view.text_extent(text, cap_px)[1] > room[1]:
        cap_px -= 1
        text = wrap_to(state.stepper.caption, room[0], cap_px)
    top = 1.0 - (1.35 * title_px + 8) / max(h, 1.0)
    add_text(plotter, text, 0.015, top, FONT_SMALL, size_px=cap_px, name="caption")


def _compose_3d(plotter: pv.Plotter, state, camera=None,
                with_scene: bool = True) -> None:
    """The 3D view of the stage (labels are placed for ``camera``, the view it will have;
    ``with_scene=False``: the scene's actors are there already)."""
    ins = state.inspection
    scene = state.scene
    stage = state.stage
    if with_scene:
        before = set(plotter.renderer.actors)
        scene_view.add_scene(plotter, scene, labels=_scene_labels(stage))
        state.scene_actors = set(plotter.renderer.actors) - before
    # Drawn apart from the scene, so a moved pixel keeps the scene's actors.
    scene_view.add_picked_pixel(plotter, scene, state.pixel_xy)
    if ins is None:
        add_text(plotter, "computing...", 0.5, 0.97, FONT, name="computing", align="center",
                 colour="#444444")
        return
    t = ins.table
    top = stage_text.hit_order(ins)[: stage_text.TABLE_ROWS]
    if stage == "trace":
        primitives_view.add_paths(plotter, ins.paths, scene, state.n_paths)
    elif stage == "create":
        primitives_view.add_paths(plotter, ins.paths, scene, state.n_paths, opacity=0.35,
                                  line_width=3)
        sel = primitives_view.create_selection(ins, state.n_paths)
        primitives_view.add_primitives(plotter, ins, sel, legend_loc="lower right")
    elif stage in ("intersect", "evaluate"):
        hits_view.add_query_ray(plotter, ins)
        if stage == "intersect":
            sel = primitives_view.create_selection(ins, state.n_paths)
            primitives_view.add_primitives(plotter, ins, sel, opacity=0.08, edges=False,
                                           legend=False, name="context")
        hits_view.add_hit_primitives(plotter, ins, top)
        hits_view.add_hit_points(plotter, ins, np.arange(len(t)),
                                 labels=(stage == "evaluate"), camera=camera)
        if stage == "intersect":
            hits_view.add_normals(plotter, ins, top[: stage_text.NORMAL_ROWS], camera=camera)
    else:
        hits_view.add_query_ray(plotter, ins)
        recon, _ = _recon(state)
        if recon is not None:
            members = member_primitives(ins, recon)
            if members:  # every member's surface through this path, with its weight
                hits_view.add_member_surfaces(plotter, ins, recon, members)
            else:  # a kernel estimator: no exact path, only its own primitive
                hits_view.add_hit_primitives(plotter, ins, [recon["row"]], opacity=0.6)
            hits_view.add_reconstruction(plotter, ins, recon, camera=camera)
    target = coverage_target(state) if state.coverage else None
    if target is not None:
        name, batch, prim = target
        primitives_view.add_primitives(plotter, ins, {(name, batch): np.array([prim])},
                                       opacity=0.3, name="coverage", legend=False, width=6.0,
                                       list_empty=False)


def _scene_labels(stage: str) -> bool:
    """Whether the scene's own labels (light, camera) are drawn: not where the stage labels
    points of its own (Evaluate's hits, Reconstruct's vertices), which they would cover."""
    return stage not in ("evaluate", "reconstruct")


def _home_camera(state, view_aspect: float | None = None):
    """``(key, camera)``: where the 3D view looks by default at this stage (a pinned camera
    (lecture); Reconstruct: framing the selected hit's path; otherwise the overview)."""
    if state.camera_pin is not None:
        return ("pin", state.camera_pin), [tuple(map(float, v)) for v in state.camera_pin]
    if state.stage == "reconstruct":
        recon, k = _recon(state)
        if recon is not None and recon.get("polyline") is not None:
            key = ("recon", state.pixel_xy, state.pass_index, k, state.estimator.spec)
            return key, hits_view.reconstruct_camera(recon, state.scene)
    aspect = round(view_aspect, 2) if view_aspect else None
    return ("overview", aspect), scene_view.overview_camera(state.scene, aspect=aspect)


def compose(plotter: pv.Plotter, state, *, keep_camera: bool = False) -> None:
    """(Re)draw every part of the window for ``state``.

    ``keep_camera`` keeps the 3D view where the user turned it, unless the stage's own view
    changed (entering Reconstruct, another hit there: it frames the new path).
    """
    scene_view.set_scale(plotter.window_size[1])
    text = panel_text(state)
    apply_layout(plotter, state, state_layout(plotter, state, text))
    compose_title(plotter, state)
    plotter.subplot(*CELL_3D)
    compose_3d(plotter, state, keep_camera=keep_camera)
    compose_images(plotter, state)
    compose_panel(plotter, state, text)


def compose_3d(plotter: pv.Plotter, state, *, keep_camera: bool = False) -> None:
    """(Re)draw the 3D view of ``state`` into the plotter's current renderer: the window's
    3D cell, or a plotter of its own (the web page's 3D view, :mod:`ui.web`).

    ``keep_camera`` as in :func:`compose`.
    """
    cam_pos = plotter.camera_position if keep_camera else None
    x0, y0, x1, y1 = plotter.renderer.GetViewport()
    w, h = plotter.window_size
    key, home = _home_camera(state, (x1 - x0) * w / max((y1 - y0) * h, 1.0))
    if cam_pos is None or key != state.framed:
        cam_pos = home
    state.framed = key
    cam_pos = [tuple(map(float, v)) for v in cam_pos]
    ren = plotter.renderer
    _clear_bars(plotter, ren)
    # The scene (box, lights, occluders, camera) stays when only the stage or the pixel
    # changed. (``ren.actors`` builds a dict on every access: read it once.)
    key3d = (id(state.scene), _scene_labels(state.stage))
    actors = ren.actors
    reuse = (state.scene_key == key3d and bool(state.scene_actors)
             and all(n in actors for n in state.scene_actors))
    if reuse:
        stale = [a for n, a in actors.items() if n not in state.scene_actors]
        if stale:  # by actor, not by name: a name also removes every 'name-...' actor
            ren.remove_actor(stale, render=False)
    else:
        ren.clear_actors()
    ren.set_background(scene_view.BACKGROUND)
    _compose_3d(plotter, state, camera=cam_pos, with_scene=not reuse)
    state.scene_key = key3d
    plotter.camera_position = cam_pos
    plotter.renderer.ResetCameraClippingRange()


def compose_panel(plotter: pv.Plotter, state, text: str | None = None) -> bool:
    """Draw the stage panel (the stage's numbers, fitted to the panel) and the status message.

    Returns False when the text needs another layout (more or fewer lines than the panel was
    made for): the caller then composes everything again.
    """
    text = panel_text(state) if text is None else text
    lay = state.layout
    if lay is not None and state_layout(plotter, state, text) != lay:
        return False
    plotter.subplot(*CELL_PANEL)
    ren = plotter.renderer
    w, h = _viewport_px(plotter, CELL_PANEL)
    line = 1.2 * pt(FONT_SMALL)
    size = fit_font(text, pt(FONT_SMALL), (0.96 * w, h - 1.4 * line - 8), mono=True)
    msize = (fit_font(state.message, pt(FONT_SMALL), (0.96 * w, 1.3 * line), bold=True)
             if state.message else 0)
    key = (text, size, state.message, msize, round(w), round(h))
    actors = ren.actors
    panel, message = actors.get("panel"), actors.get("message")
    if panel is not None and getattr(state, "panel_key", None) == key:
        state.panel_changed = False  # the timer renders this part only when it changed
        return True
    state.panel_key, state.panel_changed = key, True
    if panel is None or getattr(state, "panel_size", None) != (round(w), round(h)):
        ren.clear_actors()
        ren.set_background("#f2f2f2")
        panel = message = None
    state.panel_size = (round(w), round(h))
    # In place where the actors exist (a frame changes the pass count in the text): a new
    # text actor per frame costs more than a new string in the old one.
    if panel is None:
        add_text(plotter, text, 0.02, 1.0 - 6 / max(h, 1), FONT_SMALL, size_px=size,
                 mono=True, name="panel")
    else:
        panel.SetInput(text)
        panel.GetTextProperty().SetFontSize(size)
    if state.message and message is not None:
        message.SetInput(state.message)
        message.GetTextProperty().SetFontSize(msize)
    elif state.message:
        add_text(plotter, state.message, 0.02, (1.2 * line + 4) / max(h, 1),
                 FONT_SMALL, size_px=msize, name="message", bold=True)
    elif message is not None:
        ren.remove_actor(message, render=False)
    return True


def _clear_bars(plotter: pv.Plotter, renderer) -> None:
    """Remove the colour bars drawn in ``renderer`` (the image panels keep theirs)."""
    for title in list(plotter.scalar_bars.keys()):
        if renderer.HasViewProp(plotter.scalar_bars[title]):
            plotter.remove_scalar_bar(title)


def compose_images(plotter: pv.Plotter, state) -> None:
    """Draw the render and variance panels (the progressive tiles when ``state.prog`` is set,
    else ``state.acc``)."""
    if state.prog is not None:
        _compose_progressive(plotter, state)
        return
    plotter.subplot(*CELL_RENDER)
    plotter.renderer.clear_actors()
    plotter.renderer.set_background("white")
    title = f"{state.estimator.spec}: {stage_text._plural(state.acc.n, 'pass')}"
    if state.coverage and state.coverage_mask is not None:
        title += f"; coverage {int(state.coverage_mask.sum())} px"
    image_panels.add_render_panel(plotter, state.acc.mean, state.pixel_xy, title)
    if state.coverage and state.coverage_mask is not None:
        coverage_view.add_coverage(plotter, state.coverage_mask)
    plotter.subplot(*CELL_VARIANCE)
    plotter.renderer.clear_actors()
    if image_panels.VARIANCE_BAR in plotter.scalar_bars:
        plotter.remove_scalar_bar(image_panels.VARIANCE_BAR)
    plotter.renderer.set_background("white")
    var = state.acc.variance if state.acc.n > 1 else np.zeros_like(state.acc.mean)
    title = (f"{state.estimator.spec}: variance per pass (log scale)" if state.acc.n > 1
             else f"{state.estimator.spec}: variance needs 2+ passes")
    image_panels.add_variance_panel(plotter, var, state.pixel_xy, title, clim=state.var_clim)


def _compose_progressive(plotter: pv.Plotter, state) -> None:
    """The progressive panels (every estimator side by side, or a breakdown mode) and, on the
    inspected estimator's render tile, the coverage overlay."""
    state.panels.draw(plotter, [CELL_RENDER, CELL_VARIANCE], state.prog, state.mode,
                      state.pixel_xy, reference=state.reference, clim=state.var_clim,
                      scale=state.var_scale, inspected=state.inspected)
    plotter.subplot(*CELL_RENDER)
    ren = plotter.renderer
    actors = ren.actors
    for name in ("coverage-cells", "coverage-outline"):
        if name in actors:
            plotter.remove_actor(name, render=False)
    if not (state.coverage and state.coverage_mask is not None and state.mode == "render"):
        return
    cam = state.scene.camera
    tiles = controls.image_tiles(ren, cam.width, cam.height)
    if tiles:
        _, origin, spacing = tiles[min(state.inspected, len(tiles) - 1)]
        coverage_view.add_coverage(plotter, state.coverage_mask, origin=origin,
                                     spacing=spacing)


def make_plotter(size=DEFAULT_SIZE, off_screen: bool = False) -> pv.Plotter:
    """The window's plotter: five renderers (placed by :func:`compose`), white, FreeType."""
    scene_view.plain_text()
    p = pv.Plotter(window_size=list(size), off_screen=off_screen, border=False, shape=(1, 5))
    p.set_background("white", all_renderers=True)
    return p


def software_opengl(plotter: pv.Plotter) -> bool:
    """True when VTK renders with a software OpenGL (Mesa llvmpipe / softpipe / swrast)."""
    try:
        info = plotter.ren_win.ReportCapabilities() or ""
    except Exception:  # no context yet or a VTK without the report: assume a GPU
        return False
    return any(k in info.lower() for k in ("llvmpipe", "softpipe", "swrast"))


