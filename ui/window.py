"""The interactive window (and its off-screen twin, :func:`screenshot`).

Layout (one pyvista Plotter, 2 x 3 grid)::

    +---------------------------+-------------+-------------+
    |                           |   render    |  variance   |
    |      3D view: scene,      +-------------+-------------+
    |      stage geometry,      |                           |
    |      title and caption    |   stage panel (numbers)   |
    +---------------------------+---------------------------+

The image panels (render, variance) are ``ui.image_panels.PanelView`` tiles of a
``ui.progressive.Progressive`` render: in the window a background worker process, polled by the
timer without waiting; for :func:`screenshot` the same passes rendered in this process. With
``--estimators A,B`` they show A and B side by side at equal time; A is the estimator the stages
inspect. (A :class:`ViewState` without ``prog`` (lecture mode) shows its own accumulator.)

Keys (:data:`HELP`): ``n``/``p`` next/previous stage, ``space`` play/pause, ``r`` reset, ``s``
screenshot, ``h`` help; arrows move the picked pixel, ``[``/``]`` choose the hit, ``+``/``-``
change the number of subpaths, ``,``/``.`` the inspected pass, ``c`` coverage (the pixels the
selected hit's primitive reaches), ``1``..``9`` MIS members on/off, ``x X``/``a A``/``g G``/
``k K`` sigma_s, sigma_a, g, photons (debounced: the scene is rebuilt once the keys rest),
``m`` panel mode, ``v`` record a GIF, ``w`` sliders.
Mouse: a click on the render or variance panel picks that pixel; a right click on a primitive
in the 3D view shows its coverage; the buttons, member chips and sliders of
:mod:`ui.controls` do the same as the keys.

:func:`screenshot` composes what the window shows at a stage (without the on-screen
controls), off-screen and deterministically (same arguments, same picture; only the render
seconds printed above each tile are measured).
"""

from __future__ import annotations

import os
import textwrap
import time
from dataclasses import dataclass, field, replace

import numpy as np
import pyvista as pv

from psurf_core.accumulate import Welford
from psurf_core.estimators import parse_estimator
from psurf_core.inspect import (
    inspect_pixel,
    member_primitives,
    primitive_pixels,
    reconstruct_hit,
)
from psurf_core.render import RenderSettings, render, render_pass
from psurf_core.scene_io import load_scene

from . import controls, hits_view, image_panels, primitives_view, scene_view
from .scene_view import FONT, FONT_SMALL, FONT_TITLE, add_text
from .stepper import STAGES, Stepper, stage_index

#: Photons per pass in the window (a 64 x 48 scene stays interactive).
DEFAULT_PHOTONS = 2000
#: Passes rendered before the window opens.
DEFAULT_PASSES = 4
DEFAULT_SIZE = (1600, 900)

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
_VIEW3D, _RENDER, _VARIANCE, _PANEL = (0, 0), (0, 1), (0, 2), (1, 1)


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
    #: The window's progressive renderer (``ui.progressive.Progressive``) and its panels
    #: (``ui.image_panels.PanelView``); None: the panels show :attr:`acc` (screenshots).
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
    plotter.subplot(*_VIEW3D)
    cam_pos = plotter.camera_position if keep_camera else None
    plotter.renderer.clear_actors()
    _clear_bars(plotter)
    plotter.renderer.set_background(scene_view.BACKGROUND)
    _compose_3d(plotter, state)
    plotter.camera_position = cam_pos if cam_pos is not None else \
        scene_view.overview_camera(state.scene)
    plotter.renderer.ResetCameraClippingRange()
    _compose_images(plotter, state)
    _compose_panel(plotter, state)


def _compose_panel(plotter: pv.Plotter, state: ViewState) -> None:
    plotter.subplot(*_PANEL)
    plotter.renderer.clear_actors()
    plotter.renderer.set_background("#f2f2f2")
    add_text(plotter, panel_text(state), 0.02, 0.97, FONT_SMALL, mono=True, name="panel")
    if state.message:  # just above the window's two rows of buttons (ui.controls)
        add_text(plotter, state.message, 0.02, 0.19, FONT_SMALL, name="message",
                 colour=scene_view.OKABE_ITO["vermillion"])


