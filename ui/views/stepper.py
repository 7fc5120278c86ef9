"""The stage machine of the window and the lecture: trace -> create -> intersect -> evaluate
-> reconstruct, with each stage's title and caption; and the window's defaults.

Plain Python (no rendering, no VTK): the window asks it which stage is current and what to
say, and the ``screenshot`` command (:mod:`ui.cli.screenshot`) takes its stage names and
defaults from here without importing the views.
"""

from __future__ import annotations

from dataclasses import dataclass

#: Photons per pass in the window (a 64 x 48 scene stays interactive).
DEFAULT_PHOTONS = 2000
#: Passes rendered before the window opens.
DEFAULT_PASSES = 4
#: Window size in pixels (the design size: fonts and lines scale with the height).
DEFAULT_SIZE = (1600, 900)

STAGES = ("trace", "create", "intersect", "evaluate", "reconstruct")

TITLES = {
    "trace": "1 Trace: photon subpaths from the lights",
    "create": "2 Create: sweep each photon into primitives",
    "intersect": "3 Intersect: the query ray meets the primitives",
    "evaluate": "4 Evaluate: each hit's contribution",
    "reconstruct": "5 Reconstruct: the full path of one hit",
}

#: One or two sentences per stage, for the caption under the 3D view.
CAPTIONS = {
    "trace": ("Photons leave the lights and fly through the medium as if it were infinite; "
              "each segment is coloured by the scatter event it ends at. The box only clips "
              "what is drawn."),
    "create": ("Integrating two of a photon's sampled dimensions turns its last vertices into "
               "a swept primitive (a plane, sphere, cone, ...), one per scatter count K."),
    "intersect": ("The camera ray through the picked pixel is intersected with every "
                  "primitive: each root is a full light path ending on the ray at distance s. "
                  "Arrows: the ray direction psi (grey) and the scaled normal n (black)."),
    "evaluate": ("Each hit contributes f / (q |n.psi|); grazing hits (small |n.psi|) are "
                 "large. The contributions of all hits sum exactly to the pixel's value in "
                 "this pass."),
    "reconstruct": ("The hit fixes the integrated dimensions, so the whole path is known; "
                    "every technique of the MIS set evaluates its density Q on that same path "
                    "and the hit is weighted by Q_i / sum Q_j."),
}


def stage_index(stage: str) -> int:
    """Index of ``stage`` in :data:`STAGES`; ``ValueError`` naming the valid ones."""
    try:
        return STAGES.index(stage)
    except ValueError:
        raise ValueError(f"unknown stage '{stage}' (expected one of: "
                         f"{', '.join(STAGES)})") from None


@dataclass
class Stepper:
    """Current stage, stepping forwards and backwards (clamped at both ends)."""

    index: int = 0

    @property
    def stage(self) -> str:
        return STAGES[self.index]

    @property
    def title(self) -> str:
        return TITLES[self.stage]

    @property
    def caption(self) -> str:
        return CAPTIONS[self.stage]

    def next(self) -> str:
        self.index = min(self.index + 1, len(STAGES) - 1)
        return self.stage

    def previous(self) -> str:
        self.index = max(self.index - 1, 0)
        return self.stage

    def reset(self) -> str:
        self.index = 0
        return self.stage

    def go(self, stage: str) -> str:
        self.index = stage_index(stage)
        return self.stage
