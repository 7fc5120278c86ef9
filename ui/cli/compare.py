"""``python app.py compare``: the equal-time study of estimators on one scene.

``app.py`` wires it in with::

    from ui.cli.compare import add_compare_parser
    add_compare_parser(sub)      # sets func=run_compare

``run_compare(args)`` returns the exit code; every bad input is one line ``psurf: error: ...``
on stderr and exit code 2, before anything is rendered. Numpy/matplotlib only (no pyvista):
the study itself is :mod:`psurf_core.study`, the ``--dask``/``--workers``/``--jobs`` flags
:mod:`ui.cli.parallel` (shared with ``render``).
"""

from __future__ import annotations

import argparse
import os
import shlex
import sys
import textwrap

from .common import (
    PROG,
    CliError,
    add_sampler_flags,
    explain_estimator_error,
    fail,
    load_reference,
    nonneg_int,
    positive_float,
    positive_int,
    resolution,
    scatter_int,
    shrink,
    with_resolution,
    with_scatter,
)
from .limits import check_memory, load_scene_within, probe_writable, resolve_jobs
from .parallel import add_dask_flags

#: Defaults of ``compare`` (photons per pass: small enough that the slowest photon-surface
#: MIS sets still finish many passes in a short budget).
DEFAULT_PHOTONS = 1000
DEFAULT_SPP = 1
DEFAULT_RUNS = 1
DEFAULT_SEED = 0


# --------------------------------------------------------------------------- flag types
# (the numeric ones are ui.cli.common's, so every command words its errors alike)


def _photons(text: str) -> list:
    try:
        return [t.strip() if t.strip() == "auto" else positive_int(t.strip())
                for t in text.split(",")]
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"must be 'auto', one integer > 0 or a "
                                         f"comma-separated list of them, got {text!r}") from None


def _specs(text: str) -> list[str]:
    specs = [s.strip() for s in text.split(",")]
    if not text.strip() or any(not s for s in specs):
        raise argparse.ArgumentTypeError(f"must be a comma-separated list of estimator names "
                                         f"(e.g. beams,paper-single), got {text!r}")
    dup = sorted({s for s in specs if specs.count(s) > 1})
    if dup:
        raise argparse.ArgumentTypeError(f"estimator {dup[0]!r} is listed twice")
    return specs


# --------------------------------------------------------------------------- parsers


