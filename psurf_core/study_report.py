"""Writers of the equal-time study (``compare``): JSON, Markdown, maps and plots.

:func:`psurf_core.study.compare` computes the study as a dict; this module only writes it.
Every file is written atomically (temporary name, then rename).
"""

from __future__ import annotations

import json
import math
import os

import numpy as np

from . import images as im
from .metrics import relmse_map
from .scene import Scene


def _hi(k: int) -> str:
    """``max_scatter`` for display (-1 means unlimited)."""
    return "inf" if k == -1 else str(k)


def _finite(x):
    if isinstance(x, dict):
        return {k: _finite(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_finite(v) for v in x]
    if isinstance(x, float | np.floating):
        return float(x) if math.isfinite(x) else None
    if isinstance(x, np.integer):
        return int(x)
    return x


def to_json(study: dict) -> dict:
    """The study without its image arrays (what ``compare.json`` holds); non-finite numbers
    become ``None``."""
    return _finite({k: v for k, v in study.items() if k != "arrays"})


def _atomic_text(path: str, text: str) -> None:
    d, base = os.path.split(os.path.abspath(path))
    tmp = os.path.join(d, f".{base}.{os.getpid()}.tmp")
    try:
        with open(tmp, "w", encoding="utf-8") as f:
            f.write(text)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def write_compare_json(path: str, study: dict) -> None:
    """``compare.json``: :func:`to_json` of the study (NaN written as null)."""
    _atomic_text(path, json.dumps(to_json(study), indent=1, allow_nan=False) + "\n")


def _g(x, fmt=".3g", none="n/a") -> str:
    return none if x is None else format(x, fmt)


def _x(x) -> str:
    return "n/a" if x is None else f"{x:.3g}x"


def _runs(ratios) -> str:
    """Run r's Var against the first estimator's run r, e.g. ``0.46, 0.14, 0.43``."""
    return ", ".join("n/a" if x is None else f"{x:.2g}" for x in ratios or []) or "n/a"


def format_table(study: dict) -> str:
    """The Markdown table of a study (one row per estimator; more fields in the JSON)."""
    lines = ["| estimator | photons/pass | passes/run | s/pass | mean variance | Var | "
             "Var, run by run | Var across runs | Var, equal photons | relVar | relVar ratio | "
             "relMSE | relMSE ratio |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in study["results"]:
        ph = "-" if r["photons_per_pass"] is None else str(r["photons_per_pass"])
        lines.append(
            f"| `{r['estimator']}` | {ph} | {r['passes']:.4g} | {r['seconds_per_pass']:.3g} | "
            f"{_g(r['mean_variance'])} | {_x(r['ratio'])} | {_runs(r.get('run_ratios'))} | "
            f"{_x(r.get('run_variance_ratio'))} | {_x(r.get('ratio_equal_photons'))} | "
            f"{_g(r['relmse_from_variance'])} | "
            f"{_x(r.get('relmse_from_variance_ratio'))} | {_g(r['relmse'])} | "
            f"{_x(r['relmse_ratio'])} |")
    return "\n".join(lines)


def write_compare_md(path: str, study: dict) -> None:
    """``compare.md``: setup, the table, notes and the definitions."""
    ref = study["reference"]
    if ref["source"] == "render":
        ref_text = (f"path tracer rendered first: {ref['passes']} passes in "
                    f"{ref['seconds']:.1f} s (seed {ref['seed']})")
    else:
        extra = (f", {ref['passes']} passes" if ref["passes"] else "") + \
                (f" in {ref['seconds']:.1f} s" if ref["seconds"] else "")
        ref_text = f"`{ref['source']}` ({ref['estimator']}{extra})"
    w, h = study["resolution"]
    lines = [
        f"# Equal-time comparison: `{study['scene']}`",
        "",
        f"- scatter counts K in [{study['min_scatter']}, {_hi(study['max_scatter'])}], "
        f"{w}x{h} pixels, spp {study['spp']}, pixel sampler "
        f"{study.get('pixel_sampler', 'independent')}, photon sampler "
        f"{study.get('photon_sampler', 'independent')}, photons per pass in the table",
        f"- {study['seconds']:g} s of {study['clock']} time per run and estimator, "
        f"{study['runs']} run(s), seeds "
        f"{study['seed']}..{study['seed'] + study['runs'] - 1}",
        f"- machine: {study['machine']['cpus']} CPUs"
        + (f", passes in {study['processes']} worker processes"
           if (study.get("processes") or 1) > 1 else "")
        + ", 1-min load average "
        f"{_g(study['machine']['load_average_start'], '.2f')} at the start, "
        f"{_g(study['machine']['load_average_end'], '.2f')} at the end (wall-clock budgets: "
        "other load shortens every run alike only if it is steady)",
        f"- reference: {ref_text}; its noise alone gives relMSE "
        f"{_g(ref['relmse_floor'])}",
    ]
    if ref.get("reliability"):
        lines.append(f"- reference error estimate: {ref['reliability']['message']}")
    if study.get("command"):
        lines.append(f"- command: `{study['command']}`")
    lines += ["", format_table(study), ""]
    if study.get("warnings"):
        lines += ["Warnings:", ""] + [f"- {w}" for w in study["warnings"]] + [""]
    notes = [(r["estimator"], n) for r in study["results"] for n in r["notes"]]
    if notes:
        lines += ["Notes:", ""] + [f"- `{e}`: {n}" for e, n in notes] + [""]
    lines += [
        "Var = the variance of the final image / the first estimator's: mean variance (the "
        "pixel mean of per-pass variance / passes) with independent passes; with the r2 pixel "
        "sampler or sobol-seq photons and two or more runs, the variance across the runs' "
        "images (their passes are not independent, so per-pass variance overstates it; relVar "
        "likewise). 'Var, equal photons' "
        "compares per-pass variance x photons per pass instead (no time involved). relMSE = "
        f"mean over pixels and channels of (I - R)^2 / (R^2 + {study['relmse_eps']:g} "
        "mean(R)^2) against the reference R, averaged over runs; 'Var, run by run' is run r's "
        "Var against the first estimator's run r (a spread much wider than the runs' own "
        "noise means a heavy-tailed estimator: one rare spike moves Var, not the median run; "
        "it divides per-pass variances / passes, which with the r2 pixel sampler overstate each "
        "image's variance by the pixel-area noise r2 removes: most for the estimator whose "
        "photons are least noisy); "
        "'Var across runs' compares the variance of the runs' final images (independent "
        "seeds; n/a with one run), which does not trust per-pass variances; "
        "relVar is relMSE's mean with "
        "the estimator's variance of the final image in the numerator: the part of relMSE its "
        "noise explains (the rest is bias and the reference's own noise). Definitions: "
        "`psurf_core/study.py`.",
        "",
    ]
    _atomic_text(path, "\n".join(lines))


def _short(spec: str, n: int = 34) -> str:
    return spec if len(spec) <= n else spec[: n - 3] + "..."


def write_variance_png(path: str, study: dict) -> None:
    """Variance of the final image (luminance of ``var / passes``, run 1) per estimator,
    side by side on one log scale."""
    maps, rows = [], study["results"]
    for a in study["arrays"]["estimators"]:
        maps.append(im.luminance(a["var"] / max(1, a["passes"])))
    lo, hi = im.log_range(np.concatenate([m.ravel() for m in maps]))
    panels = [{"image": m, "values": m, "vmin": lo, "vmax": hi, "cmap": "viridis",
               "title": f"{_short(r['estimator'])}\nVar {_x(r['ratio'])}, "
                        f"{r['runs'][0]['passes']} passes",
               "label": "variance of the image (log)"} for m, r in zip(maps, rows, strict=True)]
    im.figure_png(path, panels, title=f"{os.path.basename(study['scene'])}: variance of the "
                                      f"final image, {study['seconds']:g} s each (run 1)")


def write_error_png(path: str, study: dict) -> None:
    """Per-pixel relative squared error of the final image (run 1) per estimator."""
    ref = study["arrays"]["reference"]
    maps = [relmse_map(a["mean"], ref, study["relmse_eps"])
            for a in study["arrays"]["estimators"]]
    lo, hi = im.log_range(np.concatenate([m.ravel() for m in maps]))
    panels = [{"image": m, "values": m, "vmin": lo, "vmax": hi, "cmap": "magma",
               "title": f"{_short(r['estimator'])}\nrelMSE {_g(r['runs'][0]['relmse'])}",
               "label": "relative squared error (log)"}
              for m, r in zip(maps, study["results"], strict=True)]
    im.figure_png(path, panels, title=f"{os.path.basename(study['scene'])}: error vs the "
                                      f"reference, {study['seconds']:g} s each (run 1)")


def write_renders_png(path: str, study: dict) -> None:
    """The reference and every estimator's final image (run 1) at the reference's exposure."""
    ref = study["arrays"]["reference"]
    exposure = im.auto_exposure(ref)
    panels = [{"image": im.tone_map(ref, exposure), "title": "reference"}]
    panels += [{"image": im.tone_map(a["mean"], exposure),
                "title": f"{_short(r['estimator'])}\n{r['runs'][0]['passes']} passes"}
               for a, r in zip(study["arrays"]["estimators"], study["results"], strict=True)]
    im.figure_png(path, panels, title=f"{os.path.basename(study['scene'])}: "
                                      f"{study['seconds']:g} s each, one exposure")


def write_error_vs_time_png(path: str, study: dict) -> None:
    """relMSE after each pass against elapsed seconds (log-log), every run of every
    estimator; the reference's noise floor dashed."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6.4, 4.2), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    colours = [f"C{i % 10}" for i in range(len(study["results"]))]
    for c, a, r in zip(colours, study["arrays"]["estimators"], study["results"], strict=True):
        for j, curve in enumerate(a["curves"]):
            if not curve:
                continue
            t = np.array([p[0] for p in curve])
            e = np.array([p[2] for p in curve])
            ok = (t > 0) & (e > 0) & np.isfinite(e)
            ax.plot(t[ok], e[ok], color=c, alpha=1.0 if j == 0 else 0.4, lw=1.2,
                    label=_short(r["estimator"], 48) if j == 0 else None)
    floor = study["reference"]["relmse_floor"]
    if floor is not None and floor > 0:
        ax.axhline(floor, color="0.4", ls="--", lw=1, label="reference noise floor")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("seconds")
    ax.set_ylabel(f"relMSE (eps {study['relmse_eps']:g})")
    ax.set_title(f"{os.path.basename(study['scene'])}: error vs time", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    im.write_atomically(path, lambda target: fig.savefig(target, format="png"))


def write_reference_npz(path: str, study: dict, scene: Scene) -> None:
    """The reference image as an .npz that ``--reference`` (and ``render``'s readers) accept."""
    from . import __version__

    ref = study["reference"]
    var = study["arrays"].get("reference_var")
    var = np.zeros_like(study["arrays"]["reference"]) if var is None else var
    data = {
        "mean": study["arrays"]["reference"].astype(np.float32),
        "var": np.asarray(var, dtype=np.float32),
        "passes": np.int64(ref["passes"] or 0),
        "spp": np.int64(study["spp"]),
        "seconds": np.float64(ref["seconds"] or 0.0),
        "estimator": np.str_(ref["estimator"]),
        "seed": np.int64(ref["seed"] if ref["seed"] is not None else -1),
        "scene": np.str_(scene.path),
        "min_scatter": np.int64(scene.min_scatter),
        "max_scatter": np.int64(scene.max_scatter),
        "version": np.str_(__version__),
    }
    # The pass moments, so that a later compare --reference can check its reliability.
    data.update(study["arrays"].get("reference_moments") or {})
    def write(target):
        with open(target, "wb") as f:
            np.savez_compressed(f, **data)

    im.write_atomically(path, write)


#: Files :func:`write_outputs` writes into the output folder.
OUTPUT_FILES = ("compare.json", "compare.md", "variance.png", "error.png", "renders.png",
                "error_vs_time.png")


def write_outputs(out_dir: str, study: dict) -> list[str]:
    """Write every file of :data:`OUTPUT_FILES` into ``out_dir`` (which must exist)."""
    writers = {
        "compare.json": write_compare_json,
        "compare.md": write_compare_md,
        "variance.png": write_variance_png,
        "error.png": write_error_png,
        "renders.png": write_renders_png,
        "error_vs_time.png": write_error_vs_time_png,
    }
    written = []
    for name in OUTPUT_FILES:
        p = os.path.join(out_dir, name)
        writers[name](p, study)
        written.append(p)
    return written
