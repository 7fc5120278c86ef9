"""The 3D view of a stage, composed in steps (:func:`compose_3d_steps`): the window builds it
over several timer ticks, so that no tick spends more than ~100 ms on it, and everything else
(:func:`compose_3d`, screenshots, the browser version) runs the steps at once.

A stage's 3D view is dozens of pyvista actors (its scene, paths, primitives per technique,
hits, normals, labels); building them once cost up to ~100 ms of the UI thread (the Create
stage's primitives: meshed and clipped per technique, ``benchmarks/ui_frames.py``), and
rendering them as much again in software OpenGL. The first step clears what the last stage
drew (the scene's actors stay when only the stage or the pixel changed), frames the camera and
says "drawing..." in the view, so the window can show it at once; each later step adds one
part (the primitives of one technique, the hits, the normals, ...); the last one removes the
note.
"""

from __future__ import annotations

import numpy as np

from psurf_core.inspect import member_primitives, reconstruct_hit

from . import hits_view, primitives_view, scene_view, stage_text
from ._vtk import pv
from .scene_view import FONT, add_text
from .stage_text import coverage_target

__all__ = ["compose_3d", "compose_3d_steps", "recon", "run_steps"]

#: The note shown in the 3D view while its steps are still to come (the actor's name).
DRAWING, COMPUTING = "drawing", "computing"


def recon(state):
    """``(reconstruction, display index)`` of the selected hit (Reconstruct), or ``(None,
    None)`` without hits."""
    ins = state.inspection
    if ins is None or len(ins.table) == 0:
        return None, None
    order = stage_text.hit_order(ins)
    k = min(max(state.hit, 0), len(order) - 1)
    return reconstruct_hit(ins, int(order[k])), k


def scene_labels(stage: str) -> bool:
    """Whether the scene's own labels (light, camera) are drawn: not where the stage labels
    points of its own (Evaluate's hits, Reconstruct's vertices), which they would cover."""
    return stage not in ("evaluate", "reconstruct")


def home_camera(state, view_aspect: float | None = None):
    """``(key, camera)``: where the 3D view looks by default at this stage (a pinned camera
    (lecture); Reconstruct: framing the selected hit's path; otherwise the overview)."""
    if state.camera_pin is not None:
        return ("pin", state.camera_pin), [tuple(map(float, v)) for v in state.camera_pin]
    if state.stage == "reconstruct":
        rec, k = recon(state)
        if rec is not None and rec.get("polyline") is not None:
            key = ("recon", state.pixel_xy, state.pass_index, k, state.estimator.spec)
            return key, hits_view.reconstruct_camera(rec, state.scene)
    aspect = round(view_aspect, 2) if view_aspect else None
    return ("overview", aspect), scene_view.overview_camera(state.scene, aspect=aspect)


def run_steps(steps) -> object:
    """Run a generator of steps to its end; returns its return value."""
    while True:
        try:
            next(steps)
        except StopIteration as stop:
            return stop.value


def compose_3d(plotter: pv.Plotter, state, *, keep_camera: bool = False) -> None:
    """(Re)draw the 3D view of ``state`` into the plotter's current renderer: the window's
    3D cell, or a plotter of its own (the web page's 3D view, :mod:`ui.web`).

    ``keep_camera`` keeps the view where the user turned it, unless the stage's own view
    changed (entering Reconstruct, another hit there: it frames the new path).
    """
    run_steps(compose_3d_steps(plotter, state, keep_camera=keep_camera))


