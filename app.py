"""psurf command line: ``render`` a scene to .npz/.png/.exr, or run the ``demo``.

A thin layer over :mod:`psurf_core` (argument parsing, progress, writing files); the core never
imports it. Every bad input ends with one line ``psurf: error: <what>`` on stderr and exit
code 2, before anything is written.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import textwrap

import numpy as np

PROG = "psurf"

#: Defaults of ``render`` (a 64x48 scene shows a recognisable image in a few seconds).
DEFAULT_PHOTONS = 4000
DEFAULT_SPP = 1
DEFAULT_PASSES = 8
DEFAULT_SEED = 0

#: Defaults of ``demo``.
DEMO_SCENE = os.path.join("scenes", "area.toml")
DEMO_OUT = "out"
DEMO_SECONDS = 10.0
DEMO_ESTIMATORS = ("planes", "reference")

_ROOT = os.path.dirname(os.path.abspath(__file__))


class CliError(Exception):
    """A bad command line or input: printed as one ``psurf: error:`` line, exit code 2."""


class Parser(argparse.ArgumentParser):
    """``ArgumentParser`` whose errors are :class:`CliError` (one line, exit 2, no usage)."""

    def error(self, message: str):  # noqa: D102 - argparse hook
        raise CliError(message)


# --------------------------------------------------------------------------- flag types


def _positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer > 0, got {text!r}") from None
    if v <= 0:
        raise argparse.ArgumentTypeError(f"must be an integer > 0, got {text!r}")
    return v


def _nonneg_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer >= 0, got {text!r}") from None
    if v < 0:
        raise argparse.ArgumentTypeError(f"must be an integer >= 0, got {text!r}")
    return v


def _scatter_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer >= 1 or -1, got {text!r}") from None
    if v < 1 and v != -1:
        raise argparse.ArgumentTypeError(f"must be an integer >= 1 or -1, got {text!r}")
    return v


def _positive_float(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number > 0, got {text!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text!r}")
    return v


def _shrink(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number in (0, 1], got {text!r}") from None
    if not 0.0 < v <= 1.0:
        raise argparse.ArgumentTypeError(f"must be a number in (0, 1], got {text!r}")
    return v


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

            Run 'python app.py render --help' for the render options."""),
        epilog=f"estimators (--estimator NAME):\n{estimators}",
    )
    top.add_argument("--version", action="version", version=f"{PROG} {__version__}")
    sub = top.add_subparsers(dest="command", metavar="{render,demo,screenshot}",
                             parser_class=Parser)

    r = sub.add_parser(
        "render",
        allow_abbrev=False,
        help="render a scene progressively to .npz (and .png/.exr)",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=textwrap.dedent(f"""\
            Render SCENE.toml with one estimator in whole passes and write OUT.npz with
            mean, var (per-pixel sample variance of one pass's estimate across passes; zeros
            after one pass), passes, photons_per_pass, spp, seconds, estimator, seed, radius
            and provenance (version, argv).

            Defaults: --photons {DEFAULT_PHOTONS} --spp {DEFAULT_SPP} --passes {DEFAULT_PASSES} \
--seed {DEFAULT_SEED}
            (a 64x48 scene shows a recognisable image in a few seconds).
            Files are written only when the render succeeded (temporary name, then rename).
            --png: the exposure maps the 99.5th percentile of the pixel luminance to white,
            brighter pixels clip, then the sRGB transfer function (8 bit)."""),
        epilog=f"estimators:\n{estimators}",
    )
    r.add_argument("scene", metavar="SCENE.toml", help="scene file (see SCENES.md)")
    r.add_argument("--estimator", required=True, metavar="NAME",
                   help="estimator name (list below)")
    r.add_argument("--photons", type=_positive_int, default=DEFAULT_PHOTONS, metavar="N",
                   help=f"photons per pass (default {DEFAULT_PHOTONS}; the reference ignores it)")
    r.add_argument("--spp", type=_positive_int, default=DEFAULT_SPP, metavar="K",
                   help=f"camera rays per pixel per pass (default {DEFAULT_SPP})")
    budget = r.add_mutually_exclusive_group()
    budget.add_argument("--passes", type=_positive_int, default=None, metavar="P",
                        help=f"number of passes (default {DEFAULT_PASSES})")
    budget.add_argument("--time", type=_positive_float, default=None, metavar="SECONDS",
                        help="run whole passes until SECONDS are spent (the pass in flight "
                             "finishes; at least one pass)")
    r.add_argument("--seed", type=_nonneg_int, default=DEFAULT_SEED, metavar="S",
                   help=f"random seed (default {DEFAULT_SEED}); same seed, same image")
    r.add_argument("--min-scatter", type=_scatter_int, default=None, metavar="A",
                   help="override the scene's [render] min_scatter (>= 1)")
    r.add_argument("--max-scatter", type=_scatter_int, default=None, metavar="B",
                   help="override the scene's [render] max_scatter (>= A, or -1: unlimited)")
    r.add_argument("--radius", type=_positive_float, default=None, metavar="R",
                   help="initial kernel radius in scene units (kernel estimators; default: "
                        "each technique's fraction of the medium box diagonal)")
    r.add_argument("--radius-shrink", type=_shrink, default=1.0, metavar="ALPHA",
                   help="progressive radius reduction alpha in (0, 1] (default 1: fixed)")
    r.add_argument("--memory-budget", type=_positive_int, default=None, metavar="MIB",
                   help="memory bound of the chunked ray x primitive work in MiB "
                        "(default: psurf_core.constants.DEFAULT_MEMORY_BUDGET_MIB)")
    r.add_argument("--out", required=True, metavar="OUT.npz", help="output .npz")
    r.add_argument("--png", default=None, metavar="OUT.png", help="also write a tone-mapped PNG")
    r.add_argument("--exr", default=None, metavar="OUT.exr",
                   help="also write the linear mean as OpenEXR (needs imageio EXR support; "
                        "checked before rendering)")
    r.set_defaults(func=cmd_render)

    d = sub.add_parser(
        "demo",
        allow_abbrev=False,
        help="open the interactive app, or write planes vs reference images",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=textwrap.dedent(f"""\
            With a display (DISPLAY or WAYLAND_DISPLAY, and pyvista can open a window) and
            the interactive app (ui.window) installed: open it on SCENE. Otherwise render
            SCENE with {' and '.join(DEMO_ESTIMATORS)} (about {DEMO_SECONDS:g} s each, the
            scene's scatter range) and write into DIR: render_<est>.png/.npz,
            variance_<est>.png (log-scale viridis) and comparison.png; then print a summary."""),
    )
    d.add_argument("scene", nargs="?", default=None, metavar="SCENE.toml",
                   help=f"scene file (default {DEMO_SCENE})")
    d.add_argument("--out", default=DEMO_OUT, metavar="DIR",
                   help=f"output directory, created if missing (default {DEMO_OUT}/)")
    d.add_argument("--no-window", action="store_true",
                   help="never open the interactive app; always write the images")
    # Hidden knobs for tests and quick looks.
    d.add_argument("--seconds", type=_positive_float, default=DEMO_SECONDS,
                   help=argparse.SUPPRESS)
    d.add_argument("--photons", type=_positive_int, default=DEFAULT_PHOTONS,
                   help=argparse.SUPPRESS)
    d.add_argument("--seed", type=_nonneg_int, default=DEFAULT_SEED, help=argparse.SUPPRESS)
    d.set_defaults(func=cmd_demo)

    from ui.cli import add_screenshot_parser  # the UI owns the screenshot command

    add_screenshot_parser(sub)
    return top


