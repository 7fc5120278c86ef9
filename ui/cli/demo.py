"""``python app.py demo`` (and ``python app.py [SCENE.toml]``): the paper's point, shown.

With a display it opens the window on the showcase comparison: ``scenes/showcase.toml`` (an
area light in a hazy box, a sphere and a bar casting volumetric shadows, 160x120, K = 2..3)
rendered with photon planes and the paper's MIS preset side by side at equal time, the
stages inspecting the preset. Without a display (or with ``--no-window``) it renders the same
comparison headless and writes into ``--out``:

* ``comparison.png``: the window's image panels at equal time: each estimator's render (one
  exposure), the variance of its mean on one colour scale, "Var: N x" (variance x seconds
  relative to the first estimator) and relMSE against the scene's reference;
* ``convergence.gif``: the same panels while the renders converge;
* ``app_<stage>.png``: the window's five stages for the showcase pixel;
* ``render_<est>.npz`` / ``.png`` and ``variance_<est>.png`` for every estimator;

and prints what it measured. Nothing here states a result: the numbers are those of this run
on this machine (a faster preset simply shows a better ratio). Compiling the kernels (numba,
the first run of a clone) is done before the clock starts and reported apart.
``--min-scatter``/``--max-scatter`` set the scatter range as on ``render`` and ``compare``.

For the window, the render worker and the stage inspector are started
(:func:`start_background`) before VTK is imported: they load their kernels while the window
opens.

The reference: ``scenes/<scene>_reference.npz`` when it exists and matches the scene
(``scenes/showcase_reference.npz``, a long path-traced render), or ``--reference FILE.npz``;
without one there is no relMSE.
"""

from __future__ import annotations

import argparse
import os
import textwrap

from .common import (
    CliError,
    add_resolution_flag,
    load_reference,
    nonneg_int,
    note,
    npz_writer,
    pixel,
    plural,
    png_writer,
    positive_float,
    positive_int,
    scatter_int,
    with_resolution,
    with_scatter,
    write_all,
)
from .limits import check_memory, load_scene_within

_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
#: The showcase: the scene, the comparison (the baseline first: ratios are relative to it),
#: the seconds each estimator gets, photons per pass, the pixel the stages inspect.
DEMO_SCENE = os.path.join(_ROOT, "scenes", "showcase.toml")
DEMO_ESTIMATORS = ("planes", "fast-multi")
DEMO_SECONDS = 10.0
DEMO_PHOTONS = 1000
DEMO_OUT = "out"
#: Size of the comparison figure and the stage pictures; of the GIF's frames.
FIGURE_SIZE, COMPARISON_SIZE, GIF_SIZE = (1600, 900), (1600, 1000), (960, 720)
#: Seconds of rendering between two GIF frames.
GIF_EVERY = 1.0


def add_demo_parser(sub) -> argparse.ArgumentParser:
    """Add the ``demo`` subcommand to ``sub`` (``func=cmd_demo``)."""
    d = sub.add_parser(
        "demo", allow_abbrev=False,
        help="open the window on the showcase comparison, or write it as pictures",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=textwrap.dedent(f"""\
            With a display: open the interactive window on SCENE (default the showcase,
            scenes/showcase.toml) with --estimators side by side at equal time (default
            {','.join(DEMO_ESTIMATORS)}). Without one (or --no-window): render that comparison
            for --time seconds per estimator and write into DIR comparison.png (renders,
            variance maps, Var at equal time, relMSE), convergence.gif, app_<stage>.png (the
            window's five stages) and render_<est>.npz/.png, variance_<est>.png."""))
    d.add_argument("scene", nargs="?", default=None, metavar="SCENE.toml",
                   help="scene file (default: scenes/showcase.toml)")
    d.add_argument("--out", default=DEMO_OUT, metavar="DIR",
                   help=f"output directory, created if missing (default {DEMO_OUT}/)")
    est = d.add_mutually_exclusive_group()
    est.add_argument("--estimators", default=None, metavar="A,B",
                     help="estimators side by side at equal time (ratios relative to the "
                          f"first; default {','.join(DEMO_ESTIMATORS)})")
    est.add_argument("--estimator", default=None, metavar="SPEC",
                     help="one estimator (the window shows it alone)")
    d.add_argument("--inspect", default=None, metavar="SPEC",
                   help="which estimator the stages inspect (default: the first MIS set)")
    d.add_argument("--reference", default=None, metavar="FILE.npz",
                   help="an app.py render .npz of SCENE: relMSE under each render (default: "
                        "the scene's bundled <scene>_reference.npz, when it matches)")
    d.add_argument("--pixel", default=None, type=pixel, metavar="X,Y",
                   help="the pixel the stages inspect (X column from the left, Y row from "
                        "the top; default the centre)")
    add_resolution_flag(d)
    d.add_argument("--min-scatter", type=scatter_int, default=None, metavar="A",
                   help="override the scene's [render] min_scatter (>= 1)")
    d.add_argument("--max-scatter", type=scatter_int, default=None, metavar="B",
                   help="override the scene's [render] max_scatter (>= A, or -1: unlimited)")
    d.add_argument("--time", dest="seconds", type=positive_float, default=DEMO_SECONDS,
                   metavar="SECONDS",
                   help=f"headless: seconds per estimator (equal time; default {DEMO_SECONDS:g})")
    d.add_argument("--photons", type=positive_int, default=DEMO_PHOTONS, metavar="N",
                   help=f"photons per pass (default {DEMO_PHOTONS})")
    d.add_argument("--seed", type=nonneg_int, default=0, metavar="S",
                   help="random seed (default 0)")
    d.add_argument("--no-window", action="store_true",
                   help="never open the window; always write the pictures")
    d.set_defaults(func=cmd_demo)
    return d


