"""``python app.py record`` (a GIF/MP4 of the converging image panels) and ``python app.py
breakdown`` (the per-technique, weight and per-scatter-count PNGs of an MIS set).

``app.py`` wires them in with::

    from ui.cli.record import add_record_parsers
    add_record_parsers(sub)        # record (func=run_record), breakdown (func=run_breakdown)

Both render in this process, deterministically (:class:`ui.cli.progressive.Progressive` with
``workers=0``): pass ``i`` of every estimator is seeded by ``SeedSequence([seed, i])``, so the
same command gives the same frames. ``--passes N`` gives every estimator N passes (one frame
per round, or per ``--every`` rounds); ``--time S`` gives every estimator S seconds (equal
time; a frame after every ``--every`` passes of each estimator, so the frame count depends on
the machine).

Every bad input is one line ``psurf: error: ...`` on stderr and exit code 2, before anything is
rendered; outputs are written under temporary names and moved into place at the end, so a
failure or Ctrl-C leaves nothing half-written. The frames are drawn off-screen by
:class:`ui.views.image_panels.FigureMaker`, imported (with VTK) only once the inputs are checked.
"""

from __future__ import annotations

import argparse
import os

from .common import (
    Animation,
    CliError,
    check_output,
    nonneg_int,
    pair,
    parse_estimator_flag,
    pixel,
    positive_float,
    positive_int,
    resolution,
    with_resolution,
    write_all,
)
from .limits import check_memory, load_scene_within, probe_writable

MODES = ("render", "techniques", "bounces")
DEFAULT_PHOTONS = 1000
DEFAULT_FPS = 4.0
DEFAULT_SIZE = (960, 720)


# --------------------------------------------------------------------------- flag types


def _specs(text: str) -> list[str]:
    specs = [s.strip() for s in text.split(",")]
    if not text.strip() or any(not s for s in specs):
        raise argparse.ArgumentTypeError(f"must be a comma-separated list of estimator names, "
                                         f"got {text!r}")
    dup = sorted({s for s in specs if specs.count(s) > 1})
    if dup:
        raise argparse.ArgumentTypeError(f"estimator {dup[0]!r} is listed twice")
    return specs


def _size(text: str) -> tuple[int, int]:
    return pair(text, "W,H (two integers >= 160)", 160)


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("scene", metavar="SCENE.toml", help="scene file")
    p.add_argument("--seed", type=nonneg_int, default=0, help="random seed (default: 0)")
    p.add_argument("--photons", type=positive_int, default=DEFAULT_PHOTONS, metavar="N",
                   help=f"photons per pass (default: {DEFAULT_PHOTONS})")
    p.add_argument("--size", type=_size, default=DEFAULT_SIZE, metavar="W,H",
                   help="picture size in pixels (default: {},{})".format(*DEFAULT_SIZE))
    p.add_argument("--resolution", type=resolution, default=None, metavar="W,H",
                   help="render at W x H pixels instead of the scene's resolution")
    p.add_argument("--memory-budget", type=positive_int, default=None, metavar="MIB",
                   help="memory limit of the run in MiB (it also bounds the chunked ray x "
                        "primitive work; default: the memory available, and chunks of "
                        "psurf_core.constants.DEFAULT_MEMORY_BUDGET_MIB)")
    p.add_argument("--technique", default=None, metavar="NAME",
                   help="bounces: show this technique per K (unweighted vs weighted)")
    p.add_argument("--k", type=positive_int, default=None, metavar="K",
                   help="bounces: the scatter count compared across techniques (default 2)")


def add_record_parsers(sub) -> None:
    """Add ``record`` and ``breakdown`` to the subparsers ``sub``."""
    r = sub.add_parser(
        "record", allow_abbrev=False,
        help="record a GIF/MP4 of the image panels converging",
        description=("Render the estimators progressively (equal passes with --passes, equal "
                     "time with --time) and write one frame of the image panels per round "
                     "(or per --every rounds) to a GIF or MP4."))
    _common(r)
    est = r.add_mutually_exclusive_group(required=True)
    est.add_argument("--estimator", default=None, metavar="SPEC", help="one estimator")
    est.add_argument("--estimators", type=_specs, default=None, metavar="A,B,...",
                     help="estimators side by side (ratios relative to the first)")
    budget = r.add_mutually_exclusive_group(required=True)
    budget.add_argument("--passes", type=positive_int, default=None, metavar="N",
                        help="passes per estimator")
    budget.add_argument("--time", type=positive_float, default=None, metavar="S",
                        help="seconds per estimator (equal time)")
    r.add_argument("--out", required=True, metavar="conv.gif|conv.mp4",
                   help="animation to write (.gif, or .mp4 through imageio-ffmpeg)")
    r.add_argument("--mode", choices=MODES, default="render",
                   help="panels: render (+variance), techniques (MIS), bounces (per K)")
    r.add_argument("--every", type=positive_int, default=1, metavar="K",
                   help="one frame every K rounds of passes (default: 1)")
    r.add_argument("--fps", type=positive_float, default=DEFAULT_FPS,
                   help=f"frames per second (default: {DEFAULT_FPS:g})")
    r.add_argument("--pixel", type=pixel, default=None, metavar="X,Y",
                   help="outline this pixel on the render panels")
    r.add_argument("--reference", default=None, metavar="FILE.npz",
                   help="reference image (app.py render .npz): relMSE per estimator")
    r.set_defaults(func=run_record)

    b = sub.add_parser(
        "breakdown", allow_abbrev=False,
        help="write per-technique, weight-map and per-scatter-count PNGs of an estimator",
        description=("Render N passes of one photon estimator with its breakdown and write "
                     "into DIR: technique_<name>.png (weighted contribution, one exposure), "
                     "weight_<name>.png (share of the pixel, cividis, 0..1), bounce_K<k>.png "
                     "(all techniques), unweighted_<name>_K<k>.png / weighted_<name>_K<k>.png, "
                     "panels_techniques.png, panels_bounces.png and breakdown.npz."))
    _common(b)
    b.add_argument("--estimator", required=True, metavar="SPEC", help="photon estimator")
    b.add_argument("--passes", type=positive_int, default=8, metavar="N",
                   help="passes (default: 8)")
    b.add_argument("--out", required=True, metavar="DIR", help="output directory (created)")
    b.set_defaults(func=run_breakdown)