def add_compare_parser(subparsers) -> argparse.ArgumentParser:
    """Add the ``compare`` subcommand to ``subparsers`` (``func=run_compare``)."""
    p = subparsers.add_parser(
        "compare",
        allow_abbrev=False,
        help="equal-time comparison of estimators (table, variance/error maps, error vs time)",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=textwrap.dedent(f"""\
            Render SCENE.toml with every estimator of --estimators for the same wall time
            (--time SECONDS per run; --runs R independent runs r = 0..R-1 with seeds S + r) and
            write into DIR:
              compare.json   {{"scene", "seconds", "results": [{{"estimator", "passes",
                             "mean_variance", "relmse", "ratio", ...}}], "reference", ...}}
              compare.md     the same as a Markdown table
              variance.png   variance of each final image, side by side (one log scale)
              error.png      per-pixel relative squared error vs the reference
              renders.png    reference and final images at one exposure
              error_vs_time.png   relMSE after every pass vs seconds
              reference.npz  the reference, when it was rendered here (reuse: --reference)
            Var: the variance of each final image relative to the first estimator's ("Var:
            0.23x"): across the runs (--runs 2 or more) with the defaults --pixel-sampler r2
            and --photon-sampler sobol-seq, whose passes share one low-discrepancy sequence of
            pixel points and of photons (relVar likewise); else the pixel mean of (per-pass
            variance / passes). relMSE = mean of (I - R)^2 / (R^2 + 0.01 mean(R)^2)
            against --reference FILE.npz, or else a path-tracer reference rendered first for
            --reference-time seconds (default 2 x --time x number of estimators).
            The image holds only the scene's [render] scatter range (--min-scatter/--max-scatter
            override it; single scattering: 1 and 1).
            Defaults: --photons auto --spp {DEFAULT_SPP} --pixel-sampler r2 \
--photon-sampler sobol-seq --runs {DEFAULT_RUNS} --seed {DEFAULT_SEED}."""),
    )
    p.add_argument("scene", metavar="SCENE.toml", help="scene file (see SCENES.md)")
    p.add_argument("--estimators", required=True, type=_specs, metavar="A,B,...",
                   help="estimators to compare, comma-separated; ratios are relative to the "
                        "first (e.g. beams,mis:ss-plane-uv+ss-plane-ut+ss-plane-vt)")
    p.add_argument("--time", required=True, type=positive_float, metavar="SECONDS",
                   help="wall time per run and estimator (the pass in flight finishes)")
    p.add_argument("--clock", choices=("wall", "cpu"), default="wall",
                   help="what --time measures: wall time (default) or this process's CPU time "
                        "(robust to other load on a shared machine; not with --dask/--workers)")
    p.add_argument("--runs", type=positive_int, default=DEFAULT_RUNS, metavar="R",
                   help=f"independent runs per estimator (default {DEFAULT_RUNS})")
    p.add_argument("--seed", type=nonneg_int, default=DEFAULT_SEED, metavar="S",
                   help=f"run r = 0..R-1 uses seed S + r; a rendered reference S + R "
                        f"(default {DEFAULT_SEED})")
    p.add_argument("--reference", default=None, metavar="FILE.npz",
                   help="reference image (an app.py render or compare .npz of this scene and "
                        "scatter range); default: render the path tracer first")
    p.add_argument("--reference-time", type=positive_float, default=None, metavar="SECONDS",
                   help="time of the reference render (default 2 x --time x estimators)")
    p.add_argument("--photons", type=_photons, default=["auto"], metavar="N[,N...]",
                   help="photons per pass: one count for every estimator, or one per "
                        "estimator in --estimators order; 'auto' (the default) measures "
                        "each estimator on pilot passes (its fixed and per-photon cost, its "
                        "photon and pixel variance; not counted in the budget) and picks "
                        "the pass size that minimises the final image's variance, keeping "
                        "at least 48 passes (psurf_core/pass_size.py); 'fast-full' also "
                        "gets its single-scattering share so (psurf_core/share_pilot.py; "
                        "fast-full@S fixes it)")
    p.add_argument("--resolution", type=resolution, default=None, metavar="W,H",
                   help="render at W x H pixels instead of the scene's resolution")
    p.add_argument("--spp", type=positive_int, default=DEFAULT_SPP, metavar="K",
                   help=f"camera rays per pixel per pass (default {DEFAULT_SPP})")
    add_sampler_flags(p, pixel="r2", photon="sobol-seq")
    p.add_argument("--min-scatter", type=scatter_int, default=None, metavar="A",
                   help="override the scene's [render] min_scatter (>= 1)")
    p.add_argument("--max-scatter", type=scatter_int, default=None, metavar="B",
                   help="override the scene's [render] max_scatter (>= A, or -1: unlimited)")
    p.add_argument("--radius", type=positive_float, default=None, metavar="R",
                   help="initial kernel radius of kernel estimators (default: per technique)")
    p.add_argument("--radius-shrink", type=shrink, default=1.0, metavar="ALPHA",
                   help="progressive radius reduction alpha in (0, 1] (default 1: fixed)")
    p.add_argument("--memory-budget", type=positive_int, default=None, metavar="MIB",
                   help="memory limit of the run in MiB (checked before rendering; it also "
                        "sizes the chunks of the ray x primitive work; default: the memory "
                        "available)")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="output directory (created if missing)")
    add_dask_flags(p, jobs_default="auto")
    p.set_defaults(func=run_compare)
    return p


# --------------------------------------------------------------------------- helpers


class _Bad(Exception):
    """A bad input found while preparing (becomes one error line, exit 2)."""


def _parse(spec: str, scene):
    from psurf_core.estimators import parse_estimator
    from psurf_core.scene import SceneError
    from psurf_core.techniques import UnknownTechnique

    try:
        return parse_estimator(spec, scene)
    except SceneError as e:
        raise _Bad(str(e)) from None
    except UnknownTechnique as e:
        raise _Bad(f"--estimators: {explain_estimator_error(e)} (see 'python app.py --help')") \
            from None
    except ModuleNotFoundError as e:
        raise _Bad(f"--estimators {spec!r}: not available in this build ({e})") from None
    except ValueError as e:
        raise _Bad(f"--estimators {spec!r}: {e}") from None


def _settings(args):
    from psurf_core.render import RenderSettings

    first = args.photons[0]
    kw = {"photons": DEFAULT_PHOTONS if first == "auto" else first, "spp": args.spp,
          "radius": args.radius,
          "radius_shrink": args.radius_shrink, "pixel_sampler": args.pixel_sampler,
          "photon_sampler": args.photon_sampler}
    if args.memory_budget is not None:
        kw["memory_budget_mib"] = args.memory_budget
    return RenderSettings(**kw)


