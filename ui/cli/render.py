"""``python app.py render``: render a scene progressively to .npz (and .png/.exr).

The command: its flags and defaults (:func:`add_render_parser`) and the checks of its inputs
(:func:`cmd_render`). The run itself, once every input is valid (render, checkpoint, failures,
outputs), is :mod:`ui.cli.render_run`'s; the ``.npz`` it writes (:func:`npz_payload`: mean,
variance, counts, provenance and the scene file's SHA-256) :mod:`ui.cli.render_npz`'s, both
re-exported here. The flag types and helpers it shares with the other commands are
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

Before anything is allocated or written, :func:`~ui.cli.limits.check_render_sizes` checks
the run's memory (:mod:`psurf_core.budget`) and every output folder's disk. Failures during
the run are one line and exit code 1, nothing half-written: a checkpoint that cannot be
written (the previous one stays), an output that cannot be written (none is), memory or the
workers lost (the completed passes are saved). The checkpoint directory is locked for the
run, and a killed writer's temporary files there are removed.
"""

from __future__ import annotations

import argparse
import os
import textwrap

from .checkpoint import (
    checkpoint_dir_ok,
    load_resume,
    lock_checkpoint_dir,
    same_dir,
    session_budget,
)
from .common import (
    CliError,
    add_resolution_flag,
    add_sampler_flags,
    check_output,
    nonempty_path,
    nonneg_float,
    nonneg_int,
    note,
    note_scatter_range,
    parse_estimator_flag,
    positive_float,
    positive_int,
    scatter_int,
    shrink,
    with_resolution,
    with_scatter,
)
from .limits import check_render_sizes, load_scene_within
from .parallel import add_dask_flags
from .render_npz import initial_radius, npz_payload  # noqa: F401 - npz_payload re-exported
from .render_run import DEFAULT_CHECKPOINT_EVERY, run_session, written_list  # noqa: F401

#: Defaults of ``render`` (a 64x48 scene shows a recognisable image in a few seconds).
DEFAULT_PHOTONS = 4000
DEFAULT_SPP = 1
DEFAULT_PASSES = 8
DEFAULT_SEED = 0


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
            more passes; without either, the checkpoint's own budget is finished.
            A kill at any moment leaves the last checkpoint complete; a checkpoint or output
            that cannot be written (disk full, read-only, gone) ends the run with one line
            and exit code 1, the previous checkpoint kept. Sizes are checked against
            --memory-budget (or the memory available) and the disk before rendering."""),
        epilog=f"estimators:\n{estimators}",
    )
    r.add_argument("scene", metavar="SCENE.toml", help="scene file (see SCENES.md)")
    r.add_argument("--estimator", required=True, metavar="NAME",
                   help="estimator name (list below)")
    r.add_argument("--photons", type=positive_int, default=DEFAULT_PHOTONS, metavar="N",
                   help=f"photons per pass (default {DEFAULT_PHOTONS}; the reference ignores it)")
    add_resolution_flag(r)
    r.add_argument("--spp", type=positive_int, default=DEFAULT_SPP, metavar="K",
                   help=f"camera rays per pixel per pass (default {DEFAULT_SPP})")
    add_sampler_flags(r)
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
                   help="memory limit of the run in MiB: image, camera rays, photon "
                        "batch, meshes, worker processes and the chunked ray x primitive "
                        "work (sized from it) are checked against it before anything is "
                        "allocated (default: the memory available, and chunks of "
                        "psurf_core.constants.DEFAULT_MEMORY_BUDGET_MIB)")
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


# --------------------------------------------------------------------------- render


def cmd_render(args) -> int:
    """Run ``render``; returns 0, 1 (the run failed: a disk, the memory, the workers, or an
    internal error; one line), or 130 (Ctrl-C); raises CliError for a bad input."""
    from psurf_core import RenderSettings
    from psurf_core.checkpoint import render_identity

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

    scene = with_resolution(load_scene_within(args.scene, args.memory_budget),  # meshes first
                            args.resolution)
    scene = with_scatter(scene, args.min_scatter, args.max_scatter)
    est = parse_estimator_flag(args.estimator, scene)

    settings_kw = {"photons": args.photons, "spp": args.spp, "radius": args.radius,
                   "radius_shrink": args.radius_shrink, "pixel_sampler": args.pixel_sampler,
                   "photon_sampler": args.photon_sampler}
    if args.memory_budget is not None:
        settings_kw["memory_budget_mib"] = args.memory_budget
    settings = RenderSettings(**settings_kw)
    radius = initial_radius(est, scene, settings)

    ck_dir = args.checkpoint if args.checkpoint is not None else args.resume
    identity = render_identity(args.scene, scene, est, settings, args.seed) if ck_dir else None
    ck = load_resume(args, identity) if args.resume is not None else None
    passes, time_budget = session_budget(args, ck, DEFAULT_PASSES)
    need = check_render_sizes(args, scene, est, settings, ck_dir, ck)

    # Every input is valid (notes come only now, so that an error is the only line).
    note_scatter_range(est, scene)
    for text in est.notes:  # lights / scatter counts it leaves unestimated, dropped members
        note(text)
    if radius == 0.0 and (args.radius is not None or args.radius_shrink != 1.0):
        note(f"--radius/--radius-shrink ignored: estimator '{args.estimator}' has no kernel")

    # From here on files may be written.
    lock = None
    if ck_dir is not None:
        os.makedirs(ck_dir, exist_ok=True)
        lock = lock_checkpoint_dir("--checkpoint" if args.checkpoint else "--resume", ck_dir)
    try:
        return run_session(args, scene, est, settings, radius, ck, ck_dir, identity, passes,
                           time_budget, need)
    finally:
        if lock is not None:
            os.close(lock)  # the outputs are in place (or nothing is written)
