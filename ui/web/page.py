"""One session's page: its state keys and callbacks (layout in :mod:`ui.web.layout`, the app
itself in :class:`ui.web.model.WebSession`, the process in :mod:`ui.web.session`).

Every callback goes through :func:`guarded`: an exception becomes a one-line error
on this page (the traceback goes to stderr) and the session goes on. Work that inspects a
pixel runs in a thread while the page says so ("computing..."; a cold numba compile of an MIS
estimator can take a minute), so the page stays live and its render panels keep arriving.
"""

from __future__ import annotations

import asyncio
import functools
import math
import os
import sys
import time
import traceback

#: Seconds between polls of the background render.
TICK = 0.25
#: While passes arrive the panels are redrawn every PANEL_PERIOD seconds at first, then less
#: often as the picture settles (+PANEL_SLOWDOWN s per pass, at most PANEL_PERIOD_MAX).
PANEL_PERIOD, PANEL_SLOWDOWN, PANEL_PERIOD_MAX = 0.75, 0.05, 5.0
#: Rendering pauses after this many seconds without input from the page, or after this many
#: seconds of the inspected estimator's rendering (``play`` continues): bounded work.
IDLE_PAUSE = 120.0
RENDER_BUDGET = 90.0
#: Seconds a slider must rest before the scene is rebuilt and the render restarts.
SLIDER_REST = 0.5
#: Estimators offered in the estimator box (any spec may be typed).
ESTIMATOR_ITEMS = ["planes", "points", "bre", "beams", "planes,beams", "paper-single",
                   "paper-multi", "planes,paper-multi"]
BUSY_TEXT = "computing... (the first use of an estimator compiles its kernels: up to a minute)"


def one_line(e: BaseException) -> str:
    """An exception as the command line's one error line (without ``psurf: error:``)."""
    return " ".join(str(e).split()) or type(e).__name__