def _check_out(path: str) -> None:
    if not path:
        raise _Bad("--out: empty path")
    if os.path.exists(path) and not os.path.isdir(path):
        raise _Bad(f"--out {path}: exists and is not a directory")


def _out_dir(path: str) -> None:
    _check_out(path)
    try:
        os.makedirs(path, exist_ok=True)
    except OSError as e:
        raise _Bad(f"--out {path}: cannot create directory ({e.strerror})") from None
    if not os.access(path, os.W_OK):
        raise _Bad(f"--out {path}: directory is not writable")
    probe_writable("--out", path, path)  # a read-only mount, a full disk


def _check_memory(args, scene, ests, settings, photons, render_reference: bool) -> None:
    """The largest estimator's pass work and every image the study keeps, against
    --memory-budget (or the memory available), before anything renders; ``--jobs auto``
    (the default) is first replaced by the most worker processes whose need fits
    (:func:`~ui.cli.limits.resolve_jobs`)."""
    from dataclasses import replace

    from psurf_core.budget import render_need
    from psurf_core.estimators import parse_estimator
    from psurf_core.pass_size import PILOT_PHOTONS

    runs = list(ests) + ([parse_estimator("reference", scene)] if render_reference else [])
    # 'auto' is sized later by pilot passes (the larger: PILOT_PHOTONS[-1]); checked as that
    # (the images the study keeps, which do not depend on it, are most of the need).
    sets = ([replace(settings, photons=PILOT_PHOTONS[-1] if p == "auto" else int(p))
             for p in photons] + [settings] * render_reference)
    # Kept: the reference's mean and variance, each estimator's, and the runs' final images
    # (with their stack for the spread across runs).
    kept = 2 + 2 * len(ests) + 2 * args.runs

    def need_of(jobs):
        return render_need(scene, None, None, estimators=runs, settings_list=sets, jobs=jobs,
                           local_workers=args.workers or 0, remote=args.dask is not None,
                           kept_images=kept)

    resolve_jobs(args, need_of)  # --jobs auto (the default): as many processes as fit
    check_memory(need_of(args.jobs), args.memory_budget, what="the comparison")


def _progress():
    """``(progress, on_render, close)``: a tqdm bar per render on a terminal, and one summary
    line per finished render on stdout."""
    state = {"bar": None, "label": None}
    tty = sys.stderr.isatty()

    def progress(label, passes, elapsed, budget):
        if not tty:
            return
        if state["label"] != label:
            close()
            from tqdm import tqdm

            state["bar"] = tqdm(total=budget, desc=label, file=sys.stderr, leave=False,
                                bar_format="{desc}: {percentage:3.0f}%|{bar}| "
                                           "{n:.1f}/{total:.1f} s{postfix}")
            state["label"] = label
        bar = state["bar"]
        bar.n = min(elapsed, budget)
        bar.set_postfix_str(f"{passes} passes", refresh=False)
        bar.refresh()

    def on_render(label, res):
        close()
        print(f"{label}: {res.passes} pass{'' if res.passes == 1 else 'es'} in "
              f"{res.seconds:.1f} s", flush=True)

    def close():
        if state["bar"] is not None:
            state["bar"].close()
        state["bar"] = state["label"] = None

    return progress, on_render, close


def _on_pilot(spec: str, m: dict | None) -> None:
    """One line per estimator sized by its pilot (``--photons auto``): said as the pilot
    starts (``m`` None; a slow estimator's takes seconds), completed with the pass size and
    the pass model behind it (``compare.json`` keeps the same numbers as ``pass_model``)."""
    if m is None:
        print(f"{spec}: sizing its passes (a pilot, not timed) ... ", end="", flush=True)
        return
    share = m.get("share_model")
    if share is not None:  # a shared preset: its single-scattering share came first
        print(f"single scattering on {share['share']:g} of the photons (the preset's "
              f"{share['preset_share']:g}; pilot {share['pilot_seconds']:.1f} s; "
              f"--estimators {share['spec']} --photons {m['photons']} repeat both), ", end="")
    print(f"{m['photons']} photons a pass (pilot {m['pilot_seconds']:.1f} s, not "
          f"timed; c0 {m['c0'] * 1e3:.3g} ms, c1 {m['c1'] * 1e6:.3g} us a photon, "
          f"Vj {m['vj']:.2g}, Vp {m['vp']:.2g})", flush=True)


# --------------------------------------------------------------------------- commands


