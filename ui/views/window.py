"""What the interactive window shows: its state, layout and the composition of each stage
(and the off-screen twin, :func:`screenshot`). The bindings (keys, mouse, widgets, timer) and
:func:`~ui.views.interactive.run`, which opens the window, are in :mod:`ui.views.interactive`.

Layout (one pyvista Plotter, 2 x 3 grid)::

    +---------------------------+-------------+-------------+
    |                           |   render    |  variance   |
    |      3D view: scene,      +-------------+-------------+
    |      stage geometry,      |                           |
    |      title and caption    |   stage panel (numbers)   |
    +---------------------------+---------------------------+

The image panels (render, variance) are ``ui.views.image_panels.PanelView`` tiles of a
``ui.cli.progressive.Progressive`` render: in the window a background worker process, polled by the
timer without waiting; for :func:`screenshot` the same passes rendered in this process. With
``--estimators A,B`` they show A and B side by side at equal time; A is the estimator the stages
inspect. (A :class:`ViewState` without ``prog`` (lecture mode) shows its own accumulator.)

Keys (:data:`HELP`, bound by :class:`ui.views.interactive.App`): ``n``/``p`` next/previous stage,
``space`` play/pause, ``r`` reset, ``s`` screenshot, ``h`` help; arrows move the picked pixel,
``[``/``]`` choose the hit, ``+``/``-`` change the number of subpaths, ``,``/``.`` the
inspected pass, ``c`` coverage (the pixels the selected hit's primitive reaches), ``1``..``9``
MIS members on/off, ``x X``/``a A``/``g G``/``k K`` sigma_s, sigma_a, g, photons (debounced:
the scene is rebuilt once the keys rest), ``m`` panel mode, ``v`` record a GIF, ``w`` sliders.
Mouse: a click on the render or variance panel picks that pixel; a right click on a primitive
in the 3D view shows its coverage; the buttons, member chips and sliders of
:mod:`ui.views.controls` do the same as the keys.

:func:`screenshot` composes what the window shows at a stage (without the on-screen
controls), off-screen and deterministically (same arguments, same picture: a fixed number of
passes, no wall seconds drawn).
"""

from __future__ import annotations

import os
import textwrap
from dataclasses import dataclass, field

import numpy as np

from psurf_core.accumulate import Welford
from psurf_core.estimators import parse_estimator
from psurf_core.inspect import (
    inspect_pixel,
    member_primitives,
    primitive_pixels,
    reconstruct_hit,
)
from psurf_core.render import RenderSettings, render
from psurf_core.scene_io import load_scene

from . import controls, hits_view, image_panels, primitives_view, scene_view
from ._vtk import pv
from .scene_view import FONT, FONT_SMALL, FONT_TITLE, add_text
from .stepper import (
    DEFAULT_PASSES,
    DEFAULT_PHOTONS,
    DEFAULT_SIZE,
    STAGES,
    Stepper,
    stage_index,
)

HELP = """keys
  n / p    next / previous stage
  space    play / pause rendering
  r        reset (stage, passes, camera)
  s        screenshot (PNG, current folder)
  arrows   move the picked pixel
  [ / ]    previous / next hit
  , / .    previous / next inspected pass
  c        coverage of the hit's primitive
  1 .. 9   MIS member on / off
  x X a A  sigma_s / sigma_a down / up
  g G k K  HG g / photons down / up
  + / -    more / fewer photon subpaths
  m        panels: render/techniques/bounces
  v        record a GIF (v again: stop)
  w        show / hide the sliders
  h        this help      q  quit
mouse
  click render/variance: pick the pixel
  right click a primitive: its coverage
  buttons at the bottom right"""

_GRID = dict(shape=(2, 3), col_weights=[4, 2, 2], row_weights=[9, 11],
             groups=[(np.s_[:], 0), (1, np.s_[1:])])
#: Grid cells (row, column) of the 3D view, the two image panels and the stage panel.
CELL_3D, CELL_RENDER, CELL_VARIANCE, CELL_PANEL = (0, 0), (0, 1), (0, 2), (1, 1)


