"""What the interactive window shows: its state (:class:`ViewState`) and the composition of
each stage (:func:`compose`), and the off-screen twin, :func:`screenshot`. The bindings
(keys, mouse, widgets, timer) and :func:`~ui.views.interactive.run`, which opens the window,
are in :mod:`ui.views.interactive`; nothing here handles an event, so another front end (the
browser version) can compose the same pictures from a :class:`ViewState`.

Layout (one pyvista Plotter, five renderers placed by :func:`ui.views.layout.window_layout`
for the window's size: title and caption, 3D view, stage panel on the left; the image
panels, renders above and variance maps below, on the right; the window's chips and buttons
in a footer). The image panels are :class:`ui.views.image_panels.PanelView` tiles of a
:class:`ui.cli.progressive.Progressive` render: in the window a background worker process,
polled by the timer without waiting; for :func:`screenshot` the same passes rendered in this
process. With several estimators they are shown side by side at equal time; the stages
inspect one of them (:attr:`ViewState.inspected`, default: the first MIS set), framed in the
panels. (A :class:`ViewState` without ``prog``, lecture mode, shows its own accumulator.)

The stages' numbers come from :mod:`psurf_core.inspect`, computed by a
:class:`ui.cli.inspector.Inspector` (a background process in the window, in this process for
screenshots); until they arrive the stage panel says "computing..." and the 3D view shows
the scene alone.

:func:`screenshot` composes what the window shows at a stage (without the on-screen
controls), off-screen and deterministically (same arguments, same picture: a fixed number of
passes, no wall seconds drawn).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field, replace

import numpy as np

from psurf_core.accumulate import Welford
from psurf_core.estimators import parse_estimator
from psurf_core.inspect import member_primitives, reconstruct_hit
from psurf_core.render import RenderSettings, render
from psurf_core.scene_io import load_scene

from . import controls, hits_view, image_panels, primitives_view, scene_view, stage_text
from ._vtk import pv
from .layout import CAPTION_PT, window_layout
from .panel_modes import MODES, VarScale
from .scene_view import FONT, FONT_SMALL, FONT_TITLE, add_text, fit_font, pt, wrap_to
from .stage_text import coverage_target
from .stepper import (
    CAPTIONS,
    DEFAULT_PASSES,
    DEFAULT_PHOTONS,
    DEFAULT_SIZE,
    STAGES,
    Stepper,
    stage_index,
)

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


@dataclass
class ViewState:
    """Everything one picture of the window depends on."""

    scene_path: str
    scene: object
    estimator: object  # the inspected estimator (its members switched off left out)
    seed: int
    settings: RenderSettings
    pixel_xy: tuple
    acc: Welford
    inspection: object  # PixelInspection, or None while it is computed
    stepper: Stepper = field(default_factory=Stepper)
    hit: int = 0  # display index (table sorted by contribution)
    n_paths: int = primitives_view.DEFAULT_PATHS
    show_help: bool = False
    playing: bool = False
    message: str = ""
    initial_passes: int = DEFAULT_PASSES
    #: The pass the stages inspect (one of the passes the image panels include).
    pass_index: int = 0
    #: Coverage (primitive -> pixels) shown on the render panel.
    coverage: bool = False
    #: ``(technique, batch, prim)`` picked in the 3D view; None: the selected hit's primitive.
    coverage_pick: tuple | None = None
    #: (H, W) bool pixels of the coverage primitive (row 0 at the top), or None.
    coverage_mask: np.ndarray | None = None
    #: The estimator specs of the image panels as opened (display order), the one the stages
    #: inspect, and per panel the members switched off since.
    specs: tuple = ()
    inspected: int = 0
    disabled_by: dict = field(default_factory=dict)
    #: The scene as loaded (the medium sliders change copies of it).
    base_scene: object = None
    #: The window's progressive renderer (``ui.cli.progressive.Progressive``) and its panels
    #: (``ui.views.image_panels.PanelView``); None: the panels show :attr:`acc` (lecture).
    prog: object = None
    panels: object = None
    #: Image-panel mode (``panel_modes.MODES``, the ``m`` key).
    mode: str = "render"
    #: Ground truth (H, W, 3) for relMSE in the render panels (``--reference FILE.npz``).
    reference: np.ndarray | None = None
    #: Computes the stages' inspections (``ui.cli.inspector.Inspector``).
    inspector: object = None
    #: The variance maps' shared colour scale, or a pinned range (lecture states).
    var_scale: VarScale = field(default_factory=VarScale)
    var_clim: tuple | None = None
    #: Layout: ``ui.views.layout.FOCI`` (the ``z`` key), footer rows (the window's chips and
    #: buttons; 0 in screenshots), the slider block, the longest caption to make room for.
    focus: str = "split"
    footer_rows: int = 0
    sliders_on: bool = False
    caption_chars: int = max(len(c) for c in CAPTIONS.values())
    #: The hint at the top right (lecture mode puts its counter there); None: the stage's.
    hint: str | None = None
    #: What the 3D camera was last framed for (auto-zoom of Reconstruct); see ``compose``; a
    #: pinned camera ``(position, focal point, view up)`` (lecture states) instead.
    framed: tuple | None = None
    camera_pin: tuple | None = None
    layout: object = None
    #: The 3D scene's actors (kept while only the stage changes) and what they show.
    scene_actors: set = field(default_factory=set)
    scene_key: tuple | None = None

    @property
    def stage(self) -> str:
        return self.stepper.stage

    @property
    def base_spec(self) -> str:
        """The inspected panel's spec as opened (before members were switched off)."""
        return self.specs[self.inspected] if self.specs else self.estimator.spec

    @property
    def disabled(self) -> frozenset:
        """Members of the inspected estimator switched off."""
        return self.disabled_by.get(self.inspected, frozenset())