def _command_line() -> str | None:
    """This process's command line as typed (``python app.py ...``), else None."""
    prog = os.path.basename(sys.argv[0]) if sys.argv else ""
    if prog != "app.py":
        return None
    return " ".join(shlex.quote(a) for a in ["python", "app.py", *sys.argv[1:]])


def run_compare(args) -> int:
    """Run ``compare``; returns 0, or 2 after one ``psurf: error:`` line."""
    from psurf_core import study as st
    from psurf_core.distributed import DistributedError, WorkersLostError
    from psurf_core.scene import SceneError

    try:
        _check_out(args.out)
        try:
            scene = with_resolution(load_scene_within(args.scene, args.memory_budget),
                                    args.resolution)  # meshes checked before loading
        except SceneError as e:
            raise _Bad(str(e)) from None
        scene = with_scatter(scene, args.min_scatter, args.max_scatter)
        ests = [_parse(s, scene) for s in args.estimators]
        reference = None
        if args.reference is not None:
            try:
                reference = load_reference(args.reference, scene)
            except SceneError as e:
                raise _Bad(str(e)) from None
        settings = _settings(args)
        if args.clock == "cpu" and (args.dask is not None or args.workers is not None):
            raise _Bad("--clock cpu measures this process only; use --clock wall with "
                       f"--{'dask' if args.dask is not None else 'workers'}")
        if args.clock == "cpu" and args.jobs != "auto" and args.jobs > 1:
            raise _Bad("--clock cpu measures this process only; use --clock wall with --jobs")
        if len(args.photons) not in (1, len(ests)):
            raise _Bad(f"--photons: give one count or one per estimator ({len(ests)}), got "
                       f"{len(args.photons)}")
        photons = args.photons * len(ests) if len(args.photons) == 1 else args.photons
        auto = args.jobs == "auto"
        _check_memory(args, scene, ests, settings, photons, reference is None)
        if auto and args.jobs > 1:
            print(f"{PROG}: note: passes in {args.jobs} worker processes, one a core (--jobs "
                  "auto; --jobs 1 runs them in this process)", file=sys.stderr)
        _out_dir(args.out)
    except (_Bad, CliError) as e:
        return fail(str(e))

    if args.reference is not None and args.reference_time is not None:
        print(f"{PROG}: note: --reference-time ignored: the reference is read from "
              f"{args.reference}", file=sys.stderr)
    command = _command_line()
    progress, on_render, close = _progress()
    kw = dict(runs=args.runs, seed=args.seed, reference=reference, settings=settings,
              reference_seconds=args.reference_time, progress=progress, on_render=on_render,
              on_pilot=_on_pilot, command=command, photons=photons, clock=args.clock)
    try:
        if args.dask is not None or args.workers is not None:
            from functools import partial

            from psurf_core.distributed import cluster_client, render_distributed

            with cluster_client(args.dask, args.workers) as client:
                study = st.compare(scene, ests, args.time,
                                   runner=partial(render_distributed, client=client), **kw)
        elif args.jobs > 1:
            from functools import partial

            from psurf_core.parallel import pass_pool, render_parallel

            with pass_pool(args.jobs) as pool:
                study = st.compare(scene, ests, args.time,
                                   runner=partial(render_parallel, pool=pool), **kw)
        else:
            study = st.compare(scene, ests, args.time, **kw)
    except WorkersLostError as e:  # mid-run: not a bad input
        fail(f"--{'dask' if args.dask is not None else 'workers'}: {e}")
        return 1
    except DistributedError as e:
        return fail(f"--{'dask' if args.dask is not None else 'workers'}: {e}")
    except (SceneError, ValueError) as e:
        return fail(str(e))
    finally:
        close()

    study["processes"] = args.jobs if args.dask is None and args.workers is None else None
    try:
        written = st.write_outputs(args.out, study)
        if study["reference"]["source"] == "render":
            ref_path = os.path.join(args.out, "reference.npz")
            st.write_reference_npz(ref_path, study, scene)
            written.append(ref_path)
    except OSError as e:
        return fail(f"--out {args.out}: cannot write the results ({e})")
    print()
    print(st.format_table(study))
    ref = study["reference"]
    if ref["source"] == "render":
        print(f"reference: path tracer, {ref['passes']} passes in {ref['seconds']:.1f} s; "
              f"its noise alone gives relMSE {ref['relmse_floor']:.3g}")
    for row in study["results"]:
        for note in row["notes"]:
            print(f"{PROG}: note: {row['estimator']}: {note}", file=sys.stderr)
    for warning in study.get("warnings", []):
        print(f"{PROG}: warning: {warning}", file=sys.stderr)
    for p in written:
        print(p)
    return 0