# --------------------------------------------------------------------------- shared helpers


def _check_output(flag: str, path: str) -> None:
    """The directory of ``path`` must exist, and ``path`` must not be a directory."""
    if not path:
        raise CliError(f"{flag}: empty path")
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise CliError(f"{flag} {path}: output directory does not exist: "
                       f"{os.path.dirname(path) or '.'}")
    if os.path.isdir(path):
        raise CliError(f"{flag} {path}: is a directory")
    if not os.access(folder, os.W_OK):
        raise CliError(f"{flag} {path}: output directory is not writable")


def _load_scene(path: str):
    from psurf_core import load_scene

    return load_scene(path)  # SceneError propagates (one line, names file and key)


def _estimator(spec: str, scene):
    """Parse ``--estimator`` (unknown names and inapplicable techniques become CliError)."""
    from psurf_core import SceneError, parse_estimator
    from psurf_core.techniques import UnknownTechnique

    try:
        return parse_estimator(spec, scene)
    except SceneError:
        raise
    except UnknownTechnique as e:
        raise CliError(f"--estimator: {e} (see 'python app.py --help')") from None
    except ModuleNotFoundError as e:
        raise CliError(f"--estimator {spec!r}: not available in this build ({e})") from None
    except ValueError as e:  # e.g. a malformed mis: spec
        raise CliError(f"--estimator {spec!r}: {e}") from None


