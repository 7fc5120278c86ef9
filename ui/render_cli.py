"""``python app.py render``: the render command and the CLI helpers that ``app.py``'s other
commands share (flag types, one-line errors, atomic output writes); the checkpoint machinery
is in :mod:`ui.render_checkpoint`.

No pyvista here: only argparse, numpy and :mod:`psurf_core`. ``app.py`` wires it in with::

    from ui.render_cli import add_render_parser
    add_render_parser(subparsers, estimators_help)      # sets func=cmd_render

Every bad input raises :class:`CliError` (``app.main`` prints it as one
``psurf: error: ...`` line, exit code 2) before anything is written.

Checkpoints (``--checkpoint DIR``, ``--checkpoint-every SECONDS``, ``--resume DIR``): the
Welford accumulator, seed, estimator, settings and a hash of the scene file go to
``DIR/checkpoint.npz`` (atomic write-then-rename, :mod:`psurf_core.checkpoint`) every
SECONDS, at the end, and when the render is interrupted (Ctrl-C: the completed passes are
saved, then one line and exit code 130). ``--resume DIR`` continues at the checkpoint's pass
count and gives bit-for-bit the mean and variance of an uninterrupted run; it refuses a
checkpoint made with another scene file, estimator, seed or setting.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import signal
import sys
import textwrap

import numpy as np

PROG = "psurf"

#: Defaults of ``render`` (a 64x48 scene shows a recognisable image in a few seconds).
DEFAULT_PHOTONS = 4000
DEFAULT_SPP = 1
DEFAULT_PASSES = 8
DEFAULT_SEED = 0
DEFAULT_CHECKPOINT_EVERY = 60.0

#: Exit code after Ctrl-C (128 + SIGINT, as shells report it).
EXIT_INTERRUPTED = 130


class CliError(Exception):
    """A bad command line or input: printed as one ``psurf: error:`` line, exit code 2."""


class Parser(argparse.ArgumentParser):
    """``ArgumentParser`` whose errors are :class:`CliError` (one line, exit 2, no usage)."""

    def error(self, message: str):  # noqa: D102 - argparse hook
        raise CliError(message)


# --------------------------------------------------------------------------- flag types


def _int_flag(text: str, ok, what: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be {what}, got {text!r}") from None
    if not ok(v):
        raise argparse.ArgumentTypeError(f"must be {what}, got {text!r}")
    return v


def positive_int(text: str) -> int:
    return _int_flag(text, lambda v: v > 0, "an integer > 0")


def nonneg_int(text: str) -> int:
    return _int_flag(text, lambda v: v >= 0, "an integer >= 0")


def scatter_int(text: str) -> int:
    return _int_flag(text, lambda v: v >= 1 or v == -1, "an integer >= 1 or -1")


def positive_float(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number > 0, got {text!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text!r}")
    return v


def nonneg_float(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number >= 0, got {text!r}") from None
    if not (math.isfinite(v) and v >= 0):
        raise argparse.ArgumentTypeError(f"must be a finite number >= 0, got {text!r}")
    return v


def shrink(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number in (0, 1], got {text!r}") from None
    if not 0.0 < v <= 1.0:
        raise argparse.ArgumentTypeError(f"must be a number in (0, 1], got {text!r}")
    return v


def nonempty_path(text: str) -> str:
    if not text.strip():
        raise argparse.ArgumentTypeError("must be a path, got an empty string")
    return text


# --------------------------------------------------------------------------- parser


def add_render_parser(sub, estimators: str) -> argparse.ArgumentParser:
    """Add the ``render`` subcommand to ``sub`` (``func=cmd_render``).

    ``estimators`` is the indented estimator list for the help epilog.
    """
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
            brighter pixels clip, then the sRGB transfer function (8 bit).

            Long renders: --checkpoint DIR saves the accumulated passes to DIR/checkpoint.npz
            (atomically) every --checkpoint-every seconds, at the end and on Ctrl-C (which
            then exits with code 130). Re-run the same command with --resume DIR to continue:
            the result is bit-identical to an uninterrupted render with the same seed.
            On resume, --passes P is the total pass count and --time SECONDS the time for
            more passes; without either, the checkpoint's own budget is finished."""),
        epilog=f"estimators:\n{estimators}",
    )
    r.add_argument("scene", metavar="SCENE.toml", help="scene file (see SCENES.md)")
    r.add_argument("--estimator", required=True, metavar="NAME",
                   help="estimator name (list below)")
    r.add_argument("--photons", type=positive_int, default=DEFAULT_PHOTONS, metavar="N",
                   help=f"photons per pass (default {DEFAULT_PHOTONS}; the reference ignores it)")
    r.add_argument("--spp", type=positive_int, default=DEFAULT_SPP, metavar="K",
                   help=f"camera rays per pixel per pass (default {DEFAULT_SPP})")
    budget = r.add_mutually_exclusive_group()
    budget.add_argument("--passes", type=positive_int, default=None, metavar="P",
                        help=f"number of passes (default {DEFAULT_PASSES})")
    budget.add_argument("--time", type=positive_float, default=None, metavar="SECONDS",
                        help="run whole passes until SECONDS are spent (the pass in flight "
                             "finishes; at least one pass)")
    r.add_argument("--seed", type=nonneg_int, default=DEFAULT_SEED, metavar="S",
                   help=f"random seed (default {DEFAULT_SEED}); same seed, same image")
    r.add_argument("--min-scatter", type=scatter_int, default=None, metavar="A",
                   help="override the scene's [render] min_scatter (>= 1)")
    r.add_argument("--max-scatter", type=scatter_int, default=None, metavar="B",
                   help="override the scene's [render] max_scatter (>= A, or -1: unlimited)")
    r.add_argument("--radius", type=positive_float, default=None, metavar="R",
                   help="initial kernel radius in scene units (kernel estimators; default: "
                        "each technique's fraction of the medium box diagonal)")
    r.add_argument("--radius-shrink", type=shrink, default=1.0, metavar="ALPHA",
                   help="progressive radius reduction alpha in (0, 1] (default 1: fixed)")
    r.add_argument("--memory-budget", type=positive_int, default=None, metavar="MIB",
                   help="memory bound of the chunked ray x primitive work in MiB "
                        "(default: psurf_core.constants.DEFAULT_MEMORY_BUDGET_MIB)")
    r.add_argument("--out", required=True, metavar="OUT.npz", help="output .npz")
    r.add_argument("--png", default=None, metavar="OUT.png", help="also write a tone-mapped PNG")
    r.add_argument("--exr", default=None, metavar="OUT.exr",
                   help="also write the linear mean as OpenEXR (needs imageio EXR support; "
                        "checked before rendering)")
    r.add_argument("--checkpoint", type=nonempty_path, default=None, metavar="DIR",
                   help="save the accumulated passes to DIR/checkpoint.npz (DIR is created; "
                        "it must not hold a checkpoint already)")
    r.add_argument("--checkpoint-every", type=nonneg_float, default=None, metavar="SECONDS",
                   help=f"seconds between checkpoints (default {DEFAULT_CHECKPOINT_EVERY:g}; "
                        "0: after every pass)")
    r.add_argument("--resume", type=nonempty_path, default=None, metavar="DIR",
                   help="continue the render saved in DIR/checkpoint.npz (same scene file, "
                        "estimator, seed and settings) and keep checkpointing into DIR")
    r.set_defaults(func=cmd_render)
    return r