# --------------------------------------------------------------------------- checks
def _specs(args, scene) -> list:
    """The estimators (checked, before a window or a render starts)."""
    from .common import explain_estimator_error, parse_estimator_flag

    if args.estimator is not None:
        text, flag = args.estimator, "--estimator"
    else:
        text = args.estimators or ",".join(DEMO_ESTIMATORS)
        flag = "--estimators"
    specs = [e.strip() for e in text.split(",")]
    if any(not e for e in specs):
        raise CliError(f"{flag}: must be estimator specs A,B, got {text!r}")
    if len(set(specs)) != len(specs):
        raise CliError(f"{flag}: an estimator is listed twice ({text})")
    try:
        ests = [parse_estimator_flag(e, scene, flag) for e in specs]
    except ValueError as e:
        raise CliError(explain_estimator_error(e)) from None
    if all(e.reference for e in ests):
        raise CliError(f"{flag} {text}: needs a photon estimator (the one the stages inspect; "
                       "the path tracer has no photons, primitives or hits)")
    if args.inspect is not None:
        if args.inspect not in specs:
            raise CliError(f"--inspect {args.inspect}: not one of {flag} ({', '.join(specs)})")
        if ests[specs.index(args.inspect)].reference:
            raise CliError(f"--inspect {args.inspect}: the stages need a photon estimator")
    return specs


def _check_memory(scene, specs: list, photons: int) -> None:
    """The window (its estimators, breakdown stacks, the stages' record of a whole pass, one
    background process) must fit in the memory available; the headless run needs less (no
    background process) and is held to the same bound."""
    from psurf_core import RenderSettings, parse_estimator
    from psurf_core.budget import progressive_need

    ests = [parse_estimator(s, scene) for s in specs]
    check_memory(progressive_need(scene, ests, RenderSettings(photons=photons), workers=1,
                                  breakdown=True, inspect=True), None, what="the demo")


def bundled_reference(scene_path: str) -> str | None:
    """``<scene>_reference.npz`` beside the scene file, when there is one."""
    stem, _ = os.path.splitext(os.path.abspath(scene_path))
    path = f"{stem}_reference.npz"
    return path if os.path.isfile(path) else None


def _reference(args, scene_path: str, scene):
    """The reference (``Reference``) for relMSE, or None; a given one must match."""
    if args.reference is not None:
        return load_reference(args.reference, scene)
    path = bundled_reference(scene_path)
    if path is None:
        return None
    try:
        return load_reference(path, scene)
    except ValueError as e:  # another resolution (--resolution): no relMSE, and say why
        note(f"no relMSE: the bundled reference does not fit ({e})")
        return None


def _display() -> bool:
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def start_background(scene, specs: list, args):
    """The window's background processes, started before VTK is imported: ``(prog,
    inspector)``. The render worker and the inspector then start their interpreters and load
    their kernels while this process imports VTK and opens the window (seconds each on this
    machine), so the first render arrives sooner."""
    from psurf_core.estimators import parse_estimator
    from psurf_core.render import RenderSettings

    from .inspector import Inspector
    from .progressive import Progressive

    # The specs as the window's panels name them (``ui.views.window.panel_specs``).
    shown = [parse_estimator(spec, scene).spec for spec in specs]
    prog = Progressive(scene, shown, RenderSettings(photons=args.photons, spp=1),
                       seed=args.seed, workers=1, breakdown=False)
    try:
        inspector = Inspector(1)
    except BaseException:
        prog.close()
        raise
    return prog, inspector


def _interactive_run():
    """``ui.views.interactive.run`` when a display and pyvista can open a window, else None."""
    if not _display():
        return None
    try:
        from ui.views._vtk import pv
        from ui.views.interactive import run

        if not pv.system_supports_plotting():
            return None
    except Exception:
        return None
    return run