def _progress(desc: str, passes: int | None, seconds: float | None):
    """``(on_pass, close)`` showing a tqdm bar on stderr when it is a terminal."""
    if not sys.stderr.isatty():
        return None, lambda: None
    from tqdm import tqdm

    if passes is not None:
        bar = tqdm(total=passes, desc=desc, unit="pass", file=sys.stderr, leave=False)

        def on_pass(i, acc, elapsed):
            bar.update(1)

    else:
        bar = tqdm(total=seconds, desc=desc, file=sys.stderr, leave=False,
                   bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.1f}/{total:.1f} s{postfix}")

        def on_pass(i, acc, elapsed):
            bar.n = min(elapsed, seconds)
            bar.set_postfix_str(_plural(acc.n, "pass"), refresh=False)
            bar.refresh()

    return on_pass, bar.close


def _initial_radius(estimator, scene, settings) -> float:
    from psurf_core.render import kernel_radius

    radii = [kernel_radius(t, scene, settings, 0) for t in estimator.techniques
             if t.kernel_dim > 0]
    return float(max(radii)) if radii else 0.0


def _npz_payload(result, radius: float, scene, extra: dict | None = None) -> dict:
    from psurf_core import __version__

    data = {
        "mean": result.mean.astype(np.float32),
        "var": result.var.astype(np.float32),
        "passes": np.int64(result.passes),
        "photons_per_pass": np.int64(result.photons_per_pass),
        "spp": np.int64(result.spp),
        "seconds": np.float64(result.seconds),
        "estimator": np.str_(result.estimator),
        "seed": np.int64(result.seed),
        "radius": np.float64(radius),
        "version": np.str_(__version__),
        "argv": np.array(sys.argv, dtype=str),
        "scene": np.str_(scene.path),
        "min_scatter": np.int64(scene.min_scatter),
        "max_scatter": np.int64(scene.max_scatter),
    }
    data.update(extra or {})
    return data


def _tmp_name(path: str) -> str:
    folder, base = os.path.split(os.path.abspath(path))
    stem, ext = os.path.splitext(base)
    return os.path.join(folder, f".{stem}.{os.getpid()}.tmp{ext}")


def _write_all(jobs: list) -> None:
    """Write every ``(path, writer)`` to a temporary name, then move all into place.

    A failure leaves none of the outputs (nor temporary files) behind.
    """
    temps = []
    try:
        for path, writer in jobs:
            tmp = _tmp_name(path)
            temps.append((tmp, path))
            writer(tmp)
        for tmp, path in temps:
            os.replace(tmp, path)
    finally:
        for tmp, _ in temps:
            if os.path.exists(tmp):
                os.remove(tmp)


def _npz_writer(data: dict):
    def write(tmp: str) -> None:
        with open(tmp, "wb") as f:  # a file object: savez adds no ".npz" suffix
            np.savez_compressed(f, **data)

    return write


def _png_writer(linear_rgb):
    from psurf_core import images

    def write(tmp: str) -> None:
        images.write_png(tmp, images.tone_map(linear_rgb), atomic=False)

    return write


# --------------------------------------------------------------------------- render


