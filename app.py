"""psurf command line: ``render`` a scene to .npz/.png/.exr, or run the ``demo``.

A thin layer over :mod:`psurf_core` (argument parsing, progress, writing files); the core never
imports it. Every subcommand but ``demo`` lives in :mod:`ui.cli` (``render`` in
:mod:`ui.cli.render`, the flag types and output helpers shared here in :mod:`ui.cli.common`);
this file builds the parser and owns ``demo``. Every bad input ends with one line
``psurf: error: <what>`` on stderr and exit code 2, before anything is written.
"""

from __future__ import annotations

import argparse
import os
import sys
import textwrap

from ui.cli.common import CliError, OutputWriteError, Parser
from ui.cli.common import nonneg_int as _nonneg_int
from ui.cli.common import note as _note
from ui.cli.common import npz_writer as _npz_writer
from ui.cli.common import pixel as _pixel
from ui.cli.common import plural as _plural
from ui.cli.common import png_writer as _png_writer
from ui.cli.common import positive_float as _positive_float
from ui.cli.common import positive_int as _positive_int
from ui.cli.common import progress as _progress
from ui.cli.common import write_all as _write_all
from ui.cli.compare import add_compare_parser
from ui.cli.lecture import add_lecture_parser
from ui.cli.parallel import WorkersLost
from ui.cli.record import add_record_parsers
from ui.cli.render import (  # noqa: F401 - DEFAULT_* are part of app's interface
    DEFAULT_PASSES,
    DEFAULT_PHOTONS,
    DEFAULT_SEED,
    DEFAULT_SPP,
    add_render_parser,
    cmd_render,
)
from ui.cli.render import initial_radius as _initial_radius
from ui.cli.render import npz_payload as _npz_payload
from ui.cli.screenshot import add_screenshot_parser
from ui.cli.serve import add_serve_parser

PROG = "psurf"

#: Defaults of ``demo``.
# The bundled default scene, found next to this file whatever the working directory.
DEMO_SCENE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "scenes", "area.toml")
DEMO_OUT = "out"
DEMO_SECONDS = 10.0
DEMO_ESTIMATORS = ("planes", "reference")

_ROOT = os.path.dirname(os.path.abspath(__file__))


# --------------------------------------------------------------------------- parser


def _estimator_help() -> str:
    try:
        from psurf_core.estimators import estimator_help

        text = estimator_help()
    except Exception as e:  # --help must work even while a technique module is broken
        text = f"(estimator list unavailable: {type(e).__name__}: {e})"
    return "\n".join("  " + line for line in text.splitlines())