class Page:
    """The state keys and callbacks of one session's page."""

    def __init__(self, server, session, upload_dir: str):
        self.server, self.m, self.upload_dir = server, session, upload_dir
        self.state = server.state
        self.lock = asyncio.Lock()
        self.uploads = 0
        self.last_input = time.monotonic()
        self.last_panels = 0.0
        self.idle_paused = False
        self.dirty = False  # passes arrived that the panels do not show yet
        self.budget = RENDER_BUDGET  # worker seconds before the render pauses by itself
        self.view = None  # the remote view widget (set by main)
        self.frame_task = None  # the newest frame's delivery (push_view)

    # ------------------------------------------------------------------ state
    def initial_state(self, scene_items, scene_name) -> None:
        st, p = self.state, self.m.params
        st.update({"scene_items": scene_items, "scene_name": scene_name,
                   "estimator_items": ESTIMATOR_ITEMS, "error": "", "upload_error": "",
                   "busy": False, "status": "starting", "playing": True, "panels_src": "",
                   "sigma_s": p.sigma_s, "sigma_a": p.sigma_a, "g": p.g,
                   "photons_log2": math.log2(p.photons), "view_token": 0,
                   "evaluate_columns": [c for c, _ in _eval_columns()],
                   "evaluate_keys": [k for _, k in _eval_columns()]})
        self.push_texts()
        self.state.estimators_text = self.state.estimators

    def push_texts(self) -> None:
        t = self.m.texts()
        self.state.update({k: t[k] for k in ("stage_index", "title", "caption", "pixel",
                                             "panel_text", "evaluate", "reconstruct",
                                             "members", "mode", "passes", "estimators",
                                             "spec")})
        self.state.stage = t["stage"]
        self.state.trame__title = f"psurf: {self.m.label}"  # the browser tab's title
        self.state.status = self.status_text()

    def status_text(self) -> str:
        m = self.m
        if self.state.busy:
            return BUSY_TEXT
        if m.render_error:
            return f"render error: {m.render_error}"
        if m.passes == 0:
            return "rendering the first pass (kernels compile on first use)..."
        paused = "" if m.s.playing else (" (paused: no input for 2 min, or its render "
                                         "budget spent; play continues)"
                                         if self.idle_paused else " (paused)")
        return f"{m.label}: {m.passes} passes of {m.s.estimator.spec}{paused}"

    def push_view(self, keep_camera: bool = True) -> None:
        self.m.draw_3d(keep_camera=keep_camera)
        if self.view is not None:
            self.view.update()
            self._deliver_frame()
        self.state.view_token += 1

    def _deliver_frame(self) -> None:
        """The new frame to the page once encoded (:func:`ui.web._view3d.deliver_frame`)."""
        try:
            asyncio.get_running_loop()
        except RuntimeError:  # building the page: the first frame goes when a page connects
            return
        if self.frame_task is not None and not self.frame_task.done():
            self.frame_task.cancel()  # an older frame's wait: this one supersedes it
        self.frame_task = asyncio.ensure_future(self._frame())

    async def _frame(self) -> None:
        from . import _view3d

        try:
            await _view3d.deliver_frame(self.server, self.m.view)
        except Exception:  # trame-vtk's own retry still sends it
            traceback.print_exc(file=sys.stderr)

    def push_panels(self) -> None:
        import base64

        png = self.m.panels_png()
        self.state.panels_src = "data:image/png;base64," + base64.b64encode(png).decode()
        self.last_panels = time.monotonic()

    def push_all(self, keep_camera: bool = True) -> None:
        self.push_texts()
        self.push_view(keep_camera)
        self.push_panels()

    # ------------------------------------------------------------------ running actions
    def touched(self) -> None:
        """Input from the page: rendering resumes if it was paused for idleness."""
        self.last_input = time.monotonic()
        if self.idle_paused:
            self.idle_paused = False
            self.m.play(True)
            self.state.playing = True

    async def compute(self, work) -> None:
        """Run core work (``work()``) in a thread, the page saying it is busy meanwhile."""
        self.state.busy = True
        self.state.status = BUSY_TEXT
        self.state.flush()
        try:
            await asyncio.to_thread(work)
        finally:
            self.state.busy = False

    async def tick_forever(self) -> None:
        """Poll the background render; redraw the panels while passes arrive."""
        while True:
            await asyncio.sleep(TICK)
            try:
                self.tick()
            except Exception as e:  # a failing frame must not end the loop
                traceback.print_exc(file=sys.stderr)
                with self.state:
                    self.state.error = f"render panels: {one_line(e)}"

    def tick(self) -> None:
        m = self.m
        if m.s.playing and not self.idle_paused and (
                time.monotonic() - self.last_input > IDLE_PAUSE
                or m.s.prog.runs[m.s.inspected].seconds > self.budget):
            self.idle_paused = True
            m.play(False)
        self.dirty = self.dirty or bool(m.poll())
        period = min(PANEL_PERIOD + PANEL_SLOWDOWN * m.passes, PANEL_PERIOD_MAX)
        with self.state:
            if self.dirty and not self.lock.locked() and \
                    time.monotonic() - self.last_panels >= period:
                self.dirty = False
                self.push_panels()
                self.state.passes = m.passes
                if self.state.stage_index < 3:
                    self.state.panel_text = self.m.texts()["panel_text"]
            self.state.playing = m.s.playing
            self.state.status = self.status_text()


def _eval_columns():
    from .tables import EVALUATE_COLUMNS

    return EVALUATE_COLUMNS


def guarded(page: Page, fn, *, clears: bool = True):
    """``fn`` (sync or async) with its exceptions shown on the page as one line.

    ``clears``: the call is a new action of the student's, so the previous action's error
    line goes (callbacks of state changes, which the server's own updates also fire, clear
    it themselves when they act).
    """

    @functools.wraps(fn)
    async def run(*args, **kwargs):
        try:
            async with page.lock:
                page.touched()
                if clears:
                    page.state.error = ""
                out = fn(*args, **kwargs)
                if asyncio.iscoroutine(out):
                    out = await out
                return out
        except Exception as e:
            traceback.print_exc(file=sys.stderr)
            with page.state:
                page.state.error = one_line(e)
                page.state.busy = False
                page.state.status = page.status_text()
            return None

    return run


