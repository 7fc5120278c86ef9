"""Lecture mode: the tutorials' key states in the app's window, one key press each
(``python app.py lecture``; the command line is :mod:`ui.cli.lecture`).

The states are :data:`ui.views.lecture_states.STATES`. The window is the app's own
(:mod:`ui.views.window`: 3D view, render, variance and stage panel); lecture mode only
replaces the title and caption with the state's, puts the camera where the state says, and
binds

``->`` / ``<-``  next / previous state,   ``r`` back to the pinned camera,
``space``        play / pause progressive rendering (more passes of the same seed),
``s``            screenshot,   ``h`` help,   ``q`` quit.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from . import scene_view
from ._vtk import pv, rendered_image, vtkRenderWindow
from .lecture_states import ROOT, STATES, LectureState, check_index, load_state_scene
from .stepper import Stepper
from .window import ViewState, compose, make_plotter

DEFAULT_SIZE = (1600, 900)

HELP = """lecture keys
  -> / <-   next / previous state
  r         back to the pinned camera
  space     play / pause progressive rendering
  s         screenshot (PNG in the current folder)
  h         this help
  q         quit"""


# --------------------------------------------------------------------------- building
@dataclass
class LectureStepper(Stepper):
    """A :class:`ui.views.stepper.Stepper` that shows a lecture state's title and caption."""

    lecture_title: str = ""
    lecture_caption: str = ""

    @property
    def title(self) -> str:
        return self.lecture_title

    @property
    def caption(self) -> str:
        return self.lecture_caption


def _stepper(state: LectureState) -> LectureStepper:
    s = LectureStepper(lecture_title=state.title, lecture_caption=state.caption)
    s.go(state.stage)
    return s


def build_view(state: LectureState):
    """The :class:`ui.views.window.ViewState` of a lecture state (renders its passes, inspects
    its pixel in pass 0): what :func:`ui.views.window.build_state` does, plus the scatter
    window, the state's pinned variance range and its counter in the title's corner."""
    from psurf_core import RenderSettings, parse_estimator
    from psurf_core.inspect import inspect_pixel
    from psurf_core.render import render

    from .lecture_states import CAPTION_CHARS

    scene = load_state_scene(state)
    est = parse_estimator(state.estimator, scene)
    settings = RenderSettings(photons=int(state.photons), spp=1)
    inspection = inspect_pixel(scene, est, state.seed, 0, state.pixel, settings)
    res = render(scene, est, settings, passes=max(int(state.passes), 1), seed=state.seed)
    view = ViewState(scene_path=str(ROOT / state.scene), scene=scene, estimator=est,
                     seed=int(state.seed), settings=settings, pixel_xy=tuple(state.pixel),
                     acc=res.accumulator, inspection=inspection, stepper=_stepper(state),
                     initial_passes=max(int(state.passes), 1), specs=(state.estimator,),
                     var_clim=state.var_clim, caption_chars=CAPTION_CHARS,
                     camera_pin=state.camera)
    view.hit = int(state.hit)
    view.n_paths = int(state.n_paths)
    return view


def compose_state(plotter, state: LectureState, view, index: int, *,
                  keep_camera: bool = False) -> None:
    """Draw lecture state ``index`` (the window's panels, the state's camera (``view.camera_pin``)
    and counter; a state without a pinned camera has the stage's own view, e.g. Reconstruct's
    framing of the path)."""
    # Once a window has been shown, pyvista renders after every added actor; one picture is
    # dozens of actors, so render once at the end instead (the caller renders).
    suppressed = plotter.suppress_rendering
    plotter.suppress_rendering = True
    try:
        view.hint = f"{index + 1}/{len(STATES)}  (tutorial {state.tutorial})  <- ->"
        compose(plotter, view, keep_camera=keep_camera)
        plotter.subplot(0, 0)
        if view.show_help:
            x0, y0, x1, y1 = plotter.renderer.GetViewport()
            box = (0.9 * (x1 - x0) * plotter.window_size[0],
                   0.9 * (y1 - y0) * plotter.window_size[1])
            size = scene_view.fit_font(HELP, scene_view.pt(scene_view.FONT), box, mono=True)
            scene_view.add_text(plotter, HELP, 0.04, 0.95, scene_view.FONT, mono=True,
                                box=True, name="help", size_px=size)
    finally:
        plotter.suppress_rendering = suppressed