def cmd_demo(args) -> int:
    """Run ``demo``; 0, or raises CliError (exit 2)."""
    scene_path = args.scene or DEMO_SCENE
    # Meshes are checked before they load; the sizes before anything is allocated.
    scene = with_scatter(with_resolution(load_scene_within(scene_path, None), args.resolution),
                         args.min_scatter, args.max_scatter)
    specs = _specs(args, scene)
    _check_memory(scene, specs, args.photons)
    cam = scene.camera
    if args.pixel is not None and not (args.pixel[0] < cam.width and args.pixel[1] < cam.height):
        x, y = args.pixel
        raise CliError(f"--pixel {x},{y}: outside the {cam.width}x{cam.height} image "
                       f"(X in 0..{cam.width - 1}, Y in 0..{cam.height - 1})")
    ref = _reference(args, scene_path, scene)
    if not args.no_window and _display():
        prog, inspector = start_background(scene, specs, args)
        run = _interactive_run()
        if run is not None:
            run(scene_path, estimators=specs, reference=ref.source if ref else None,
                pixel_xy=args.pixel, photons=args.photons, inspect=args.inspect,
                seed=args.seed, scene=scene, prog=prog, inspector=inspector)
            return 0
        prog.close()  # no window after all (VTK cannot open one): the pictures instead
        inspector.close()
    if os.path.exists(args.out) and not os.path.isdir(args.out):
        raise CliError(f"--out {args.out}: exists and is not a directory")
    try:
        os.makedirs(args.out, exist_ok=True)
    except OSError as e:
        raise CliError(f"--out {args.out}: cannot create directory ({e.strerror})") from None
    if not os.access(args.out, os.W_OK):
        raise CliError(f"--out {args.out}: not writable")
    return _headless(scene_path, scene, specs, ref, args)


# --------------------------------------------------------------------------- headless
def _offscreen():
    try:
        from ui.views._vtk import pv

        pv.OFF_SCREEN = True
        from ui.views import image_panels, window
    except (ImportError, RuntimeError) as e:
        raise CliError(f"off-screen rendering is unavailable ({type(e).__name__}: {e}); it "
                       "needs VTK with EGL or OSMesa (libegl1 / libosmesa6)") from None
    return image_panels, window


def _headless(scene_path: str, scene, specs: list, ref, args) -> int:
    """Render the comparison at equal time; write the pictures; print what was measured."""
    from psurf_core import images as im
    from psurf_core.render import RenderSettings
    from psurf_core.study import relmse

    from .common import Animation
    from .progressive import Progressive

    image_panels, window = _offscreen()
    reference = ref.mean if ref is not None else None
    prog = Progressive(scene, specs, RenderSettings(photons=args.photons), seed=args.seed,
                       workers=0, max_seconds=args.seconds)
    out = args.out
    gif = Animation(os.path.join(out, "convergence.gif"), ".gif", fps=4.0)
    figures = image_panels.FigureMaker(GIF_SIZE)
    scale = image_panels.VarScale(keys=False)
    written = []
    try:
        print(f"demo: {os.path.basename(scene_path)} ({scene.camera.width}x"
              f"{scene.camera.height}), {' vs '.join(specs)}, {args.seconds:g} s each "
              "(equal time; compiling kernels is not counted)", flush=True)
        shown = -GIF_EVERY
        while not prog.done:
            prog.poll()
            spent = min(r.seconds for r in prog.runs)
            if spent - shown >= GIF_EVERY:
                shown = spent
                gif.add(figures.frame(prog, "render", reference=reference, scale=scale))
        gif.add(figures.frame(prog, "render", reference=reference, scale=scale))
        gif.commit()
        written.append(gif.out)
    except BaseException:
        gif.abort()
        raise
    finally:
        figures.close()
    # The side-by-side: the window's image panels, bigger, with what was compared.
    big = image_panels.FigureMaker(COMPARISON_SIZE, title=True)
    try:
        img = big.frame(prog, "render", reference=reference, scale=scale,
                        title=_title(scene_path, scene, specs, ref, args))
    finally:
        big.close()
    cpng = os.path.join(out, "comparison.png")
    write_all([(cpng, lambda tmp: im.write_png(tmp, img, atomic=False))])
    written.append(cpng)
    for run in prog.runs:
        name = "".join(c if c.isalnum() or c in "-_" else "_" for c in run.spec)
        lum = im.luminance(run.acc.variance)
        lo, hi = im.log_range(lum)
        rpng = os.path.join(out, f"render_{name}.png")
        vpng = os.path.join(out, f"variance_{name}.png")
        npz = os.path.join(out, f"render_{name}.npz")
        write_all([
            (rpng, png_writer(run.acc.mean)),
            (vpng, lambda tmp, v=lum, lo=lo, hi=hi, t=run.spec, n=run.acc.n: im.figure_png(
                tmp, [{"image": v, "values": v, "vmin": lo, "vmax": hi, "cmap": "viridis",
                       "title": f"{t}: per-pass variance, {plural(n, 'pass')}",
                       "label": "luminance variance (log scale)"}])),
            (npz, npz_writer(_payload(run, scene, args))),
        ])
        written += [rpng, vpng, npz]
    written += _stages(window, scene_path, specs, prog, reference, args)
    prog.close()
    for p in written:
        print(p)
    print("web page (the app for a class, one session per browser tab): "
          f"{_serve_command(scene_path, specs)}, then open http://127.0.0.1:8080/")
    rows = prog.summary(reference)
    for run, row in zip(prog.runs, rows, strict=True):
        line = (f"{run.spec}: {plural(run.acc.n, 'pass')} in {run.seconds:.1f} s "
                f"(+{run.compile_seconds:.1f} s compiling or loading kernels, not counted)")
        if len(rows) > 1 and row["ratio"] is not None:
            line += f"; Var {row['ratio']:.3g}x {specs[0]} at equal time"
        if reference is not None:
            line += f"; relMSE {relmse(run.acc.mean, reference):.3g}"
        print(line)
    if ref is not None and ref.var is not None and ref.passes:
        from psurf_core.metrics import var_relmse

        floor = var_relmse(ref.var / ref.passes, ref.mean)
        print(f"reference {os.path.basename(ref.source)}: {ref.estimator}, "
              f"{plural(ref.passes, 'pass')}; its own noise adds ~{floor:.2g} to every relMSE")
    return 0