def _clear_bars(plotter: pv.Plotter) -> None:
    for title in list(plotter.scalar_bars.keys()):
        plotter.remove_scalar_bar(title)


def _compose_images(plotter: pv.Plotter, state: ViewState) -> None:
    if state.prog is not None:
        _compose_progressive(plotter, state)
        return
    plotter.subplot(*_RENDER)
    plotter.renderer.clear_actors()
    plotter.renderer.set_background("white")
    title = f"render, {state.acc.n} passes"
    if state.coverage and state.coverage_mask is not None:
        title += f"; coverage {int(state.coverage_mask.sum())} px"
    image_panels.add_render_panel(plotter, state.acc.mean, state.pixel_xy, title)
    if state.coverage and state.coverage_mask is not None:
        primitives_view.add_coverage(plotter, state.coverage_mask)
    plotter.subplot(*_VARIANCE)
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
    state.panels.draw(plotter, [_RENDER, _VARIANCE], state.prog, state.mode, state.pixel_xy,
                      reference=state.reference)
    plotter.subplot(*_RENDER)
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


#: Environment variable with a script for the window (tests under Xvfb): steps separated by
#: ``;``, one per timer tick: a key sym (``n``, ``space``, ``Right``), ``click:render:X,Y`` /
#: ``click:variance:X,Y`` (a real mouse click on that image pixel's centre), ``shot:PATH.png``,
#: ``passes>=N`` / ``passes+N`` (wait until the panels hold N passes / N more), ``wait`` or
#: ``quit``.
SCRIPT_ENV = "PSURF_WINDOW_SCRIPT"
#: Environment variable ``W,H`` overriding the window size (a quicker scripted test).
SIZE_ENV = "PSURF_WINDOW_SIZE"


def panel_specs(state: ViewState) -> list:
    """Estimator specs of the image panels: the inspected estimator first, then the extras."""
    return [state.estimator.spec, *state.extra_specs]


def attach_progressive(state: ViewState, workers: int = 1, breakdown: bool = True) -> None:
    """Render the panels progressively (``ui.progressive``: ``workers`` background processes,
    0 = in the timer tick) into ``image_panels.PanelView`` tiles; starts playing."""
    from .image_panels import PanelView
    from .progressive import Progressive

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


def run(scene_path: str, estimator: str = "planes", *, estimators=None, seed: int = 0,
        pixel_xy=None, photons: int = DEFAULT_PHOTONS, size=DEFAULT_SIZE,
        workers: int = 1, reference: str | None = None) -> None:
    """Open the interactive window on ``scene_path`` (blocks until it is closed).

    ``estimators`` (specs) are rendered side by side at equal time in a background process;
    the first is the one the stages inspect (default: ``[estimator]``). ``reference`` (an
    ``app.py render`` .npz of the scene) adds relMSE under each render.

    With :data:`SCRIPT_ENV` set, its steps are played through the window's own event path
    (synthetic key presses and mouse clicks), one per timer tick, and ``quit`` closes it.
    """
    specs = list(estimators) if estimators else [estimator]
    state = build_state(scene_path, specs[0], seed, pixel_xy, photons, render_passes=False)
    state.extra_specs = tuple(specs[1:])
    state.reference = load_reference_image(reference, state.scene)
    attach_progressive(state, workers=workers)
    if os.environ.get(SIZE_ENV):
        size = tuple(int(v) for v in os.environ[SIZE_ENV].split(","))
    plotter = make_plotter(size)
    app = App(plotter, state)
    try:
        compose(plotter, state)
        app.bind()
        script = os.environ.get(SCRIPT_ENV)
        if script:
            app.script = [step.strip() for step in script.split(";") if step.strip()]
        plotter.show(title="psurf - photon surfaces, step by step")
    finally:
        app.close()


