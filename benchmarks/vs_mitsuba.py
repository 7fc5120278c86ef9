"""psurf against Mitsuba 3's ``volpath`` at equal wall time on every bundled scene.

Usage::

    python benchmarks/vs_mitsuba.py [--time 30] [--ref-time 300] [--cases a,b,...]
        [--estimator SPEC | --estimator CASE=SPEC ...] [--photons N] [--jobs 2]
        [--reference composite|mitsuba|psurf] [--mitsuba-spp N] [--variant V] [--seed S]
        [--out out/vs_mitsuba.json] [--md out/vs_mitsuba.md] [--work out/vs_mitsuba]

(``make bench-mitsuba`` installs the ``bench`` extra and runs it.) For each case of
:data:`CASES` (a bundled scene and a scatter window ``[min_scatter, max_scatter]``):

1. **reference**: long renders, ``--ref-time`` seconds each, seed ``1000`` (no contestant uses
   it), cached in ``--work/refs``, summed (:func:`reference_parts`). By default
   (``--reference composite``) single scattering comes from Mitsuba and two or more events from
   psurf's ``planes``: a path tracer with next-event estimation is excellent at K = 1 but
   converges slowly beyond it (per sample, Mitsuba's relVar at K = 2..3 is 20-30x that at
   K = 1 on the study scenes, and from a point light its variance is infinite), while photon
   planes are unbiased for K >= 2 and ~100x less noisy per second there (docs/vs_mitsuba.md).
   The K = 1 part shares no code with psurf; the K >= 2 part shares psurf's tracing but not the
   contestant's estimator, and Mitsuba's image-sum z against it checks it.
   ``--reference mitsuba`` (or ``psurf``, its ``reference`` path tracer) renders the whole
   window with one path tracer instead.
2. **psurf**: ``app.py render SCENE --estimator SPEC --time T --jobs J`` with the window's
   ``--min-scatter/--max-scatter`` (``SPEC`` from :func:`recommended`, or ``--estimator``);
   kernels compile before its clock starts.
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
at least :data:`MIN_PASSES_FOR_Z` passes, the largest of the channels in the table). The ratios
are psurf / Mitsuba: ``relmse_ratio`` as measured; ``relmse_above_floor_ratio`` of
``relmse - floor`` (each score's expected value is its own relMSE against the truth plus the
floor, so the plain ratio is pulled towards 1 when the floor is not small; ``None`` when a score
is not above the floor: the reference is too short to rank that case); ``var_ratio`` of
``var``; and ``relvar_ratio_time_normalized`` with each relVar times its measured seconds
(Mitsuba runs for psurf's measured seconds, so this corrects only rounding to whole passes).

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

import mitsuba_scene as ms  # noqa: E402

from psurf_core.metrics import RELMSE_EPS, relmse, var_relmse  # noqa: E402
from psurf_core.scene_io import load_scene  # noqa: E402

#: (case, scene file, min_scatter, max_scatter): every bundled scene with its own [render]
#: window, and the study scenes with the windows of docs/study.md.
CASES = (
    ("point", "scenes/point.toml", 1, -1),
    ("area", "scenes/area.toml", 1, -1),
    ("area_occluder", "scenes/area_occluder.toml", 1, -1),
    ("hg", "scenes/hg.toml", 1, -1),
    ("mesh_light", "scenes/mesh_light.toml", 1, -1),
    ("study_medium_k1", "scenes/study_medium.toml", 1, 1),
    ("study_medium_k23", "scenes/study_medium.toml", 2, 3),
    ("study_area_k1", "scenes/study_area.toml", 1, 1),
    ("study_occluder_k23", "scenes/study_occluder.toml", 2, 3),
)

#: Seed of the reference renders (contestants use ``--seed``, default 0).
REFERENCE_SEED = 1000


def recommended(min_scatter: int, max_scatter: int) -> str:
    """psurf's recommended estimator for a window: the paper's presets (README)."""
    if max_scatter == 1:
        return "paper-single"
    if min_scatter >= 2:
        return "paper-multi"
    return "paper-full"


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


def psurf_render(scene_path, kmin, kmax, estimator, seconds, seed, jobs, photons, out):
    """Run ``app.py render`` and load its .npz (dict of mean, var, passes, seconds, ...)."""
    cmd = [sys.executable, str(ROOT / "app.py"), "render", str(ROOT / scene_path),
           "--estimator", estimator, "--time", f"{seconds:g}", "--seed", str(seed),
           "--min-scatter", str(kmin), "--max-scatter", str(kmax), "--out", str(out)]
    if jobs > 1:
        cmd += ["--jobs", str(jobs)]
    if photons is not None and estimator != "reference":
        cmd += ["--photons", str(photons)]
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, cwd=ROOT, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    with np.load(out) as z:
        d = {k: z[k] for k in ("mean", "var", "passes", "seconds", "photons_per_pass", "spp")}
    return {"mean": d["mean"].astype(np.float64), "var": d["var"].astype(np.float64),
            "passes": int(d["passes"]), "seconds": float(d["seconds"]),
            "photons_per_pass": int(d["photons_per_pass"]), "spp": int(d["spp"]),
            "process_wall_seconds": wall,
            "command": " ".join(shlex.quote(str(c)) for c in cmd)}


def calibrate_spp(renderer_for, seconds: float, spp0: int = 16, target_passes: int = 40) -> int:
    """Samples per pixel per Mitsuba pass so that a pass takes about ``seconds / target``."""
    r = renderer_for(spp0)
    r.pass_image(seed=ms.pass_seed(0, 0, tag=2))  # compiles
    t0 = time.perf_counter()
    r.pass_image(seed=ms.pass_seed(0, 1, tag=2))
    dt_pass = max(time.perf_counter() - t0, 1e-4)
    spp = int(spp0 * (seconds / target_passes) / dt_pass)
    return int(np.clip(1 << max(int(np.log2(max(spp, 1))), 0), 1, 1 << 14))


def mitsuba_render(scene, seconds, seed, jobs, spp):
    """Equal-time Mitsuba render of the scene's window (dict as :func:`psurf_render`)."""
    def make(s):
        return ms.MitsubaRenderer(scene, spp=s, threads=jobs)

    if spp is None:
        spp = calibrate_spp(make, seconds)
    r = make(spp).render(seconds=seconds, seed=seed)
    return {"mean": r.mean, "var": r.var, "passes": r.passes, "seconds": r.seconds,
            "spp": r.spp, "warmup_seconds": r.warmup_seconds, "variant": r.variant}


