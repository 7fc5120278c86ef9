"""The interactive window's bindings: :class:`App` (keys, mouse, chips and buttons, sliders,
timer) and :func:`run`, which opens the window.

What the window shows (layout, composition of each stage, the off-screen
:func:`ui.views.window.screenshot`) lives in :mod:`ui.views.window`; this module owns only what
a person (or a test script, :mod:`ui.views.script`) does to it. Keys are listed in
:data:`ui.views.window.HELP`.

Nothing here waits for a computation: the image panels render in a background process
(:mod:`ui.cli.progressive`) and the stages' inspections in another (:mod:`ui.cli.inspector`);
the timer (:meth:`App.tick`) takes what arrived. If the render process dies the window says
so and restarts it, keeping the passes already merged.
"""

from __future__ import annotations

import os
import time

from psurf_core.render import render

from . import controls, primitives_view
from ._vtk import pv
from .footer import Controls
from .interactive_draw import Drawer
from .interactive_params import EstimatorControls, MediumControls, Pointer, Recorder
from .interactive_timer import Ticker
from .layout import next_focus
from .panel_modes import MODE_HELP, next_mode
from .script import SCRIPT_ENV, SIZE_ENV, launch_time
from .stepper import DEFAULT_PHOTONS, DEFAULT_SIZE
from .window import (
    HELP,
    ViewState,
    accept_results,
    attach_progressive,
    build_state,
    compose,
    load_reference_image,
    make_plotter,
    panel_specs,
    reinspect,
    update_coverage,
)

__all__ = ["App", "SCRIPT_ENV", "SIZE_ENV", "run"]


def run(scene_path: str, estimator: str = "planes", *, estimators=None, seed: int = 0,
        pixel_xy=None, photons: int = DEFAULT_PHOTONS, size=DEFAULT_SIZE,
        workers: int = 1, reference: str | None = None, resolution=None,
        inspect=None, scene=None, prog=None, inspector=None) -> None:
    """Open the interactive window on ``scene_path`` (blocks until it is closed).

    ``estimators`` (specs) are rendered side by side at equal time in a background process
    (default: ``[estimator]``); the stages inspect ``inspect`` (default: the first MIS set).
    ``reference`` (an ``app.py render`` .npz of the scene) adds relMSE under each render;
    ``resolution`` ``(W, H)`` overrides the scene's. ``scene`` (loaded, e.g. with another
    scatter range), ``prog`` and ``inspector`` (background processes started before this
    module was imported, :func:`ui.cli.demo.start_background`) replace loading and starting
    them here.

    With :data:`ui.views.script.SCRIPT_ENV` set, its steps are played through the window's
    own event path (synthetic key presses and mouse clicks), one per timer tick, and ``quit``
    closes it.
    """
    try:
        state = build_state(scene_path, estimator, seed, pixel_xy, photons,
                            render_passes=False, estimators=estimators, inspect=inspect,
                            resolution=resolution, inspector_workers=1, scene=scene,
                            inspector=inspector)
        state.reference = load_reference_image(reference, state.scene)
        # Breakdowns (per technique, per K) double a pass's cost: only while a mode shows
        # them (``next_mode``).
        attach_progressive(state, workers=workers, prog=prog, breakdown=False)
    except BaseException:  # bad input: the processes started for the window stop too
        for started in (prog, inspector):
            if started is not None:
                started.close()
        raise
    if os.environ.get(SIZE_ENV):
        size = tuple(int(v) for v in os.environ[SIZE_ENV].split(","))
    plotter = make_plotter(size)
    app = App(plotter, state)
    try:
        app.bind()
        app.redraw(keep_camera=False)
        script = os.environ.get(SCRIPT_ENV)
        if script:
            app.script = [step.strip() for step in script.split(";") if step.strip()]
        app.open_window()
        plotter.show(title="psurf - photon surfaces, step by step")
    finally:
        app.close()


