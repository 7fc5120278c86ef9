"""``python app.py screenshot``: one stage of the window, rendered off-screen to a PNG.

``app.py`` wires it in with::

    from ui.cli.screenshot import add_screenshot_parser
    add_screenshot_parser(subparsers)      # sets func=run_screenshot

``run_screenshot(args)`` returns the exit code; every bad input is one line
``psurf: error: ...`` on stderr and exit code 2, before anything is written. The picture is
:func:`ui.views.window.screenshot`'s, imported (with VTK) only to draw it.
"""

from __future__ import annotations

import argparse
import os

from ui.views.stepper import DEFAULT_PASSES, DEFAULT_PHOTONS, STAGES

from .common import (
    CliError,
    explain_estimator_error,
    fail,
    nonneg_int,
    pixel,
    positive_int,
    resolution,
    window_size,
    with_resolution,
)
from .limits import check_memory, load_scene_within, probe_writable


def add_screenshot_parser(subparsers) -> argparse.ArgumentParser:
    """Add the ``screenshot`` subcommand to ``subparsers`` (``func=run_screenshot``)."""
    p = subparsers.add_parser(
        "screenshot",
        help="render one stage of the interactive window off-screen to a PNG",
        description=("Render what the window shows at one stage (trace, create, intersect, "
                     "evaluate, reconstruct) for a picked pixel, off-screen and "
                     "deterministically (same arguments, same picture)."),
    )
    p.add_argument("scene", metavar="SCENE.toml", help="scene file")
    p.add_argument("--stage", required=True, choices=STAGES, help="stage to show")
    p.add_argument("--pixel", required=True, type=pixel, metavar="X,Y",
                   help="picked pixel: X column from the left, Y row from the top")
    p.add_argument("--estimator", default="planes", metavar="SPEC",
                   help="photon estimator (default: planes; e.g. mis:planes+plane-t1t2)")
    p.add_argument("--seed", type=nonneg_int, default=0, help="random seed (default: 0)")
    p.add_argument("--out", required=True, metavar="shot.png", help="PNG to write")
    p.add_argument("--size", type=window_size, default=(1600, 900), metavar="W,H",
                   help="picture (window) size in pixels (default: 1600,900)")
    p.add_argument("--passes", type=positive_int, default=DEFAULT_PASSES, metavar="P",
                   help=f"passes in the render panels (default: {DEFAULT_PASSES})")
    p.add_argument("--photons", type=positive_int, default=DEFAULT_PHOTONS, metavar="N",
                   help=f"photons per pass (default: {DEFAULT_PHOTONS})")
    p.add_argument("--hit", type=nonneg_int, default=None, metavar="K",
                   help="reconstruct and --coverage: the hit numbered #K in the evaluate "
                        "table (default 0)")
    p.add_argument("--pass", dest="pass_index", type=nonneg_int, default=0, metavar="N",
                   help="the inspected pass, 0 <= N < --passes (default: 0)")
    p.add_argument("--estimators", default=None, metavar="A,B",
                   help="image panels: these estimators side by side (replaces --estimator; "
                        "each gets --passes passes; Var ratios relative to the first)")
    p.add_argument("--inspect", default=None, metavar="SPEC",
                   help="which of --estimators the stages inspect (default: the first MIS "
                        "set)")
    p.add_argument("--resolution", type=resolution, default=None, metavar="W,H",
                   help="render at W x H pixels instead of the scene's resolution")
    p.add_argument("--layout", default="split", choices=("split", "images", "3d"),
                   help="how the width is shared (the window's z key; default: split)")
    p.add_argument("--mode", default="render", choices=("render", "techniques", "bounces"),
                   help="image-panel mode (the window's m key; default: render)")
    p.add_argument("--reference", default=None, metavar="FILE.npz",
                   help="an app.py render .npz of this scene: relMSE under each render")
    p.add_argument("--coverage", action="store_true",
                   help="tint the pixels the selected hit's primitive contributes to "
                        "(primitive -> pixels) on the render panel")
    p.set_defaults(func=run_screenshot)
    return p