def bind(page: Page) -> None:
    """Register the page's triggers and state callbacks."""
    from ui.views.controls import MediumParams
    from ui.views.stepper import STAGES

    from . import scenes

    server, st, m = page.server, page.state, page.m
    ctrl = server.controller

    def trigger(name):
        return lambda fn: ctrl.trigger(name)(guarded(page, fn))

    @trigger("step")
    def step(d):
        m.step(int(d))
        page.push_texts()
        page.push_view()
        return m.s.stage

    @trigger("hit")
    def hit(d):
        m.step_hit(int(d))
        page.push_texts()
        page.push_view()

    @trigger("paths")
    def paths(factor):
        m.paths(float(factor))
        page.push_texts()
        page.push_view()

    @trigger("pass")
    async def pass_(d):
        if m.step_pass(int(d)):
            await page.compute(m.inspect)
        page.push_texts()
        page.push_view()

    @trigger("pick")
    async def pick(x, y, w, h):
        xy = m.pick(float(x), float(y), float(w), float(h))
        if xy is None:
            return None
        m.set_pixel(xy)
        await page.compute(m.inspect)
        page.push_all()
        return list(m.s.pixel_xy)

    @trigger("member")
    async def member(name):
        m.toggle_member(str(name))
        await page.compute(m.inspect)
        page.push_all()

    @trigger("set_estimators")
    async def set_estimators(text):
        m.set_estimators(str(text or ""))
        await page.compute(m.inspect)
        page.push_all()

    async def apply_sliders():
        p = MediumParams(float(st.sigma_s), float(st.sigma_a), float(st.g),
                         int(round(2.0 ** float(st.photons_log2)))).clamped()
        if p == m.params.clamped():
            return  # the server's own update of the sliders, or no real change
        st.error = ""
        m.set_params(p)
        await page.compute(m.inspect)
        q = m.params
        st.update({"sigma_s": q.sigma_s, "sigma_a": q.sigma_a, "g": q.g,
                   "photons_log2": math.log2(q.photons)})
        page.push_all()

    guarded_apply = guarded(page, apply_sliders, clears=False)
    pending = {"task": None, "waiting": False}

    @st.change("sigma_s", "sigma_a", "g", "photons_log2")
    def slid(**_):
        """A slider moved (drag or keys): applied once it rests (as the window debounces)."""
        if pending["task"] is not None and pending["waiting"]:
            pending["task"].cancel()  # still resting: start the wait again

        async def later():
            pending["waiting"] = True
            await asyncio.sleep(SLIDER_REST)
            pending["waiting"] = False  # from here on it runs to the end
            await guarded_apply()

        pending["task"] = asyncio.ensure_future(later())

    @trigger("play")
    def play():
        if page.idle_paused:  # another budget from here
            page.budget = m.s.prog.runs[m.s.inspected].seconds + RENDER_BUDGET
        page.idle_paused = False
        m.play(not m.s.playing)
        st.playing = m.s.playing
        st.status = page.status_text()

    @trigger("reset_camera")
    def reset_camera():
        page.push_view(keep_camera=False)

    @trigger("upload")
    async def upload(name, text):
        st.upload_error = ""
        page.uploads += 1
        try:
            path = scenes.save_upload(str(name), str(text).encode("utf-8"), page.upload_dir,
                                      page.uploads)
            await page.compute(lambda: m.open_scene(path, f"{os.path.basename(name)} "
                                                          f"(uploaded)"))
        except Exception as e:  # the core's SceneError names our file: name theirs
            msg = one_line(e).replace(page.upload_dir + os.sep, "")
            msg = msg.replace(f"upload-{page.uploads}.toml", os.path.basename(str(name)))
            st.upload_error = msg
            return msg
        st.scene_items = [*scenes.bundled(), m.label]
        st.scene_name = m.label
        _sync_params(st, m)
        page.push_all(keep_camera=False)
        return ""

    def on_change(*keys):
        def deco(fn):
            g = guarded(page, fn, clears=False)
            st.change(*keys)(g)
            return fn
        return deco

    @on_change("stage_index")
    def go(stage_index, **_):
        i = int(stage_index if stage_index is not None else 0)
        if STAGES[i] != m.s.stage:
            st.error = ""
            m.go(STAGES[i])
            page.push_texts()
            page.push_view()

    @on_change("mode")
    def mode(mode, **_):
        if mode and mode != m.s.mode:
            st.error = ""
            m.set_mode(mode)
            page.push_panels()

    @on_change("scene_name")
    async def scene(scene_name, **_):
        if not scene_name or scene_name == m.label:
            return
        if scene_name not in scenes.bundled():
            return  # an earlier upload's label: nothing to reopen
        st.error = ""
        path = scenes.bundled_path(scene_name)
        await page.compute(lambda: m.open_scene(path, scene_name))
        st.scene_items = scenes.bundled()
        _sync_params(st, m)
        page.push_all(keep_camera=False)


def _sync_params(st, m) -> None:
    q = m.params
    st.update({"sigma_s": q.sigma_s, "sigma_a": q.sigma_a, "g": q.g,
               "photons_log2": math.log2(q.photons), "estimators_text": ",".join(m.s.specs)})
