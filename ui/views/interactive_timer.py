"""What one tick of the window's timer does (:class:`Ticker`, a mixin of
:class:`ui.views.interactive.App`): take what the background processes sent, play a script
step, apply a rested parameter change, and draw only what changed, once.

Every 200 ms (``App.TICK_MS``) the timer calls :meth:`Ticker.tick` and nothing else (not
pyvista's ``add_timer_event``, which rendered the whole window after every callback). Merged
passes redraw the image panels and the stage text, rendering only their renderers
(:meth:`Ticker._frame`); a tick with nothing new draws nothing.

In the window (``App.defer``) no tick and no key does more than one costly thing (each about
a frame, ~30-70 ms of the UI thread in software OpenGL at 1600x900): a key or a new
inspection composes and renders what it changed (title, stage text, image panels, the 3D
view's first step: its scene and "drawing..."); the following ticks add the 3D view's parts
(:func:`ui.views.view3d.compose_3d_steps`, while a tick is younger than
:data:`STEP_BUDGET`), then render it alone; passes merged meanwhile wait for the next free
tick. Off-screen (tests) a new inspection is composed in one tick and rendered in the next.
``benchmarks/ui_frames.py`` times it.

The mixin uses the app's plotter ``p``, state ``s``, ``controls``, ``script``, ``pending``,
``clock``, ``defer``, ``apply_params``, ``redraw``, ``_record_frame`` and the drawing of
:class:`ui.views.interactive_draw.Drawer` (``held``, ``_render_parts``, ``_turned``).
"""

from __future__ import annotations

import gc
import threading
import time

from psurf_core.inspect import reconstruct_hit
from psurf_core.render import render_pass

from . import baked_light
from .compose import compose_images, compose_panel, software_opengl
from .script import play_step
from .window import accept_results

#: A tick runs one step of the 3D view, and another while it began less than this ago (s): a
#: step is at most a few tens of milliseconds (one technique's primitives meshed and clipped).
STEP_BUDGET = 0.045
#: The 3D view, once complete, is rendered in the same tick only if the tick has spent less
#: than this (s); otherwise in the next one (a render of the Create stage's 3D view is
#: ~40-60 ms of software OpenGL at 1600x900, benchmarks/ui_frames.py).
RENDER_ROOM = 0.03
#: Merged passes are composed into the panels only in a tick that has spent less than this
#: (s; taking a pass in, unpickling a breakdown, took up to ~20 ms), and rendered in the same
#: tick only if it has spent less than ``PANELS_ROOM`` (a render of the panels: ~35-40 ms).
FRAME_ROOM, PANELS_ROOM = 0.03, 0.05

__all__ = ["Ticker"]


