"""How the window's state changes (building it, asking for an inspection, taking its answer,
attaching the panels' progressive render), and the off-screen twin of the window,
:func:`screenshot`. The state itself (:class:`ViewState`: scene, estimators side by side,
the inspected one, pixel, pass, stage, what the background processes computed) and which
estimators its panels show are :mod:`ui.views.view_state` (re-exported here). What each part
shows is :mod:`ui.views.compose` (:func:`compose`, re-exported here); the bindings (keys,
mouse, widgets, timer) and :func:`~ui.views.interactive.run`, which opens the window, are in
:mod:`ui.views.interactive`.
Nothing here handles an event, so another front end (the browser version) can keep a
:class:`ViewState` and compose the same pictures.

Layout (one pyvista Plotter, five renderers placed by :func:`ui.views.layout.window_layout`
for the window's size: title and caption, 3D view, stage panel on the left; the image
panels, renders above and variance maps below, on the right; the window's chips and buttons
in a footer). The image panels are :class:`ui.views.image_panels.PanelView` tiles of a
:class:`ui.cli.progressive.Progressive` render: in the window a background worker process,
polled by the timer without waiting; for :func:`screenshot` the same passes rendered in this
process. With several estimators they are shown side by side at equal time; the stages
inspect one of them (:attr:`ViewState.inspected`, default: the first MIS set), framed in the
panels. (A :class:`ViewState` without ``prog``, lecture mode, shows its own accumulator.)

The stages' numbers come from :mod:`psurf_core.inspect`, computed by a
:class:`ui.cli.inspector.Inspector` (a background process in the window, in this process for
screenshots); until they arrive the stage panel says "computing..." and the 3D view shows
the scene alone.

:func:`screenshot` composes what the window shows at a stage (without the on-screen
controls), off-screen and deterministically (same arguments, same picture: a fixed number of
passes, no wall seconds drawn).
"""

from __future__ import annotations

import os
from dataclasses import replace

import numpy as np

from psurf_core.accumulate import Welford
from psurf_core.estimators import parse_estimator
from psurf_core.render import RenderSettings, render
from psurf_core.scene_io import load_scene

from . import image_panels, primitives_view
from ._vtk import rendered_image
from .compose import (  # noqa: F401 - the window's composition, re-exported for its users
    CELL_3D,
    CELL_PANEL,
    CELL_RENDER,
    CELL_TITLE,
    CELL_VARIANCE,
    HELP,
    apply_layout,
    compose,
    compose_3d,
    compose_images,
    compose_panel,
    compose_title,
    make_plotter,
    panel_text,
    software_opengl,
    state_layout,
)
from .panel_modes import MODES
from .stage_text import coverage_target
from .stepper import DEFAULT_PASSES, DEFAULT_PHOTONS, DEFAULT_SIZE, stage_index
from .view_state import (  # noqa: F401 - the state and its panels' estimators, re-exported
    ViewState,
    _resolve_inspect,
    default_inspected,
    panel_estimator,
    panel_specs,
)