# --------------------------------------------------------------------------- shared helpers


def check_output(flag: str, path: str) -> None:
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


def load_scene(path: str):
    from psurf_core import load_scene as _load

    return _load(path)  # SceneError propagates (one line, names file and key)


def parse_estimator_flag(spec: str, scene):
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


def progress(desc: str, passes: int | None, seconds: float | None, start: int = 0):
    """``(on_pass, close)`` showing a tqdm bar on stderr when it is a terminal."""
    if not sys.stderr.isatty():
        return None, lambda: None
    from tqdm import tqdm

    if passes is not None:
        bar = tqdm(total=passes, initial=start, desc=desc, unit="pass", file=sys.stderr,
                   leave=False)

        def on_pass(i, acc, elapsed):
            bar.update(1)

    else:
        bar = tqdm(total=seconds, desc=desc, file=sys.stderr, leave=False,
                   bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.1f}/{total:.1f} s{postfix}")

        def on_pass(i, acc, elapsed):
            bar.n = min(elapsed, seconds)
            bar.set_postfix_str(plural(acc.n, "pass"), refresh=False)
            bar.refresh()

    return on_pass, bar.close


def initial_radius(estimator, scene, settings) -> float:
    from psurf_core.render import kernel_radius

    radii = [kernel_radius(t, scene, settings, 0) for t in estimator.techniques
             if t.kernel_dim > 0]
    return float(max(radii)) if radii else 0.0


