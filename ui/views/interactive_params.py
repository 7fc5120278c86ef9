"""What the window's controls change: the picked pixel (clicks), the inspected estimator and
its MIS members, the medium and the photon count (keys, sliders, debounced), and the GIF
recorder. These are the parts of :class:`ui.views.interactive.App` that change what is shown
or rendered (mixins: they use the app's plotter ``p``, state ``s``, ``controls``, ``members``,
``restart``, ``_reinspect``, ``set_pixel`` and ``redraw``)."""

from __future__ import annotations

import os
import time
from dataclasses import replace

import numpy as np

from . import controls, primitives_view
from ._vtk import vtkCellPicker
from .compose import CELL_3D, CELL_RENDER, CELL_VARIANCE, compose_panel
from .window import accept_results, panel_estimator, update_coverage


class Pointer:
    """Left clicks (chips and buttons, a pixel on a render or variance tile: in the render mode
    also that tile's estimator) and right clicks (a primitive in the 3D view: its coverage)."""

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



class EstimatorControls:
    """Which estimator the stages inspect (``e``/``E``, a click on its render or chip) and its
    MIS members (``1``..``9``, the member chips): each says what it did, or why it cannot."""

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



class MediumControls:
    """sigma_s, sigma_a, g and photons per pass: a key step or a slider pushes a value, the
    timer applies the last one once the control has rested (:class:`controls.Debouncer`)."""

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



class Recorder:
    """``v``: a GIF of every new progressive frame (the atomic writer ``record`` uses)."""

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