def build_parser() -> Parser:
    """The ``psurf`` argument parser (``render`` and ``demo`` subcommands)."""
    from psurf_core import __version__

    estimators = _estimator_help()
    top = Parser(
        prog=PROG,
        allow_abbrev=False,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=textwrap.dedent("""\
            Unbiased volumetric photon density estimation (photon surfaces, Deng et al. 2019).

            subcommands:
              render SCENE.toml --estimator NAME --out OUT.npz   render a scene progressively
              demo [SCENE.toml] [--out DIR]                      interactive app, or (without a
                                                                 display) planes vs reference
                                                                 images in DIR
              screenshot SCENE.toml --stage STAGE --pixel X,Y    one step of the app, off-screen
              compare SCENE.toml --estimators A,B --time S       equal-time variance study
              lecture [--state N] [--screenshot OUT.png]         the tutorials' key states,
                                                                 full-screen (-> / <-)
              record SCENE.toml --estimators A,B --passes N      GIF/MP4 of the converging
                     --out conv.gif [--mode render|techniques|bounces]   image panels
              breakdown SCENE.toml --estimator SPEC --out DIR    per-technique, weight and
                                                                 per-K PNGs of an MIS set
              serve [SCENE.toml] [--port 8080] [--host H]        the app as a web page, one
                                                                 session per browser tab

            Run 'python app.py render --help' for the render options."""),
        epilog=f"estimators (--estimator NAME):\n{estimators}",
    )
    top.add_argument("--version", action="version", version=f"{PROG} {__version__}")
    sub = top.add_subparsers(
        dest="command", parser_class=Parser,
        metavar="{render,demo,screenshot,compare,lecture,record,breakdown,serve}")

    add_render_parser(sub, estimators)  # with --dask/--workers/--jobs

    d = sub.add_parser(
        "demo",
        allow_abbrev=False,
        help="open the interactive app, or write planes vs reference images",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=textwrap.dedent(f"""\
            With a display (DISPLAY or WAYLAND_DISPLAY, and pyvista can open a window) and
            the interactive app (ui.views.window) installed: open it on SCENE. Otherwise render
            SCENE with {' and '.join(DEMO_ESTIMATORS)} (about {DEMO_SECONDS:g} s each, the
            scene's scatter range) and write into DIR: render_<est>.png/.npz,
            variance_<est>.png (log-scale viridis) and comparison.png; then print a summary."""),
    )
    d.add_argument("scene", nargs="?", default=None, metavar="SCENE.toml",
                   help=f"scene file (default {DEMO_SCENE})")
    d.add_argument("--out", default=DEMO_OUT, metavar="DIR",
                   help=f"output directory, created if missing (default {DEMO_OUT}/)")
    d.add_argument("--estimators", default=None, metavar="A,B",
                   help="window: estimators rendered side by side at equal time (the first "
                        "is the one the stages inspect; default planes)")
    d.add_argument("--reference", default=None, metavar="FILE.npz",
                   help="window: an app.py render .npz of SCENE; relMSE under each render")
    d.add_argument("--pixel", default=None, type=_pixel, metavar="X,Y",
                   help="window: the pixel the stages inspect (X column from the left, Y row "
                        "from the top; default the centre)")
    d.add_argument("--no-window", action="store_true",
                   help="never open the interactive app; always write the images")
    # Hidden knobs for tests and quick looks.
    d.add_argument("--seconds", type=_positive_float, default=DEMO_SECONDS,
                   help=argparse.SUPPRESS)
    d.add_argument("--photons", type=_positive_int, default=DEFAULT_PHOTONS,
                   help=argparse.SUPPRESS)
    d.add_argument("--seed", type=_nonneg_int, default=DEFAULT_SEED, help=argparse.SUPPRESS)
    d.set_defaults(func=cmd_demo)

    add_screenshot_parser(sub)  # one stage of the window, off-screen
    add_compare_parser(sub)  # equal-time study
    add_lecture_parser(sub)  # lecture mode: the tutorials' key states
    add_record_parsers(sub)  # record (GIF/MP4), breakdown (MIS PNGs)
    add_serve_parser(sub)  # the web page (ui.web)
    return top


# --------------------------------------------------------------------------- demo


def _interactive_run():
    """``ui.views.interactive.run`` when a display, pyvista and the app are all available, else
    None."""
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        return None
    import importlib
    import importlib.util

    try:
        if importlib.util.find_spec("ui.views.interactive") is None:
            return None
        run = getattr(importlib.import_module("ui.views.interactive"), "run", None)
    except ImportError:
        return None
    if not callable(run):
        return None
    try:
        from ui.views._vtk import pv

        if not pv.system_supports_plotting():
            return None
    except Exception:
        return None
    return run


def _demo_scene_path(arg: str | None) -> str:
    if arg is not None:
        return arg
    if os.path.exists(DEMO_SCENE):
        return DEMO_SCENE
    return os.path.join(_ROOT, DEMO_SCENE)


def _k_range(scene, min_k: int = 1) -> str:
    lo = max(scene.min_scatter, min_k)
    return f"K in [{lo}, {'inf' if scene.max_scatter == -1 else scene.max_scatter}]"


def _window_specs(text: str | None, scene) -> list | None:
    """``--estimators A,B`` checked before the window opens (the first needs photons)."""
    if not text:
        return None
    from psurf_core import parse_estimator

    specs = [e.strip() for e in text.split(",")]
    try:
        if any(not e for e in specs) or parse_estimator(specs[0], scene).reference:
            raise ValueError(f"must be estimator specs A,B with a photon estimator first "
                             f"(the one the stages inspect), got {text!r}")
        for e in specs[1:]:
            parse_estimator(e, scene)
    except ValueError as e:
        raise CliError(f"--estimators: {e}") from None
    return specs


def _check_demo_memory(scene, specs, photons: int) -> None:
    """The window (its estimators, breakdown stacks, the stages' record of a whole pass, one
    background process) and the headless renders must fit in the memory available."""
    from psurf_core import RenderSettings, parse_estimator
    from psurf_core.budget import progressive_need, render_need
    from ui.cli.limits import check_memory

    settings = RenderSettings(photons=photons)
    ests = [parse_estimator(s, scene) for s in (specs or ["planes"])]
    check_memory(progressive_need(scene, ests, settings, workers=1, breakdown=True,
                                  inspect=True), None, what="the demo")
    for name in DEMO_ESTIMATORS:
        try:
            est = parse_estimator(name, scene)
        except Exception:  # skipped with a note by the demo itself
            continue
        check_memory(render_need(scene, est, settings), None, what=f"the demo's {name} render")