# --------------------------------------------------------------------------- state
def build_state(scene_path: str, estimator: str = "planes", seed: int = 0, pixel_xy=None,
                photons: int = DEFAULT_PHOTONS, passes: int = DEFAULT_PASSES, stage="trace",
                hit: int | None = None, pass_index: int = 0,
                coverage: bool = False, render_passes: bool = True, *,
                estimators=None, inspect=None, resolution=None,
                inspector_workers: int = 0, scene=None, inspector=None) -> ViewState:
    """Load the scene, render ``passes`` passes and inspect the pixel in pass ``pass_index``.

    ``estimators`` (specs, display order; default ``[estimator]``) are the image panels;
    ``inspect`` (an index or one of the specs; default the first MIS set) the one the stages
    inspect. ``resolution`` ``(W, H)`` overrides the scene's. ``render_passes=False`` leaves
    the accumulator empty (the progressive worker renders the passes).
    ``inspector_workers=1`` computes the inspection in a background process (the window):
    :attr:`ViewState.inspection` is None until :func:`accept_results` takes it.
    ``scene`` (a loaded scene, e.g. with the command line's scatter range; ``resolution`` is
    then ignored) replaces loading ``scene_path``; ``inspector`` (a started
    ``ui.cli.inspector.Inspector``) replaces starting one.

    Raises ``SceneError`` / ``UnknownTechnique`` / ``ValueError`` for bad input.
    """
    from ui.cli.common import with_resolution
    from ui.cli.inspector import Inspector

    if scene is None:
        scene = with_resolution(load_scene(scene_path), resolution)
    specs = tuple(estimators) if estimators else (str(estimator),)
    ests = [parse_estimator(s, scene) for s in specs]
    inspected = _resolve_inspect(inspect, list(specs), ests)
    cam = scene.camera
    if pixel_xy is None:
        pixel_xy = (cam.width // 2, cam.height // 2)
    if not (0 <= pixel_xy[0] < cam.width and 0 <= pixel_xy[1] < cam.height):
        raise ValueError(f"--pixel {pixel_xy[0]},{pixel_xy[1]}: outside the "
                         f"{cam.width}x{cam.height} image")
    passes = max(int(passes), 1)
    if not 0 <= int(pass_index) < passes:
        raise ValueError(f"--pass {pass_index}: the image panels hold passes 0..{passes - 1} "
                         f"(--passes {passes})")
    settings = RenderSettings(photons=int(photons), spp=1)
    est = ests[inspected]
    acc = (render(scene, est, settings, passes=passes, seed=seed).accumulator if render_passes
           else Welford.empty((cam.height, cam.width, 3)))
    st = ViewState(scene_path=str(scene_path), scene=scene, estimator=est, seed=int(seed),
                   settings=settings, pixel_xy=tuple(int(v) for v in pixel_xy),
                   acc=acc, inspection=None, initial_passes=passes,
                   pass_index=int(pass_index), specs=specs, inspected=inspected,
                   base_scene=scene,
                   inspector=inspector if inspector is not None else Inspector(inspector_workers))
    st.stepper.go(stage)
    reinspect(st, keep_hit=True)
    accept_results(st)
    if hit is not None:
        n = len(st.inspection.table) if st.inspection is not None else None
        if n == 0 and int(hit) > 0:
            raise ValueError(f"--hit {hit}: the pixel has no hit in pass {pass_index}")
        if n and not 0 <= int(hit) < n:
            raise ValueError(f"--hit {hit}: the pixel has {n} hits in pass {pass_index} "
                             f"(valid: 0..{n - 1})")
        st.hit = int(hit)
    if coverage:
        st.coverage = True
        update_coverage(st)
        accept_results(st)
    return st


def update_coverage(state: ViewState) -> None:
    """Ask for the coverage (primitive -> pixels) of the current target in the current pass;
    :attr:`ViewState.coverage_mask` is None until it arrives (and when coverage is off)."""
    from ui.cli.inspector import CoverageRequest

    state.coverage_mask = None
    target = coverage_target(state) if state.coverage else None
    if target is None:
        if state.inspector is not None:
            state.inspector.cancel("coverage")
        return
    name, batch, prim = target
    state.inspector.submit(CoverageRequest(state.scene, state.estimator.spec, state.seed,
                                           state.pass_index, name, prim, batch,
                                           state.settings))


def reinspect(state: ViewState, *, keep_hit: bool = False) -> None:
    """Ask for the picked pixel's inspection in :attr:`ViewState.pass_index` again (after the
    pixel, the pass, the scene or the estimator changed). The stages show "computing..."
    until it arrives; the hit selection and a 3D pick are reset."""
    from ui.cli.inspector import PixelRequest

    state.inspection = None
    state.coverage_mask = None
    if not keep_hit:
        state.hit = 0
    state.coverage_pick = None
    state.inspector.cancel("coverage")
    state.inspector.submit(PixelRequest(state.scene, state.estimator.spec, state.seed,
                                        state.pass_index, state.pixel_xy, state.settings))


def accept_results(state: ViewState) -> bool:
    """Take the inspector's new answers into the state; True when the stages changed."""
    if state.inspector is None:
        return False
    changed = False
    for res in state.inspector.poll():
        changed = True
        if res.error is not None:
            state.message = f"inspection failed: {res.error}"
            continue
        if res.kind == "pixel":
            state.inspection = replace(res.value, scene=state.scene)
            n = len(state.inspection.table)
            state.hit = min(max(state.hit, 0), max(n - 1, 0))
            if state.coverage:
                update_coverage(state)
        else:
            state.coverage_mask = res.value
    for text in state.inspector.take_notices():
        state.message, changed = text, True
    return changed


# --------------------------------------------------------------------------- public API
def screenshot(scene_path: str, stage: str, pixel_xy, estimator: str = "planes", seed: int = 0,
               out: str = "shot.png", size=DEFAULT_SIZE, passes: int = DEFAULT_PASSES,
               hit: int | None = None, photons: int = DEFAULT_PHOTONS,
               n_paths: int = primitives_view.DEFAULT_PATHS, pass_index: int = 0,
               coverage: bool = False, estimators=None, mode: str = "render",
               reference: str | None = None, inspect=None, resolution=None,
               focus: str = "split", seconds: float | None = None) -> np.ndarray:
    """Render what the window shows at ``stage`` off-screen and write it to ``out`` (PNG).

    Parameters
    ----------
    stage : {'trace', 'create', 'intersect', 'evaluate', 'reconstruct'}
    pixel_xy : (int, int)
        Picked pixel ``(X, Y)``: column from the left, row from the top.
    estimators : sequence of str, optional
        The image panels' estimators side by side (the window's ``--estimators``; default
        ``[estimator]``); each gets ``passes`` passes here (the window: equal time).
    inspect : int or str, optional
        Which of them the stages inspect (default: the first MIS set).
    passes : int
        Passes of the progressive render shown in the image panels.
    seconds : float, optional
        Render the panels at equal time instead: every estimator this many seconds (the
        picture then shows the seconds and depends on the machine).
    hit : int, optional
        Which hit Reconstruct (and coverage) use, as numbered ``#i`` in the evaluate table
        (largest contribution first); default 0.
    pass_index : int
        The inspected pass, ``0 <= pass_index < passes`` (the window's ``,`` / ``.``).
    coverage : bool
        Tint the pixels the selected hit's primitive contributes to on the render panel
        (the window's ``c``).
    mode : {'render', 'techniques', 'bounces'}
        Image-panel mode (the window's ``m``).
    reference : str, optional
        An ``app.py render`` .npz of this scene: relMSE is shown under each estimator.
    resolution : (int, int), optional
        Override the scene's resolution.
    focus : {'split', 'images', '3d'}
        The layout (the window's ``z``).

    Returns
    -------
    (H, W, 3) uint8
        The image written.
    """
    stage_index(stage)
    if mode not in MODES:
        raise ValueError(f"unknown panel mode '{mode}' (expected one of: {', '.join(MODES)})")
    state = build_state(scene_path, estimator, seed, pixel_xy, photons, passes, stage, hit,
                        pass_index=pass_index, coverage=coverage, render_passes=False,
                        estimators=estimators, inspect=inspect, resolution=resolution)
    state.n_paths = int(n_paths)
    state.mode, state.focus = mode, focus
    state.reference = load_reference_image(reference, state.scene)
    # The window's panels, rendered here pass by pass (workers=0: deterministic, and
    # bit-identical to a serial render of the same seed).
    attach_progressive(state, workers=0, breakdown=(mode != "render"),
                       max_seconds=seconds)
    if seconds is None:
        state.prog.run(passes=state.initial_passes)
        for r in state.prog.runs:
            # Wall seconds differ from run to run; a screenshot compares at equal passes so
            # the same arguments always give the same picture.
            r.seconds = 0.0
    else:
        state.prog.run()
    state.acc = state.prog.runs[state.inspected].acc
    plotter = make_plotter(size, off_screen=True)
    try:
        compose(plotter, state)
        img = rendered_image(plotter)
    finally:
        plotter.close()
        state.prog.close()
        state.inspector.close()
    import imageio.v3 as iio

    d = os.path.dirname(os.path.abspath(out))
    os.makedirs(d, exist_ok=True)
    iio.imwrite(out, img)
    return img


def attach_progressive(state: ViewState, workers: int = 1, breakdown: bool = True,
                       max_seconds: float | None = None, prog=None) -> None:
    """Render the panels progressively (``ui.cli.progressive``: ``workers`` background processes,
    0 = in the timer tick) into ``image_panels.PanelView`` tiles; starts playing.

    ``prog``: a ``Progressive`` started already on this state's scene, estimators, settings
    and seed (the window starts its worker before VTK is imported: the first picture comes
    sooner); it must render what the panels show.
    """
    from ui.cli.progressive import Progressive

    if prog is not None:
        prog.set_breakdown(breakdown)
        j = prog.job
        if (list(j.specs), j.settings, j.seed) != (panel_specs(state), state.settings,
                                                   state.seed):
            raise ValueError(f"the started render ({', '.join(j.specs)}, seed {j.seed}) is "
                             "not what the window shows")
        state.prog = prog
    else:
        state.prog = Progressive(state.scene, panel_specs(state), state.settings,
                                 seed=state.seed, workers=workers, breakdown=breakdown,
                                 max_seconds=max_seconds)
    state.panels = image_panels.PanelView()
    state.acc = state.prog.runs[state.inspected].acc
    state.playing = True


def load_reference_image(path: str | None, scene) -> np.ndarray | None:
    """The ``mean`` (H, W, 3) of a reference .npz for ``scene`` (None without a path).

    Raises ``SceneError`` naming the file for a missing/unreadable file, another resolution
    or scatter range (``psurf_core.study.load_reference``).
    """
    if path is None:
        return None
    from ui.cli.common import load_reference

    return load_reference(os.fspath(path), scene).mean
