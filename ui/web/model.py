"""One browser tab's app: the window's state (:class:`ui.views.window.ViewState`) and the
actions a page can take on it, without trame (plain Python; tests drive it directly).

Everything shown comes from the window's own code: the state and inspection from
:func:`~ui.views.window.build_state` / :func:`~ui.views.window.reinspect`, the 3D view from
:func:`~ui.views.window.compose_3d`, the image panels from
:class:`~ui.views.image_panels.PanelView` of the window's background render
(:class:`ui.cli.progressive.Progressive`, one worker process per session), pixel picking from
:func:`ui.views.controls.pick_pixel`, member toggles and sliders from :mod:`ui.views.controls`.
The downloadable figure is the window itself (:func:`~ui.views.window.compose`, off-screen).

Actions that inspect a pixel again (:meth:`WebSession.inspect`) are plain core work and may
run in a thread; drawing (``draw_*``, ``*_png``) and :class:`Progressive` calls belong to the
thread that owns the plotters.
"""

from __future__ import annotations

import io
import os
from dataclasses import replace
from types import SimpleNamespace

import numpy as np

from psurf_core.estimators import parse_estimator
from psurf_core.inspect import reconstruct_hit
from psurf_core.scene_io import load_scene
from ui.views import controls, hits_view, image_panels, scene_view, window
from ui.views.stepper import DEFAULT_PHOTONS, STAGES

from . import _view3d, tables
from .scenes import parse_specs

#: Size of the panels picture (render | maps), in pixels.
PANEL_SIZE = (1100, 430)
#: Most photon subpaths drawn (the window's ``+`` stops there too).
MAX_PATHS = 512