class App:
    """Key, mouse, widget and timer bindings of the interactive window.

    Every action is a method, so tests drive them on an off-screen plotter; :meth:`click`
    takes a display position as VTK reports it (pixels, ``y`` from the bottom).
    """

    #: Timer period (ms): progressive passes, debounced parameter changes, scripted steps.
    TICK_MS = 200

    def __init__(self, plotter: pv.Plotter, state: ViewState, *, with_controls: bool = True):
        self.p = plotter
        self.s = state
        if not state.base_spec:
            state.base_spec = state.estimator.spec
        if state.base_scene is None:
            state.base_scene = state.scene
        self.params = controls.MediumParams.of(state.scene, state.settings.photons)
        self.pending = controls.Debouncer()
        self.clock = time.monotonic
        self.with_controls = with_controls
        self.controls = None
        self.script: list = []
        self._tags: dict = {}
        self.recorder = None
        self._gl_checked = False
        self._t0 = time.perf_counter()

    @property
    def members(self) -> tuple:
        from psurf_core.estimators import parse_estimator

        return controls.members(parse_estimator(self.s.base_spec, self.s.scene))

    # ---------------------------------------------------------------- binding
    def bind(self) -> None:
        p = self.p
        if self.with_controls:
            self.controls = controls.Controls(p, self._actions(), on_slider=self.slide)
            self.controls.draw(self.s, self.members, self.s.disabled)
        if p.iren is None:  # no interactor: nothing to bind (methods can still be called)
            return
        # VTK's own character shortcuts (w, s, r, p, e, ...) would fight ours.
        p.iren.interactor.RemoveObservers("CharEvent")
        for key in ("Up", "Down", "plus", "minus", "b", "v", "C"):
            p.clear_events_for_key(key, raise_on_missing=False)
        keys = {
            "n": self.next, "p": self.previous, "space": self.toggle_play, "r": self.reset,
            "s": self.save, "h": self.toggle_help, "Left": lambda: self.move(-1, 0),
            "Right": lambda: self.move(1, 0), "Up": lambda: self.move(0, -1),
            "Down": lambda: self.move(0, 1), "bracketleft": lambda: self.step_hit(-1),
            "bracketright": lambda: self.step_hit(1), "plus": lambda: self.paths(2.0),
            "equal": lambda: self.paths(2.0), "minus": lambda: self.paths(0.5),
            "comma": lambda: self.step_pass(-1), "period": lambda: self.step_pass(1),
            "c": self.toggle_coverage, "q": self.quit, "m": self.next_mode,
            "v": self.toggle_record, "w": self.toggle_sliders,
            "x": lambda: self.nudge("sigma_s", -1), "X": lambda: self.nudge("sigma_s", 1),
            "a": lambda: self.nudge("sigma_a", -1), "A": lambda: self.nudge("sigma_a", 1),
            "g": lambda: self.nudge("g", -1), "G": lambda: self.nudge("g", 1),
            "k": lambda: self.nudge("photons", -1), "K": lambda: self.nudge("photons", 1),
        }
        for i in range(9):
            keys[str(i + 1)] = lambda i=i: self.toggle_member_index(i)
        for k, fn in keys.items():
            p.add_key_event(k, fn)
        if self.controls is not None:
            self.controls.add_sliders(self.params)
        ii = p.iren.interactor
        # Above the camera style (priority 0) and the widgets, so a click on a button or an
        # image panel does not also rotate or pan; elsewhere the event goes on unchanged.
        self._tags["left"] = ii.AddObserver("LeftButtonPressEvent", self._on_left, 10.0)
        self._tags["right"] = ii.AddObserver("RightButtonPressEvent", self._on_right, 10.0)
        p.add_timer_event(max_steps=10**9, duration=self.TICK_MS, callback=self.tick)

    def _actions(self) -> dict:
        return {"previous": self.previous, "next": self.next, "play": self.toggle_play,
                "reset": self.reset, "coverage": self.toggle_coverage,
                "pass-": lambda: self.step_pass(-1), "pass+": lambda: self.step_pass(1),
                "save": self.save, "help": self.toggle_help, "member": self.toggle_member,
                "mode": self.next_mode, "record": self.toggle_record,
                "sliders": self.toggle_sliders}

    def _on_left(self, obj, _event) -> None:
        if self.click(obj.GetEventPosition()) in ("button", "pixel"):
            obj.GetCommand(self._tags["left"]).SetAbortFlag(1)

    def _on_right(self, obj, _event) -> None:
        if self.pick_primitive(obj.GetEventPosition()) is not None:
            obj.GetCommand(self._tags["right"]).SetAbortFlag(1)

    # ---------------------------------------------------------------- drawing
    def redraw(self, keep_camera: bool = True) -> None:
        # Once a window is shown pyvista renders after every added actor; composing a stage
        # adds dozens, so rendering is held until the whole frame is built (as in lecture mode).
        held = self.p.suppress_rendering
        self.p.suppress_rendering = True
        try:
            compose(self.p, self.s, keep_camera=keep_camera)
            if self.controls is not None:
                self.controls.draw(self.s, self.members, self.s.disabled,
                                   recording=self.recorder is not None)
        finally:
            self.p.suppress_rendering = held
        self.p.render()

    # ---------------------------------------------------------------- mouse
    def _panel_index(self, name: str) -> int:
        return self.p.renderers.loc_to_index({"render": _RENDER, "variance": _VARIANCE}[name])

    def click(self, display_xy) -> str | None:
        """A left click at a display position: ``"button"`` (a button or member chip ran),
        ``"pixel"`` (the render or variance panel picked a pixel), ``"panel"`` (an image
        panel outside the image: nothing changes) or None (left to the camera style)."""
        if self.controls is not None and self.controls.click(display_xy):
            return "button"
        vps = [r.GetViewport() for r in self.p.renderers]
        i = controls.viewport_at(display_xy, self.p.window_size, vps)
        if i not in (self._panel_index("render"), self._panel_index("variance")):
            return None
        cam = self.s.scene.camera
        xy = controls.pick_pixel(self.p.renderers[i], display_xy, self.p.window_size,
                                 cam.width, cam.height)
        if xy is None:
            return "panel"
        self.set_pixel(xy)
        return "pixel"

    def pixel_display(self, panel: str, pixel_xy) -> tuple:
        """Display position of the centre of image pixel ``pixel_xy`` on ``panel``
        (``"render"`` or ``"variance"``): where a click picks it."""
        ren = self.p.renderers[self._panel_index(panel)]
        cam = ren.GetActiveCamera()
        w, h = self.s.scene.camera.width, self.s.scene.camera.height
        _, origin, spacing = controls.image_tiles(ren, w, h)[0]
        fx, fy, _ = cam.GetFocalPoint()
        return controls.panel_to_display(controls.pixel_centre(pixel_xy, h, origin, spacing),
                                         self.p.window_size, ren.GetViewport(), (fx, fy),
                                         cam.GetParallelScale())

    def pick_primitive(self, display_xy):
        """A right click in the 3D view: the primitive drawn under it becomes the coverage
        target (``(technique, batch, prim)``), or None when there is none."""
        from vtkmodules.vtkRenderingCore import vtkCellPicker

        vps = [r.GetViewport() for r in self.p.renderers]
        i = controls.viewport_at(display_xy, self.p.window_size, vps)
        if i != self.p.renderers.loc_to_index(_VIEW3D):
            return None
        ren = self.p.renderers[i]
        picker = vtkCellPicker()
        picker.SetTolerance(0.002)
        # Only primitives: the translucent medium box in front of them must not catch the ray.
        picker.PickFromListOn()
        for name, actor in ren.actors.items():
            if name.partition("-")[0] in primitives_view.PRIM_ACTORS:
                picker.AddPickList(actor)
        if not picker.Pick(display_xy[0], display_xy[1], 0.0, ren):
            return None
        target = primitives_view.picked_primitive(ren, picker.GetActor(), picker.GetCellId())
        if target is None:
            return None
        s = self.s
        s.coverage, s.coverage_pick = True, target
        update_coverage(s)
        s.message = f"coverage of {target[0]} primitive {target[2]}"
        self.redraw()
        return target

    # ---------------------------------------------------------------- actions
    def next(self) -> None:
        self.s.stepper.next()
        self.redraw()

    def previous(self) -> None:
        self.s.stepper.previous()
        self.redraw()

    def toggle_help(self) -> None:
        self.s.show_help = not self.s.show_help
        self.redraw()

    def toggle_play(self) -> None:
        s = self.s
        s.playing = not s.playing
        if s.prog is not None:
            (s.prog.resume if s.playing else s.prog.pause)()
            s.message = "playing (background worker)" if s.playing else "paused"
        else:
            s.message = "playing: one pass per tick" if s.playing else "paused"
        self.redraw()

    def restart(self, message: str) -> None:
        """Start the render over (scene, estimator or photons changed): the progressive
        worker gets the new job, or (no worker) the initial passes are rendered here; then the
        pixel is inspected anew."""
        s = self.s
        if s.prog is not None:
            s.prog.reset(scene=s.scene, estimators=panel_specs(s), settings=s.settings)
            s.acc = s.prog.runs[0].acc
            s.pass_index = 0
        else:
            s.acc = render(s.scene, s.estimator, s.settings, passes=s.initial_passes,
                           seed=s.seed).accumulator
            s.pass_index = min(s.pass_index, s.acc.n - 1)
        reinspect(s)
        s.message = message

    def reset(self) -> None:
        s = self.s
        s.stepper.reset()
        s.playing = False
        s.n_paths = primitives_view.DEFAULT_PATHS
        s.pass_index = 0
        self.restart("reset")
        self.redraw(keep_camera=False)

    def save(self) -> None:
        s = self.s
        out = f"psurf-{s.stage}-{s.pixel_xy[0]}x{s.pixel_xy[1]}-pass{s.acc.n}.png"
        self.p.screenshot(out)
        s.message = f"saved {os.path.abspath(out)}"
        self.redraw()

    def quit(self) -> None:
        if self.p.iren is not None:
            self.p.iren.interactor.TerminateApp()

    def set_pixel(self, pixel_xy) -> None:
        s = self.s
        s.pixel_xy = (int(pixel_xy[0]), int(pixel_xy[1]))
        reinspect(s)
        s.message = f"picked pixel ({s.pixel_xy[0]}, {s.pixel_xy[1]})"
        self.redraw()

    def move(self, dx: int, dy: int) -> None:
        cam = self.s.scene.camera
        x = min(max(self.s.pixel_xy[0] + dx, 0), cam.width - 1)
        y = min(max(self.s.pixel_xy[1] + dy, 0), cam.height - 1)
        self.set_pixel((x, y))
        self.s.message = ""

    def step_hit(self, d: int) -> None:
        s = self.s
        n = len(s.inspection.table)
        if n:
            s.hit = (s.hit + d) % n
        s.coverage_pick = None
        update_coverage(s)
        self.redraw()

    def step_pass(self, d: int) -> None:
        """Inspect the previous / next pass (of those the image panels include)."""
        s = self.s
        k = min(max(s.pass_index + d, 0), max(s.acc.n - 1, 0))
        if k != s.pass_index:
            s.pass_index = k
            reinspect(s)
        s.message = f"inspecting pass {s.pass_index} of {s.acc.n}"
        self.redraw()

    def toggle_coverage(self) -> None:
        s = self.s
        s.coverage = not s.coverage
        s.coverage_pick = None
        update_coverage(s)
        s.message = "coverage: the selected hit's primitive" if s.coverage else ""
        self.redraw()

    def paths(self, factor: float) -> None:
        self.s.n_paths = int(min(max(round(self.s.n_paths * factor), 1), 512))
        self.redraw()

    def toggle_member_index(self, i: int) -> None:
        names = self.members
        if len(names) > 1 and i < len(names):
            self.toggle_member(names[i])

    def toggle_member(self, name: str) -> None:
        """Switch an estimator member (MIS technique) on or off; one always stays on."""
        s = self.s
        disabled = set(s.disabled) ^ {name}
        try:
            est = controls.estimator_with(s.base_spec, s.scene, disabled)
        except ValueError as e:
            s.message = str(e)
            self.redraw()
            return
        s.estimator, s.disabled = est, frozenset(disabled)
        self.restart(f"estimator {est.spec}")
        self.redraw()

    # ---------------------------------------------------------------- medium and photons
    def nudge(self, key: str, direction: int) -> None:
        """A key step of a parameter (x2 photons, x1.25 sigmas, +-0.1 g); applied debounced."""
        p = self.params
        if key == "photons":
            p = replace(p, photons=int(p.photons * (2.0 if direction > 0 else 0.5)))
        elif key == "g":
            p = replace(p, g=round(p.g + 0.1 * direction, 2))
        else:
            v = getattr(p, key)
            v = max(v, 0.04) * 1.25 if direction > 0 else v / 1.25
            p = replace(p, **{key: round(v, 3)})
        self.set_params(p.clamped())

    def slide(self, key: str, value: float) -> None:
        """A slider moved (``photons`` comes as log2)."""
        v = 2.0 ** value if key == "photons" else value
        self.set_params(replace(self.params, **{key: v}).clamped(), from_slider=True)

    def set_params(self, params, *, from_slider: bool = False) -> None:
        self.params = params
        self.pending.push(params, self.clock())
        if self.controls is not None and not from_slider:
            for k in ("sigma_s", "sigma_a", "g"):
                self.controls.set_slider(k, getattr(params, k))
            self.controls.set_slider("photons", np.log2(params.photons))
        self.s.message = (f"sigma_s {params.sigma_s:.3g}  sigma_a {params.sigma_a:.3g}  "
                          f"g {params.g:.2f}  photons {params.photons}  (applying...)")
        _compose_panel(self.p, self.s)
        self.p.render()

    def apply_params(self, params) -> None:
        """Build the new scene and settings and restart rendering and inspection."""
        s = self.s
        s.scene = controls.scene_with(s.base_scene, params)
        s.settings = replace(s.settings, photons=int(params.photons))
        dropped = ""
        if s.reference is not None and s.scene.medium != s.base_scene.medium:
            # The reference is the image of the medium as loaded; relMSE against it would
            # measure the change of medium, not the estimator's error.
            s.reference = None
            dropped = "; reference dropped (another medium)"
        self.restart(f"sigma_s {params.sigma_s:.3g}  sigma_a {params.sigma_a:.3g}  "
                     f"g {params.g:.2f}  photons {params.photons}: restarted{dropped}")
        self.redraw()

    def flush(self) -> None:
        """Apply a pending parameter change now (tests; the timer waits for quiet)."""
        if self.pending.pending:
            self.apply_params(self.pending.due(float("inf")))

    def toggle_sliders(self) -> None:
        """Show / hide the medium and photon sliders (over the lower left of the 3D view)."""
        if self.controls is not None:
            self.controls.show_sliders(not self.controls.sliders_on)
            self.s.message = ("sliders: changes apply when the slider rests"
                              if self.controls.sliders_on else "")
        self.redraw()

    def next_mode(self) -> None:
        """Cycle the image-panel modes (render / techniques / bounces)."""
        from .image_panels import MODE_HELP, next_mode

        s = self.s
        if s.prog is None:
            s.message = "panel modes need the progressive renderer (the window)"
        else:
            s.mode = next_mode(s.mode)
            s.message = f"panels: {s.mode}: {MODE_HELP[s.mode]}"
        self.redraw()

    def toggle_record(self) -> None:
        """Start / stop recording the window (a GIF of every new progressive frame, written
        with ``ui.record_cli``'s atomic animation writer)."""
        s = self.s
        if self.recorder is None:
            from .record_cli import _Animation

            out = os.path.abspath(f"psurf-record-{time.strftime('%Y%m%d-%H%M%S')}.gif")
            self.recorder = _Animation(out, ".gif", fps=5.0)
            s.message = f"recording {out} (v stops)"
            self.redraw()
            self._record_frame()
        else:
            rec, self.recorder = self.recorder, None
            rec.commit()
            s.message = f"saved {rec.frames} frames to {rec.out}"
            self.redraw()

    def _record_frame(self) -> None:
        if self.recorder is not None:
            self.recorder.add(self.p.screenshot(None, return_img=True))

    def close(self) -> None:
        """Window closed: finish a recording and stop the progressive worker."""
        if self.recorder is not None:
            rec, self.recorder = self.recorder, None
            rec.commit()
            print(f"psurf: saved {rec.frames} frames to {rec.out}", flush=True)
        if self.s.prog is not None:
            self.s.prog.close()
        if self.controls is not None:
            self.controls.close()

    # ---------------------------------------------------------------- timer
    def tick(self, _step=None) -> None:
        if not self._gl_checked:  # the first tick: the window and its GL context exist now
            self._gl_checked = True
            if software_opengl(self.p):
                # Without a GPU (Mesa llvmpipe: EGL/OSMesa, Xvfb) multisampling makes every
                # full render ~3-5x dearer (benchmarks/ui_frames.py); the window stays
                # responsive without it. Screenshots keep it: they are figures, not frames.
                self.p.ren_win.SetMultiSamples(0)
                self.p.render()
        if self.script:
            self._script_step(self.script.pop(0))
        params = self.pending.due(self.clock())
        if params is not None:
            self.apply_params(params)
            return
        s = self.s
        if s.prog is not None:
            # Non-blocking: merges what the worker finished (at most POLL_BUDGET seconds).
            if s.prog.poll():
                s.acc = s.prog.runs[0].acc
                if s.prog.errors:
                    s.message = f"render error: {s.prog.errors[0].splitlines()[-1]}"
                self._frame()
            return
        if not s.playing:
            return
        s.acc.add(render_pass(s.scene, s.estimator, s.acc.n, s.seed, s.settings))
        s.message = f"playing: {s.acc.n} passes"
        self._frame()

    def _frame(self) -> None:
        """Redraw the image panels and the stage panel (the 3D view and its camera stay)."""
        held = self.p.suppress_rendering
        self.p.suppress_rendering = True
        try:
            _compose_images(self.p, self.s)
            _compose_panel(self.p, self.s)
        finally:
            self.p.suppress_rendering = held
        # Only the image panels and the stage text changed. The 3D view is the costliest part
        # of a frame (tens to hundreds of ms in software OpenGL, measured by
        # benchmarks/ui_frames.py), so it keeps last frame's pixels: VTK renders into its own
        # framebuffer, and a renderer that is not drawn leaves its viewport as it was. Any
        # other render (camera moves, stage changes, resizes) draws everything again.
        view3d = self.p.renderers[self.p.renderers.loc_to_index(_VIEW3D)]
        view3d.SetDraw(False)
        try:
            self.p.render()
        finally:
            view3d.SetDraw(True)
        self._record_frame()

    def _script_step(self, step: str) -> None:
        """One step of :data:`SCRIPT_ENV`, sent through the interactor like a user's."""
        ii = self.p.iren.interactor
        if step == "wait":
            return
        if step.startswith("passes>="):  # hold the script until the worker sent N passes
            if self.s.acc.n < int(step[8:]):
                self.script.insert(0, step)
            return
        if step.startswith("passes+"):  # ... until N more passes than now arrived
            self.script.insert(0, f"passes>={self.s.acc.n + int(step[7:])}")
            return
        if step == "quit":
            print("window: quit", flush=True)
            self.quit()
            return
        if step.startswith("shot:"):
            self.p.screenshot(step[5:])
            print(f"window: wrote {step[5:]}", flush=True)
            return
        if step.startswith("click:"):
            _, panel, xy = step.split(":")
            x, y = (int(v) for v in xy.split(","))
            dx, dy = (int(round(v)) for v in self.pixel_display(panel, (x, y)))
            ii.SetEventPosition(dx, dy)
            ii.MouseMoveEvent()
            ii.LeftButtonPressEvent()
            ii.LeftButtonReleaseEvent()
            print(f"window: clicked {panel} at display ({dx}, {dy}): pixel "
                  f"{self.s.pixel_xy}", flush=True)
            return
        ii.SetKeySym(step)
        ii.SetKeyCode(step if len(step) == 1 else "\0")
        ii.KeyPressEvent()
        ii.KeyReleaseEvent()
        print(f"window: key {step}: stage {self.s.stage}, pixel {self.s.pixel_xy}, "
              f"pass {self.s.pass_index}, passes {self.s.acc.n}  "
              f"[{time.perf_counter() - self._t0:.1f} s]", flush=True)