# --------------------------------------------------------------------------- checks


def _scene_and_estimators(args, specs, need_breakdown: bool):
    scene = with_resolution(load_scene_within(args.scene, args.memory_budget), args.resolution)
    flag = "--estimators" if len(specs) > 1 else "--estimator"
    ests = [parse_estimator_flag(s, scene, flag) for s in specs]
    photon = [e for e in ests if not e.reference]
    if need_breakdown and not photon:
        raise CliError(f"--mode {getattr(args, 'mode', 'techniques')}: needs a photon "
                       "estimator (the path tracer has no techniques)")
    if args.technique is not None and not any(
            args.technique in [t.name for t in e.techniques] for e in photon):
        names = sorted({t.name for e in photon for t in e.techniques})
        raise CliError(f"--technique {args.technique}: not in the estimators' techniques "
                       f"({', '.join(names) or 'none'})")
    if args.k is not None and photon:
        from psurf_core.breakdown import BreakdownLayout

        lay = BreakdownLayout.of(scene, photon[0])
        if args.k < lay.k_min:
            raise CliError(f"--k {args.k}: the breakdown of {photon[0].spec} starts at "
                           f"K={lay.k_min}")
    return scene, ests


def _settings(args):
    from psurf_core.render import RenderSettings

    kw = {"photons": args.photons}
    if args.memory_budget is not None:
        kw["memory_budget_mib"] = args.memory_budget
    return RenderSettings(**kw)


def _check_memory(args, scene, ests, settings, breakdown: bool, what: str) -> None:
    """Every estimator's accumulator (and breakdown stacks), one pass, the picture: against
    --memory-budget or the memory available, before anything renders."""
    from dataclasses import replace

    from psurf_core.budget import picture_bytes, progressive_need

    need = progressive_need(scene, ests, settings, workers=0, breakdown=breakdown)
    need = replace(need, extra=need.extra + (picture_bytes(*args.size),))
    check_memory(need, args.memory_budget, what=what)


def _writer_check(out: str) -> str:
    ext = os.path.splitext(out)[1].lower()
    if ext not in (".gif", ".mp4"):
        raise CliError(f"--out {out}: must end in .gif or .mp4")
    check_output("--out", out)
    if ext == ".mp4":
        try:
            import imageio_ffmpeg

            imageio_ffmpeg.get_ffmpeg_exe()
        except (ImportError, RuntimeError) as e:
            raise CliError(f"--out {out}: MP4 needs the 'imageio-ffmpeg' package ({e}); "
                           "install it or write a .gif") from None
    return ext


def _offscreen():
    try:
        from ui.views._vtk import pv

        pv.OFF_SCREEN = True
        from ui.views.image_panels import FigureMaker
    except (ImportError, RuntimeError) as e:
        raise CliError(f"off-screen rendering is unavailable ({type(e).__name__}: {e}); it "
                       "needs VTK with EGL or OSMesa (libegl1 / libosmesa6)") from None
    return FigureMaker


# --------------------------------------------------------------------------- record