def _check_memory(args, scene, specs) -> None:
    """The window's progressive panels, the stages' record of one whole pass (every photon)
    and the picture, against the memory available, before anything renders."""
    from dataclasses import replace

    from psurf_core.budget import picture_bytes, progressive_need
    from psurf_core.estimators import parse_estimator
    from psurf_core.render import RenderSettings

    ests = [parse_estimator(s, scene) for s in specs]
    need = progressive_need(scene, ests, RenderSettings(photons=args.photons), workers=0,
                            breakdown=args.mode != "render", inspect=True)
    check_memory(replace(need, extra=need.extra + (picture_bytes(*args.size),)), None,
                 what="the screenshot")


def run_screenshot(args) -> int:
    """Run ``screenshot``; returns 0, or 2 after one ``psurf: error:`` line."""
    from psurf_core.estimators import parse_estimator
    from psurf_core.scene import SceneError
    from psurf_core.techniques import UnknownTechnique

    out = args.out
    if not out.lower().endswith(".png"):
        return fail(f"--out {out}: must end in .png")
    d = os.path.dirname(os.path.abspath(out))
    if not os.path.isdir(d):
        return fail(f"--out {out}: directory {d} does not exist")
    if os.path.isdir(out):
        return fail(f"--out {out}: is a directory")
    specs = [args.estimator]
    if args.estimators is not None:
        specs = [e.strip() for e in args.estimators.split(",")]
        if any(not e for e in specs):
            return fail(f"--estimators {args.estimators}: must be a comma-separated list of "
                         "estimator specs")
    flag = "--estimators" if args.estimators is not None else "--estimator"
    try:
        # meshes checked before they load
        scene = with_resolution(load_scene_within(args.scene, None), args.resolution)
        ests = [parse_estimator(spec, scene) for spec in specs]
    except (SceneError, CliError) as e:
        return fail(str(e))
    except UnknownTechnique as e:
        return fail(f"{flag}: {explain_estimator_error(e)}")
    if args.inspect is not None and args.inspect not in specs:
        return fail(f"--inspect {args.inspect}: not one of {flag} ({', '.join(specs)})")
    if all(e.reference for e in ests) or (args.inspect is not None
                                           and ests[specs.index(args.inspect)].reference):
        return fail(f"{flag} reference: the stages need a photon estimator "
                     "(the path tracer has no photons or primitives)")
    cam = scene.camera
    x, y = args.pixel
    if not (x < cam.width and y < cam.height):
        return fail(f"--pixel {x},{y}: outside the {cam.width}x{cam.height} image "
                     f"(X in 0..{cam.width - 1}, Y in 0..{cam.height - 1})")
    if args.pass_index >= args.passes:
        return fail(f"--pass {args.pass_index}: the image panels hold passes "
                     f"0..{args.passes - 1} (--passes {args.passes})")
    try:
        _check_memory(args, scene, specs)
    except CliError as e:
        return fail(str(e))
    try:
        probe_writable("--out", out, d)
    except CliError as e:
        return fail(str(e))
    try:
        from ui.views._vtk import pv

        pv.OFF_SCREEN = True
        from ui.views.window import screenshot

        screenshot(args.scene, args.stage, (x, y), specs[0], args.seed, out,
                   size=tuple(args.size), passes=args.passes, hit=args.hit,
                   photons=args.photons, pass_index=args.pass_index, coverage=args.coverage,
                   estimators=specs, mode=args.mode, reference=args.reference,
                   inspect=args.inspect, resolution=args.resolution, focus=args.layout)
    except (SceneError, UnknownTechnique, ValueError) as e:
        return fail(explain_estimator_error(e))
    except (ImportError, RuntimeError) as e:
        return fail(f"off-screen rendering is unavailable ({type(e).__name__}: {e}); "
                     "it needs VTK with EGL or OSMesa (libegl1 / libosmesa6)")
    print(f"wrote {out}")
    return 0