# --------------------------------------------------------------------------- public API
def lecture_screenshot(state_index: int, out: str, size=DEFAULT_SIZE) -> np.ndarray:
    """Render lecture state ``state_index`` (0-based) off-screen and write it to ``out``.

    Returns
    -------
    (H, W, 3) uint8
        The image written (the same picture for the same state, size and machine setup).
    """
    import imageio.v3 as iio

    state = STATES[check_index(state_index)]
    view = build_view(state)
    pv.OFF_SCREEN = True
    plotter = make_plotter(tuple(size), off_screen=True)
    try:
        compose_state(plotter, state, view, state_index)
        img = rendered_image(plotter)
    finally:
        plotter.close()
    folder = os.path.dirname(os.path.abspath(out))
    os.makedirs(folder, exist_ok=True)
    iio.imwrite(out, img)
    return img


@dataclass
class Lecture:
    """Key bindings of the lecture window (methods also work on an off-screen plotter)."""

    plotter: object
    index: int = 0
    view: object = None
    playing: bool = False
    cache: dict = field(default_factory=dict)

    @property
    def state(self) -> LectureState:
        return STATES[self.index]

    def show(self, index: int) -> None:
        """Go to state ``index``: its pinned picture (built once, then reused; a state whose
        rendering was continued with ``space`` is rebuilt, so a click always shows the same
        picture)."""
        self.index = check_index(index)
        view = self.cache.get(self.index)
        if view is None or view.acc.n != max(int(self.state.passes), 1):
            view = self.cache[self.index] = build_view(self.state)
        view.show_help, view.message = False, ""
        self.view = view
        self.playing = False
        self._draw(keep_camera=False)

    def _draw(self, keep_camera: bool = True) -> None:
        compose_state(self.plotter, self.state, self.view, self.index, keep_camera=keep_camera)
        self.plotter.render()

    def next(self) -> None:
        self.show(min(self.index + 1, len(STATES) - 1))

    def previous(self) -> None:
        self.show(max(self.index - 1, 0))

    def reset_camera(self) -> None:
        self._draw(keep_camera=False)

    def toggle_help(self) -> None:
        self.view.show_help = not self.view.show_help
        self._draw()

    def toggle_play(self) -> None:
        self.playing = not self.playing
        self.view.message = "playing: one pass per tick" if self.playing else "paused"
        self._draw()

    def save(self) -> str:
        out = os.path.abspath(f"psurf-lecture-{self.index + 1:02d}.png")
        self.plotter.screenshot(out)
        return out

    def tick(self, _step=None) -> None:
        """One more pass of the state's own seed (the picture grows, still reproducible)."""
        if not self.playing:
            return
        from psurf_core.render import render_pass

        v = self.view
        v.acc.add(render_pass(v.scene, v.estimator, v.acc.n, v.seed, v.settings))
        v.message = f"playing: {v.acc.n} passes"
        self._draw()

    def bind(self) -> None:
        p = self.plotter
        if p.iren is None:  # off-screen: nothing to bind
            return
        p.iren.interactor.RemoveObservers("CharEvent")  # VTK's own shortcuts (w, s, r, ...)
        for key in ("Left", "Right", "Up", "Down"):
            p.clear_events_for_key(key, raise_on_missing=False)
        keys = {"Right": self.next, "Left": self.previous, "Next": self.next,
                "Prior": self.previous, "r": self.reset_camera, "h": self.toggle_help,
                "space": self.toggle_play, "s": self.save}
        for k, fn in keys.items():
            p.add_key_event(k, fn)
        # tick() alone (it renders what it drew): pyvista's add_timer_event would render the
        # whole window four times a second, also while nothing plays.
        p.iren.interactor.AddObserver("TimerEvent", lambda _obj, _event: self.tick())
        p.iren.create_timer(250, repeating=True)


def _screen_size():
    """The display's size in pixels, or None when unknown."""
    try:
        w = vtkRenderWindow()
        w.SetOffScreenRendering(False)
        size = tuple(int(v) for v in w.GetScreenSize())
        w.Finalize()
        return size if min(size) >= 300 else None
    except Exception:
        return None


def run_lecture(start: int = 0, size=None, full_screen: bool = True) -> None:
    """Open the lecture window at state ``start`` (0-based); blocks until it is closed."""
    check_index(start)
    if size is None:
        size = (_screen_size() if full_screen else None) or DEFAULT_SIZE
    plotter = make_plotter(tuple(size))
    lecture = Lecture(plotter)
    lecture.show(start)
    lecture.bind()
    plotter.show(title="psurf lecture - photon surfaces", full_screen=full_screen)
