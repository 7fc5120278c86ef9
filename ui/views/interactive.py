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
from dataclasses import replace

import numpy as np

from psurf_core.render import render, render_pass

from . import controls, primitives_view
from ._vtk import pv, vtkCellPicker
from .footer import Controls
from .layout import next_focus
from .panel_modes import MODE_HELP, next_mode
from .script import SCRIPT_ENV, SIZE_ENV, play_step
from .stepper import DEFAULT_PHOTONS, DEFAULT_SIZE
from .window import (
    CELL_3D,
    CELL_RENDER,
    CELL_VARIANCE,
    HELP,
    ViewState,
    accept_results,
    attach_progressive,
    build_state,
    compose,
    compose_images,
    compose_panel,
    load_reference_image,
    make_plotter,
    panel_estimator,
    panel_specs,
    reinspect,
    software_opengl,
    update_coverage,
)

__all__ = ["App", "SCRIPT_ENV", "SIZE_ENV", "run"]


def run(scene_path: str, estimator: str = "planes", *, estimators=None, seed: int = 0,
        pixel_xy=None, photons: int = DEFAULT_PHOTONS, size=DEFAULT_SIZE,
        workers: int = 1, reference: str | None = None, resolution=None,
        inspect=None) -> None:
    """Open the interactive window on ``scene_path`` (blocks until it is closed).

    ``estimators`` (specs) are rendered side by side at equal time in a background process
    (default: ``[estimator]``); the stages inspect ``inspect`` (default: the first MIS set).
    ``reference`` (an ``app.py render`` .npz of the scene) adds relMSE under each render;
    ``resolution`` ``(W, H)`` overrides the scene's.

    With :data:`ui.views.script.SCRIPT_ENV` set, its steps are played through the window's
    own event path (synthetic key presses and mouse clicks), one per timer tick, and ``quit``
    closes it.
    """
    state = build_state(scene_path, estimator, seed, pixel_xy, photons, render_passes=False,
                        estimators=estimators, inspect=inspect, resolution=resolution,
                        inspector_workers=1)
    state.reference = load_reference_image(reference, state.scene)
    attach_progressive(state, workers=workers)
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
        plotter.show(title="psurf - photon surfaces, step by step")
    finally:
        app.close()