def cmd_render(args) -> int:
    from psurf_core import RenderSettings
    from psurf_core.render import render

    _check_output("--out", args.out)
    if args.png is not None:
        _check_output("--png", args.png)
    if args.exr is not None:
        _check_output("--exr", args.exr)
        from psurf_core.images import can_write_exr

        ok, why = can_write_exr()
        if not ok:
            raise CliError(f"--exr {args.exr}: {why}")

    scene = _load_scene(args.scene)
    scene = _with_scatter(scene, args.min_scatter, args.max_scatter)
    est = _estimator(args.estimator, scene)
    _note_scatter_range(est, scene)

    settings_kw = {"photons": args.photons, "spp": args.spp, "radius": args.radius,
                   "radius_shrink": args.radius_shrink}
    if args.memory_budget is not None:
        settings_kw["memory_budget_mib"] = args.memory_budget
    settings = RenderSettings(**settings_kw)
    radius = _initial_radius(est, scene, settings)
    if radius == 0.0 and (args.radius is not None or args.radius_shrink != 1.0):
        _note(f"--radius/--radius-shrink ignored: estimator '{args.estimator}' has no kernel")

    passes = None if args.time is not None else (args.passes or DEFAULT_PASSES)
    on_pass, close = _progress(args.estimator, passes, args.time)
    try:
        result = render(scene, est, settings, passes=passes, time_budget=args.time,
                        seed=args.seed, on_pass=on_pass)
    finally:
        close()

    jobs = [(args.out, _npz_writer(_npz_payload(result, radius, scene, {
        "radius_shrink": np.float64(args.radius_shrink),
        "memory_budget_mib": np.int64(settings.memory_budget_mib)})))]
    if args.png is not None:
        jobs.append((args.png, _png_writer(result.mean)))
    if args.exr is not None:
        from psurf_core.images import write_exr

        jobs.append((args.exr, lambda tmp: write_exr(tmp, result.mean)))
    _write_all(jobs)
    written = ", ".join(p for p, _ in jobs)
    budget = "" if est.reference else f" x {result.photons_per_pass} photons"
    print(f"{args.estimator}: {_plural(result.passes, 'pass')}{budget}, spp {result.spp}, "
          f"{result.seconds:.2f} s -> {written}")
    return 0


def _with_scatter(scene, lo: int | None, hi: int | None):
    """Apply ``--min-scatter/--max-scatter`` and check the combined range."""
    if lo is not None and lo < 1:
        raise CliError(f"--min-scatter: must be >= 1, got {lo}")
    new_lo = scene.min_scatter if lo is None else lo
    new_hi = scene.max_scatter if hi is None else hi
    if new_hi != -1 and new_hi < new_lo:
        if hi is not None:
            raise CliError(f"--max-scatter: must be >= min_scatter ({new_lo}) or -1, got {hi}")
        raise CliError(f"--min-scatter: must be <= the scene's max_scatter ({new_hi}), got {lo}")
    return scene.with_scatter(lo, hi)


def _plural(n: int, word: str) -> str:
    return f"{n} {word}" + ("" if n == 1 else "es" if word.endswith("s") else "s")


def _note(text: str) -> None:
    print(f"{PROG}: note: {text}", file=sys.stderr)


def _note_scatter_range(est, scene) -> None:
    """Warn when the estimator covers none of the scatter range (a black image)."""
    if est.reference or not est.techniques or scene.max_scatter == -1:
        return
    if all(t.min_k > scene.max_scatter for t in est.techniques):
        k = min(t.min_k for t in est.techniques)
        _note(f"estimator '{est.spec}' estimates K >= {k} scattering events only; the scatter "
              f"range [{scene.min_scatter}, {scene.max_scatter}] gives a black image")


# --------------------------------------------------------------------------- demo


def _interactive_run():
    """``ui.window.run`` when a display, pyvista and the app are all available, else None."""
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        return None
    import importlib
    import importlib.util

    try:
        if importlib.util.find_spec("ui.window") is None:
            return None
        run = getattr(importlib.import_module("ui.window"), "run", None)
    except ImportError:
        return None
    if not callable(run):
        return None
    try:
        import pyvista

        if not pyvista.system_supports_plotting():
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


def cmd_demo(args) -> int:
    scene_path = _demo_scene_path(args.scene)
    scene = _load_scene(scene_path)
    if not args.no_window:
        run = _interactive_run()
        if run is not None:
            run(scene_path)
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

    for p in written:
        print(p)
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

    try:
        parser = build_parser()
        args = parser.parse_args(argv)
        if getattr(args, "func", None) is None:
            raise CliError("a subcommand is required: render, demo or screenshot (see --help)")
        return args.func(args)
    except (CliError, SceneError) as e:
        print(f"{PROG}: error: {' '.join(str(e).split())}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted; nothing written", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