class Ticker:
    """The window's timer: :meth:`tick` (and the start-up times it prints when asked)."""

    def _on_timer(self, _obj, _event) -> None:
        self.tick()

    def _stamp(self) -> None:
        """With :data:`ui.views.script.TIMES_ENV` set, print when the window first showed
        itself, a render, every estimator's render and the stage's inspection (seconds since
        the launch; ``benchmarks/ui_frames.py --first-picture`` reads them)."""
        if self._launched is None:
            return
        s = self.s
        passes = s.prog.passes if s.prog is not None else [s.acc.n]
        now = {"window": self._shown or self.p.iren is None,
               "first-pass": any(passes), "all-passes": all(passes),
               "inspection": s.inspection is not None}
        if not now["window"]:
            return
        for name, reached in now.items():
            if reached and name not in self._milestones:
                self._milestones.add(name)
                # and the CPU seconds this process has used (a busy machine stretches the
                # wall seconds, not these)
                print(f"window: time {name} {time.time() - self._launched:.3f} s "
                      f"cpu {time.process_time():.2f} s", flush=True)

    # ---------------------------------------------------------------- start-up
    def open_window(self) -> None:
        """Create the window's OpenGL context before its first render (``run`` calls it just
        before ``plotter.show``), so that its first render is already without multisampling
        in software OpenGL (:meth:`_check_gl`): that render, every shader compiled for the
        first time, is the dearest of all (``plotter.show`` of the showcase's window at
        1600x900 under Xvfb: 0.38-0.40 s of CPU with VTK's 4 samples, 0.21-0.22 s without,
        load 5)."""
        rw = self.p.ren_win
        # X windows only (Linux, Xvfb: what was tried): an EGL window made early and then
        # shown crashed (VTK 9.7, segmentation fault); elsewhere the first tick does it.
        if self._gl_checked or rw is None or self.p.off_screen or \
                type(rw).__name__ != "vtkXOpenGLRenderWindow":
            return
        rw.Initialize()
        self._check_gl()

    def _check_gl(self) -> None:
        self._gl_checked = True
        if software_opengl(self.p):
            # Without a GPU (Mesa llvmpipe: EGL/OSMesa, Xvfb) multisampling makes every full
            # render ~3-5x dearer (benchmarks/ui_frames.py); the window stays responsive
            # without it. Screenshots keep it: they are figures, not frames. (Changed after
            # the first render, the next render goes without it; the picture shown stays.)
            self.p.ren_win.SetMultiSamples(0)
            # Translucent primitives lit on the CPU, once per view: the same picture for the
            # view they are drawn for, half the render of the Create stage's 3D view.
            baked_light.enable(self.p)

    def _watch_first_frame(self) -> None:
        """Stamp ``window`` (:meth:`_stamp`) when the window has rendered its first frame."""
        rw = self.p.ren_win

        def first(_obj, _event):
            rw.RemoveObserver(self._tags.pop("first-frame"))
            self._shown = True
            self._stamp()

        self._tags["first-frame"] = rw.AddObserver("EndEvent", first)

    # ---------------------------------------------------------------- timer
    def tick(self, _step=None) -> None:
        """The timer: a resize, a script step, a rested parameter change, the inspector's
        answers and the render worker's passes (never waits for any of them)."""
        t_start = time.perf_counter()
        if not self._gl_checked:  # the window and its GL context exist now
            self._check_gl()
        if self.defer and not getattr(self, "_frozen", False):
            # Everything alive by the window's first tick (modules, VTK, pyvista, the scene)
            # lives as long as the window: left out of the garbage collector's full passes,
            # which took 85 ms of a tick (benchmarks/ui_frames.py, gc_full_ms) scanning it
            # all. (Only in the window: a test process goes on after its windows.)
            gc.freeze()
            self._frozen = True
        if not self._shown:
            self._shown = True
            self._stamp()
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
        stage_new = accept_results(s)  # a new inspection (or coverage): the stage anew
        got = 0
        if s.prog is not None:
            # Non-blocking: merges what the worker finished (at most POLL_BUDGET seconds).
            got = s.prog.poll()
            notes = s.prog.take_notices()
            if notes:
                s.message = notes[-1]
            if got or notes:
                got = 1
                s.acc = s.prog.runs[s.inspected].acc
                if s.prog.errors:
                    s.message = f"render error: {s.prog.errors[-1].splitlines()[-1]}"
        elif s.playing:
            s.acc.add(render_pass(s.scene, s.estimator, s.acc.n, s.seed, s.settings))
            s.message = f"playing: {s.acc.n} passes"
            got = 1
        if self.defer:
            self._tick_parts(stage_new, got, t_start)
        # At most one composition or one render per tick. A new stage (an inspection arrived)
        # is composed in this tick, with the passes merged above, and the whole window is
        # rendered in the next: building its actors and rendering it (3D view included) each
        # cost as much as a frame, so they are not added up in one tick. New passes redraw
        # the image panels and the stage text only.
        elif stage_new:
            self.compose_all()
            self._render_due = True
        elif self._render_due:
            if got and not self._compose_frame():
                self.compose_all()  # the stage text needs another layout
            self.redraw_render()
        elif got:
            self._frame()
        elif s.inspector is not None and s.inspector.busy("pixel") is not None:
            now = time.monotonic()
            if now - self._busy_shown >= 1.0:  # "computing... (N s)" counts up
                self._busy_shown = now
                self._frame()
        if not self._render_due and self._job is None:  # after a stage's composition and render
            self._warm_reconstruct()

    def _tick_parts(self, stage_new: bool, got: int, t_start: float) -> None:
        """A tick of the window (:attr:`defer`), one costly thing at most: a new stage draws
        its text and starts its 3D view; else the 3D view's next steps run (one, and more
        while the tick is younger than :data:`STEP_BUDGET`); else the completed 3D view is
        rendered (in the tick that finished it if it has room, :data:`RENDER_ROOM`); else
        merged passes redraw the image panels and the stage text. Passes merged meanwhile
        wait for a tick without 3D work (a few ticks at most). The panels are composed only
        in a young tick (:data:`FRAME_ROOM`: taking the passes in can cost tens of ms) and
        rendered in the same tick if there is room (:data:`PANELS_ROOM`), else in the next
        (a new panel mode's first breakdown lays out a dozen tiles anew)."""
        s = self.s
        self._frame_due = bool(got) or self._frame_due
        if stage_new:
            self.redraw(images=self._frame_due)
            self._frame_due = self._parts_due = False
            return
        if self._parts_due:  # composed in a tick that had no room left to render them
            parts, self._parts_due = self._parts_due, None
            self._render_parts(parts)
            return
        if self._job is not None:
            with self.held():
                first = True
                while self._job is not None and (
                        first or time.perf_counter() - t_start < STEP_BUDGET):
                    first = False
                    try:
                        next(self._job)
                    except StopIteration:
                        self._job = None
                        self._render_due = True
            if not self._render_due or time.perf_counter() - t_start >= RENDER_ROOM:
                return
        if self._render_due:
            self._render_due = False
            self._render_parts({"3d"})
            return
        busy = (s.inspector is not None and s.inspector.busy("pixel") is not None
                and time.monotonic() - self._busy_shown >= 1.0)
        if busy:  # "computing... (N s)" counts up
            self._busy_shown = time.monotonic()
        if (self._frame_due or busy) and time.perf_counter() - t_start < FRAME_ROOM:
            self._frame_due = False
            if not self._compose_frame():  # the panel's text needs another layout
                self.redraw(view3d=False)
                return
            parts = {"render", "variance"} | ({"panel"} if s.panel_changed else set())
            if time.perf_counter() - t_start < PANELS_ROOM:
                self._render_parts(parts)
            else:
                self._parts_due = parts
        elif not self._frame_due and self._turned():
            self._render_parts({"3d"})

    def _warm_reconstruct(self) -> None:
        """Load the Reconstruct stage's compiled kernel (``psurf_core.path_record``'s gather:
        numba's cache and the modules it imports, ~0.7 s of CPU the first time in a process,
        which froze the window the first time that stage was shown) in a thread, once, at
        the end of the first tick after the first inspection was drawn. VTK lets the GIL go
        while it renders and while the event loop waits, so the loading runs mostly between
        ticks; a Reconstruct stage asked for meanwhile waits for it (numba's lock) instead of
        loading it again."""
        ins = self.s.inspection
        if self._recon_warm is not None or ins is None or len(ins.table) == 0:
            return

        def warm():
            try:
                reconstruct_hit(ins, 0)
            except Exception:  # the stage itself reports what goes wrong
                pass

        self._recon_warm = threading.Thread(target=warm, name="psurf-warm-reconstruct",
                                            daemon=True)
        self._recon_warm.start()

    def redraw_render(self) -> None:
        """Render the whole window as composed (the second half of a new stage's redraw)."""
        self.p.render()
        self._render_due = False
        self._stamp()
        self._record_frame()

    def _compose_frame(self) -> bool:
        """Compose the image panels and the stage panel; False when the panel's text needs
        another layout."""
        held = self.p.suppress_rendering
        self.p.suppress_rendering = True
        try:
            compose_images(self.p, self.s)
            return compose_panel(self.p, self.s)
        finally:
            self.p.suppress_rendering = held

    def _frame(self) -> None:
        """Redraw the image panels and the stage panel (the 3D view and its camera stay)."""
        fits = self._compose_frame()
        if not fits:  # the panel's text needs another layout: everything is laid out again
            self.redraw(view3d=False)  # (the 3D view too if it moved)
            self._record_frame()
            return
        # Only the image panels and the stage text changed: only their renderers are drawn.
        # The 3D view is the costliest part of a frame (tens to hundreds of ms in software
        # OpenGL, measured by benchmarks/ui_frames.py), the footer's and the title's text
        # actors cost too, so they keep last frame's pixels. Any other render (camera moves,
        # stage changes, resizes) draws everything again.
        self._render_parts({"render", "variance"} | ({"panel"} if self.s.panel_changed
                                                     else set()))