# --------------------------------------------------------------------------- estimators
def default_inspected(ests) -> int:
    """The panel the stages inspect by default: the first MIS set (a group of two or more
    techniques), else the first photon estimator."""
    photon = [i for i, e in enumerate(ests) if not e.reference]
    if not photon:
        raise ValueError("the stages need a photon estimator; 'reference' (the path tracer) "
                         "has no photons, primitives or hits")
    mis = [i for i in photon if any(len(g) > 1 for g in ests[i].groups)]
    return (mis or photon)[0]


def _resolve_inspect(inspect, specs, ests) -> int:
    if inspect is None:
        return default_inspected(ests)
    i = specs.index(inspect) if isinstance(inspect, str) and inspect in specs else inspect
    if not isinstance(i, int) or not 0 <= i < len(specs):
        raise ValueError(f"--inspect {inspect}: not one of the estimators ({', '.join(specs)})")
    if ests[i].reference:
        raise ValueError(f"--inspect {specs[i]}: the stages need a photon estimator (the path "
                         "tracer has no photons, primitives or hits)")
    return i


def panel_estimator(state: ViewState, i: int):
    """Panel ``i``'s estimator: its spec as opened without the members switched off."""
    spec = state.specs[i]
    off = state.disabled_by.get(i, frozenset())
    if not off:
        return parse_estimator(spec, state.scene)
    return controls.estimator_with(spec, state.scene, off)


def panel_specs(state: ViewState) -> list:
    """Estimator specs of the image panels in display order (members switched off left out:
    ``SPEC~A``)."""
    if not state.specs:
        return [state.estimator.spec]
    return [panel_estimator(state, i).spec for i in range(len(state.specs))]


