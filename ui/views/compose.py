"""What each part of the window shows for a :class:`ui.views.window.ViewState`: the layout
applied to the renderers, the title and caption, the 3D view of the stage, the stage panel and
the image panels (:func:`compose` draws them all; the window's timer redraws only the image
panels and the stage panel, :func:`compose_images` and :func:`compose_panel`, and builds the
3D view over several ticks, :func:`compose_steps` and :mod:`ui.views.view3d`).

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

from . import (
    controls,
    coverage_view,
    image_panels,
    scene_view,
    stage_text,
)
from ._vtk import pv
from .layout import CAPTION_PT, window_layout
from .scene_view import FONT_SMALL, FONT_TITLE, add_text, fit_font, pt, wrap_to
from .stepper import DEFAULT_SIZE, STAGES, stage_index
from .view3d import compose_3d, compose_3d_steps, recon, run_steps  # noqa: F401 (re-exported)

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



def panel_text(state) -> str:
    """The stage panel's text (see :func:`ui.views.stage_text.panel_text`)."""
    rec, k = recon(state) if state.stage == "reconstruct" else (None, None)
    return stage_text.panel_text(state, rec, k)


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


def compose(plotter: pv.Plotter, state, *, keep_camera: bool = False) -> None:
    """(Re)draw every part of the window for ``state``.

    ``keep_camera`` keeps the 3D view where the user turned it, unless the stage's own view
    changed (entering Reconstruct, another hit there: it frames the new path).
    """
    run_steps(compose_steps(plotter, state, keep_camera=keep_camera))


def compose_steps(plotter: pv.Plotter, state, *, keep_camera: bool = False,
                  view3d: bool = True):
    """:func:`compose` as a generator (:mod:`ui.views.view3d`): the first step lays the window
    out and draws the title, the image panels, the stage panel and the start of the 3D view
    (the scene, "drawing..."); each later step adds a part of the 3D view.
    ``view3d=False`` leaves the 3D view as it is (nothing it shows changed)."""
    scene_view.set_scale(plotter.window_size[1])
    text = panel_text(state)
    apply_layout(plotter, state, state_layout(plotter, state, text))
    compose_title(plotter, state)
    compose_images(plotter, state)
    compose_panel(plotter, state, text)
    if view3d:
        plotter.subplot(*CELL_3D)
        yield from compose_3d_steps(plotter, state, keep_camera=keep_camera)


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