class App(Ticker, Drawer, Pointer, EstimatorControls, MediumControls, Recorder):
    """Key, mouse, widget and timer bindings of the interactive window (what a click picks, the
    inspected estimator and its members, the medium / photon controls and the recorder are
    :mod:`ui.views.interactive_params`'s).

    Every action is a method, so tests drive them on an off-screen plotter; :meth:`click`
    takes a display position as VTK reports it (pixels, ``y`` from the bottom).
    """

    #: Timer period (ms): progressive passes, inspections, debounced changes, script steps.
    TICK_MS = 200

    def __init__(self, plotter: pv.Plotter, state: ViewState, *, with_controls: bool = True,
                 defer: bool | None = None):
        self.p = plotter
        self.s = state
        #: Build the 3D view over the timer's ticks (:mod:`ui.views.interactive_timer`);
        #: default: in a window on the screen, not off-screen (tests, screenshots).
        self.defer = not plotter.off_screen if defer is None else bool(defer)
        self._job = None  # the 3D view's remaining steps (ui.views.view3d)
        self._frame_due = False  # passes merged, the panels not drawn yet (3D work first)
        self._parts_due = None  # parts composed but not rendered yet (no room in their tick)
        if not state.specs:
            state.specs = (state.estimator.spec,)
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
        self._gl_checked = False  # software OpenGL looked for (multisampling off)
        self._shown = False  # the window has rendered its first frame
        self._recon_warm = None  # the thread loading Reconstruct's kernel (Ticker)
        self._size = tuple(plotter.window_size)
        self._busy_shown = 0.0
        self._t0 = time.perf_counter()
        self.scripted, self._said = False, ""
        self._launched = launch_time()  # None: no time stamps printed
        self._render_due = False  # a tick composed a new stage; the next one renders it
        self._milestones: set = set()

    @property
    def members(self) -> tuple:
        """The inspected estimator's members (as opened: switched-off ones included)."""
        from psurf_core.estimators import parse_estimator

        return controls.members(parse_estimator(self.s.base_spec, self.s.scene))

    # ---------------------------------------------------------------- binding
    def bind(self) -> None:
        p = self.p
        if self.with_controls:
            self.controls = Controls(p, self._actions(), on_slider=self.slide)
            self._draw_controls()
        if p.iren is None:  # no interactor: nothing to bind (methods can still be called)
            return
        self._watch_first_frame()
        # VTK's own character shortcuts (w, s, r, p, e, ...) would fight ours.
        p.iren.interactor.RemoveObservers("CharEvent")
        for key in ("Up", "Down", "plus", "minus", "b", "v", "C", "e", "l", "z"):
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
            "e": lambda: self.next_estimator(1), "E": lambda: self.next_estimator(-1),
            "l": self.toggle_scale, "z": self.next_focus,
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
        # The timer calls tick() and nothing else: pyvista's add_timer_event renders the whole
        # window after every callback (the 3D view too: tens to hundreds of milliseconds in
        # software OpenGL, five times a second, when the tick itself drew nothing or only the
        # image panels). A tick renders what it changed itself.
        self._tags["timer"] = ii.AddObserver("TimerEvent", self._on_timer)
        p.iren.create_timer(self.TICK_MS, repeating=True)

    def _actions(self) -> dict:
        return {"previous": self.previous, "next": self.next, "play": self.toggle_play,
                "reset": self.reset, "coverage": self.toggle_coverage,
                "pass-": lambda: self.step_pass(-1), "pass+": lambda: self.step_pass(1),
                "save": self.save, "help": self.toggle_help, "member": self.toggle_member,
                "mode": self.next_mode, "record": self.toggle_record,
                "sliders": self.toggle_sliders, "scale": self.toggle_scale,
                "focus": self.next_focus, "inspect": self._inspect_action}

    def _inspect_action(self, index: str | None = None) -> None:
        if index is None:
            self.next_estimator(1)
        else:
            self.inspect_estimator(int(index))

    def _on_left(self, obj, _event) -> None:
        if self.click(obj.GetEventPosition()) in ("button", "pixel"):
            obj.GetCommand(self._tags["left"]).SetAbortFlag(1)

    def _on_right(self, obj, _event) -> None:
        if self.pick_primitive(obj.GetEventPosition()) is not None:
            obj.GetCommand(self._tags["right"]).SetAbortFlag(1)

    # ---------------------------------------------------------------- drawing
    def _draw_controls(self) -> None:
        if self.controls is None:
            return
        s = self.s
        s.footer_rows = self.controls.draw(s, self.members, s.disabled,
                                           recording=self.recorder is not None)
        s.sliders_on = self.controls.sliders_on

    def redraw(self, keep_camera: bool = True, *, view3d: bool = True, images: bool = True,
               everything: bool = False) -> None:
        """Compose every part of the window for the state and render it.

        With :attr:`defer` (the window) the 3D view is built over the next timer ticks
        (:meth:`~ui.views.interactive_timer.Ticker.tick`): this composes and renders the other
        parts and the 3D view's first step (its scene, "drawing...") now. ``view3d=False``:
        nothing the 3D view shows changed; it is neither composed nor drawn again (unless the
        layout moved it); ``images=False``: nor are the image panels (a stage step);
        ``everything``: every part is drawn again all the same (the help box, which lies
        over all of them, came or went).
        """
        if self.defer:
            self.redraw_deferred(keep_camera, view3d=view3d, images=images,
                                 everything=everything)
            return
        self.compose_all(keep_camera)
        self.p.render()
        self._render_due = False
        self._stamp()

    def compose_all(self, keep_camera: bool = True) -> None:
        """Compose every part of the window for the state, without rendering it."""
        with self.held():
            self._job = None
            self._draw_controls()
            compose(self.p, self.s, keep_camera=keep_camera)
            self._place_widgets()

    def _place_widgets(self) -> None:
        if self.controls is not None and self.s.layout is not None:
            self.controls.place_sliders(self.s.layout.sliders)
            self.controls.show_help(HELP, self.s.show_help)

    # ---------------------------------------------------------------- stages
    def next(self) -> None:
        self.s.stepper.next()
        self.redraw(images=False)

    def previous(self) -> None:
        self.s.stepper.previous()
        self.redraw(images=False)

    def toggle_help(self) -> None:
        self.s.show_help = not self.s.show_help
        self.redraw(view3d=False, everything=True)

    def _reinspect(self) -> None:
        reinspect(self.s)
        accept_results(self.s)  # an inspector in this process has answered already

    def set_pixel(self, pixel_xy) -> None:
        s = self.s
        s.pixel_xy = (int(pixel_xy[0]), int(pixel_xy[1]))
        self._reinspect()
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
        n = len(s.inspection.table) if s.inspection is not None else 0
        if n:
            s.hit = (s.hit + d) % n
        s.coverage_pick = None
        update_coverage(s)
        accept_results(s)
        self.redraw()

    def step_pass(self, d: int) -> None:
        """Inspect the previous / next pass (of those the image panels include)."""
        s = self.s
        k = min(max(s.pass_index + d, 0), max(s.acc.n - 1, 0))
        if k != s.pass_index:
            s.pass_index = k
            self._reinspect()
        s.message = f"inspecting pass {s.pass_index} of {s.acc.n}"
        self.redraw()

    def toggle_coverage(self) -> None:
        s = self.s
        s.coverage = not s.coverage
        s.coverage_pick = None
        update_coverage(s)
        accept_results(s)
        s.message = "coverage: the selected hit's primitive" if s.coverage else ""
        self.redraw()

    def paths(self, factor: float) -> None:
        self.s.n_paths = int(min(max(round(self.s.n_paths * factor), 1), 512))
        self.redraw()

    # ---------------------------------------------------------------- rendering
    def toggle_play(self) -> None:
        s = self.s
        s.playing = not s.playing
        if s.prog is not None:
            (s.prog.resume if s.playing else s.prog.pause)()
            s.message = "playing (background worker)" if s.playing else "paused"
        else:
            s.message = "playing: one pass per tick" if s.playing else "paused"
        self.redraw(view3d=False)

    def restart(self, message: str) -> None:
        """Start the render over (scene, estimator or photons changed): the progressive
        worker gets the new job, or (no worker) the initial passes are rendered here; then the
        pixel is inspected anew."""
        s = self.s
        if s.prog is not None:
            s.prog.reset(scene=s.scene, estimators=panel_specs(s), settings=s.settings)
            s.acc = s.prog.runs[s.inspected].acc
            s.pass_index = 0
        else:
            s.acc = render(s.scene, s.estimator, s.settings, passes=s.initial_passes,
                           seed=s.seed).accumulator
            s.pass_index = min(s.pass_index, s.acc.n - 1)
        s.var_scale.reset()
        self._reinspect()
        s.message = message

    def reset(self) -> None:
        s = self.s
        s.stepper.reset()
        s.playing = False
        s.n_paths = primitives_view.DEFAULT_PATHS
        s.pass_index = 0
        self.restart("reset")
        self.redraw(keep_camera=False)

    def toggle_scale(self) -> None:
        """Fix the variance maps' shared colour scale at its current range, or let it follow
        the maps (auto)."""
        s = self.s
        locked = s.var_scale.toggle()
        s.message = ("variance scale fixed: the maps darken as they converge" if locked
                     else "variance scale auto: refitted to every frame")
        self.redraw(view3d=False)

    def next_focus(self) -> None:
        """Cycle the layouts (split / images large / 3D view large)."""
        s = self.s
        s.focus = next_focus(s.focus)
        s.message = f"layout: {s.focus}"
        self.redraw()

    def next_mode(self) -> None:
        """Cycle the image-panel modes (render / techniques / bounces)."""
        s = self.s
        if s.prog is None:
            s.message = "panel modes need the progressive renderer (the window)"
        else:
            s.mode = next_mode(s.mode)
            s.prog.set_breakdown(s.mode != "render")
            s.message = f"panels: {s.mode}: {MODE_HELP[s.mode]}"
        self.redraw(view3d=False)

    def save(self) -> None:
        s = self.s
        out = f"psurf-{s.stage}-{s.pixel_xy[0]}x{s.pixel_xy[1]}-pass{s.acc.n}.png"
        self.settle()  # the 3D view complete
        self.p.screenshot(out)
        s.message = f"saved {os.path.abspath(out)}"
        self.redraw(view3d=False)

    def quit(self) -> None:
        if self.p.iren is not None:
            self.p.iren.interactor.TerminateApp()

    def close(self) -> None:
        """Window closed: finish a recording, stop the background processes."""
        if self.recorder is not None:
            rec, self.recorder = self.recorder, None
            rec.commit()
            print(f"psurf: saved {rec.frames} frames to {rec.out}", flush=True)
        if self.s.prog is not None:
            self.s.prog.close()
        if self.s.inspector is not None:
            self.s.inspector.close()
        if self.controls is not None:
            self.controls.close()
