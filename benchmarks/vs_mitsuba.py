"""psurf against Mitsuba 3's ``volpath`` at equal wall time on every bundled scene.

Usage::

    python benchmarks/vs_mitsuba.py [--time 30] [--ref-time 300] [--cases a,b,...]
        [--estimator SPEC | --estimator CASE=SPEC ...] [--photons auto|N] [--jobs 2]
        [--reference composite|mitsuba|psurf] [--mitsuba-spp N] [--variant V] [--seed S]
        [--out out/vs_mitsuba.json] [--md out/vs_mitsuba.md] [--work out/vs_mitsuba]
        [--ref-clock wall|cpu] [--refs-only] [--reference-file CASE=PATH ...]

(``make bench-mitsuba`` installs the ``bench`` extra and runs it.) For each case of
:data:`CASES` (a bundled scene and a scatter window ``[min_scatter, max_scatter]``):

1. **reference**: long renders, ``--ref-time`` seconds each, seed ``1000`` (no contestant uses
   it), cached in ``--work/refs``, summed (``mitsuba_renders.reference_parts``; the sum is
   also written there as an ``app.py compare --reference`` file). ``--refs-only`` renders
   the references of the chosen cases and stops. By default
   (``--reference composite``) single scattering comes from Mitsuba and two or more events from
   psurf's ``planes``: a path tracer with next-event estimation is excellent at K = 1 but
   converges slowly beyond it (per sample, Mitsuba's relVar at K = 2..3 is 20-30x that at
   K = 1 on the study scenes, and from a point light its variance is infinite), while photon
   planes are unbiased for K >= 2 and ~100x less noisy per second there (docs/vs_mitsuba.md).
   The K = 1 part shares no code with psurf; the K >= 2 part shares psurf's tracing but not the
   contestant's estimator, and Mitsuba's image-sum z against it checks it.
   ``--reference mitsuba`` (or ``psurf``, its ``reference`` path tracer) renders the whole
   window with one path tracer instead; ``--reference-file CASE=PATH`` reads a case's
   reference from an ``app.py render`` .npz (e.g. docs/study.md's long references).
2. **psurf**: ``app.py render SCENE --estimator SPEC --time T --jobs J --photons N`` with the
   window's ``--min-scatter/--max-scatter`` (``SPEC`` from :func:`recommended`, or
   ``--estimator``); kernels compile before its clock starts. ``N`` is ``--photons``, by
   default ``auto``: chosen by pilot passes outside the clock as ``app.py compare`` chooses
   it, with ``fast-full``'s single-scattering share before it (``fast-full@S``, the spec the
   row records; ``mitsuba_renders.psurf_plan``).
3. **Mitsuba**: :class:`mitsuba_scene.MitsubaRenderer` for the wall time psurf's run took
   (its ``seconds``: at least ``T``, since psurf finishes the pass in flight) on ``J`` Dr.Jit
   threads after a warm-up pass (which compiles the kernels outside the clock),
   in passes of ``--mitsuba-spp`` samples per pixel (default: calibrated so that a pass takes
   about a 40th of the budget).

Both run one after the other, never at the same time. Scores (definitions as
``psurf_core.study``; means over pixels and channels): ``relmse`` of the final image against
the reference (``psurf_core.metrics.relmse``); ``var``, the mean per-pixel variance of the final
image (per-pass variance / passes); ``relvar``, the relMSE that this variance alone explains;
``floor``, the reference's own relVar (in every score); ``sum_z``, the z-score of the image sum
against the reference's (a bias or a convention mismatch shows as ``|sum_z| >> 3``; only with
at least :data:`MIN_PASSES_FOR_Z` passes, the largest of the channels in the table; its
standard error and ``sum_z_method``: :func:`sum_standard_error`, starred in the table when
from per-pixel variances). The ratios are psurf / Mitsuba: ``relmse_ratio`` as measured;
``relmse_above_floor_ratio`` of ``relmse - floor`` (each score's expected value is its own
relMSE against the truth plus the floor, so the plain ratio is pulled towards 1 when the floor
is not small; ``None`` when a score is not above the floor: the reference is too short to rank
that case); ``var_ratio`` of ``var``; and ``relvar_ratio_time_normalized`` with each relVar
times its measured seconds (Mitsuba runs for psurf's measured seconds, so this corrects only
rounding to whole passes).

Writes ``--out`` (JSON: every number, the command, date, commit, load averages) and ``--md``
(the Markdown table). Nothing here is a test: the machine's load changes every number.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import shlex
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import mitsuba_renders as mr  # noqa: E402
import mitsuba_scene as ms  # noqa: E402

from psurf_core.metrics import RELMSE_EPS, relmse, var_relmse  # noqa: E402
from psurf_core.scene_io import load_scene  # noqa: E402

#: (case, scene file, min_scatter, max_scatter): every bundled scene with the window of its
#: own ``[render]`` table (K = 1..inf where it has none), and the study scenes with the
#: windows of docs/study.md (``tests/test_vs_mitsuba.py`` checks that no bundled scene is left
#: out).
CASES = (
    ("point", "scenes/point.toml", 1, -1),
    ("area", "scenes/area.toml", 1, -1),
    ("area_occluder", "scenes/area_occluder.toml", 1, -1),
    ("hg", "scenes/hg.toml", 1, -1),
    ("mesh_light", "scenes/mesh_light.toml", 1, -1),
    ("showcase", "scenes/showcase.toml", 2, 3),
    ("dense_mesh_light", "scenes/dense_mesh_light.toml", 1, 4),
    ("study_medium_k1", "scenes/study_medium.toml", 1, 1),
    ("study_medium_k23", "scenes/study_medium.toml", 2, 3),
    ("study_area_k1", "scenes/study_area.toml", 1, 1),
    ("study_occluder_k23", "scenes/study_occluder.toml", 2, 3),
)

def recommended(min_scatter: int, max_scatter: int) -> str:
    """psurf's recommended estimator for a window: the README's presets tuned for equal time
    (``fast-single`` for K = 1, ``fast-multi`` for windows from K = 2, ``fast-full``
    otherwise), which win docs/study.md's equal-time comparisons where the paper's
    ``paper-*`` presets lose."""
    if max_scatter == 1:
        return "fast-single"
    if min_scatter >= 2:
        return "fast-multi"
    return "fast-full"


def _estimators(flags: list[str], cases) -> dict[str, str]:
    out = {c[0]: recommended(c[2], c[3]) for c in cases}
    for f in flags:
        if "=" in f:
            case, spec = f.split("=", 1)
            if case not in out:
                raise SystemExit(f"--estimator {f}: no case {case!r} (cases: {', '.join(out)})")
            out[case] = spec
        else:
            out = dict.fromkeys(out, f)
    return out


#: Fewer passes than this give no ``sum_z``: a per-pass variance from a handful of passes of
#: a heavy-tailed estimator is too unreliable to divide by (docs/vs_mitsuba.md: 4 passes of
#: ``paper-single`` gave -6.8 where 40 gave -0.9; 14 of ``paper-multi`` -3.1 where 269 agree).
MIN_PASSES_FOR_Z = 30


#: ``sum_z_method`` values: the standard error of the image-sum difference from the stored
#: per-pass image sums, or from the per-pixel variances as if the pixels were independent.
PER_PASS_SUMS, INDEPENDENT_PIXELS = "per-pass sums", "independent pixels"


def sum_standard_error(img: dict, ref: dict) -> tuple[np.ndarray, str]:
    """(3,) standard error of ``sum(img mean) - sum(ref mean)`` per channel, and its method.

    :data:`PER_PASS_SUMS` when ``img`` has ``sum_var`` (3,), the per-pass variance of its
    image sum, and ``ref`` its ``sum_var_mean`` (3,): ``sqrt(sum_var / passes +
    sum_var_mean)``, right whatever the correlation between the pixels of a pass. Otherwise
    :data:`INDEPENDENT_PIXELS`: the per-pixel variances of the means (``var / passes``,
    ``var_mean``, (H, W, 3)) summed, too small for photon estimators (one photon's surface
    reaches many pixels of its pass).
    """
    n = max(int(img["passes"]), 1)
    if img.get("sum_var") is not None and ref.get("sum_var_mean") is not None:
        return np.sqrt(np.asarray(img["sum_var"]) / n + ref["sum_var_mean"]), PER_PASS_SUMS
    var = (img["var"] / n).sum(axis=(0, 1)) + ref["var_mean"].sum(axis=(0, 1))
    return np.sqrt(var), INDEPENDENT_PIXELS


def score(img: dict, ref: dict) -> dict:
    """relMSE, Var, relVar and the image-sum z of a render against the reference.

    ``sum_z`` (per channel; ``None`` below :data:`MIN_PASSES_FOR_Z` passes) divides the
    difference of the image sums by :func:`sum_standard_error`; ``sum_z_method`` says how
    that was computed (``None`` with no ``sum_z``).
    """
    var_mean = img["var"] / max(img["passes"], 1)
    se, method = sum_standard_error(img, ref)
    with np.errstate(divide="ignore", invalid="ignore"):
        sum_z = (img["mean"].sum(axis=(0, 1)) - ref["mean"].sum(axis=(0, 1))) / se
    enough = img["passes"] >= MIN_PASSES_FOR_Z
    return {
        "relmse": relmse(img["mean"], ref["mean"]),
        "var": float(np.mean(var_mean)) if img["passes"] > 1 else None,
        "relvar": var_relmse(var_mean, ref["mean"]) if img["passes"] > 1 else None,
        "sum_z": [float(x) for x in sum_z] if enough else None,
        "sum_z_method": method if enough else None,
        "mean_radiance": float(np.mean(img["mean"])),
    }


def _ratio(a, b):
    return None if a is None or b is None or b == 0 else float(a / b)


def _above(relmse_value: float, floor: float) -> float | None:
    """relMSE less the reference's floor; ``None`` when not above it (reference too short)."""
    d = relmse_value - floor
    return d if d > 0 else None