@dataclass
class ViewState:
    """Everything one picture of the window depends on."""

    scene_path: str
    scene: object
    estimator: object
    seed: int
    settings: RenderSettings
    pixel_xy: tuple
    acc: Welford
    inspection: object
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
    #: Spec the estimator was opened with, and the members switched off since.
    base_spec: str = ""
    disabled: frozenset = frozenset()
    #: The scene as loaded (the medium sliders change copies of it).
    base_scene: object = None
    #: The window's progressive renderer (``ui.cli.progressive.Progressive``) and its panels
    #: (``ui.views.image_panels.PanelView``); None: the panels show :attr:`acc` (screenshots).
    prog: object = None
    panels: object = None
    #: Image-panel mode (``image_panels.MODES``, the ``m`` key) and the estimators shown
    #: beside the inspected one (``--estimators A,B``: B is extra).
    mode: str = "render"
    extra_specs: tuple = ()
    #: Ground truth (H, W, 3) for relMSE in the render panels (``--reference FILE.npz``).
    reference: np.ndarray | None = None

    @property
    def stage(self) -> str:
        return self.stepper.stage


def build_state(scene_path: str, estimator: str = "planes", seed: int = 0, pixel_xy=None,
                photons: int = DEFAULT_PHOTONS, passes: int = DEFAULT_PASSES, stage="trace",
                hit: int | None = None, pass_index: int = 0,
                coverage: bool = False, render_passes: bool = True) -> ViewState:
    """Load the scene, render ``passes`` passes and inspect the pixel in pass ``pass_index``.

    ``render_passes=False`` leaves the accumulator empty (the window's progressive worker
    renders the passes).

    Raises ``SceneError`` / ``UnknownTechnique`` / ``ValueError`` for bad input.
    """
    scene = load_scene(scene_path)
    est = parse_estimator(estimator, scene)
    if est.reference:
        raise ValueError("the window shows photon estimators; 'reference' has no stages")
    cam = scene.camera
    if pixel_xy is None:
        pixel_xy = (cam.width // 2, cam.height // 2)
    passes = max(int(passes), 1)
    if not 0 <= int(pass_index) < passes:
        raise ValueError(f"--pass {pass_index}: the image panels hold passes 0..{passes - 1} "
                         f"(--passes {passes})")
    settings = RenderSettings(photons=int(photons), spp=1)
    inspection = inspect_pixel(scene, est, seed, int(pass_index), pixel_xy, settings)
    acc = (render(scene, est, settings, passes=passes, seed=seed).accumulator if render_passes
           else Welford.empty((cam.height, cam.width, 3)))
    st = ViewState(scene_path=str(scene_path), scene=scene, estimator=est, seed=int(seed),
                   settings=settings, pixel_xy=tuple(int(v) for v in pixel_xy),
                   acc=acc, inspection=inspection,
                   initial_passes=passes, pass_index=int(pass_index),
                   base_spec=str(estimator), base_scene=scene)
    st.stepper.go(stage)
    if hit is not None:
        n = len(inspection.table)
        if n == 0 and int(hit) > 0:
            raise ValueError(f"--hit {hit}: the pixel has no hit in pass {pass_index}")
        if n and not 0 <= int(hit) < n:
            raise ValueError(f"--hit {hit}: the pixel has {n} hits in pass {pass_index} "
                             f"(valid: 0..{n - 1})")
        st.hit = int(hit)
    if coverage:
        st.coverage = True
        update_coverage(st)
    return st


def coverage_target(state: ViewState):
    """``(technique, batch, prim)`` whose coverage is shown: the primitive picked in the 3D
    view, else the selected hit's; None when the pixel has no hit."""
    if state.coverage_pick is not None:
        return state.coverage_pick
    t = state.inspection.table
    if len(t) == 0:
        return None
    order = hits_view.hit_order(state.inspection)
    r = int(order[min(max(state.hit, 0), len(order) - 1)])
    return str(t.technique[r]), int(t.batch[r]), int(t.prim[r])


def update_coverage(state: ViewState) -> None:
    """Recompute :attr:`ViewState.coverage_mask` (primitive -> pixels) for the current
    target and pass; None when coverage is off or there is no target."""
    target = coverage_target(state) if state.coverage else None
    if target is None:
        state.coverage_mask = None
        return
    name, batch, prim = target
    state.coverage_mask = primitive_pixels(state.scene, state.estimator, state.seed,
                                           state.pass_index, name, prim, state.settings,
                                           batch=batch)


def reinspect(state: ViewState) -> None:
    """Inspect the picked pixel again in :attr:`ViewState.pass_index` (after the pixel, the
    pass, the scene or the estimator changed); the hit selection and a 3D pick are reset."""
    state.inspection = inspect_pixel(state.scene, state.estimator, state.seed,
                                     state.pass_index, state.pixel_xy, state.settings)
    state.hit = 0
    state.coverage_pick = None
    update_coverage(state)


# --------------------------------------------------------------------------- composing
def _wrap(text: str, width: int) -> str:
    return "\n".join(textwrap.wrap(text, width=width))


def _recon(state: ViewState):
    t = state.inspection.table
    if len(t) == 0:
        return None, None
    order = hits_view.hit_order(state.inspection)
    k = min(max(state.hit, 0), len(order) - 1)
    return reconstruct_hit(state.inspection, int(order[k])), k


def panel_text(state: ViewState) -> str:
    """The stage panel's text (lower right)."""
    ins = state.inspection
    est = state.estimator
    head = (f"{os.path.basename(state.scene_path)}   estimator {est.spec}   seed {state.seed}\n"
            f"passes {state.acc.n}   photons/pass {state.settings.photons}   "
            f"pixel ({state.pixel_xy[0]}, {state.pixel_xy[1]})\n")
    stage = state.stage
    if stage == "trace":
        paths = ins.paths
        events = [int(p.alive.sum(axis=1).mean() * 100) / 100 for p in paths]
        inbox = [float(p.prefix_ok[:, 1].mean()) for p in paths if p.depth]
        body = (f"pass {ins.pass_index}: {ins.n_photons} photons in {len(paths)} batch(es)\n"
                f"mean traced segments per photon: {np.mean(events):.2f}\n"
                f"first vertex inside the box: {100 * np.mean(inbox):.0f}%\n"
                f"drawn: the first {min(state.n_paths, ins.n_photons)} subpaths "
                f"(+/- to change)")
    elif stage == "create":
        lines = [f"pass {ins.pass_index}: primitives per technique"]
        for name, tech in ins.techniques.items():
            n = sum(len(p) for (t, _), p in ins.prims.items() if t == name)
            ks = [p.K for (t, _), p in ins.prims.items() if t == name and len(p)]
            kr = (f"K {int(min(k.min() for k in ks))}..{int(max(k.max() for k in ks))}"
                  if ks else "no K")
            lines.append(f"  {name} [{tech.family}]: {n}  ({kr})")
        lines.append(f"drawn: those of the first {state.n_paths} photons")
        body = "\n".join(lines)
    elif stage == "intersect":
        t = ins.table
        r = ins.rays
        lines = [f"{len(r)} ray(s); in the medium for s in "
                 f"[{r.s_min[0]:.2f}, {r.s_max[0]:.2f}]", f"{len(t)} hits:"]
        for name in ins.techniques:
            m = t.technique == name
            if m.any():
                lines.append(f"  {name}: {int(m.sum())} hits, s {t.s[m].min():.2f}.."
                             f"{t.s[m].max():.2f}")
            else:
                lines.append(f"  {name}: no hit")
        if len(t):
            nd = t.n_dot_psi[np.isfinite(t.n_dot_psi)]
            if nd.size:
                lines.append(f"|n.psi| from {nd.min():.1e} to {nd.max():.1e}")
            lines.append("arrows at the largest hits:")
            for i, r in enumerate(hits_view.hit_order(ins)[: hits_view.NORMAL_ROWS]):
                lines.append(f"  #{i} {t.technique[r]}  s {t.s[r]:.3f}  "
                             f"|n| {np.linalg.norm(t.normal[r]):.3g}  "
                             f"|n.psi| {t.n_dot_psi[r]:.3g}")
        lines.append(f"drawn: primitives of the top {hits_view.TABLE_ROWS} hits")
        body = "\n".join(lines)
    elif stage == "evaluate":
        body = hits_view.evaluate_table_text(ins)
    else:
        recon, k = _recon(state)
        body = ("no hit in this pass: move the pixel (arrows)" if recon is None
                else hits_view.reconstruct_text(ins, recon, k) + "\n[ / ] other hits")
    return head + "\n" + body + coverage_text(state)


def coverage_text(state: ViewState) -> str:
    """The panel's coverage line (empty when coverage is off)."""
    if not state.coverage:
        return ""
    target = coverage_target(state)
    if target is None or state.coverage_mask is None:
        return "\ncoverage: no hit selected (move the pixel)"
    name, batch, prim = target
    src = "picked in 3D" if state.coverage_pick is not None else f"hit #{state.hit}"
    return (f"\ncoverage ({src}): {name} primitive {prim}, batch {batch}\n"
            f"  reaches {int(state.coverage_mask.sum())} pixels in pass {state.pass_index}")


def _compose_3d(plotter: pv.Plotter, state: ViewState) -> None:
    ins = state.inspection
    scene = state.scene
    stage = state.stage
    scene_view.add_scene(plotter, scene, pixel_xy=state.pixel_xy,
                         labels=(stage != "reconstruct"))
    t = ins.table
    top = hits_view.hit_order(ins)[: hits_view.TABLE_ROWS]
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
                                 labels=(stage == "evaluate"))
        if stage == "intersect":
            hits_view.add_normals(plotter, ins, top[: hits_view.NORMAL_ROWS])
    else:
        hits_view.add_query_ray(plotter, ins)
        recon, _ = _recon(state)
        if recon is not None:
            members = member_primitives(ins, recon)
            if members:  # every member's surface through this path, with its weight
                hits_view.add_member_surfaces(plotter, ins, recon, members)
            else:  # a kernel estimator: no exact path, only its own primitive
                hits_view.add_hit_primitives(plotter, ins, [recon["row"]], opacity=0.6)
            hits_view.add_reconstruction(plotter, ins, recon)
    target = coverage_target(state) if state.coverage else None
    if target is not None:
        name, batch, prim = target
        primitives_view.add_primitives(plotter, ins, {(name, batch): np.array([prim])},
                                       opacity=0.3, name="coverage", legend=False, width=6.0,
                                       list_empty=False)
    # Title and caption, top left; the help overlay on top of everything.
    add_text(plotter, state.stepper.title, 0.015, 0.985, FONT_TITLE, bold=True, name="title")
    add_text(plotter, _wrap(state.stepper.caption, 78), 0.015, 0.935, FONT_SMALL,
             name="caption")
    n = stage_index(stage) + 1
    add_text(plotter, f"stage {n}/{len(STAGES)}    n / p: step    h: help", 0.985, 0.05,
             FONT_SMALL, name="stage-hint", colour="#555555", align="right")
    if state.show_help:
        add_text(plotter, HELP, 0.04, 0.78, FONT, mono=True, box=True, name="help")