def _serve_command(scene_path: str, specs: list) -> str:
    """The ``serve`` command line that opens this comparison in a browser."""
    from ui.web import scenes

    name = os.path.basename(scene_path)
    bundled = name in scenes.bundled() and os.path.samefile(scenes.bundled_path(name),
                                                             scene_path)
    return (f"python app.py serve {name if bundled else scene_path} --estimators "
            f"{','.join(specs)} --port 8080")


def _title(scene_path, scene, specs, ref, args) -> str:
    """What the comparison figure compares, and how (its title line)."""
    import time

    from psurf_core import __version__

    hi = "inf" if scene.max_scatter == -1 else scene.max_scatter
    against = (f"relMSE vs {os.path.basename(ref.source)}" if ref is not None
               else "no reference: no relMSE")
    return (f"{os.path.basename(scene_path)} {scene.camera.width}x{scene.camera.height}, "
            f"K {scene.min_scatter}..{hi}: {' vs '.join(specs)}, {args.seconds:g} s each "
            f"(equal time), {args.photons} photons/pass, seed {args.seed}; {against}; "
            f"psurf {__version__}, {os.cpu_count()} cores, {time.strftime('%Y-%m-%d')}")


def _payload(run, scene, args) -> dict:
    import sys

    import numpy as np

    from psurf_core import __version__

    return {"mean": run.acc.mean.astype(np.float32), "var": run.acc.variance.astype(np.float32),
            "passes": np.int64(run.acc.n), "photons_per_pass": np.int64(args.photons),
            "spp": np.int64(1), "seconds": np.float64(run.seconds),
            "estimator": np.str_(run.spec), "seed": np.int64(args.seed),
            "version": np.str_(__version__), "argv": np.array(sys.argv, dtype=str),
            "scene": np.str_(scene.path), "min_scatter": np.int64(scene.min_scatter),
            "max_scatter": np.int64(scene.max_scatter)}


def _stages(window, scene_path, specs, prog, reference, args) -> list:
    """The window's five stages (``app_<stage>.png``) with the comparison's own panels."""
    from ui.views._vtk import rendered_image
    from ui.views.image_panels import PanelView
    from ui.views.stepper import STAGES

    state = window.build_state(scene_path, specs[0], args.seed, args.pixel, args.photons,
                               render_passes=False, estimators=specs, inspect=args.inspect,
                               scene=prog.job.scene)
    state.prog, state.panels, state.reference = prog, PanelView(), reference
    state.acc = prog.runs[state.inspected].acc
    plotter = window.make_plotter(FIGURE_SIZE, off_screen=True)
    out = []
    try:
        for stage in STAGES:
            state.stepper.go(stage)
            window.compose(plotter, state)
            img = rendered_image(plotter)
            path = os.path.join(args.out, f"app_{stage}.png")
            from psurf_core import images as im

            write_all([(path, lambda tmp, x=img: im.write_png(tmp, x[..., :3], atomic=False))])
            out.append(path)
    finally:
        plotter.close()
        state.inspector.close()
    return out