def cmd_demo(args) -> int:
    from ui.cli.limits import load_scene_within

    scene_path = _demo_scene_path(args.scene)
    scene = load_scene_within(scene_path, None)  # meshes checked before they load
    specs = _window_specs(args.estimators, scene)
    _check_demo_memory(scene, specs, args.photons)
    if args.pixel is not None:
        x, y = args.pixel
        cam = scene.camera
        if not (x < cam.width and y < cam.height):
            raise CliError(f"--pixel {x},{y}: outside the {cam.width}x{cam.height} image "
                           f"(X in 0..{cam.width - 1}, Y in 0..{cam.height - 1})")
    if args.reference is not None:
        from psurf_core.study import load_reference

        load_reference(args.reference, scene)  # SceneError naming the file, before any window
    if not args.no_window:
        run = _interactive_run()
        if run is not None:
            run(scene_path, estimators=specs, reference=args.reference,
                pixel_xy=args.pixel)
            return 0
    if os.path.exists(args.out) and not os.path.isdir(args.out):
        raise CliError(f"--out {args.out}: exists and is not a directory")
    try:
        os.makedirs(args.out, exist_ok=True)
    except OSError as e:
        raise CliError(f"--out {args.out}: cannot create directory ({e.strerror})") from None
    return _demo_offline(scene, args)


def _demo_offline(scene, args) -> int:
    """Render the demo estimators, write their images and the comparison, print a summary."""
    from psurf_core import RenderSettings, SceneError, parse_estimator
    from psurf_core import images as im
    from psurf_core.render import render

    settings = RenderSettings(photons=args.photons, spp=1)
    results, ests, written = {}, {}, []
    for name in DEMO_ESTIMATORS:
        try:
            est = parse_estimator(name, scene)
        except (SceneError, ValueError, ModuleNotFoundError) as e:
            _note(f"demo: skipping '{name}': {e}")
            continue
        on_pass, close = _progress(f"demo {name}", None, args.seconds)
        try:
            res = render(scene, est, settings, time_budget=args.seconds, seed=args.seed,
                         on_pass=on_pass)
        finally:
            close()
        results[name], ests[name] = res, est
        lum_var = im.luminance(res.var)
        lo, hi = im.log_range(lum_var)
        title = (f"{name}, {_k_range(scene, _min_k(est))}: per-pass variance, "
                 f"{res.passes} passes" + (" (1 pass: no estimate)" if res.passes < 2 else ""))
        rpng = os.path.join(args.out, f"render_{name}.png")
        vpng = os.path.join(args.out, f"variance_{name}.png")
        npz = os.path.join(args.out, f"render_{name}.npz")
        _write_all([
            (rpng, _png_writer(res.mean)),
            (vpng, lambda tmp, v=lum_var, lo=lo, hi=hi, t=title: im.figure_png(
                tmp, [{"image": v, "values": v, "vmin": lo, "vmax": hi, "cmap": "viridis",
                       "title": t, "label": "luminance variance (log scale)"}])),
            (npz, _npz_writer(_npz_payload(res, _initial_radius(est, scene, settings), scene))),
        ])
        written += [rpng, vpng, npz]

    # A photon estimator may not produce every scatter count of the scene (planes: K >= 2);
    # it is then also compared with a reference restricted to its range.
    matched = {}
    if "reference" in results:
        for name, est in ests.items():
            k = _min_k(est)
            if name == "reference" or k <= scene.min_scatter:
                continue
            if scene.max_scatter != -1 and k > scene.max_scatter:
                continue
            sub = scene.with_scatter(min_scatter=k)
            on_pass, close = _progress(f"demo reference {_k_range(sub)}", None, args.seconds / 2)
            try:
                matched[name] = (k, render(sub, parse_estimator("reference", sub), settings,
                                           time_budget=args.seconds / 2, seed=args.seed + 1,
                                           on_pass=on_pass))
            finally:
                close()

    if len(results) >= 2:
        cols_img, cols_var = {}, {}
        for n, r in results.items():
            label = f"{n}, {_k_range(scene, _min_k(ests[n]))}"
            cols_img[label], cols_var[label] = r.mean, r.var
        for k, r in matched.values():
            label = f"reference, {_k_range(scene, k)}"
            cols_img.setdefault(label, r.mean)
            cols_var.setdefault(label, r.var)
        cpng = os.path.join(args.out, "comparison.png")
        _write_all([(cpng, lambda tmp: im.comparison_figure(
            tmp, cols_img, cols_var, title=f"{os.path.basename(scene.path)}: mean images (one "
                                           f"exposure) and per-pass variance (one scale)"))])
        written.append(cpng)
    written += _demo_screenshots(scene, args)

    for p in written:
        print(p)
    print(f"web page (the app for a class, one session per browser tab): "
          f"python app.py serve {os.path.basename(scene.path)} --port 8080, then open "
          f"http://127.0.0.1:8080/")
    ref = results.get("reference")
    for name, res in results.items():
        line = (f"{name}: {_plural(res.passes, 'pass')} in {res.seconds:.1f} s, "
                f"mean {res.mean.mean():.4g}, mean per-pass variance {res.var.mean():.3g}")
        if ref is not None and name != "reference":
            k, target = matched.get(name, (scene.min_scatter, ref))
            rel = im.relative_mse(res.mean, target.mean)
            line += (f"; relMSE vs reference ({_k_range(scene, k)}, {target.passes} passes) "
                     f"{rel:.3g}, from noise alone ~{_noise_relmse(res, target):.2g}")
            if name in matched:
                line += (f"; note: {name} covers only {_k_range(scene, k)} of the scene's "
                         f"{_k_range(scene)} (whole-range reference mean {ref.mean.mean():.4g})")
        print(line)
    return 0 if results else 1