def npz_payload(result, radius: float, scene, extra: dict | None = None) -> dict:
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


def write_all(jobs: list) -> None:
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


def npz_writer(data: dict):
    def write(tmp: str) -> None:
        with open(tmp, "wb") as f:  # a file object: savez adds no ".npz" suffix
            np.savez_compressed(f, **data)

    return write


def png_writer(linear_rgb):
    from psurf_core import images

    def write(tmp: str) -> None:
        images.write_png(tmp, images.tone_map(linear_rgb), atomic=False)

    return write


def plural(n: int, word: str) -> str:
    return f"{n} {word}" + ("" if n == 1 else "es" if word.endswith("s") else "s")


def note(text: str) -> None:
    print(f"{PROG}: note: {text}", file=sys.stderr)


def with_scatter(scene, lo: int | None, hi: int | None):
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


def note_scatter_range(est, scene) -> None:
    """Warn when the estimator covers none of the scatter range (a black image)."""
    if est.reference or not est.techniques or scene.max_scatter == -1:
        return
    if all(t.min_k > scene.max_scatter for t in est.techniques):
        k = min(t.min_k for t in est.techniques)
        note(f"estimator '{est.spec}' estimates K >= {k} scattering events only; the scatter "
             f"range [{scene.min_scatter}, {scene.max_scatter}] gives a black image")


@contextlib.contextmanager
def sigint_deferred():
    """Ignore Ctrl-C while files are moved into place (main thread only; else a no-op)."""
    try:
        old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    except ValueError:  # not the main thread
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)


# --------------------------------------------------------------------------- render