class App:
    """Key, mouse, widget and timer bindings of the interactive window.

    Every action is a method, so tests drive them on an off-screen plotter; :meth:`click`
    takes a display position as VTK reports it (pixels, ``y`` from the bottom).
    """

    #: Timer period (ms): progressive passes, inspections, debounced changes, script steps.
    TICK_MS = 200

    def __init__(self, plotter: pv.Plotter, state: ViewState, *, with_controls: bool = True):
        self.p = plotter
        self.s = state
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
        self._gl_checked = False
        self._size = tuple(plotter.window_size)
        self._busy_shown = 0.0
        self._t0 = time.perf_counter()
        self.scripted, self._said = False, ""

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
        p.add_timer_event(max_steps=10**9, duration=self.TICK_MS, callback=self.tick)

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

    def redraw(self, keep_camera: bool = True) -> None:
        # Once a window is shown pyvista renders after every added actor; composing a stage
        # adds dozens, so rendering is held until the whole frame is built (as in lecture mode).
        held = self.p.suppress_rendering
        self.p.suppress_rendering = True
        try:
            self._draw_controls()
            compose(self.p, self.s, keep_camera=keep_camera)
            if self.controls is not None and self.s.layout is not None:
                self.controls.place_sliders(self.s.layout.sliders)
                self.controls.show_help(HELP, self.s.show_help)
        finally:
            self.p.suppress_rendering = held
        self.p.render()

    # ---------------------------------------------------------------- mouse
    def _panel_index(self, name: str) -> int:
        cell = {"render": CELL_RENDER, "variance": CELL_VARIANCE}[name]
        return self.p.renderers.loc_to_index(cell)

    def click(self, display_xy) -> str | None:
        """A left click at a display position: ``"button"`` (a button or chip ran),
        ``"pixel"`` (a render or variance tile picked a pixel: in the render mode also its
        estimator for the stages), ``"panel"`` (an image panel outside the images: nothing
        changes) or None (left to the camera style)."""
        if self.controls is not None and self.controls.click(display_xy):
            return "button"
        vps = [r.GetViewport() for r in self.p.renderers]
        i = controls.viewport_at(display_xy, self.p.window_size, vps)
        if i not in (self._panel_index("render"), self._panel_index("variance")):
            return None
        cam = self.s.scene.camera
        hit = controls.pick_tile(self.p.renderers[i], display_xy, self.p.window_size,
                                 cam.width, cam.height)
        if hit is None:
            return "panel"
        name, xy = hit
        tile = controls.tile_index(name)
        s = self.s
        if (s.prog is not None and s.mode == "render" and tile is not None
                and tile != s.inspected and tile < len(s.specs)
                and not panel_estimator(s, tile).reference):
            s.pixel_xy = (int(xy[0]), int(xy[1]))
            self.inspect_estimator(tile)
            return "pixel"
        self.set_pixel(xy)
        return "pixel"

    def pixel_display(self, panel: str, pixel_xy, tile: int | None = None) -> tuple:
        """Display position of the centre of image pixel ``pixel_xy`` on ``panel``
        (``"render"`` or ``"variance"``), on the tile of estimator ``tile`` (default: the
        inspected one): where a click picks it."""
        ren = self.p.renderers[self._panel_index(panel)]
        cam = ren.GetActiveCamera()
        w, h = self.s.scene.camera.width, self.s.scene.camera.height
        tiles = controls.image_tiles(ren, w, h)
        k = self.s.inspected if tile is None else int(tile)
        by_index = {controls.tile_index(n): (o, sp) for n, o, sp in tiles}
        origin, spacing = by_index.get(k, (tiles[0][1], tiles[0][2]))
        fx, fy, _ = cam.GetFocalPoint()
        return controls.panel_to_display(controls.pixel_centre(pixel_xy, h, origin, spacing),
                                         self.p.window_size, ren.GetViewport(), (fx, fy),
                                         cam.GetParallelScale())

    def pick_primitive(self, display_xy):
        """A right click in the 3D view: the primitive drawn under it becomes the coverage
        target (``(technique, batch, prim)``), or None when there is none."""
        vps = [r.GetViewport() for r in self.p.renderers]
        i = controls.viewport_at(display_xy, self.p.window_size, vps)
        if i != self.p.renderers.loc_to_index(CELL_3D):
            return None
        ren = self.p.renderers[i]
        picker = vtkCellPicker()
        picker.SetTolerance(0.002)
        # Only primitives: the translucent medium box in front of them must not catch the ray.
        picker.PickFromListOn()
        for name, actor in ren.actors.items():
            if name.partition("-")[0] in primitives_view.PRIM_ACTORS and name.endswith(":mesh"):
                picker.AddPickList(actor)
        if not picker.Pick(display_xy[0], display_xy[1], 0.0, ren):
            return None
        target = primitives_view.picked_primitive(ren, picker.GetActor(), picker.GetCellId())
        if target is None:
            return None
        s = self.s
        s.coverage, s.coverage_pick = True, target
        update_coverage(s)
        accept_results(s)
        s.message = f"coverage of {target[0]} primitive {target[2]}"
        self.redraw()
        return target

    # ---------------------------------------------------------------- stages
    def next(self) -> None:
        self.s.stepper.next()
        self.redraw()

    def previous(self) -> None:
        self.s.stepper.previous()
        self.redraw()

    def toggle_help(self) -> None:
        self.s.show_help = not self.s.show_help
        self.redraw()

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

    # ---------------------------------------------------------------- estimators
    def inspect_estimator(self, i: int) -> None:
        """Let the stages inspect panel ``i``'s estimator (its members switched off stay so)."""
        s = self.s
        if not 0 <= i < len(s.specs):
            return
        est = panel_estimator(s, i)
        if est.reference:
            s.message = (f"{s.specs[i]} is the path tracer: it has no photons or hits to "
                         "inspect (it stays in the panels)")
            self.redraw()
            return
        s.inspected, s.estimator = i, est
        if s.prog is not None:
            s.acc = s.prog.runs[i].acc
        s.pass_index = min(s.pass_index, max(s.acc.n - 1, 0))
        self._reinspect()
        n = len(self.members)
        s.message = (f"inspecting {est.spec}" + (f" (keys 1..{min(n, 9)}: its members)"
                                                  if n > 1 else ""))
        self.redraw()

    def next_estimator(self, d: int = 1) -> None:
        """The next (``d = 1``) or previous photon estimator of the panels."""
        s = self.s
        photon = [i for i in range(len(s.specs)) if not panel_estimator(s, i).reference]
        if len(photon) < 2:
            s.message = (f"{s.specs[s.inspected]} is the only photon estimator "
                         "(--estimators A,B shows more)")
            self.redraw()
            return
        k = photon.index(s.inspected) if s.inspected in photon else 0
        self.inspect_estimator(photon[(k + d) % len(photon)])

    def _mis_elsewhere(self) -> str:
        s = self.s
        for i in range(len(s.specs)):
            est = panel_estimator(s, i)
            if i != s.inspected and not est.reference and len(est.techniques) > 1:
                return f" (e: inspect {s.specs[i]})"
        return ""

    def toggle_member_index(self, i: int) -> None:
        """Keys 1..9: switch member ``i`` of the inspected estimator, or say why not."""
        names = self.members
        s = self.s
        if len(names) < 2:
            s.message = (f"{s.base_spec} is a single technique: no member to switch"
                         + self._mis_elsewhere())
            self.redraw()
        elif i >= len(names):
            s.message = f"{s.base_spec} has {len(names)} members: keys 1..{len(names)}"
            self.redraw()
        else:
            self.toggle_member(names[i])

    def toggle_member(self, name: str) -> None:
        """Switch a member (MIS technique) of the inspected estimator on or off; one always
        stays on. Every panel restarts (an equal-time comparison starts together)."""
        s = self.s
        disabled = set(s.disabled) ^ {name}
        try:
            est = controls.estimator_with(s.base_spec, s.scene, disabled)
        except ValueError:
            s.message = f"{name} is the last member on: at least one must stay on"
            self.redraw()
            return
        s.estimator = est
        s.disabled_by = {**s.disabled_by, s.inspected: frozenset(disabled)}
        state = "off" if name in disabled else "on"
        self.restart(f"{name} {state}: {s.base_spec} renders as {est.spec}; panels restarted")
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
        self.redraw()

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
        self.redraw()

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
            s.message = f"panels: {s.mode}: {MODE_HELP[s.mode]}"
        self.redraw()

    def save(self) -> None:
        s = self.s
        out = f"psurf-{s.stage}-{s.pixel_xy[0]}x{s.pixel_xy[1]}-pass{s.acc.n}.png"
        self.p.screenshot(out)
        s.message = f"saved {os.path.abspath(out)}"
        self.redraw()

    def quit(self) -> None:
        if self.p.iren is not None:
            self.p.iren.interactor.TerminateApp()

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
        if not compose_panel(self.p, self.s):
            self.redraw()
            return
        self.p.render()

    def apply_params(self, params) -> None:
        """Build the new scene and settings and restart rendering and inspection."""
        s = self.s
        s.scene = controls.scene_with(s.base_scene, params)
        s.settings = replace(s.settings, photons=int(params.photons))
        s.estimator = panel_estimator(s, s.inspected)
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
        """Show / hide the medium and photon sliders (a block under the 3D view)."""
        if self.controls is not None:
            self.controls.show_sliders(not self.controls.sliders_on)
            self.s.message = ("sliders: changes apply when the slider rests"
                              if self.controls.sliders_on else "")
        self.redraw()

    # ---------------------------------------------------------------- recording
    def toggle_record(self) -> None:
        """Start / stop recording the window (a GIF of every new progressive frame, written
        with :class:`ui.cli.common.Animation`, the atomic writer ``record`` uses)."""
        s = self.s
        if self.recorder is None:
            from ui.cli.common import Animation

            out = os.path.abspath(f"psurf-record-{time.strftime('%Y%m%d-%H%M%S')}.gif")
            self.recorder = Animation(out, ".gif", fps=5.0)
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

    # ---------------------------------------------------------------- timer
    def tick(self, _step=None) -> None:
        """The timer: a resize, a script step, a rested parameter change, the inspector's
        answers and the render worker's passes (never waits for any of them)."""
        if not self._gl_checked:  # the first tick: the window and its GL context exist now
            self._gl_checked = True
            if software_opengl(self.p):
                # Without a GPU (Mesa llvmpipe: EGL/OSMesa, Xvfb) multisampling makes every
                # full render ~3-5x dearer (benchmarks/ui_frames.py); the window stays
                # responsive without it. Screenshots keep it: they are figures, not frames.
                self.p.ren_win.SetMultiSamples(0)
                self.p.render()
        if tuple(self.p.window_size) != self._size:  # resized: lay everything out again
            self._size = tuple(self.p.window_size)
            self.redraw()
        if self.script:
            play_step(self, self.script.pop(0))
            self.scripted = True
        if self.scripted and self.s.message != self._said:  # a script's log of the status line
            self._said = self.s.message
            print(f"window: message: {self._said}", flush=True)
        params = self.pending.due(self.clock())
        if params is not None:
            self.apply_params(params)
            return
        s = self.s
        if accept_results(s):  # a new inspection (or coverage): the stage is drawn anew
            self.redraw()
        elif s.inspector is not None and s.inspector.busy("pixel") is not None:
            now = time.monotonic()
            if now - self._busy_shown >= 1.0:  # "computing... (N s)" counts up
                self._busy_shown = now
                self._frame()
        if s.prog is not None:
            # Non-blocking: merges what the worker finished (at most POLL_BUDGET seconds).
            got = s.prog.poll()
            notes = s.prog.take_notices()
            if notes:
                s.message = notes[-1]
            if got or notes:
                s.acc = s.prog.runs[s.inspected].acc
                if s.prog.errors:
                    s.message = f"render error: {s.prog.errors[-1].splitlines()[-1]}"
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
            compose_images(self.p, self.s)
            fits = compose_panel(self.p, self.s)
        finally:
            self.p.suppress_rendering = held
        if not fits:  # the panel's text needs another layout: everything is laid out again
            self.redraw()
            self._record_frame()
            return
        # Only the image panels and the stage text changed. The 3D view is the costliest part
        # of a frame (tens to hundreds of ms in software OpenGL, measured by
        # benchmarks/ui_frames.py), so it keeps last frame's pixels: VTK renders into its own
        # framebuffer, and a renderer that is not drawn leaves its viewport as it was. Any
        # other render (camera moves, stage changes, resizes) draws everything again.
        view3d = self.p.renderers[self.p.renderers.loc_to_index(CELL_3D)]
        view3d.SetDraw(False)
        try:
            self.p.render()
        finally:
            view3d.SetDraw(True)
        self._record_frame()