def compose(plotter: pv.Plotter, state: ViewState, *, keep_camera: bool = False) -> None:
    """(Re)draw every panel of the window for ``state``."""
    scene_view.set_scale(plotter.window_size[1])
    plotter.subplot(*CELL_3D)
    _clear_bars(plotter)
    compose_3d(plotter, state, keep_camera=keep_camera)
    compose_images(plotter, state)
    compose_panel(plotter, state)


def compose_3d(plotter: pv.Plotter, state: ViewState, *, keep_camera: bool = False) -> None:
    """(Re)draw the 3D view of ``state`` into the plotter's current renderer: the window's
    left cell, or a plotter of its own (the web page's 3D view, :mod:`ui.web`)."""
    cam_pos = plotter.camera_position if keep_camera else None
    plotter.renderer.clear_actors()
    plotter.renderer.set_background(scene_view.BACKGROUND)
    _compose_3d(plotter, state)
    plotter.camera_position = cam_pos if cam_pos is not None else \
        scene_view.overview_camera(state.scene)
    plotter.renderer.ResetCameraClippingRange()


def compose_panel(plotter: pv.Plotter, state: ViewState) -> None:
    """Draw the stage panel: the numbers of the current stage and the status message."""
    plotter.subplot(*CELL_PANEL)
    plotter.renderer.clear_actors()
    plotter.renderer.set_background("#f2f2f2")
    add_text(plotter, panel_text(state), 0.02, 0.97, FONT_SMALL, mono=True, name="panel")
    if state.message:  # just above the window's two rows of buttons (ui.views.controls)
        add_text(plotter, state.message, 0.02, 0.19, FONT_SMALL, name="message",
                 colour=scene_view.OKABE_ITO["vermillion"])