def _load_npz(path: Path) -> dict:
    with np.load(path) as z:
        d = {k: (z[k].item() if z[k].ndim == 0 else z[k]) for k in z.files}
    return d | {"mean": np.asarray(d["mean"], np.float64), "var": np.asarray(d["var"], np.float64)}


def reference_parts(kind: str, kmin: int, kmax: int) -> list[tuple[str, int, int]]:
    """The renders ``(renderer, min_scatter, max_scatter)`` whose sum is a case's reference.

    ``composite`` (the default): single scattering from Mitsuba, two or more events from
    psurf's ``planes`` (unbiased for K >= 2, and per second far less noisy there than any path
    tracer with next-event estimation: docs/vs_mitsuba.md); ``mitsuba`` and ``psurf`` (its
    ``reference`` path tracer): the whole window from one renderer.
    """
    if kind != "composite":
        return [(kind, kmin, kmax)]
    parts = [("mitsuba", 1, 1)] if kmin == 1 else []
    if kmax < 0 or kmax >= 2:
        parts.append(("planes", max(kmin, 2), kmax))
    return parts


def _render_part(renderer, case, scene, scene_path, kmin, kmax, args) -> dict:
    """One reference part, cached as ``--work/refs/<case>_<renderer>_K<a>-<b>_<s>s.npz`` (an
    ``app.py render``-style .npz; delete it to render anew)."""
    refs = Path(args.work) / "refs"
    refs.mkdir(parents=True, exist_ok=True)
    path = refs / f"{case}_{renderer}_K{kmin}-{kmax}_{args.ref_time:g}s.npz"
    if not path.exists():
        if renderer == "mitsuba":
            sc = scene.with_scatter(kmin, kmax)
            spp = args.mitsuba_spp or calibrate_spp(
                lambda s: ms.MitsubaRenderer(sc, spp=s, threads=args.jobs), args.ref_time)
            r = ms.MitsubaRenderer(sc, spp=spp, threads=args.jobs).render(
                seconds=args.ref_time, seed=REFERENCE_SEED)
            ms.save_npz(path, r, sc, REFERENCE_SEED)
        else:
            estimator = "reference" if renderer == "psurf" else renderer
            psurf_render(scene_path, kmin, kmax, estimator, args.ref_time, REFERENCE_SEED,
                         args.jobs, None, path)
    d = _load_npz(path)
    if (int(d["min_scatter"]), int(d["max_scatter"])) != (kmin, kmax):
        raise SystemExit(f"{path}: rendered for another scatter window; delete it")
    return d | {"path": str(path)}