# --------------------------------------------------------------------------- state
def build_state(scene_path: str, estimator: str = "planes", seed: int = 0, pixel_xy=None,
                photons: int = DEFAULT_PHOTONS, passes: int = DEFAULT_PASSES, stage="trace",
                hit: int | None = None, pass_index: int = 0,
                coverage: bool = False, render_passes: bool = True, *,
                estimators=None, inspect=None, resolution=None,
                inspector_workers: int = 0) -> ViewState:
    """Load the scene, render ``passes`` passes and inspect the pixel in pass ``pass_index``.

    ``estimators`` (specs, display order; default ``[estimator]``) are the image panels;
    ``inspect`` (an index or one of the specs; default the first MIS set) the one the stages
    inspect. ``resolution`` ``(W, H)`` overrides the scene's. ``render_passes=False`` leaves
    the accumulator empty (the progressive worker renders the passes).
    ``inspector_workers=1`` computes the inspection in a background process (the window):
    :attr:`ViewState.inspection` is None until :func:`accept_results` takes it.

    Raises ``SceneError`` / ``UnknownTechnique`` / ``ValueError`` for bad input.
    """
    from ui.cli.common import with_resolution
    from ui.cli.inspector import Inspector

    scene = with_resolution(load_scene(scene_path), resolution)
    specs = tuple(estimators) if estimators else (str(estimator),)
    ests = [parse_estimator(s, scene) for s in specs]
    inspected = _resolve_inspect(inspect, list(specs), ests)
    cam = scene.camera
    if pixel_xy is None:
        pixel_xy = (cam.width // 2, cam.height // 2)
    if not (0 <= pixel_xy[0] < cam.width and 0 <= pixel_xy[1] < cam.height):
        raise ValueError(f"--pixel {pixel_xy[0]},{pixel_xy[1]}: outside the "
                         f"{cam.width}x{cam.height} image")
    passes = max(int(passes), 1)
    if not 0 <= int(pass_index) < passes:
        raise ValueError(f"--pass {pass_index}: the image panels hold passes 0..{passes - 1} "
                         f"(--passes {passes})")
    settings = RenderSettings(photons=int(photons), spp=1)
    est = ests[inspected]
    acc = (render(scene, est, settings, passes=passes, seed=seed).accumulator if render_passes
           else Welford.empty((cam.height, cam.width, 3)))
    st = ViewState(scene_path=str(scene_path), scene=scene, estimator=est, seed=int(seed),
                   settings=settings, pixel_xy=tuple(int(v) for v in pixel_xy),
                   acc=acc, inspection=None, initial_passes=passes,
                   pass_index=int(pass_index), specs=specs, inspected=inspected,
                   base_scene=scene, inspector=Inspector(inspector_workers))
    st.stepper.go(stage)
    reinspect(st, keep_hit=True)
    accept_results(st)
    if hit is not None:
        n = len(st.inspection.table) if st.inspection is not None else None
        if n == 0 and int(hit) > 0:
            raise ValueError(f"--hit {hit}: the pixel has no hit in pass {pass_index}")
        if n and not 0 <= int(hit) < n:
            raise ValueError(f"--hit {hit}: the pixel has {n} hits in pass {pass_index} "
                             f"(valid: 0..{n - 1})")
        st.hit = int(hit)
    if coverage:
        st.coverage = True
        update_coverage(st)
        accept_results(st)
    return st


def update_coverage(state: ViewState) -> None:
    """Ask for the coverage (primitive -> pixels) of the current target in the current pass;
    :attr:`ViewState.coverage_mask` is None until it arrives (and when coverage is off)."""
    from ui.cli.inspector import CoverageRequest

    state.coverage_mask = None
    target = coverage_target(state) if state.coverage else None
    if target is None:
        if state.inspector is not None:
            state.inspector.cancel("coverage")
        return
    name, batch, prim = target
    state.inspector.submit(CoverageRequest(state.scene, state.estimator.spec, state.seed,
                                           state.pass_index, name, prim, batch,
                                           state.settings))


def reinspect(state: ViewState, *, keep_hit: bool = False) -> None:
    """Ask for the picked pixel's inspection in :attr:`ViewState.pass_index` again (after the
    pixel, the pass, the scene or the estimator changed). The stages show "computing..."
    until it arrives; the hit selection and a 3D pick are reset."""
    from ui.cli.inspector import PixelRequest

    state.inspection = None
    state.coverage_mask = None
    if not keep_hit:
        state.hit = 0
    state.coverage_pick = None
    state.inspector.cancel("coverage")
    state.inspector.submit(PixelRequest(state.scene, state.estimator.spec, state.seed,
                                        state.pass_index, state.pixel_xy, state.settings))


def accept_results(state: ViewState) -> bool:
    """Take the inspector's new answers into the state; True when the stages changed."""
    if state.inspector is None:
        return False
    changed = False
    for res in state.inspector.poll():
        changed = True
        if res.error is not None:
            state.message = f"inspection failed: {res.error}"
            continue
        if res.kind == "pixel":
            state.inspection = replace(res.value, scene=state.scene)
            n = len(state.inspection.table)
            state.hit = min(max(state.hit, 0), max(n - 1, 0))
            if state.coverage:
                update_coverage(state)
        else:
            state.coverage_mask = res.value
    for text in state.inspector.take_notices():
        state.message, changed = text, True
    return changed


# --------------------------------------------------------------------------- composing
def _recon(state: ViewState):
    ins = state.inspection
    if ins is None or len(ins.table) == 0:
        return None, None
    order = stage_text.hit_order(ins)
    k = min(max(state.hit, 0), len(order) - 1)
    return reconstruct_hit(ins, int(order[k])), k


def panel_text(state: ViewState) -> str:
    """The stage panel's text (see :func:`ui.views.stage_text.panel_text`)."""
    recon, k = _recon(state) if state.stage == "reconstruct" else (None, None)
    return stage_text.panel_text(state, recon, k)


def state_layout(plotter: pv.Plotter, state: ViewState, text: str):
    """The layout of ``state`` in ``plotter``'s window (the panel sized for ``text``)."""
    return window_layout(plotter.window_size, focus=state.focus, footer_rows=state.footer_rows,
                         sliders=state.sliders_on,
                         panel_lines=max(text.count("\n") + 1, PANEL_MIN_LINES),
                         caption_chars=state.caption_chars)


def apply_layout(plotter: pv.Plotter, state: ViewState, lay) -> None:
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


def compose_title(plotter: pv.Plotter, state: ViewState) -> None:
    """Title (bold), hint (right) and caption (wrapped to the width, shrunk if it must be)."""
    plotter.subplot(*CELL_TITLE)
    plotter.renderer.clear_actors()
    plotter.renderer.set_background("white")
    w, h = _viewport_px(plotter, CELL_TITLE)
    n = stage_index(state.stage) + 1
    hint = state.hint or f"stage {n}/{len(STAGES)}   n / p: step   h: help"
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


def _compose_3d(plotter: pv.Plotter, state: ViewState, camera=None,
                with_scene: bool = True) -> None:
    """The 3D view of the stage (labels are placed for ``camera``, the view it will have;
    ``with_scene=False``: the scene's actors are there already)."""
    ins = state.inspection
    scene = state.scene
    stage = state.stage
    if with_scene:
        before = set(plotter.renderer.actors)
        scene_view.add_scene(plotter, scene, pixel_xy=state.pixel_xy,
                             labels=(stage != "reconstruct"))
        state.scene_actors = set(plotter.renderer.actors) - before
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


def _home_camera(state: ViewState):
    """``(key, camera)``: where the 3D view looks by default at this stage (a pinned camera
    (lecture); Reconstruct: framing the selected hit's path; otherwise the overview)."""
    if state.camera_pin is not None:
        return ("pin", state.camera_pin), [tuple(map(float, v)) for v in state.camera_pin]
    if state.stage == "reconstruct":
        recon, k = _recon(state)
        if recon is not None and recon.get("polyline") is not None:
            key = ("recon", state.pixel_xy, state.pass_index, k, state.estimator.spec)
            return key, hits_view.reconstruct_camera(recon, state.scene)
    return ("overview",), scene_view.overview_camera(state.scene)


def compose(plotter: pv.Plotter, state: ViewState, *, keep_camera: bool = False) -> None:
    """(Re)draw every part of the window for ``state``.

    ``keep_camera`` keeps the 3D view where the user turned it, unless the stage's own view
    changed (entering Reconstruct, another hit there: it frames the new path).
    """
    scene_view.set_scale(plotter.window_size[1])
    text = panel_text(state)
    apply_layout(plotter, state, state_layout(plotter, state, text))
    compose_title(plotter, state)
    plotter.subplot(*CELL_3D)
    cam_pos = plotter.camera_position if keep_camera else None
    key, home = _home_camera(state)
    if cam_pos is None or key != state.framed:
        cam_pos = home
    state.framed = key
    cam_pos = [tuple(map(float, v)) for v in cam_pos]
    ren = plotter.renderer
    _clear_bars(plotter, ren)
    # The scene (box, lights, occluders, camera) stays when only the stage changed.
    key3d = (id(state.scene), state.pixel_xy, state.stage != "reconstruct")
    reuse = (state.scene_key == key3d and bool(state.scene_actors)
             and all(n in ren.actors for n in state.scene_actors))
    if reuse:
        for name in [n for n in ren.actors if n not in state.scene_actors]:
            if name in ren.actors:
                plotter.remove_actor(name, render=False)
    else:
        ren.clear_actors()
    ren.set_background(scene_view.BACKGROUND)
    _compose_3d(plotter, state, camera=cam_pos, with_scene=not reuse)
    state.scene_key = key3d
    plotter.camera_position = cam_pos
    plotter.renderer.ResetCameraClippingRange()
    compose_images(plotter, state)
    compose_panel(plotter, state, text)


def compose_panel(plotter: pv.Plotter, state: ViewState, text: str | None = None) -> bool:
    """Draw the stage panel (the stage's numbers, fitted to the panel) and the status message.

    Returns False when the text needs another layout (more or fewer lines than the panel was
    made for): the caller then composes everything again.
    """
    text = panel_text(state) if text is None else text
    lay = state.layout
    if lay is not None and state_layout(plotter, state, text) != lay:
        return False
    plotter.subplot(*CELL_PANEL)
    plotter.renderer.clear_actors()
    plotter.renderer.set_background("#f2f2f2")
    w, h = _viewport_px(plotter, CELL_PANEL)
    line = 1.2 * pt(FONT_SMALL)
    size = fit_font(text, pt(FONT_SMALL), (0.96 * w, h - 1.4 * line - 8), mono=True)
    add_text(plotter, text, 0.02, 1.0 - 6 / max(h, 1), FONT_SMALL, size_px=size,
             mono=True, name="panel")
    if state.message:
        msize = fit_font(state.message, pt(FONT_SMALL), (0.96 * w, 1.3 * line), bold=True)
        add_text(plotter, state.message, 0.02, (1.2 * line + 4) / max(h, 1),
                 FONT_SMALL, size_px=msize, name="message", bold=True)
    return True


def _clear_bars(plotter: pv.Plotter, renderer) -> None:
    """Remove the colour bars drawn in ``renderer`` (the image panels keep theirs)."""
    for title in list(plotter.scalar_bars.keys()):
        if renderer.HasViewProp(plotter.scalar_bars[title]):
            plotter.remove_scalar_bar(title)


def compose_images(plotter: pv.Plotter, state: ViewState) -> None:
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
        primitives_view.add_coverage(plotter, state.coverage_mask)
    plotter.subplot(*CELL_VARIANCE)
    plotter.renderer.clear_actors()
    if image_panels.VARIANCE_BAR in plotter.scalar_bars:
        plotter.remove_scalar_bar(image_panels.VARIANCE_BAR)
    plotter.renderer.set_background("white")
    var = state.acc.variance if state.acc.n > 1 else np.zeros_like(state.acc.mean)
    title = (f"{state.estimator.spec}: variance per pass (log scale)" if state.acc.n > 1
             else f"{state.estimator.spec}: variance needs 2+ passes")
    image_panels.add_variance_panel(plotter, var, state.pixel_xy, title, clim=state.var_clim)


def _compose_progressive(plotter: pv.Plotter, state: ViewState) -> None:
    """The progressive panels (every estimator side by side, or a breakdown mode) and, on the
    inspected estimator's render tile, the coverage overlay."""
    state.panels.draw(plotter, [CELL_RENDER, CELL_VARIANCE], state.prog, state.mode,
                      state.pixel_xy, reference=state.reference, clim=state.var_clim,
                      scale=state.var_scale, inspected=state.inspected)
    plotter.subplot(*CELL_RENDER)
    ren = plotter.renderer
    for name in ("coverage-cells", "coverage-outline"):
        if name in ren.actors:
            plotter.remove_actor(name, render=False)
    cam = state.scene.camera
    tiles = controls.image_tiles(ren, cam.width, cam.height)
    if state.coverage and state.coverage_mask is not None and tiles and state.mode == "render":
        _, origin, spacing = tiles[min(state.inspected, len(tiles) - 1)]
        primitives_view.add_coverage(plotter, state.coverage_mask, origin=origin,
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


# --------------------------------------------------------------------------- public API
def screenshot(scene_path: str, stage: str, pixel_xy, estimator: str = "planes", seed: int = 0,
               out: str = "shot.png", size=DEFAULT_SIZE, passes: int = DEFAULT_PASSES,
               hit: int | None = None, photons: int = DEFAULT_PHOTONS,
               n_paths: int = primitives_view.DEFAULT_PATHS, pass_index: int = 0,
               coverage: bool = False, estimators=None, mode: str = "render",
               reference: str | None = None, inspect=None, resolution=None,
               focus: str = "split", seconds: float | None = None) -> np.ndarray:
    """Render what the window shows at ``stage`` off-screen and write it to ``out`` (PNG).

    Parameters
    ----------
    stage : {'trace', 'create', 'intersect', 'evaluate', 'reconstruct'}
    pixel_xy : (int, int)
        Picked pixel ``(X, Y)``: column from the left, row from the top.
    estimators : sequence of str, optional
        The image panels' estimators side by side (the window's ``--estimators``; default
        ``[estimator]``); each gets ``passes`` passes here (the window: equal time).
    inspect : int or str, optional
        Which of them the stages inspect (default: the first MIS set).
    passes : int
        Passes of the progressive render shown in the image panels.
    seconds : float, optional
        Render the panels at equal time instead: every estimator this many seconds (the
        picture then shows the seconds and depends on the machine).
    hit : int, optional
        Which hit Reconstruct (and coverage) use, as numbered ``#i`` in the evaluate table
        (largest contribution first); default 0.
    pass_index : int
        The inspected pass, ``0 <= pass_index < passes`` (the window's ``,`` / ``.``).
    coverage : bool
        Tint the pixels the selected hit's primitive contributes to on the render panel
        (the window's ``c``).
    mode : {'render', 'techniques', 'bounces'}
        Image-panel mode (the window's ``m``).
    reference : str, optional
        An ``app.py render`` .npz of this scene: relMSE is shown under each estimator.
    resolution : (int, int), optional
        Override the scene's resolution.
    focus : {'split', 'images', '3d'}
        The layout (the window's ``z``).

    Returns
    -------
    (H, W, 3) uint8
        The image written.
    """
    stage_index(stage)
    if mode not in MODES:
        raise ValueError(f"unknown panel mode '{mode}' (expected one of: {', '.join(MODES)})")
    state = build_state(scene_path, estimator, seed, pixel_xy, photons, passes, stage, hit,
                        pass_index=pass_index, coverage=coverage, render_passes=False,
                        estimators=estimators, inspect=inspect, resolution=resolution)
    state.n_paths = int(n_paths)
    state.mode, state.focus = mode, focus
    state.reference = load_reference_image(reference, state.scene)
    # The window's panels, rendered here pass by pass (workers=0: deterministic, and
    # bit-identical to a serial render of the same seed).
    attach_progressive(state, workers=0, breakdown=(mode != "render"),
                       max_seconds=seconds)
    if seconds is None:
        state.prog.run(passes=state.initial_passes)
        for r in state.prog.runs:
            # Wall seconds differ from run to run; a screenshot compares at equal passes so
            # the same arguments always give the same picture.
            r.seconds = 0.0
    else:
        state.prog.run()
    state.acc = state.prog.runs[state.inspected].acc
    plotter = make_plotter(size, off_screen=True)
    try:
        compose(plotter, state)
        img = plotter.screenshot(None, return_img=True)
    finally:
        plotter.close()
        state.prog.close()
        state.inspector.close()
    import imageio.v3 as iio

    d = os.path.dirname(os.path.abspath(out))
    os.makedirs(d, exist_ok=True)
    iio.imwrite(out, img)
    return img


def attach_progressive(state: ViewState, workers: int = 1, breakdown: bool = True,
                       max_seconds: float | None = None) -> None:
    """Render the panels progressively (``ui.cli.progressive``: ``workers`` background processes,
    0 = in the timer tick) into ``image_panels.PanelView`` tiles; starts playing."""
    from ui.cli.progressive import Progressive

    state.prog = Progressive(state.scene, panel_specs(state), state.settings, seed=state.seed,
                             workers=workers, breakdown=breakdown, max_seconds=max_seconds)
    state.panels = image_panels.PanelView()
    state.acc = state.prog.runs[state.inspected].acc
    state.playing = True


def load_reference_image(path: str | None, scene) -> np.ndarray | None:
    """The ``mean`` (H, W, 3) of a reference .npz for ``scene`` (None without a path).

    Raises ``SceneError`` naming the file for a missing/unreadable file, another resolution
    or scatter range (``psurf_core.study.load_reference``).
    """
    if path is None:
        return None
    from ui.cli.common import load_reference

    return load_reference(os.fspath(path), scene).mean