class WebSession:
    """The app one browser tab sees.

    Parameters
    ----------
    scene_path : str
        A bundled scene or a checked upload (:mod:`ui.web.scenes`).
    specs : list of str
        Estimators of the panels; the first is inspected (:func:`parse_specs`).
    workers : int
        Background render processes (0: none, passes are rendered by :meth:`poll`).
    max_passes : int, optional
        Passes per estimator after which the render stops (default: until paused).
    """

    def __init__(self, scene_path: str, specs, *, seed: int = 0,
                 photons: int = DEFAULT_PHOTONS, workers: int = 1, label: str | None = None,
                 max_passes: int | None = None):
        specs = list(specs)
        # The page inspects its first estimator (the window: the first MIS set by default).
        st = window.build_state(scene_path, specs[0], seed, None, photons, render_passes=False,
                                estimators=specs, inspect=0)
        window.attach_progressive(st, workers=workers)
        self._lowered = _lowest_priority(st.prog)
        if max_passes is not None:  # a fixed number of passes (tests: the same pictures)
            st.prog.reset(max_passes=int(max_passes))
        self.s = st
        self.label = label or os.path.basename(scene_path)
        self.params = controls.MediumParams.of(st.scene, photons)
        self.view = _view3d.view_plotter()
        self.panel_plotter = _view3d.panel_plotter(PANEL_SIZE)
        self.panel_view = image_panels.PanelView()

    # ------------------------------------------------------------------ reading
    @property
    def members(self) -> tuple:
        """Technique names of the inspected estimator as opened (the member toggles)."""
        return controls.members(parse_estimator(self.s.base_spec, self.s.scene))

    @property
    def passes(self) -> int:
        return self.s.acc.n

    def recon(self):
        """``(reconstruct_hit record, display index)`` of the selected hit, or (None, 0)."""
        ins = self.s.inspection
        if len(ins.table) == 0:
            return None, 0
        order = hits_view.hit_order(ins)
        k = min(max(self.s.hit, 0), len(order) - 1)
        return reconstruct_hit(ins, int(order[k])), k

    def texts(self) -> dict:
        """What the page shows besides the pictures (stage, caption, tables, members)."""
        s = self.s
        recon, k = self.recon() if s.stage == "reconstruct" else (None, 0)
        return {
            "stage": s.stage, "stage_index": STAGES.index(s.stage), "title": s.stepper.title,
            "caption": s.stepper.caption, "pixel": list(s.pixel_xy), "hit": s.hit,
            "pass_index": s.pass_index, "passes": s.acc.n, "panel_text": window.panel_text(s),
            "evaluate": tables.evaluate_rows(s.inspection),
            "reconstruct": tables.reconstruct_rows(s.inspection, recon, k),
            "members": [{"name": n, "on": n not in s.disabled} for n in self.members],
            "estimators": ",".join(window.panel_specs(s)), "spec": s.estimator.spec,
            "base_spec": s.base_spec, "mode": s.mode, "scene": self.label,
        }

    # ------------------------------------------------------------------ stepping
    def step(self, d: int) -> None:
        """Next (``d > 0``) or previous stage."""
        (self.s.stepper.next if d > 0 else self.s.stepper.previous)()

    def go(self, stage: str) -> None:
        self.s.stepper.go(stage)

    def step_hit(self, d: int) -> None:
        n = len(self.s.inspection.table)
        if n:
            self.s.hit = (self.s.hit + int(d)) % n

    def paths(self, factor: float) -> None:
        """Draw ``factor`` times as many photon subpaths in Trace and Create (the window's
        ``+`` / ``-``; 1 to :data:`MAX_PATHS`)."""
        self.s.n_paths = int(min(max(round(self.s.n_paths * float(factor)), 1), MAX_PATHS))

    def step_pass(self, d: int) -> bool:
        """Inspect another of the passes the panels hold; True when :meth:`inspect` is due."""
        s = self.s
        k = min(max(s.pass_index + int(d), 0), max(s.acc.n - 1, 0))
        changed = k != s.pass_index
        s.pass_index = k
        return changed

    def set_pixel(self, xy) -> None:
        """Pick pixel ``(X, Y)`` (clamped to the image); call :meth:`inspect` next."""
        cam = self.s.scene.camera
        self.s.pixel_xy = (min(max(int(xy[0]), 0), cam.width - 1),
                           min(max(int(xy[1]), 0), cam.height - 1))

    def inspect(self) -> None:
        """Inspect the picked pixel in the inspected pass again (core work: any thread; the
        session's inspector computes in this process, so the answer is there on return)."""
        window.reinspect(self.s)
        window.accept_results(self.s)

    # ------------------------------------------------------------------ estimator, scene
    def _restart(self) -> None:
        """The panels' render starts over for the current scene, estimators and settings."""
        s = self.s
        s.prog.reset(scene=s.scene, estimators=window.panel_specs(s), settings=s.settings)
        s.acc = s.prog.runs[s.inspected].acc
        s.pass_index = 0

    def toggle_member(self, name: str) -> None:
        """Switch an MIS member on or off (one stays on: ``ValueError``); restarts."""
        s = self.s
        disabled = set(s.disabled) ^ {str(name)}
        s.estimator = controls.estimator_with(s.base_spec, s.scene, disabled)
        s.disabled_by = {**s.disabled_by, s.inspected: frozenset(disabled)}
        self._restart()

    def set_estimators(self, text: str) -> None:
        """Another estimator list ``A,B`` (``ValueError`` naming the bad one); restarts."""
        s = self.s
        specs = parse_specs(text, s.scene)
        s.estimator = parse_estimator(specs[0], s.scene)
        s.specs, s.inspected, s.disabled_by = tuple(specs), 0, {}
        self._restart()

    def set_params(self, params: controls.MediumParams) -> None:
        """New sigma_s, sigma_a, g and photons (clamped to the sliders' ranges); restarts."""
        s = self.s
        self.params = params.clamped()
        s.scene = controls.scene_with(s.base_scene, self.params)
        s.estimator = controls.estimator_with(s.base_spec, s.scene, s.disabled)
        s.settings = replace(s.settings, photons=int(self.params.photons))
        self._restart()

    def open_scene(self, path: str, label: str) -> None:
        """Another scene (checked by the caller): the estimators are kept when they apply,
        else the scene's first photon estimator of the defaults is used (``SceneError`` /
        ``ValueError`` leave the session as it was)."""
        old = self.s
        parse_specs(",".join(old.specs), load_scene(path))  # one line naming the bad one
        st = window.build_state(path, old.base_spec, old.seed, None, old.settings.photons,
                                render_passes=False, estimators=old.specs, inspect=old.inspected)
        if old.disabled_by:  # members switched off stay off: inspect that estimator
            st.disabled_by = dict(old.disabled_by)
            st.estimator = window.panel_estimator(st, st.inspected)
            window.reinspect(st)
            window.accept_results(st)
        st.mode, st.stepper = old.mode, old.stepper
        st.prog, st.panels, st.playing = old.prog, old.panels, old.playing
        self.s, self.label = st, label
        self.params = controls.MediumParams.of(st.scene, old.settings.photons)
        self._restart()

    def set_mode(self, mode: str) -> None:
        if mode not in image_panels.MODES:
            raise ValueError(f"unknown panel mode {mode!r} (one of: "
                             f"{', '.join(image_panels.MODES)})")
        self.s.mode = mode

    def play(self, on: bool) -> None:
        self.s.playing = bool(on)
        (self.s.prog.resume if on else self.s.prog.pause)()

    def poll(self) -> int:
        """Merge the passes the worker finished (never waits); returns how many."""
        s = self.s
        got = s.prog.poll()
        if got:
            s.acc = s.prog.runs[s.inspected].acc
        self._lowered = _lowest_priority(s.prog, self._lowered)  # a worker restarted
        return got

    @property
    def render_error(self) -> str:
        errs = self.s.prog.errors
        return errs[0].splitlines()[0] if errs else ""

    # ------------------------------------------------------------------ pictures
    def draw_3d(self, keep_camera: bool = True) -> None:
        """Compose the stage in the 3D view (the window's left cell, alone)."""
        p = self.view
        scene_view.set_scale(p.window_size[1])
        # Once rendered, pyvista renders after every added actor; a stage adds dozens (seconds
        # in software OpenGL): held until the frame is built, as the window does.
        held, p.suppress_rendering = p.suppress_rendering, True
        try:
            window.compose_3d(p, self.s, keep_camera=keep_camera)
        finally:
            p.suppress_rendering = held

    def panels_png(self) -> bytes:
        """The image panels (render and variance, or the mode's maps) as PNG."""
        s = self.s
        scene_view.set_scale(PANEL_SIZE[1] * scene_view.DESIGN_HEIGHT / 460.0)
        self.panel_view.draw(self.panel_plotter, [(0, 0), (0, 1)], s.prog, s.mode, s.pixel_xy,
                             reference=s.reference)
        # zlib level 1: half the encoding time of the default for 16 % more bytes; the
        # panels are redrawn as passes arrive, and encoding was 60 % of an idle session's CPU.
        return png_bytes(_view3d.screenshot(self.panel_plotter), compress_level=1)

    def pick(self, x: float, y: float, shown_w: float, shown_h: float):
        """The image pixel under a click at ``(x, y)`` on the panels picture shown
        ``shown_w x shown_h`` (CSS pixels from its top left), or None."""
        w, h = self.panel_plotter.window_size
        if shown_w <= 0 or shown_h <= 0:
            return None
        display = (float(x) * w / shown_w, h - float(y) * h / shown_h)
        vps = [r.GetViewport() for r in self.panel_plotter.renderers]
        i = controls.viewport_at(display, (w, h), vps)
        if i is None:
            return None
        cam = self.s.scene.camera
        return controls.pick_pixel(self.panel_plotter.renderers[i], display, (w, h),
                                   cam.width, cam.height)

    def figure_png(self) -> bytes:
        """The desktop window's picture of this state (3D view with this camera, panels,
        stage panel), as PNG."""
        s = self.s
        panels, s.panels = s.panels, image_panels.PanelView()
        p = window.make_plotter(off_screen=True)
        try:
            window.compose(p, s)
            p.subplot(*window.CELL_3D)
            p.camera_position = self.view.camera_position
            p.renderer.ResetCameraClippingRange()
            return png_bytes(_view3d.screenshot(p))
        finally:
            s.panels = panels
            p.close()

    def render_npz(self) -> bytes:
        """The inspected estimator's render as an ``app.py render`` .npz."""
        from ui.cli.render import initial_radius, npz_payload

        s = self.s
        run = s.prog.runs[s.inspected]
        res = SimpleNamespace(mean=run.acc.mean, var=run.acc.variance if run.acc.n > 1
                              else np.zeros_like(run.acc.mean), passes=run.acc.n,
                              photons_per_pass=s.settings.photons, spp=s.settings.spp,
                              seconds=run.seconds, estimator=run.spec, seed=s.seed,
                              sum_var=run.acc.sum_variance)
        buf = io.BytesIO()
        np.savez_compressed(buf, **npz_payload(res, initial_radius(s.estimator, s.scene,
                                                                   s.settings), s.scene))
        return buf.getvalue()

    def close(self) -> None:
        """Stop the render worker and free the plotters."""
        self.s.prog.close()
        self.view.close()
        self.panel_plotter.close()


