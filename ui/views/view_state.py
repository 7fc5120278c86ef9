"""The window's state, :class:`ViewState` (scene, estimators side by side, the inspected one,
pixel, pass, stage, what the background processes computed), and which estimators its image
panels show: the specs as opened less the members switched off (:func:`panel_specs`,
:func:`panel_estimator`) and the one the stages inspect by default (:func:`default_inspected`).

Plain data and queries on it: nothing here starts a background process, draws or handles an
event. Building a state and changing it (asking for an inspection, taking its answer,
attaching the progressive render) is :mod:`ui.views.window`, which re-exports these names.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from psurf_core.accumulate import Welford
from psurf_core.estimators import parse_estimator
from psurf_core.render import RenderSettings

from . import controls, primitives_view
from .panel_modes import VarScale
from .stepper import CAPTIONS, DEFAULT_PASSES, Stepper


@dataclass
class ViewState:
    """Everything one picture of the window depends on."""

    scene_path: str
    scene: object
    estimator: object  # the inspected estimator (its members switched off left out)
    seed: int
    settings: RenderSettings
    pixel_xy: tuple
    acc: Welford
    inspection: object  # PixelInspection, or None while it is computed
    stepper: Stepper = field(default_factory=Stepper)
    hit: int = 0  # display index (table sorted by contribution)
    n_paths: int = primitives_view.DEFAULT_PATHS
    show_help: bool = False
    playing: bool = False
    message: str = ""
    initial_passes: int = DEFAULT_PASSES
    #: The pass the stages inspect (one of the passes the image panels include).
    pass_index: int = 0
    #: Coverage (primitive -> pixels) shown on the render panel.
    coverage: bool = False
    #: ``(technique, batch, prim)`` picked in the 3D view; None: the selected hit's primitive.
    coverage_pick: tuple | None = None
    #: (H, W) bool pixels of the coverage primitive (row 0 at the top), or None.
    coverage_mask: np.ndarray | None = None
    #: The estimator specs of the image panels as opened (display order), the one the stages
    #: inspect, and per panel the members switched off since.
    specs: tuple = ()
    inspected: int = 0
    disabled_by: dict = field(default_factory=dict)
    #: The scene as loaded (the medium sliders change copies of it).
    base_scene: object = None
    #: The window's progressive renderer (``ui.cli.progressive.Progressive``) and its panels
    #: (``ui.views.image_panels.PanelView``); None: the panels show :attr:`acc` (lecture).
    prog: object = None
    panels: object = None
    #: Image-panel mode (``panel_modes.MODES``, the ``m`` key).
    mode: str = "render"
    #: Ground truth (H, W, 3) for relMSE in the render panels (``--reference FILE.npz``).
    reference: np.ndarray | None = None
    #: Computes the stages' inspections (``ui.cli.inspector.Inspector``).
    inspector: object = None
    #: The variance maps' shared colour scale, or a pinned range (lecture states).
    var_scale: VarScale = field(default_factory=VarScale)
    var_clim: tuple | None = None
    #: Layout: ``ui.views.layout.FOCI`` (the ``z`` key), footer rows (the window's chips and
    #: buttons; 0 in screenshots), the slider block, the longest caption to make room for.
    focus: str = "split"
    footer_rows: int = 0
    sliders_on: bool = False
    caption_chars: int = max(len(c) for c in CAPTIONS.values())
    #: The hint at the top right (lecture mode puts its counter there); None: the stage's.
    hint: str | None = None
    #: What the 3D camera was last framed for (auto-zoom of Reconstruct); see ``compose``; a
    #: pinned camera ``(position, focal point, view up)`` (lecture states) instead.
    framed: tuple | None = None
    camera_pin: tuple | None = None
    layout: object = None
    #: The 3D scene's actors (kept while only the stage changes) and what they show.
    scene_actors: set = field(default_factory=set)
    scene_key: tuple | None = None
    #: What the title and the stage panel were last drawn from (``compose``: a part whose
    #: key is unchanged is left as it is); whether the last ``compose_panel`` changed it.
    title_key: tuple | None = None
    panel_key: tuple | None = None
    panel_size: tuple | None = None
    panel_changed: bool = True

    @property
    def stage(self) -> str:
        return self.stepper.stage

    @property
    def base_spec(self) -> str:
        """The inspected panel's spec as opened (before members were switched off)."""
        return self.specs[self.inspected] if self.specs else self.estimator.spec

    @property
    def disabled(self) -> frozenset:
        """Members of the inspected estimator switched off."""
        return self.disabled_by.get(self.inspected, frozenset())



# --------------------------------------------------------------------------- estimators
def default_inspected(ests) -> int:
    """The panel the stages inspect by default: the first MIS set (a group of two or more
    techniques), else the first photon estimator."""
    photon = [i for i, e in enumerate(ests) if not e.reference]
    if not photon:
        raise ValueError("the stages need a photon estimator; 'reference' (the path tracer) "
                         "has no photons, primitives or hits")
    mis = [i for i in photon if any(len(g) > 1 for g in ests[i].groups)]
    return (mis or photon)[0]


def _resolve_inspect(inspect, specs, ests) -> int:
    if inspect is None:
        return default_inspected(ests)
    i = specs.index(inspect) if isinstance(inspect, str) and inspect in specs else inspect
    if not isinstance(i, int) or not 0 <= i < len(specs):
        raise ValueError(f"--inspect {inspect}: not one of the estimators ({', '.join(specs)})")
    if ests[i].reference:
        raise ValueError(f"--inspect {specs[i]}: the stages need a photon estimator (the path "
                         "tracer has no photons, primitives or hits)")
    return i


def panel_estimator(state: ViewState, i: int):
    """Panel ``i``'s estimator: its spec as opened without the members switched off."""
    spec = state.specs[i]
    off = state.disabled_by.get(i, frozenset())
    if not off:
        return parse_estimator(spec, state.scene)
    return controls.estimator_with(spec, state.scene, off)


def panel_specs(state: ViewState) -> list:
    """Estimator specs of the image panels in display order (members switched off left out:
    ``SPEC~A``)."""
    if not state.specs:
        return [state.estimator.spec]
    return [panel_estimator(state, i).spec for i in range(len(state.specs))]