def _clear_bars(plotter: pv.Plotter) -> None:
    for title in list(plotter.scalar_bars.keys()):
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
    title = f"render, {state.acc.n} passes"
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
    title = ("variance per pass (log scale)" if state.acc.n > 1
             else "variance: needs 2+ passes")
    image_panels.add_variance_panel(plotter, var, state.pixel_xy, title)


def _compose_progressive(plotter: pv.Plotter, state: ViewState) -> None:
    """The progressive panels (every estimator side by side, or a breakdown mode) and, on the
    inspected estimator's render tile, the coverage overlay."""
    state.panels.draw(plotter, [CELL_RENDER, CELL_VARIANCE], state.prog, state.mode, state.pixel_xy,
                      reference=state.reference)
    plotter.subplot(*CELL_RENDER)
    ren = plotter.renderer
    for name in ("coverage-cells", "coverage-outline"):
        if name in ren.actors:
            plotter.remove_actor(name, render=False)
    cam = state.scene.camera
    tiles = controls.image_tiles(ren, cam.width, cam.height)
    if state.coverage and state.coverage_mask is not None and tiles:
        _, origin, spacing = tiles[0]
        primitives_view.add_coverage(plotter, state.coverage_mask, origin=origin,
                                     spacing=spacing)


def make_plotter(size=DEFAULT_SIZE, off_screen: bool = False) -> pv.Plotter:
    """The window's plotter: the 2 x 3 grid of the layout, white, FreeType text."""
    scene_view.plain_text()
    p = pv.Plotter(window_size=list(size), off_screen=off_screen, border=False, **_GRID)
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
               coverage: bool = False, estimators=(), mode: str = "render",
               reference: str | None = None) -> np.ndarray:
    """Render what the window shows at ``stage`` off-screen and write it to ``out`` (PNG).

    Parameters
    ----------
    stage : {'trace', 'create', 'intersect', 'evaluate', 'reconstruct'}
    pixel_xy : (int, int)
        Picked pixel ``(X, Y)``: column from the left, row from the top.
    passes : int
        Passes of the progressive render shown in the image panels.
    hit : int, optional
        Which hit Reconstruct (and coverage) use, as numbered ``#i`` in the evaluate table
        (largest contribution first); default 0.
    pass_index : int
        The inspected pass, ``0 <= pass_index < passes`` (the window's ``,`` / ``.``).
    coverage : bool
        Tint the pixels the selected hit's primitive contributes to on the render panel
        (the window's ``c``).
    estimators : sequence of str
        Estimators shown beside ``estimator`` in the image panels (the window's
        ``--estimators``); each gets ``passes`` passes here (the window: equal time).
    mode : {'render', 'techniques', 'bounces'}
        Image-panel mode (the window's ``m``).
    reference : str, optional
        An ``app.py render`` .npz of this scene: relMSE is shown under each estimator.

    Returns
    -------
    (H, W, 3) uint8
        The image written.
    """
    stage_index(stage)
    from .image_panels import MODES

    if mode not in MODES:
        raise ValueError(f"unknown panel mode '{mode}' (expected one of: {', '.join(MODES)})")
    state = build_state(scene_path, estimator, seed, pixel_xy, photons, passes, stage, hit,
                        pass_index=pass_index, coverage=coverage, render_passes=False)
    state.n_paths = int(n_paths)
    state.extra_specs, state.mode = tuple(estimators), mode
    state.reference = load_reference_image(reference, state.scene)
    # The window's panels, rendered here pass by pass (workers=0: deterministic, and
    # bit-identical to a serial render of the same seed).
    attach_progressive(state, workers=0, breakdown=(mode != "render"))
    state.prog.run(passes=state.initial_passes)
    state.acc = state.prog.runs[0].acc
    for r in state.prog.runs:
        # Wall seconds differ from run to run; a screenshot compares at equal passes so the
        # same arguments always give the same picture.
        r.seconds = 0.0
    plotter = make_plotter(size, off_screen=True)
    try:
        compose(plotter, state)
        img = plotter.screenshot(None, return_img=True)
    finally:
        plotter.close()
        state.prog.close()
    import imageio.v3 as iio

    d = os.path.dirname(os.path.abspath(out))
    os.makedirs(d, exist_ok=True)
    iio.imwrite(out, img)
    return img


def panel_specs(state: ViewState) -> list:
    """Estimator specs of the image panels: the inspected estimator first, then the extras."""
    return [state.estimator.spec, *state.extra_specs]


def attach_progressive(state: ViewState, workers: int = 1, breakdown: bool = True) -> None:
    """Render the panels progressively (``ui.cli.progressive``: ``workers`` background processes,
    0 = in the timer tick) into ``image_panels.PanelView`` tiles; starts playing."""
    from ui.cli.progressive import Progressive

    from .image_panels import PanelView

    state.prog = Progressive(state.scene, panel_specs(state), state.settings, seed=state.seed,
                             workers=workers, breakdown=breakdown)
    state.panels = PanelView()
    state.acc = state.prog.runs[0].acc
    state.playing = True


def load_reference_image(path: str | None, scene) -> np.ndarray | None:
    """The ``mean`` (H, W, 3) of a reference .npz for ``scene`` (None without a path).

    Raises ``SceneError`` naming the file for a missing/unreadable file, another resolution
    or scatter range (``psurf_core.study.load_reference``).
    """
    if path is None:
        return None
    from psurf_core.study import load_reference

    return load_reference(os.fspath(path), scene).mean
