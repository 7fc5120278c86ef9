"""``python app.py render``: render a scene progressively to .npz (and .png/.exr).

The command (:func:`add_render_parser`, :func:`cmd_render`), its defaults, and the ``.npz`` it
writes (:func:`npz_payload`: mean, variance, counts, provenance and the scene file's SHA-256,
also used by ``demo``). The flag types and helpers it shares with the other commands are
:mod:`ui.cli.common`'s, the checkpoints :mod:`ui.cli.checkpoint`'s and
``--dask``/``--workers``/``--jobs`` :mod:`ui.cli.parallel`'s. No pyvista here: only argparse,
numpy and :mod:`psurf_core`. ``app.py`` wires it in with::

    from ui.cli.render import add_render_parser
    add_render_parser(subparsers, estimators_help)      # sets func=cmd_render

Every bad input raises :class:`~ui.cli.common.CliError` (``app.main`` prints it as one
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
import os
import sys
import textwrap

import numpy as np

from .checkpoint import (
    Checkpointer,
    checkpoint_dir_ok,
    load_resume,
    report_interrupt,
    same_dir,
    save_on_failure,
    session_budget,
)
from .common import (
    PROG,
    CliError,
    check_output,
    load_scene,
    nonempty_path,
    nonneg_float,
    nonneg_int,
    note,
    note_scatter_range,
    npz_writer,
    parse_estimator_flag,
    plural,
    png_writer,
    positive_float,
    positive_int,
    progress,
    resolution,
    scatter_int,
    shrink,
    sigint_deferred,
    with_resolution,
    with_scatter,
    write_all,
)
from .parallel import add_dask_flags, maybe_distributed

#: Defaults of ``render`` (a 64x48 scene shows a recognisable image in a few seconds).
DEFAULT_PHOTONS = 4000
DEFAULT_SPP = 1
DEFAULT_PASSES = 8
DEFAULT_SEED = 0
DEFAULT_CHECKPOINT_EVERY = 60.0


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
    r.add_argument("--resolution", type=resolution, default=None, metavar="W,H",
                   help="render at W x H pixels instead of the scene's [camera] resolution")
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
    add_dask_flags(r)
    r.set_defaults(func=cmd_render)
    return r


# --------------------------------------------------------------------------- output


def initial_radius(estimator, scene, settings) -> float:
    """The largest pass-0 kernel radius of the estimator's techniques (0.0: no kernel)."""
    from psurf_core.render import kernel_radius

    radii = [kernel_radius(t, scene, settings, 0) for t in estimator.techniques
             if t.kernel_dim > 0]
    return float(max(radii)) if radii else 0.0


def npz_payload(result, radius: float, scene, extra: dict | None = None) -> dict:
    """The arrays of a render ``.npz`` (``mean``, ``var``, counts, ``radius``, provenance),
    updated with ``extra``."""
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
    if os.path.isfile(scene.path):  # which scene file, exactly (a bundled reference is checked)
        from psurf_core.checkpoint import file_sha256

        data["scene_sha256"] = np.str_(file_sha256(scene.path))
    data.update(extra or {})
    return data


# --------------------------------------------------------------------------- render


def cmd_render(args) -> int:
    """Run ``render``; returns 0, 1 (an internal error) or 130 (Ctrl-C), or raises CliError."""
    from psurf_core import RenderSettings
    from psurf_core.checkpoint import render_identity
    from psurf_core.render import RenderResult, render

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

    scene = with_resolution(load_scene(args.scene), args.resolution)
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
    passes, time_budget = session_budget(args, ck, DEFAULT_PASSES)

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