def compose_3d_steps(plotter: pv.Plotter, state, *, keep_camera: bool = False):
    """:func:`compose_3d` as a generator: each ``next`` adds one part of the view (the first
    one clears the last stage, frames the camera and puts up the note "drawing..."; the view
    is complete when the generator is exhausted). Between steps the caller may draw other
    parts of the window: each step makes the 3D renderer the current one again."""
    index = plotter.renderers.active_index
    ren = plotter.renderer

    def current():  # another part of the window may have been composed since the last step
        plotter.renderers.set_active_renderer(*plotter.renderers.index_to_loc(index))

    cam_pos = plotter.camera_position if keep_camera else None
    x0, y0, x1, y1 = ren.GetViewport()
    w, h = plotter.window_size
    key, home = home_camera(state, (x1 - x0) * w / max((y1 - y0) * h, 1.0))
    if cam_pos is None or key != state.framed:
        cam_pos = home
    state.framed = key
    cam_pos = [tuple(map(float, v)) for v in cam_pos]
    _clear_bars(plotter, ren)
    # The scene (box, lights, occluders, camera) stays when only the stage or the pixel
    # changed. (``ren.actors`` builds a dict on every access: read it once.)
    key3d = (id(state.scene), scene_labels(state.stage))
    actors = ren.actors
    reuse = (state.scene_key == key3d and bool(state.scene_actors)
             and all(n in actors for n in state.scene_actors))
    if reuse:
        stale = [a for n, a in actors.items() if n not in state.scene_actors]
        if stale:  # by actor, not by name: a name also removes every 'name-...' actor
            ren.remove_actor(stale, render=False)
    else:
        ren.clear_actors()
    ren.set_background(scene_view.BACKGROUND)
    if not reuse:
        before = set(ren.actors)
        scene_view.add_scene(plotter, state.scene, labels=scene_labels(state.stage))
        state.scene_actors = set(ren.actors) - before
    state.scene_key = key3d
    # Drawn apart from the scene, so a moved pixel keeps the scene's actors.
    scene_view.add_picked_pixel(plotter, state.scene, state.pixel_xy)
    plotter.camera_position = cam_pos
    ren.ResetCameraClippingRange()
    if state.inspection is None:
        add_text(plotter, "computing...", 0.5, 0.97, FONT, name=COMPUTING, align="center",
                 colour="#444444")
        return
    add_text(plotter, "drawing...", 0.5, 0.97, FONT, name=DRAWING, align="center",
             colour="#444444")
    yield
    current()
    yield from _stage_steps(plotter, state, cam_pos, current)
    current()
    note = ren.actors.get(DRAWING)
    if note is not None:
        ren.remove_actor(note, render=False)
    # pyvista frames the camera on the first actor of a renderer whose camera was never set
    plotter.camera_position = cam_pos
    ren.ResetCameraClippingRange()


def _stage_steps(plotter: pv.Plotter, state, camera, current):
    """The stage's own parts, one per step (labels are placed for ``camera``)."""
    ins = state.inspection
    scene = state.scene
    stage = state.stage
    t = ins.table
    top = stage_text.hit_order(ins)[: stage_text.TABLE_ROWS]
    if stage == "trace":
        primitives_view.add_paths(plotter, ins.paths, scene, state.n_paths)
    elif stage == "create":
        primitives_view.add_paths(plotter, ins.paths, scene, state.n_paths, opacity=0.35,
                                  line_width=3)
        yield
        current()
        sel = primitives_view.create_selection(ins, state.n_paths)
        yield from _with(current, primitives_view.primitive_steps(
            plotter, ins, sel, legend_loc="lower right"))
    elif stage in ("intersect", "evaluate"):
        hits_view.add_query_ray(plotter, ins)
        if stage == "intersect":
            sel = primitives_view.create_selection(ins, state.n_paths)
            yield from _with(current, primitives_view.primitive_steps(
                plotter, ins, sel, opacity=0.08, edges=False, legend=False, name="context"))
        yield
        current()
        yield from _with(current, primitives_view.primitive_steps(
            plotter, ins, hits_view.hit_selection(ins, top), name="hitprims", width=4.0,
            list_empty=False))
        yield
        current()
        hits_view.add_hit_points(plotter, ins, np.arange(len(t)),
                                 labels=(stage == "evaluate"), camera=camera)
        if stage == "intersect":
            yield
            current()
            hits_view.add_normals(plotter, ins, top[: stage_text.NORMAL_ROWS], camera=camera)
    else:
        hits_view.add_query_ray(plotter, ins)
        rec, _ = recon(state)
        if rec is not None:
            members = member_primitives(ins, rec)
            yield
            current()
            if members:  # every member's surface through this path, with its weight
                hits_view.add_member_surfaces(plotter, ins, rec, members)
            else:  # a kernel estimator: no exact path, only its own primitive
                hits_view.add_hit_primitives(plotter, ins, [rec["row"]], opacity=0.6)
            yield
            current()
            hits_view.add_reconstruction(plotter, ins, rec, camera=camera)
    target = coverage_target(state) if state.coverage else None
    if target is not None:
        yield
        current()
        name, batch, prim = target
        primitives_view.add_primitives(plotter, ins, {(name, batch): np.array([prim])},
                                       opacity=0.3, name="coverage", legend=False, width=6.0,
                                       list_empty=False)


def _with(current, steps):
    """``steps`` (a generator drawing into the current renderer), with the 3D renderer made
    current again before each of its steps; returns its return value."""
    while True:
        try:
            next(steps)
        except StopIteration as stop:
            return stop.value
        yield
        current()


def _clear_bars(plotter: pv.Plotter, renderer) -> None:
    """Remove the colour bars drawn in ``renderer`` (the image panels keep theirs)."""
    for title in list(plotter.scalar_bars.keys()):
        if renderer.HasViewProp(plotter.scalar_bars[title]):
            plotter.remove_scalar_bar(title)