def run_case(case, scene_path, kmin, kmax, estimator, args) -> dict:
    """Reference, psurf and Mitsuba for one case; the row of the table."""
    scene = load_scene(ROOT / scene_path).with_scatter(kmin, kmax)
    ref = _reference(case, scene, scene_path, kmin, kmax, args)
    work = Path(args.work)
    # With --photons auto the pilot also chooses fast-full's share (fast-full@S): the row
    # records the spec that ran.
    estimator, photons = (mr.psurf_plan(scene, estimator, args.time) if args.photons == "auto"
                          else (estimator, int(args.photons)))
    ps = mr.psurf_render(scene_path, kmin, kmax, estimator, args.time, args.seed, args.jobs,
                         photons, work / f"{case}_psurf.npz")
    # psurf finishes the pass in flight, so its run may exceed --time; Mitsuba gets the
    # seconds psurf measured: the same wall time on both sides.
    mt = mr.mitsuba_render(scene, ps["seconds"], args.seed, args.jobs, args.mitsuba_spp)
    sp, sm = score(ps, ref), score(mt, ref)
    floor = var_relmse(ref["var_mean"], ref["mean"])
    tn = (None if sp["relvar"] is None or sm["relvar"] is None
          else _ratio(sp["relvar"] * ps["seconds"], sm["relvar"] * mt["seconds"]))
    keep = ("passes", "seconds", "spp")
    return {
        "case": case, "scene": scene_path, "min_scatter": kmin, "max_scatter": kmax,
        "estimator": estimator,
        "reference": {"kind": "file" if case in args.reference_files else args.reference,
                      "seconds": ref["seconds"],
                      "parts": ref["parts"], "relmse_floor": floor, "file": ref["file"]},
        "psurf": {k: ps[k] for k in (*keep, "photons_per_pass", "process_wall_seconds",
                                     "command")} | sp | {"photons_from": str(args.photons)},
        "mitsuba": {k: mt[k] for k in (*keep, "warmup_seconds", "variant")} | sm
        | {"max_depth, subtracted": list(ms.depth_pair(scene))},
        "relmse_ratio": _ratio(sp["relmse"], sm["relmse"]),
        "relmse_above_floor_ratio": _ratio(*(_above(x["relmse"], floor) for x in (sp, sm))),
        "var_ratio": _ratio(sp["var"], sm["var"]),
        "relvar_ratio_time_normalized": tn,
    }