def reference(case, scene, scene_path, kmin, kmax, args) -> dict:
    """The case's reference: the sum of its :func:`reference_parts`, each ``--ref-time``
    seconds (independent renders, so the variances of their means add).

    Returns
    -------
    dict
        ``mean`` and ``var_mean`` (variance of the mean, per pixel) as (H, W, 3) arrays,
        ``seconds`` (all parts) and ``parts`` (renderer, window, passes, spp, seconds, file).
    """
    mean = var_mean = None
    parts, seconds = [], 0.0
    for renderer, a, b in reference_parts(args.reference, kmin, kmax):
        d = _render_part(renderer, case, scene, scene_path, a, b, args)
        vm = d["var"] / max(int(d["passes"]), 1)
        mean = d["mean"] if mean is None else mean + d["mean"]
        var_mean = vm if var_mean is None else var_mean + vm
        seconds += float(d["seconds"])
        parts.append({"renderer": renderer, "min_scatter": a, "max_scatter": b,
                      "estimator": str(d.get("estimator", renderer)),
                      "passes": int(d["passes"]), "spp": int(d["spp"]),
                      "photons_per_pass": (int(d["photons_per_pass"])
                                           if "photons_per_pass" in d else None),
                      "seconds": float(d["seconds"]), "file": d["path"]})
    return {"mean": mean, "var_mean": var_mean, "seconds": seconds, "parts": parts}


#: Fewer passes than this give no ``sum_z``: a per-pass variance from a handful of passes of
#: a heavy-tailed estimator is too unreliable to divide by (docs/vs_mitsuba.md: 4 passes of
#: ``paper-single`` gave -6.8 where 40 gave -0.9; 14 of ``paper-multi`` -3.1 where 269 agree).
MIN_PASSES_FOR_Z = 30


