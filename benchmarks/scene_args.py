"""The arguments every scatter-range benchmark takes: ``SCENE.toml KMIN KMAX`` and
``--resolution W,H``, and the scene they name.

One home for the preamble the benchmarks below repeated (``ablation``, ``cone_misses``,
``coverage_floor``, ``member_cost``, ``pass_phases``, ``pass_wall_cpu``, ``photon_qmc``,
``pilot_choice``, ``tail_share``): the study's comparisons run at the scenes' 64x48 and at
256x192, and every benchmark measuring them can render at either (the flag and its
application are the command line's own, :func:`ui.cli.common.add_resolution_flag` and
:func:`ui.cli.common.with_resolution`).
"""

from __future__ import annotations

import argparse

from psurf_core.scene import Scene
from psurf_core.scene_io import load_scene
from ui.cli.common import add_resolution_flag, with_resolution


def add_scene_args(ap: argparse.ArgumentParser) -> None:
    """Positional ``scene kmin kmax`` and ``--resolution W,H`` on ``ap``."""
    ap.add_argument("scene", help="scene file (SCENES.md)")
    ap.add_argument("kmin", type=int, help="fewest scatterings a path in the image has")
    ap.add_argument("kmax", type=int, help="most scatterings a path in the image has")
    add_resolution_flag(ap)


def scene_of(args: argparse.Namespace) -> Scene:
    """The scene ``args`` name (:func:`add_scene_args`): its scatter range ``kmin..kmax``,
    at ``--resolution`` where given."""
    return with_resolution(load_scene(args.scene).with_scatter(args.kmin, args.kmax),
                           args.resolution)
