"""How the window draws a change in parts (:class:`Drawer`, a mixin of
:class:`ui.views.interactive.App`): a key or a new inspection composes what it changed and
renders only those renderers now, and the 3D view's first step (its scene, "drawing...");
the timer (:mod:`ui.views.interactive_timer`) runs the 3D view's other steps and renders it.

Every render of the window in software OpenGL costs ~16-20 ms at 1600x900 however little is
drawn, plus each renderer drawn (the image panels ~20 ms, a stage's 3D view 15-60 ms): VTK
renders into its own framebuffer, and a renderer that is not drawn keeps its pixels, so a
change draws only the parts it touched (:meth:`Drawer._render_parts`).

The mixin uses the app's plotter ``p``, state ``s``, ``controls``, ``_job``,
``_render_due``, ``_parts_due``, ``_draw_controls``, ``_place_widgets``, ``_stamp`` and
``_record_frame``.
"""

from __future__ import annotations

import contextlib

from . import baked_light
from .compose import (
    CELL_3D,
    CELL_PANEL,
    CELL_RENDER,
    CELL_TITLE,
    CELL_VARIANCE,
    compose_3d_steps,
    compose_steps,
    run_steps,
)

__all__ = ["Drawer"]


def _moved(old, new) -> set:
    """The parts (``_render_parts``' names) whose place differs between two layouts; ``all``
    when the window's size, the footer or the slider block changed."""
    if old == new:
        return set()
    if old is None or new is None or (old.size, old.footer, old.sliders) != (
            new.size, new.footer, new.sliders):
        return {"all"}
    a, b = old.parts(), new.parts()
    names = {"title": "title", "view3d": "3d", "panel": "panel", "images": "render",
             "maps": "variance"}
    return {mine for part, mine in names.items() if a[part] != b[part]}


class Drawer:
    """Composing and rendering parts of the window (see the module docstring)."""

    @contextlib.contextmanager
    def held(self):
        """Rendering held while actors are added (once a window is shown pyvista renders after
        every added actor; a stage adds dozens)."""
        held = self.p.suppress_rendering
        self.p.suppress_rendering = True
        try:
            yield
        finally:
            self.p.suppress_rendering = held

    def redraw_deferred(self, keep_camera: bool = True, *, view3d: bool = True,
                        images: bool = True, everything: bool = False) -> None:
        """``App.redraw`` in the window: compose the footer, the layout, the title, the image
        panels, the stage panel and (``view3d``) the 3D view's first step now and render
        what changed or moved; the 3D view's other steps follow in the next ticks.
        ``images=False``: the image panels show nothing new (a stage step)."""
        s = self.s
        lay, title, footer = s.layout, s.title_key, getattr(self.controls, "_key", None)
        with self.held():
            self._draw_controls()
            steps = compose_steps(self.p, s, keep_camera=keep_camera, view3d=view3d)
            try:
                next(steps)
            except StopIteration:
                steps = None
            moved = _moved(lay, s.layout)
            if moved & {"3d", "all"} and not view3d:  # the 3D view moved: composed again too
                self.p.subplot(*CELL_3D)
                steps, view3d = compose_3d_steps(self.p, s, keep_camera=keep_camera), True
                try:
                    next(steps)
                except StopIteration:
                    steps = None
            if view3d:
                self._job, self._render_due = steps, False
            self._place_widgets()
        parts = {"panel"} | moved
        if images:
            parts |= {"render", "variance"}
            self._parts_due = None
        if view3d:
            parts.add("3d")
        if s.title_key != title:
            parts.add("title")
        if self.controls is not None and self.controls._key != footer:
            parts.add("footer")
        self._render_parts(set(self._renderers()) if everything or "all" in moved else parts)

    def _turned(self) -> bool:
        """Whether the user turned the 3D view (and let go) since its baked primitives were
        shaded; if so they are shaded for the new view (:func:`ui.views.baked_light.relight`)
        and the view must be drawn again."""
        if not baked_light.enabled(self.p) or self.p.iren is None:
            return False
        style = self.p.iren.interactor.GetInteractorStyle()
        if style is not None and style.GetState() != 0:  # a button still held: still turning
            return False
        ren = self._renderers()["3d"]
        moved = ren.GetActiveCamera().GetMTime()
        if moved == getattr(self, "_camera_seen", None):  # (listing the actors costs ~1 ms)
            return False
        self._camera_seen = moved
        return baked_light.relight(ren) > 0

    def settle(self) -> None:
        """Finish the 3D view's steps at once and render the whole window (a screenshot, the
        ``s`` key, a script's ``shot``)."""
        if self._job is not None:
            with self.held():
                run_steps(self._job)
            self._job = None
        self.p.render()
        self._render_due = False

    def _renderers(self) -> dict:
        p = self.p
        out = {name: p.renderers[p.renderers.loc_to_index(cell)] for name, cell in
               (("3d", CELL_3D), ("render", CELL_RENDER), ("variance", CELL_VARIANCE),
                ("panel", CELL_PANEL), ("title", CELL_TITLE))}
        if self.controls is not None:
            out["footer"] = self.controls.overlay
        return out

    def _render_parts(self, parts) -> None:
        """Render the window drawing only the renderers named in ``parts`` (``3d``,
        ``render``, ``variance``, ``panel``, ``title``, ``footer``): VTK renders into its own
        framebuffer, and a renderer that is not drawn leaves its viewport as it was (the
        layout's parts never overlap; the footer's layer, which also holds the help box over
        the others, is drawn whenever the help is shown)."""
        rens = self._renderers()
        if self.s.show_help:
            parts = set(parts) | {"footer"}
        skip = [r for name, r in rens.items() if name not in parts]
        for ren in skip:
            ren.SetDraw(False)
        try:
            self.p.render()
        finally:
            for ren in skip:
                ren.SetDraw(True)
        self._stamp()
        self._record_frame()