#: Niceness of a session's render worker: the pages of every session come first (the window
#: runs its worker at +10; ten sessions' workers at +10 took half the CPU from the pages).
WORKER_NICENESS = 19


def worker_pids(prog) -> list[int]:
    """Process ids of the render workers of ``prog`` (none with ``workers=0``)."""
    pool = getattr(prog, "_pool", None)
    return list(pool.pids) if pool is not None else []


def _lowest_priority(prog, done=frozenset()) -> frozenset:
    """Put the render workers of ``prog`` not in ``done`` at the lowest priority: nice
    :data:`WORKER_NICENESS` and Linux's ``SCHED_IDLE`` (they run when the pages of every
    session have nothing to do); returns the workers' ids (a restarted worker is new)."""
    pids = frozenset(worker_pids(prog))
    for pid in pids - done:
        try:
            os.setpriority(os.PRIO_PROCESS, pid, WORKER_NICENESS)
        except (AttributeError, OSError):  # not POSIX, or not allowed: leave it at +10
            pass
        try:
            os.sched_setscheduler(pid, os.SCHED_IDLE, os.sched_param(0))
        except (AttributeError, OSError):  # not Linux: the niceness alone
            pass
    return pids


def png_bytes(img, compress_level: int | None = None) -> bytes:
    """PNG file bytes of an (H, W, 3) uint8 image (``compress_level`` 0-9: zlib's, the
    default 6 when None)."""
    import imageio.v3 as iio

    kw = {} if compress_level is None else {"compress_level": int(compress_level)}
    return iio.imwrite("<bytes>", np.asarray(img), extension=".png", **kw)