def run_record(args) -> int:
    """Run ``record``; returns 0, or raises CliError (exit 2)."""

    specs = [args.estimator] if args.estimator is not None else args.estimators
    ext = _writer_check(args.out)
    probe_writable("--out", args.out, os.path.dirname(os.path.abspath(args.out)))
    scene, ests = _scene_and_estimators(args, specs, args.mode != "render")
    cam = scene.camera
    if args.pixel is not None and not (args.pixel[0] < cam.width and args.pixel[1] < cam.height):
        raise CliError(f"--pixel {args.pixel[0]},{args.pixel[1]}: outside the "
                       f"{cam.width}x{cam.height} image")
    settings = _settings(args)
    _check_memory(args, scene, ests, settings, args.mode != "render", "the recording")
    reference = None
    if args.reference is not None:
        from .common import load_reference

        reference = load_reference(args.reference, scene).mean  # SceneError: one line
    FigureMaker = _offscreen()
    from .progressive import Progressive

    prog = Progressive(scene, specs, settings, seed=args.seed,
                       workers=0, breakdown=args.mode != "render",
                       max_seconds=args.time)
    fm = FigureMaker(args.size)
    anim = Animation(args.out, ext, args.fps)
    kw = dict(reference=reference, technique=args.technique, k=args.k)
    try:
        if args.passes is not None:
            for r in range(1, args.passes + 1):
                prog.run(passes=r)
                if r % args.every == 0 or r == args.passes:
                    anim.add(fm.frame(prog, args.mode, args.pixel, **kw))
        else:
            shown = 0
            while not prog.done:
                prog.poll()
                rounds = min(prog.passes)
                if rounds >= shown + args.every:
                    shown = rounds
                    anim.add(fm.frame(prog, args.mode, args.pixel, **kw))
            if min(prog.passes) > shown or anim.frames == 0:
                anim.add(fm.frame(prog, args.mode, args.pixel, **kw))
        anim.commit()
    except BaseException:
        anim.abort()
        raise
    finally:
        fm.close()
        prog.close()
    rows = prog.summary(reference)
    print(f"wrote {args.out} ({anim.frames} frames)")
    for row in rows:
        line = f"{row['label']}: {row['passes']} passes in {row['seconds']:.1f} s"
        if len(rows) > 1 and row["ratio"] is not None:
            line += f", Var {row['ratio']:.3g}x (x time, vs {rows[0]['label']})"
        if row["relmse"] is not None:
            line += f", relMSE {row['relmse']:.3g}"
        print(line)
    return 0


# --------------------------------------------------------------------------- breakdown


def _safe(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in name)


def run_breakdown(args) -> int:
    """Run ``breakdown``; returns 0, or raises CliError (exit 2)."""
    import numpy as np

    from psurf_core import images as im

    out = args.out
    if os.path.exists(out) and not os.path.isdir(out):
        raise CliError(f"--out {out}: exists and is not a directory")
    scene, ests = _scene_and_estimators(args, [args.estimator], True)
    settings = _settings(args)
    _check_memory(args, scene, ests, settings, True, "the breakdown")
    probe_writable("--out", out, out if os.path.isdir(out) else
                   os.path.dirname(os.path.abspath(out)))
    FigureMaker = _offscreen()
    from .progressive import Progressive

    prog = Progressive(scene, [args.estimator], settings,
                       seed=args.seed, workers=0, breakdown=True)
    prog.run(passes=args.passes)
    b = prog.runs[0].breakdown
    lay = b.layout
    fm = FigureMaker(args.size)
    kw = dict(technique=args.technique, k=args.k)
    try:
        panels = {m: fm.frame(prog, m, None, **kw) for m in ("techniques", "bounces")}
    finally:
        fm.close()
        prog.close()
    try:
        os.makedirs(out, exist_ok=True)
    except OSError as e:
        raise CliError(f"--out {out}: cannot create directory ({e.strerror})") from None

    from matplotlib import colormaps

    exposure = im.auto_exposure(b.image)
    jobs = []

    def png(name, rgb8):
        jobs.append((os.path.join(out, name),
                     lambda tmp, x=rgb8: im.write_png(tmp, x, atomic=False)))

    for name, x in zip(lay.techniques, b.technique_images(), strict=True):
        png(f"technique_{_safe(name)}.png", im.tone_map(x, exposure))
    cividis = colormaps["cividis"]
    for name, w in zip(lay.techniques, b.technique_weights(), strict=True):
        png(f"weight_{_safe(name)}.png", np.round(cividis(w)[..., :3] * 255).astype(np.uint8))
    for lbl, k, x in zip(lay.labels, lay.ks, b.k_images(), strict=True):
        suffix = f"K{k}" + ("plus" if lbl.startswith("K>=") else "")
        png(f"bounce_{suffix}.png", im.tone_map(x, exposure))
        ex_k = im.auto_exposure(x)
        for t, name in enumerate(lay.techniques):
            png(f"unweighted_{_safe(name)}_{suffix}.png",
                im.tone_map(b.unweighted.mean[t, k - lay.k_min], ex_k))
            png(f"weighted_{_safe(name)}_{suffix}.png",
                im.tone_map(b.weighted.mean[t, k - lay.k_min], ex_k))
    for m, img in panels.items():
        png(f"panels_{m}.png", img)

    def npz(tmp):
        with open(tmp, "wb") as f:
            np.savez_compressed(
                f, techniques=np.array(lay.techniques), k_labels=np.array(lay.labels),
                unweighted=b.unweighted.mean.astype(np.float32),
                weighted=b.weighted.mean.astype(np.float32),
                weights=b.technique_weights().astype(np.float32),
                passes=np.int64(b.n), photons_per_pass=np.int64(args.photons),
                seed=np.int64(args.seed), estimator=np.str_(args.estimator))

    jobs.append((os.path.join(out, "breakdown.npz"), npz))
    write_all(jobs)
    for path, _ in jobs:
        print(path)
    return 0
