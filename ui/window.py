"""The interactive window (and its off-screen twin, :func:`screenshot`).

Layout (one pyvista Plotter, 2 x 3 grid)::

    +---------------------------+-------------+-------------+
    |                           |   render    |  variance   |
    |      3D view: scene,      +-------------+-------------+
    |      stage geometry,      |                           |
    |      title and caption    |   stage panel (numbers)   |
    +---------------------------+---------------------------+

Keys: ``n``/``p`` next/previous stage, ``space`` play/pause progressive rendering (one pass per
timer tick), ``r`` reset, ``s`` screenshot, ``h`` help; arrows move the picked pixel,
``[``/``]`` choose the hit shown by Reconstruct, ``+``/``-`` change the number of subpaths.

:func:`screenshot` composes exactly what the window shows at a stage, off-screen and
deterministically (same seed, same passes, same picture).
"""

from __future__ import annotations

import os
import textwrap
from dataclasses import dataclass, field

import numpy as np
import pyvista as pv

from psurf_core.accumulate import Welford
from psurf_core.estimators import parse_estimator
from psurf_core.inspect import inspect_pixel, reconstruct_hit
from psurf_core.render import RenderSettings, render, render_pass
from psurf_core.scene_io import load_scene

from . import hits_view, image_panels, primitives_view, scene_view
from .scene_view import FONT, FONT_SMALL, FONT_TITLE, add_text
from .stepper import STAGES, Stepper, stage_index

#: Photons per pass in the window (a 64 x 48 scene stays interactive).
DEFAULT_PHOTONS = 2000
#: Passes rendered before the window opens.
DEFAULT_PASSES = 4
DEFAULT_SIZE = (1600, 900)

HELP = """keys
  n / p     next / previous stage
  space     play / pause progressive rendering
  r         reset (stage, passes, camera)
  s         screenshot (PNG in the current folder)
  h         this help
  arrows    move the picked pixel
  [ / ]     previous / next hit (Reconstruct)
  + / -     more / fewer photon subpaths
  q         quit"""

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

    @property
    def stage(self) -> str:
        return self.stepper.stage