def _reference(case, scene, scene_path, kmin, kmax, args) -> dict:
    """The case's ``--reference-file``, else its rendered (or cached) reference."""
    if case in args.reference_files:
        return mr.reference_from_file(args.reference_files[case], kmin, kmax)
    return mr.reference(case, scene, scene_path, kmin, kmax, args)


def _reference_files(flags: list[str], names) -> dict[str, str]:
    out = {}
    for f in flags:
        case, eq, path = f.partition("=")
        if not eq or case not in names:
            raise SystemExit(f"--reference-file {f}: expected CASE=PATH with CASE one of "
                             f"{', '.join(names)}")
        if not Path(path).is_file():
            raise SystemExit(f"--reference-file {f}: no file {path}")
        out[case] = path
    return out


def _f(x, fmt=".3g"):
    return "–" if x is None else format(x, fmt)


def _x(x):
    return "–" if x is None else f"{x:.3g}×"


def markdown(rows: list[dict]) -> str:
    """The comparison table (psurf / Mitsuba ratios and both sides' numbers); a sum z from
    the independent-pixel standard error is starred, with a note under the table."""
    head = ("| case | K | psurf estimator | psurf relMSE | Mitsuba relMSE | **relMSE ratio** | "
            "ratio above the ref floor | Var ratio | relVar ratio, time-normalized "
            "| psurf s, passes | Mitsuba s, passes (spp) | ref floor | sum z psurf, Mitsuba |")
    lines = [head, "|" + "---|" * 3 + "---:|" * 10]
    for r in rows:
        k = f"{r['min_scatter']}..{'∞' if r['max_scatter'] < 0 else r['max_scatter']}"
        p, m = r["psurf"], r["mitsuba"]
        zs = ", ".join(_z(x) for x in (p, m))
        lines.append(
            f"| {r['case']} | {k} | `{r['estimator']}` | {_f(p['relmse'])} | {_f(m['relmse'])} "
            f"| **{_x(r['relmse_ratio'])}** | {_x(r['relmse_above_floor_ratio'])} "
            f"| {_x(r['var_ratio'])} "
            f"| {_x(r['relvar_ratio_time_normalized'])} | {p['seconds']:.1f}, {p['passes']} "
            f"| {m['seconds']:.1f}, {m['passes']} ({m['spp']}) "
            f"| {_f(r['reference']['relmse_floor'])} | {zs} |")
    if any(x.get("sum_z_method") == INDEPENDENT_PIXELS
           for r in rows for x in (r["psurf"], r["mitsuba"])):
        lines += ["", "\\* sum z from per-pixel variances as if the pixels were independent "
                  "(a render or reference without stored per-pass image sums): not a bias "
                  "test for photon estimators."]
    return "\n".join(lines) + "\n"