#: What the headless demo shows of the window: its five stages for the centre pixel.
DEMO_SCREENSHOT_ESTIMATOR = "planes"


def _demo_screenshots(scene, args) -> list:
    """The window's five stages (``app_<stage>.png``, off-screen) for the scene's centre
    pixel: what ``make demo`` would have shown with a display. Returns the paths written; an
    off-screen renderer that is missing costs a note, not the demo."""
    try:
        from ui.views._vtk import pv

        pv.OFF_SCREEN = True
        from ui.views.stepper import STAGES
        from ui.views.window import screenshot
    except (ImportError, RuntimeError) as e:
        _note(f"no app screenshots: off-screen rendering is unavailable ({e})")
        return []
    cam = scene.camera
    pixel = (cam.width // 2, cam.height // 2)
    out = []
    for stage in STAGES:
        path = os.path.join(args.out, f"app_{stage}.png")
        try:
            screenshot(scene.path, stage, pixel, DEMO_SCREENSHOT_ESTIMATOR, 0, path,
                       photons=min(args.photons, 2000), passes=2)
        except (ImportError, RuntimeError) as e:
            _note(f"no app screenshots: off-screen rendering failed ({e})")
            break
        out.append(path)
    return out


def _min_k(est) -> int:
    """Smallest scatter count an estimator can produce (1 for the reference)."""
    return min((t.min_k for t in est.techniques), default=1)


def _noise_relmse(res, ref) -> float:
    """The relMSE that the variance of the two means alone would give (no bias)."""
    den = float((ref.mean**2).mean())
    if den == 0.0:
        return float("inf")
    num = (res.var / max(res.passes, 1)).mean() + (ref.var / max(ref.passes, 1)).mean()
    return float(num / den)


# --------------------------------------------------------------------------- main


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit code (2 for every bad input)."""
    from psurf_core import SceneError

    argv = sys.argv[1:] if argv is None else list(argv)
    if not argv or argv[0].endswith(".toml"):
        # `python app.py [SCENE.toml]` opens the app (the demo: a window, or PNGs headless).
        argv = ["demo", *argv]
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
        if getattr(args, "func", None) is None:
            raise CliError("a subcommand is required: render, demo, screenshot, compare or "
                           "lecture "
                           "(see --help)")
        return args.func(args)
    except (CliError, SceneError) as e:
        print(f"{PROG}: error: {' '.join(str(e).split())}", file=sys.stderr)
        return 2
    except (OutputWriteError, WorkersLost) as e:  # a disk or a cluster failed mid-run
        print(f"{PROG}: error: {' '.join(str(e).split())}", file=sys.stderr)
        return 1
    except MemoryError:
        print(f"{PROG}: error: out of memory (lower the resolution, --spp or --photons)",
              file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted; nothing written", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