def build_state(scene_path: str, estimator: str = "planes", seed: int = 0, pixel_xy=None,
                photons: int = DEFAULT_PHOTONS, passes: int = DEFAULT_PASSES, stage="trace",
                hit: int | None = None) -> ViewState:
    """Load the scene, render ``passes`` passes and inspect the pixel in pass 0.

    Raises ``SceneError`` / ``UnknownTechnique`` / ``ValueError`` for bad input.
    """
    scene = load_scene(scene_path)
    est = parse_estimator(estimator, scene)
    if est.reference:
        raise ValueError("the window shows photon estimators; 'reference' has no stages")
    cam = scene.camera
    if pixel_xy is None:
        pixel_xy = (cam.width // 2, cam.height // 2)
    settings = RenderSettings(photons=int(photons), spp=1)
    inspection = inspect_pixel(scene, est, seed, 0, pixel_xy, settings)
    res = render(scene, est, settings, passes=max(int(passes), 1), seed=seed)
    st = ViewState(scene_path=str(scene_path), scene=scene, estimator=est, seed=int(seed),
                   settings=settings, pixel_xy=tuple(int(v) for v in pixel_xy),
                   acc=res.accumulator, inspection=inspection,
                   initial_passes=max(int(passes), 1))
    st.stepper.go(stage)
    if hit is not None:
        n = len(inspection.table)
        if n == 0 and int(hit) > 0:
            raise ValueError(f"--hit {hit}: the pixel has no hit in pass 0")
        if n and not 0 <= int(hit) < n:
            raise ValueError(f"--hit {hit}: the pixel has {n} hits in pass 0 "
                             f"(valid: 0..{n - 1})")
        st.hit = int(hit)
    return st


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
    return head + "\n" + body


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
            hits_view.add_hit_primitives(plotter, ins, [recon["row"]], opacity=0.6)
            hits_view.add_reconstruction(plotter, ins, recon)
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
    if state.message:
        add_text(plotter, state.message, 0.02, 0.08, FONT_SMALL, name="message",
                 colour=scene_view.OKABE_ITO["vermillion"])


def _clear_bars(plotter: pv.Plotter) -> None:
    for title in list(plotter.scalar_bars.keys()):
        plotter.remove_scalar_bar(title)


def _compose_images(plotter: pv.Plotter, state: ViewState) -> None:
    plotter.subplot(*_RENDER)
    plotter.renderer.clear_actors()
    plotter.renderer.set_background("white")
    image_panels.add_render_panel(plotter, state.acc.mean, state.pixel_xy,
                                  f"render, {state.acc.n} passes")
    plotter.subplot(*_VARIANCE)
    plotter.renderer.clear_actors()
    if image_panels.VARIANCE_BAR in plotter.scalar_bars:
        plotter.remove_scalar_bar(image_panels.VARIANCE_BAR)
    plotter.renderer.set_background("white")
    var = state.acc.variance if state.acc.n > 1 else np.zeros_like(state.acc.mean)
    title = ("variance per pass (log scale)" if state.acc.n > 1
             else "variance: needs 2+ passes")
    image_panels.add_variance_panel(plotter, var, state.pixel_xy, title)


def make_plotter(size=DEFAULT_SIZE, off_screen: bool = False) -> pv.Plotter:
    scene_view.plain_text()
    p = pv.Plotter(window_size=list(size), off_screen=off_screen, border=False, **_GRID)
    p.set_background("white", all_renderers=True)
    return p


# --------------------------------------------------------------------------- public API
def screenshot(scene_path: str, stage: str, pixel_xy, estimator: str = "planes", seed: int = 0,
               out: str = "shot.png", size=DEFAULT_SIZE, passes: int = DEFAULT_PASSES,
               hit: int | None = None, photons: int = DEFAULT_PHOTONS,
               n_paths: int = primitives_view.DEFAULT_PATHS) -> np.ndarray:
    """Render what the window shows at ``stage`` off-screen and write it to ``out`` (PNG).

    Parameters
    ----------
    stage : {'trace', 'create', 'intersect', 'evaluate', 'reconstruct'}
    pixel_xy : (int, int)
        Picked pixel ``(X, Y)``: column from the left, row from the top.
    passes : int
        Passes of the progressive render shown in the image panels (the inspected pass is 0).
    hit : int, optional
        Reconstruct: which hit, as numbered ``#i`` in the evaluate table (largest
        contribution first); default 0.

    Returns
    -------
    (H, W, 3) uint8
        The image written.
    """
    stage_index(stage)
    state = build_state(scene_path, estimator, seed, pixel_xy, photons, passes, stage, hit)
    state.n_paths = int(n_paths)
    plotter = make_plotter(size, off_screen=True)
    try:
        compose(plotter, state)
        img = plotter.screenshot(None, return_img=True)
    finally:
        plotter.close()
    import imageio.v3 as iio

    d = os.path.dirname(os.path.abspath(out))
    os.makedirs(d, exist_ok=True)
    iio.imwrite(out, img)
    return img


def run(scene_path: str, estimator: str = "planes", *, seed: int = 0, pixel_xy=None,
        photons: int = DEFAULT_PHOTONS, passes: int = DEFAULT_PASSES,
        size=DEFAULT_SIZE) -> None:
    """Open the interactive window on ``scene_path`` (blocks until it is closed)."""
    state = build_state(scene_path, estimator, seed, pixel_xy, photons, passes)
    plotter = make_plotter(size)
    compose(plotter, state)
    App(plotter, state).bind()
    plotter.show(title="psurf - photon surfaces, step by step")


class App:
    """Key and timer bindings of the interactive window."""

    def __init__(self, plotter: pv.Plotter, state: ViewState):
        self.p = plotter
        self.s = state
        self.blockers = None

    def bind(self) -> None:
        p = self.p
        if p.iren is None:  # off-screen: nothing to bind (methods can still be called)
            return
        # VTK's own character shortcuts (w, s, r, p, e, ...) would fight ours.
        p.iren.interactor.RemoveObservers("CharEvent")
        for key in ("Up", "Down", "plus", "minus"):
            p.clear_events_for_key(key, raise_on_missing=False)
        keys = {
            "n": self.next, "p": self.previous, "space": self.toggle_play, "r": self.reset,
            "s": self.save, "h": self.toggle_help, "Left": lambda: self.move(-1, 0),
            "Right": lambda: self.move(1, 0), "Up": lambda: self.move(0, -1),
            "Down": lambda: self.move(0, 1), "bracketleft": lambda: self.step_hit(-1),
            "bracketright": lambda: self.step_hit(1), "plus": lambda: self.paths(2.0),
            "equal": lambda: self.paths(2.0), "minus": lambda: self.paths(0.5),
        }
        for k, fn in keys.items():
            p.add_key_event(k, fn)
        p.add_timer_event(max_steps=10**9, duration=200, callback=self.tick)

    def redraw(self, keep_camera: bool = True) -> None:
        # Once a window is shown pyvista renders after every added actor; composing a stage
        # adds dozens, so rendering is held until the whole frame is built (as in lecture mode).
        held = self.p.suppress_rendering
        self.p.suppress_rendering = True
        try:
            compose(self.p, self.s, keep_camera=keep_camera)
        finally:
            self.p.suppress_rendering = held
        self.p.render()

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
        self.s.playing = not self.s.playing
        self.s.message = "playing: one pass per tick" if self.s.playing else "paused"
        self.redraw()

    def reset(self) -> None:
        s = self.s
        s.stepper.reset()
        s.playing = False
        s.hit = 0
        s.n_paths = primitives_view.DEFAULT_PATHS
        s.acc = render(s.scene, s.estimator, s.settings, passes=s.initial_passes,
                       seed=s.seed).accumulator
        s.message = "reset"
        self.redraw(keep_camera=False)

    def save(self) -> None:
        s = self.s
        out = f"psurf-{s.stage}-{s.pixel_xy[0]}x{s.pixel_xy[1]}-pass{s.acc.n}.png"
        self.p.screenshot(out)
        s.message = f"saved {os.path.abspath(out)}"
        self.redraw()

    def move(self, dx: int, dy: int) -> None:
        s = self.s
        cam = s.scene.camera
        x = min(max(s.pixel_xy[0] + dx, 0), cam.width - 1)
        y = min(max(s.pixel_xy[1] + dy, 0), cam.height - 1)
        s.pixel_xy = (x, y)
        s.inspection = inspect_pixel(s.scene, s.estimator, s.seed, 0, s.pixel_xy, s.settings)
        s.hit = 0
        s.message = ""
        self.redraw()

    def step_hit(self, d: int) -> None:
        n = len(self.s.inspection.table)
        if n:
            self.s.hit = (self.s.hit + d) % n
        self.redraw()

    def paths(self, factor: float) -> None:
        self.s.n_paths = int(min(max(round(self.s.n_paths * factor), 1), 512))
        self.redraw()

    def tick(self, _step=None) -> None:
        s = self.s
        if not s.playing:
            return
        s.acc.add(render_pass(s.scene, s.estimator, s.acc.n, s.seed, s.settings))
        s.message = f"playing: {s.acc.n} passes"
        _compose_images(self.p, s)  # the 3D view (and its camera) stays as it is
        _compose_panel(self.p, s)
        self.p.render()