def _z(x: dict) -> str:
    """The largest-magnitude channel's sum z (starred: independent-pixel standard error)."""
    if x["sum_z"] is None:
        return "–"
    star = "\\*" if x.get("sum_z_method") == INDEPENDENT_PIXELS else ""
    return f"{max(x['sum_z'], key=abs):.1f}{star}"


def _commit() -> str:
    """The checkout's short commit, ``+dirty`` when tracked files differ from it."""
    def git(*a):
        return subprocess.run(["git", *a], cwd=ROOT, text=True, capture_output=True,
                              check=True).stdout.strip()

    try:
        dirty = git("status", "--porcelain", "--untracked-files=no")
        return git("rev-parse", "--short", "HEAD") + ("+dirty" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def _photons(text: str) -> str | int:
    if text == "auto":
        return text
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise argparse.ArgumentTypeError(f"must be 'auto' or an integer > 0, got {text!r}")
    return n


def refs_only(cases, args) -> int:
    """Render (or find cached) every reference part of ``cases``; print each part's passes,
    its floor and the wall time its render took (``cached`` when it was already there)."""
    t0 = time.perf_counter()
    for case, scene_path, kmin, kmax in cases:
        scene = load_scene(ROOT / scene_path).with_scatter(kmin, kmax)
        ref = _reference(case, scene, scene_path, kmin, kmax, args)
        for p in ref["parts"]:
            took = ("cached" if p["render_seconds"] is None
                    else f"rendered in {p['render_seconds']:.0f} s")
            print(f"{case}: {p['renderer']} K={p['min_scatter']}..{p['max_scatter']}: "
                  f"{p['passes']} passes, {took}: {p['file']}", flush=True)
        print(f"{case}: floor {var_relmse(ref['var_mean'], ref['mean']):.3g}, sum in "
              f"{ref['file']}", flush=True)
    print(f"references of {len(cases)} case(s) in {time.perf_counter() - t0:.0f} s "
          f"(load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores)")
    return 0


def main(argv=None) -> int:
    """Command line (module docstring)."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--time", type=float, default=30.0, help="seconds of wall time per side")
    ap.add_argument("--ref-time", type=float, default=300.0,
                    help="seconds of each reference part (reference_parts)")
    ap.add_argument("--ref-clock", choices=("wall", "cpu"), default="wall",
                    help="a reference part's budget: --ref-time of wall time on --jobs cores, "
                         "or (cpu) --ref-time x --jobs CPU seconds as a pass count, for "
                         "rendering references on a busy machine (default: wall)")
    ap.add_argument("--cases", default="all", help="comma-separated case names, or 'all'")
    ap.add_argument("--estimator", action="append", default=[],
                    help="SPEC for every case or CASE=SPEC (repeat); default: recommended()")
    ap.add_argument("--photons", type=_photons, default="auto",
                    help="psurf photons per pass: a count, or 'auto' (the default: the pass "
                         "model's N*, as app.py compare chooses it)")
    ap.add_argument("--jobs", type=int, default=2, help="psurf --jobs and Dr.Jit threads")
    ap.add_argument("--reference", choices=("composite", "mitsuba", "psurf"),
                    default="composite", help="reference_parts() (default: composite)")
    ap.add_argument("--reference-file", action="append", default=[], metavar="CASE=PATH",
                    help="use an app.py render .npz as CASE's reference (repeat; it must "
                         "come from no contestant), instead of rendering one")
    ap.add_argument("--mitsuba-spp", type=int, default=None,
                    help="Mitsuba samples per pixel per pass (default: calibrated)")
    ap.add_argument("--variant", default=None, help="Mitsuba variant (default: probed)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default="out/vs_mitsuba.json")
    ap.add_argument("--md", default="out/vs_mitsuba.md")
    ap.add_argument("--work", default="out/vs_mitsuba", help="renders and cached references")
    ap.add_argument("--refs-only", action="store_true",
                    help="render (or find cached) the references of the cases, then stop")
    args = ap.parse_args(argv)
    names = [c[0] for c in CASES]
    wanted = names if args.cases == "all" else args.cases.split(",")
    bad = [w for w in wanted if w not in names]
    if bad:
        ap.error(f"unknown case(s) {', '.join(bad)}; cases: {', '.join(names)}")
    cases = [c for c in CASES if c[0] in wanted]
    estimators = _estimators(args.estimator, cases)
    args.reference_files = _reference_files(args.reference_file, names)
    variant = ms.pick_variant(args.variant)
    Path(args.work).mkdir(parents=True, exist_ok=True)
    if args.refs_only:
        return refs_only(cases, args)
    started = dt.datetime.now(dt.UTC)
    commit = _commit()  # before the run: the code that ran, not what HEAD is at the end
    load0 = os.getloadavg()
    rows = []
    for case, path, kmin, kmax in cases:
        row = run_case(case, path, kmin, kmax, estimators[case], args)
        rows.append(row)
        print(f"{case}: relMSE psurf {row['psurf']['relmse']:.3g}, Mitsuba "
              f"{row['mitsuba']['relmse']:.3g}, ratio {_f(row['relmse_ratio'])}", flush=True)
    table = markdown(rows)
    result = {
        "command": " ".join(shlex.quote(a) for a in [sys.executable, *sys.argv]),
        "started_utc": started.isoformat(timespec="seconds"),
        "finished_utc": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        "commit": commit, "variant": variant, "cpu_count": os.cpu_count(),
        "loadavg_start": load0, "loadavg_end": os.getloadavg(),
        "relmse_eps": RELMSE_EPS, "time": args.time, "jobs": args.jobs, "rows": rows,
    }
    for path, text in ((args.out, json.dumps(result, indent=1)), (args.md, table)):
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(str(path) + ".tmp")
        tmp.write_text(text)
        tmp.replace(path)
    print(table)
    print(f"wrote {args.out} and {args.md} (Mitsuba variant {variant}; load average "
          f"{load0[0]:.1f} -> {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