def cmd_render(args) -> int:
    # Checkpoint machinery lives beside this module and imports its helpers: imported here.
    from psurf_core import RenderSettings
    from psurf_core.checkpoint import render_identity
    from psurf_core.render import RenderResult, render

    from .render_checkpoint import (
        Checkpointer,
        checkpoint_dir_ok,
        load_resume,
        report_interrupt,
        same_dir,
        save_on_failure,
        session_budget,
    )

    check_output("--out", args.out)
    if args.png is not None:
        check_output("--png", args.png)
    if args.exr is not None:
        check_output("--exr", args.exr)
        from psurf_core.images import can_write_exr

        ok, why = can_write_exr()
        if not ok:
            raise CliError(f"--exr {args.exr}: {why}")
    if args.checkpoint_every is not None and args.checkpoint is None and args.resume is None:
        raise CliError("--checkpoint-every: needs --checkpoint DIR (or --resume DIR)")
    if args.checkpoint is not None:
        resuming_here = args.resume is not None and same_dir(args.checkpoint, args.resume)
        checkpoint_dir_ok("--checkpoint", args.checkpoint, must_be_empty=not resuming_here)
    if args.resume is not None:
        if not os.path.isdir(args.resume):
            raise CliError(f"--resume {args.resume}: no such directory")
        checkpoint_dir_ok("--resume", args.resume, must_be_empty=False)

    scene = load_scene(args.scene)
    scene = with_scatter(scene, args.min_scatter, args.max_scatter)
    est = parse_estimator_flag(args.estimator, scene)

    settings_kw = {"photons": args.photons, "spp": args.spp, "radius": args.radius,
                   "radius_shrink": args.radius_shrink}
    if args.memory_budget is not None:
        settings_kw["memory_budget_mib"] = args.memory_budget
    settings = RenderSettings(**settings_kw)
    radius = initial_radius(est, scene, settings)

    ck_dir = args.checkpoint if args.checkpoint is not None else args.resume
    identity = render_identity(args.scene, scene, est, settings, args.seed) if ck_dir else None
    ck = load_resume(args, identity) if args.resume is not None else None
    passes, time_budget = session_budget(args, ck)

    # Every input is valid (notes come only now, so that an error is the only line).
    note_scatter_range(est, scene)
    for text in est.notes:  # lights / scatter counts it leaves unestimated, dropped members
        note(text)
    if radius == 0.0 and (args.radius is not None or args.radius_shrink != 1.0):
        note(f"--radius/--radius-shrink ignored: estimator '{args.estimator}' has no kernel")

    # From here on files may be written.
    acc = ck.accumulator if ck is not None else None
    seconds_before = ck.seconds if ck is not None else 0.0
    ckpt = None
    if ck_dir is not None:
        os.makedirs(ck_dir, exist_ok=True)
        every = DEFAULT_CHECKPOINT_EVERY if args.checkpoint_every is None else args.checkpoint_every
        budget = ({"passes": passes} if passes is not None else
                  {"time": seconds_before + time_budget})
        extra = {"scene": os.path.abspath(args.scene), "argv": list(sys.argv), "budget": budget}
        start = acc if acc is not None else _empty_acc(scene)
        on_disk = start.n if ck is not None and same_dir(ck_dir, args.resume) else None
        ckpt = Checkpointer(ck_dir, identity, every, start, seconds_before, extra, on_disk)

    start_n = acc.n if acc is not None else 0
    bar, close = progress(args.estimator, passes, time_budget, start_n)

    def on_pass(i, a, elapsed):
        if ckpt is not None:
            ckpt.on_pass(i, a, elapsed)
        if bar is not None:
            bar(i, a, elapsed)

    try:
        if acc is not None and passes is not None and acc.n >= passes:
            result = RenderResult(acc.mean.copy(), acc.variance, acc.n, settings.photons,
                                  settings.spp, 0.0, est.spec, args.seed, acc)
        else:
            from ui.compare_cli import maybe_distributed  # --dask / --workers

            kw = dict(passes=passes, time_budget=time_budget, seed=args.seed, accumulator=acc,
                      on_pass=on_pass)
            result = (maybe_distributed(args, scene, est, settings, error=CliError, **kw)
                      or render(scene, est, settings, **kw))
    except KeyboardInterrupt:
        close()
        return report_interrupt(ckpt, args)
    except FloatingPointError as e:  # Welford.add refused a non-finite pixel: a bug
        close()
        saved = save_on_failure(ckpt)
        print(f"{PROG}: error: internal: {e} (estimator '{est.spec}'; please report it)"
              f"{saved}", file=sys.stderr)
        return 1
    finally:
        close()
    result.seconds += seconds_before

    jobs = [(args.out, npz_writer(npz_payload(result, radius, scene, {
        "radius_shrink": np.float64(args.radius_shrink),
        "memory_budget_mib": np.int64(settings.memory_budget_mib)})))]
    if args.png is not None:
        jobs.append((args.png, png_writer(result.mean)))
    if args.exr is not None:
        from psurf_core.images import write_exr

        jobs.append((args.exr, lambda tmp: write_exr(tmp, result.mean)))
    with sigint_deferred():
        if ckpt is not None:
            ckpt.write()
        write_all(jobs)
    written = ", ".join(p for p, _ in jobs)
    budget_text = "" if est.reference else f" x {result.photons_per_pass} photons"
    resumed = f" (continued from {plural(start_n, 'pass')})" if ck is not None else ""
    print(f"{args.estimator}: {plural(result.passes, 'pass')}{budget_text}, spp {result.spp}, "
          f"{result.seconds:.2f} s{resumed} -> {written}")
    return 0


def _empty_acc(scene):
    from psurf_core.accumulate import Welford

    return Welford.empty((scene.camera.height, scene.camera.width, 3))