def score(img: dict, ref: dict) -> dict:
    """relMSE, Var, relVar and the image-sum z of a render against the reference."""
    var_mean = img["var"] / max(img["passes"], 1)
    ref_var_mean = ref["var_mean"]
    se = np.sqrt(var_mean.sum(axis=(0, 1)) + ref_var_mean.sum(axis=(0, 1)))
    with np.errstate(divide="ignore", invalid="ignore"):
        sum_z = (img["mean"].sum(axis=(0, 1)) - ref["mean"].sum(axis=(0, 1))) / se
    return {
        "relmse": relmse(img["mean"], ref["mean"]),
        "var": float(np.mean(var_mean)) if img["passes"] > 1 else None,
        "relvar": var_relmse(var_mean, ref["mean"]) if img["passes"] > 1 else None,
        "sum_z": ([float(x) for x in sum_z] if img["passes"] >= MIN_PASSES_FOR_Z else None),
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
    ref = reference(case, scene, scene_path, kmin, kmax, args)
    work = Path(args.work)
    ps = psurf_render(scene_path, kmin, kmax, estimator, args.time, args.seed, args.jobs,
                      args.photons, work / f"{case}_psurf.npz")
    # psurf finishes the pass in flight, so its run may exceed --time; Mitsuba gets the
    # seconds psurf measured: the same wall time on both sides.
    mt = mitsuba_render(scene, ps["seconds"], args.seed, args.jobs, args.mitsuba_spp)
    sp, sm = score(ps, ref), score(mt, ref)
    floor = var_relmse(ref["var_mean"], ref["mean"])
    tn = (None if sp["relvar"] is None or sm["relvar"] is None
          else _ratio(sp["relvar"] * ps["seconds"], sm["relvar"] * mt["seconds"]))
    keep = ("passes", "seconds", "spp")
    return {
        "case": case, "scene": scene_path, "min_scatter": kmin, "max_scatter": kmax,
        "estimator": estimator,
        "reference": {"kind": args.reference, "seconds": ref["seconds"],
                      "parts": ref["parts"], "relmse_floor": floor},
        "psurf": {k: ps[k] for k in (*keep, "photons_per_pass", "process_wall_seconds",
                                     "command")} | sp,
        "mitsuba": {k: mt[k] for k in (*keep, "warmup_seconds", "variant")} | sm
        | {"max_depth, subtracted": list(ms.depth_pair(scene))},
        "relmse_ratio": _ratio(sp["relmse"], sm["relmse"]),
        "relmse_above_floor_ratio": _ratio(*(_above(x["relmse"], floor) for x in (sp, sm))),
        "var_ratio": _ratio(sp["var"], sm["var"]),
        "relvar_ratio_time_normalized": tn,
    }


def _f(x, fmt=".3g"):
    return "–" if x is None else format(x, fmt)


def _x(x):
    return "–" if x is None else f"{x:.3g}×"


def markdown(rows: list[dict]) -> str:
    """The comparison table (psurf / Mitsuba ratios and both sides' numbers)."""
    head = ("| case | K | psurf estimator | psurf relMSE | Mitsuba relMSE | **relMSE ratio** | "
            "ratio above the ref floor | Var ratio | relVar ratio, time-normalized "
            "| psurf s, passes | Mitsuba s, passes (spp) | ref floor | sum z psurf, Mitsuba |")
    lines = [head, "|" + "---|" * 3 + "---:|" * 10]
    for r in rows:
        k = f"{r['min_scatter']}..{'∞' if r['max_scatter'] < 0 else r['max_scatter']}"
        p, m = r["psurf"], r["mitsuba"]
        zs = ", ".join("–" if x["sum_z"] is None else f"{max(x['sum_z'], key=abs):.1f}"
                       for x in (p, m))
        lines.append(
            f"| {r['case']} | {k} | `{r['estimator']}` | {_f(p['relmse'])} | {_f(m['relmse'])} "
            f"| **{_x(r['relmse_ratio'])}** | {_x(r['relmse_above_floor_ratio'])} "
            f"| {_x(r['var_ratio'])} "
            f"| {_x(r['relvar_ratio_time_normalized'])} | {p['seconds']:.1f}, {p['passes']} "
            f"| {m['seconds']:.1f}, {m['passes']} ({m['spp']}) "
            f"| {_f(r['reference']['relmse_floor'])} | {zs} |")
    return "\n".join(lines) + "\n"


def _commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, text=True,
                              capture_output=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def main(argv=None) -> int:
    """Command line (module docstring)."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--time", type=float, default=30.0, help="seconds of wall time per side")
    ap.add_argument("--ref-time", type=float, default=300.0,
                    help="seconds of each reference part (reference_parts)")
    ap.add_argument("--cases", default="all", help="comma-separated case names, or 'all'")
    ap.add_argument("--estimator", action="append", default=[],
                    help="SPEC for every case or CASE=SPEC (repeat); default: recommended()")
    ap.add_argument("--photons", type=int, default=None,
                    help="psurf photons per pass (default: app.py render's)")
    ap.add_argument("--jobs", type=int, default=2, help="psurf --jobs and Dr.Jit threads")
    ap.add_argument("--reference", choices=("composite", "mitsuba", "psurf"),
                    default="composite", help="reference_parts() (default: composite)")
    ap.add_argument("--mitsuba-spp", type=int, default=None,
                    help="Mitsuba samples per pixel per pass (default: calibrated)")
    ap.add_argument("--variant", default=None, help="Mitsuba variant (default: probed)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default="out/vs_mitsuba.json")
    ap.add_argument("--md", default="out/vs_mitsuba.md")
    ap.add_argument("--work", default="out/vs_mitsuba", help="renders and cached references")
    args = ap.parse_args(argv)
    names = [c[0] for c in CASES]
    wanted = names if args.cases == "all" else args.cases.split(",")
    bad = [w for w in wanted if w not in names]
    if bad:
        ap.error(f"unknown case(s) {', '.join(bad)}; cases: {', '.join(names)}")
    cases = [c for c in CASES if c[0] in wanted]
    estimators = _estimators(args.estimator, cases)
    variant = ms.pick_variant(args.variant)
    Path(args.work).mkdir(parents=True, exist_ok=True)
    started = dt.datetime.now(dt.UTC)
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
        "commit": _commit(), "variant": variant, "cpu_count": os.cpu_count(),
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
