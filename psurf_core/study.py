"""Equal-time comparison of estimators: variance, relMSE against a reference, error vs time.

Every estimator renders the same scene for the same wall time ``seconds``, ``runs`` times
(run ``r`` with seed ``S + r``; the same seeds for every estimator), with the same
:class:`~psurf_core.render.RenderSettings`. The image contains only the scatter counts
``[min_scatter, max_scatter]`` of the scene (``Scene.with_scatter`` picks them): a
single-scattering comparison needs a scene with ``min_scatter = max_scatter = 1``.

Numbers (every mean below is over pixels *and* the three colour channels; per estimator they
are then averaged over the runs):

``passes``
    Passes finished in one run (the mean over runs; ``passes_per_run`` lists them). The pass
    in flight when the time is up finishes and counts, so a run may exceed ``seconds`` by up to
    one pass (``seconds_per_run`` is the measured time on the budget's clock; every run also
    records ``wall_seconds`` and ``cpu_seconds``).
``per_pass_variance``
    ``mean(var)``: the per-pixel sample variance of one pass's estimate across the run's
    passes.
``mean_variance``
    ``mean(var / passes)``: the estimated variance of the run's final (mean) image, the
    "Var" of an equal-time comparison. ``null`` when a run had fewer than two passes.
``ratio``
    ``mean_variance / mean_variance`` of the first estimator ("Var: 0.23x"); ``relmse_ratio``
    likewise for ``relmse``. ``ratio_time_normalized`` multiplies each ``mean_variance`` by its
    measured run time first (it corrects for the last pass's overshoot).
``relmse``
    ``mean((I - R)^2 / (R^2 + EPS * mean(R)^2))`` with ``I`` the run's final image, ``R`` the
    reference, ``EPS = RELMSE_EPS = 1e-2`` and ``mean(R)`` the mean of the reference over
    pixels and channels. The per-pixel relative error ``(I - R)^2 / R^2`` would explode in
    dark pixels; the ``EPS`` term bounds their weight. It includes bias (kernel estimators) and
    the reference's own noise: ``reference.relmse_floor = mean((var_R / n_R) / (R^2 + EPS
    mean(R)^2))`` is what a perfect estimator would score, and ``relmse_from_variance`` is the
    same formula with the estimator's ``var / passes``: what its noise alone explains (the
    relative variance of the final image; ``relmse_from_variance_ratio`` compares it with the
    first estimator's, free of bias and of the reference's noise).
``per_photon_variance``, ``ratio_equal_photons``
    ``per_pass_variance x photons_per_pass`` (the variance one photon's contribution would
    have; ``null`` for the path tracer) and its ratio to the first estimator's: the comparison
    at an equal photon count, free of implementation speed.
``run_variance``
    With two or more runs, ``mean`` of the per-pixel sample variance of the runs' final images
    (a check on ``mean_variance`` that does not trust the per-pass variance of a heavy-tailed
    estimator); ``null`` with one run.
``curve``
    Per run, ``[seconds, passes, relmse]`` after passes 1, 2, 3, ... (thinned to at most
    :data:`CURVE_POINTS` points, log-spaced in passes), from ``render``'s ``on_pass``.

The budget is wall time by default. ``clock="cpu"`` measures this process's CPU time instead
(checked after every pass), so that other processes competing for the cores on a shared machine
do not shorten some runs more than others.

Without a reference image, :func:`compare` first renders the path tracer (``reference``) on the
same scene and scatter range for ``reference_seconds`` (default :func:`default_reference_seconds`)
with seed ``S + runs`` (no run uses it), and reports its passes and time.

numpy and matplotlib only (figures through :mod:`psurf_core.images`, no pyplot).
"""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from . import images as im
from .estimators import Estimator, parse_estimator
from .render import RenderSettings, render
from .scene import Scene, SceneError

__all__ = [
    "CURVE_POINTS",
    "RELMSE_EPS",
    "Reference",
    "compare",
    "default_reference_seconds",
    "load_reference",
    "relmse",
    "relmse_map",
    "to_json",
    "write_compare_json",
    "write_compare_md",
    "write_error_png",
    "write_error_vs_time_png",
    "write_outputs",
    "write_reference_npz",
    "write_renders_png",
    "write_variance_png",
]

#: Weight of the squared image mean in the relMSE denominator.
RELMSE_EPS = 1e-2

#: Points kept per run in the error-vs-time curve of ``compare.json``.
CURVE_POINTS = 64

#: Default reference time: this many times the total time of one run of every estimator.
REFERENCE_TIME_FACTOR = 2.0


# --------------------------------------------------------------------------- error metrics


def _den(ref: np.ndarray, eps: float) -> np.ndarray:
    ref = np.asarray(ref, dtype=np.float64)
    m = float(np.mean(ref))
    return ref**2 + eps * m * m


def relmse_map(img: np.ndarray, ref: np.ndarray, eps: float = RELMSE_EPS) -> np.ndarray:
    """(H, W) per-pixel relative squared error, averaged over channels.

    ``(img - ref)^2 / (ref^2 + eps * mean(ref)^2)``; 0 where both the numerator and the
    denominator are 0 (an all-black reference and image).
    """
    img = np.asarray(img, dtype=np.float64)
    num = (img - np.asarray(ref, dtype=np.float64)) ** 2
    den = _den(ref, eps)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(den > 0, num / np.where(den > 0, den, 1.0), np.where(num > 0, np.inf, 0.0))
    return r.mean(axis=-1)


def relmse(img: np.ndarray, ref: np.ndarray, eps: float = RELMSE_EPS) -> float:
    """Scalar relMSE: the mean of :func:`relmse_map` (module docstring)."""
    return float(np.mean(relmse_map(img, ref, eps)))


def _var_relmse(var_of_mean: np.ndarray, ref: np.ndarray, eps: float = RELMSE_EPS) -> float:
    den = _den(ref, eps)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(den > 0, var_of_mean / np.where(den > 0, den, 1.0), 0.0)
    return float(np.mean(r))


# --------------------------------------------------------------------------- reference


@dataclass
class Reference:
    """The image errors are measured against.

    Attributes
    ----------
    mean : (H, W, 3) float64
    var : (H, W, 3) float64 or None
        Per-pass variance (for the noise floor); None when unknown.
    passes : int or None
    seconds : float or None
        Render time (None for a file without it).
    source : str
        ``"render"`` (made by :func:`compare`) or the .npz path it was read from.
    estimator : str
    seed : int or None
    """

    mean: np.ndarray
    var: np.ndarray | None = None
    passes: int | None = None
    seconds: float | None = None
    source: str = "render"
    estimator: str = "reference"
    seed: int | None = None

    @property
    def floor(self) -> float | None:
        """relMSE that the reference's own noise adds to every estimator's score."""
        if self.var is None or not self.passes:
            return None
        return _var_relmse(self.var / self.passes, self.mean)


def load_reference(path: str, scene: Scene) -> Reference:
    """Read a reference image from an ``app.py render`` / ``compare`` .npz.

    Raises
    ------
    SceneError
        Missing or unreadable file, no ``mean``, a resolution other than the scene camera's,
        non-finite pixels, or a recorded scatter range other than the scene's.
    """
    try:
        with np.load(path, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except FileNotFoundError:
        raise SceneError(f"--reference {path}: file not found") from None
    except (OSError, ValueError) as e:
        raise SceneError(f"--reference {path}: cannot read .npz ({e})") from None
    if "mean" not in data:
        raise SceneError(f"--reference {path}: no 'mean' array (expected an app.py render .npz)")
    mean = np.asarray(data["mean"], dtype=np.float64)
    cam = scene.camera
    if mean.shape != (cam.height, cam.width, 3):
        raise SceneError(f"--reference {path}: image is {'x'.join(map(str, mean.shape))}, the "
                         f"scene renders {cam.height}x{cam.width}x3 (height x width x RGB)")
    if not np.isfinite(mean).all():
        raise SceneError(f"--reference {path}: 'mean' has non-finite pixels")
    if "min_scatter" in data and "max_scatter" in data:
        lo, hi = int(data["min_scatter"]), int(data["max_scatter"])
        if (lo, hi) != (scene.min_scatter, scene.max_scatter):
            raise SceneError(f"--reference {path}: rendered for scatter counts "
                             f"[{lo}, {_hi(hi)}], this comparison is "
                             f"[{scene.min_scatter}, {_hi(scene.max_scatter)}] "
                             "(use --min-scatter/--max-scatter or another reference)")
    var = data.get("var")
    passes = int(data["passes"]) if "passes" in data else None
    return Reference(
        mean=mean,
        var=None if var is None else np.asarray(var, dtype=np.float64),
        passes=passes,
        seconds=float(data["seconds"]) if "seconds" in data else None,
        source=os.fspath(path),
        estimator=str(data["estimator"]) if "estimator" in data else "?",
        seed=int(data["seed"]) if "seed" in data else None,
    )


def default_reference_seconds(seconds: float, n_estimators: int) -> float:
    """``REFERENCE_TIME_FACTOR x seconds x n_estimators`` (twice one run of every estimator)."""
    return REFERENCE_TIME_FACTOR * seconds * max(1, n_estimators)


def _hi(k: int) -> str:
    return "inf" if k == -1 else str(k)


# --------------------------------------------------------------------------- the study


def _min_k(est: Estimator) -> int:
    return min((t.min_k for t in est.techniques), default=1)


def _load() -> float | None:
    """1-minute load average (None where the OS has none)."""
    try:
        return float(os.getloadavg()[0])
    except (AttributeError, OSError):
        return None


def _machine(load_start) -> dict:
    import platform

    from . import __version__

    return {"psurf": __version__, "python": platform.python_version(),
            "numpy": np.__version__, "cpus": os.cpu_count(),
            "load_average_start": load_start, "load_average_end": _load()}


def _thin(curve: list, n: int = CURVE_POINTS) -> list:
    if len(curve) <= n:
        return curve
    idx = np.unique(np.round(np.geomspace(1, len(curve), n)).astype(int) - 1)
    return [curve[i] for i in idx]


def _nan_to_none(x):
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def _mean_or_none(values: list) -> float | None:
    vals = [v for v in values if v is not None and math.isfinite(v)]
    if len(vals) != len(values) or not vals:
        return None
    return float(np.mean(vals))


def _ratio(a, b) -> float | None:
    if a is None or b is None or not b > 0:
        return None
    return float(a / b)


def compare(
    scene: Scene,
    specs: list,
    seconds: float,
    runs: int = 1,
    seed: int = 0,
    reference: Reference | str | None = None,
    settings: RenderSettings | None = None,
    *,
    reference_seconds: float | None = None,
    progress: Callable[[str, int, float, float], None] | None = None,
    on_render: Callable[[str, object], None] | None = None,
    runner: Callable | None = None,
    command: str | None = None,
    photons: int | list | None = None,
    clock: str = "wall",
) -> dict:
    """Render every estimator for ``seconds`` of wall time, ``runs`` times; compare.

    Parameters
    ----------
    scene : Scene
        Its ``[render]`` scatter range is the range compared.
    specs : list of str or Estimator
        Estimators in table order; ratios are relative to the first.
    seconds : float
        Time per run and estimator (wall time, or CPU time with ``clock="cpu"``).
    runs : int
        Independent runs per estimator; run ``r`` uses seed ``seed + r``.
    seed : int
    reference : Reference, str or None
        The reference image (a :class:`Reference` or an .npz path); None renders the path
        tracer for ``reference_seconds`` first, with seed ``seed + runs``.
    settings : RenderSettings, optional
        Shared by every estimator (photons per pass, spp, kernel radius, ...).
    progress : callable(label, passes, elapsed, budget), optional
        Called after every pass of every render (``label`` e.g. ``"beams run 1/2"``).
    on_render : callable(label, RenderResult), optional
        Called after every render (the reference's label is ``"reference"``).
    runner : callable, optional
        ``runner(scene, estimator, settings, time_budget=, seed=, on_pass=)`` returning a
        ``RenderResult``; :func:`psurf_core.render.render` by default (pass a partial of
        :func:`psurf_core.distributed.render_distributed` to use a Dask cluster).
    command : str, optional
        The command line, recorded in the outputs.
    photons : int or list of int, optional
        Photons per pass, for all estimators or one per estimator (each estimator is most
        efficient with its own pass size: large enough that the per-pass overhead is small,
        small enough for many passes); ``settings.photons`` by default.
    clock : ``"wall"`` or ``"cpu"``
        What ``seconds`` measures: wall time (``render``'s own budget), or this process's CPU
        time (``time.process_time``, checked after every pass through ``on_pass``), which other
        processes competing for the cores do not shorten. ``"cpu"`` needs the default runner.

    Returns
    -------
    dict
        JSON-ready ``{"scene", "seconds", "runs", "seed", ..., "reference": {...},
        "results": [{"estimator", "passes", "mean_variance", "relmse", "ratio", ...}]}`` plus
        ``"arrays"`` (images for the writers; :func:`to_json` drops it).
    """
    if not specs:
        raise ValueError("no estimators to compare")
    if not (seconds > 0 and math.isfinite(seconds)):
        raise ValueError(f"seconds must be a finite number > 0, got {seconds}")
    if runs < 1:
        raise ValueError(f"runs must be >= 1, got {runs}")
    settings = settings if settings is not None else RenderSettings()
    runner = runner if runner is not None else render
    load_start = _load()
    if clock not in ("wall", "cpu"):
        raise ValueError(f"clock must be 'wall' or 'cpu', got {clock!r}")
    if clock == "cpu" and runner is not render:
        raise ValueError("a CPU-time budget measures this process only: not with a cluster")
    ests = [s if isinstance(s, Estimator) else parse_estimator(s, scene) for s in specs]
    if photons is None:
        photons = settings.photons
    if isinstance(photons, int | np.integer):
        photons = [int(photons)] * len(ests)
    photons = [int(p) for p in photons]
    if len(photons) != len(ests) or min(photons) < 1:
        raise ValueError(f"photons: give one count > 0 or one per estimator ({len(ests)}), "
                         f"got {photons}")

    def tracker(label: str, budget: float, ref_mean: np.ndarray | None, curve: list):
        def on_pass(i, acc, elapsed):
            if ref_mean is not None:
                curve.append([float(elapsed), int(acc.n), relmse(acc.mean, ref_mean)])
            if progress is not None:
                progress(label, acc.n, elapsed, budget)

        return on_pass

    def run(est, st, budget, run_seed, label, ref_mean, curve):
        track = tracker(label, budget, ref_mean, curve)
        if clock == "wall":
            return runner(scene, est, st, time_budget=budget, seed=run_seed, on_pass=track)
        c0 = time.process_time()

        def on_pass(i, acc, elapsed):
            used = time.process_time() - c0
            track(i, acc, used)
            return False if used >= budget else None

        return runner(scene, est, st, passes=1 << 62, seed=run_seed, on_pass=on_pass)

    # ---- the reference
    if isinstance(reference, str | os.PathLike):
        reference = load_reference(os.fspath(reference), scene)
    if reference is None:
        ref_seconds = (reference_seconds if reference_seconds is not None
                       else default_reference_seconds(seconds, len(ests)))
        ref_seed = seed + runs
        res = run(parse_estimator("reference", scene), settings, ref_seconds, ref_seed,
                  "reference", None, [])
        if on_render is not None:
            on_render("reference", res)
        reference = Reference(res.mean.copy(), res.var.copy(), res.passes, res.seconds,
                              "render", "reference", ref_seed)
    ref = reference.mean
    floor = reference.floor

    # ---- the estimators
    results, arrays = [], {"reference": ref, "reference_var": reference.var, "estimators": []}
    for k, est in enumerate(ests):
        est_settings = replace(settings, photons=photons[k])
        per_run, finals = [], []
        for r in range(runs):
            curve: list = []
            label = f"{est.spec} run {r + 1}/{runs}"
            t0, c0 = time.perf_counter(), time.process_time()
            res = run(est, est_settings, seconds, seed + r, label, ref, curve)
            wall, cpu = time.perf_counter() - t0, time.process_time() - c0
            if on_render is not None:
                on_render(label, res)
            n = res.passes
            mv = float(np.mean(res.var / n)) if n >= 2 else float("nan")
            per_run.append({
                "seed": seed + r,
                "passes": int(n),
                "seconds": float(res.seconds),
                "wall_seconds": float(wall),
                "cpu_seconds": float(cpu),
                "per_pass_variance": float(np.mean(res.var)) if n >= 2 else float("nan"),
                "mean_variance": mv,
                "relmse": relmse(res.mean, ref),
                "load_average": _load(),
                "relmse_from_variance": _var_relmse(res.var / n, ref) if n >= 2 else
                float("nan"),
                "curve": _thin(curve),
            })
            finals.append(res.mean)
            if r == 0:
                arrays["estimators"].append({"mean": res.mean.copy(), "var": res.var.copy(),
                                             "passes": int(n),
                                             "curves": []})
            arrays["estimators"][k]["curves"].append(curve)
        run_var = (float(np.mean(np.var(np.stack(finals), axis=0, ddof=1)))
                   if runs >= 2 else None)
        notes = list(est.notes)
        if not est.reference and _min_k(est) > scene.min_scatter:
            notes.append(f"covers K >= {_min_k(est)} only; the image has K >= "
                         f"{scene.min_scatter} (the missing part counts as error)")
        if any(run["passes"] < 2 for run in per_run):
            notes.append("a run finished fewer than 2 passes: no variance estimate "
                         "(lower --photons or raise --time)")
        passes = [run["passes"] for run in per_run]
        secs = [run["seconds" if clock == "wall" else "cpu_seconds"] for run in per_run]
        results.append({
            "estimator": est.spec,
            "photons_per_pass": None if est.reference else photons[k],
            "passes": float(np.mean(passes)),
            "passes_per_run": passes,
            "seconds_per_run": secs,
            "cpu_seconds_per_run": [run["cpu_seconds"] for run in per_run],
            "seconds_per_pass": float(np.sum(secs) / max(1, np.sum(passes))),
            "per_pass_variance": _mean_or_none([x["per_pass_variance"] for x in per_run]),
            "mean_variance": _mean_or_none([x["mean_variance"] for x in per_run]),
            "relmse": _mean_or_none([x["relmse"] for x in per_run]),
            "relmse_from_variance": _mean_or_none([x["relmse_from_variance"]
                                                   for x in per_run]),
            "run_variance": run_var,
            "notes": notes,
            "runs": [{k2: _nan_to_none(v) for k2, v in x.items()} for x in per_run],
        })

    first = results[0]
    for row in results:
        row["ratio"] = _ratio(row["mean_variance"], first["mean_variance"])
        row["relmse_ratio"] = _ratio(row["relmse"], first["relmse"])
        tn = (None if row["mean_variance"] is None else
              row["mean_variance"] * float(np.mean(row["seconds_per_run"])))
        tn0 = (None if first["mean_variance"] is None else
               first["mean_variance"] * float(np.mean(first["seconds_per_run"])))
        row["ratio_time_normalized"] = _ratio(tn, tn0)
        row["run_variance_ratio"] = _ratio(row["run_variance"], first["run_variance"])
        row["per_photon_variance"] = (None if row["per_pass_variance"] is None
                                      or row["photons_per_pass"] is None
                                      else row["per_pass_variance"] * row["photons_per_pass"])
    for row in results:
        row["ratio_equal_photons"] = _ratio(row["per_photon_variance"],
                                            first["per_photon_variance"])
        row["relmse_from_variance_ratio"] = _ratio(row["relmse_from_variance"],
                                                   first["relmse_from_variance"])

    cam = scene.camera
    return {
        "scene": scene.path,
        "seconds": float(seconds),
        "clock": clock,
        "runs": int(runs),
        "seed": int(seed),
        "resolution": [cam.width, cam.height],
        "min_scatter": scene.min_scatter,
        "max_scatter": scene.max_scatter,
        "photons_per_pass": [r["photons_per_pass"] for r in results],
        "spp": settings.spp,
        "radius": settings.radius,
        "radius_shrink": settings.radius_shrink,
        "relmse_eps": RELMSE_EPS,
        "command": command,
        "machine": _machine(load_start),
        "reference": {
            "source": reference.source,
            "estimator": reference.estimator,
            "passes": reference.passes,
            "seconds": reference.seconds,
            "seed": reference.seed,
            "relmse_floor": floor,
        },
        "results": results,
        "arrays": arrays,
    }


# --------------------------------------------------------------------------- writers


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


def format_table(study: dict) -> str:
    """The Markdown table of a study (one row per estimator; more fields in the JSON)."""
    lines = ["| estimator | photons/pass | passes/run | s/pass | mean variance | Var | "
             "Var, equal photons | relVar | relVar ratio | relMSE | relMSE ratio |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in study["results"]:
        ph = "-" if r["photons_per_pass"] is None else str(r["photons_per_pass"])
        lines.append(
            f"| `{r['estimator']}` | {ph} | {r['passes']:.4g} | {r['seconds_per_pass']:.3g} | "
            f"{_g(r['mean_variance'])} | {_x(r['ratio'])} | "
            f"{_x(r.get('ratio_equal_photons'))} | {_g(r['relmse_from_variance'])} | "
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
        f"{w}x{h} pixels, spp {study['spp']}, photons per pass in the table",
        f"- {study['seconds']:g} s of {study['clock']} time per run and estimator, "
        f"{study['runs']} run(s), seeds "
        f"{study['seed']}..{study['seed'] + study['runs'] - 1}",
        f"- machine: {study['machine']['cpus']} CPUs, 1-min load average "
        f"{_g(study['machine']['load_average_start'], '.2f')} at the start, "
        f"{_g(study['machine']['load_average_end'], '.2f')} at the end (wall-clock budgets: "
        "other load shortens every run alike only if it is steady)",
        f"- reference: {ref_text}; its noise alone gives relMSE "
        f"{_g(ref['relmse_floor'])}",
    ]
    if study.get("command"):
        lines.append(f"- command: `{study['command']}`")
    lines += ["", format_table(study), ""]
    notes = [(r["estimator"], n) for r in study["results"] for n in r["notes"]]
    if notes:
        lines += ["Notes:", ""] + [f"- `{e}`: {n}" for e, n in notes] + [""]
    lines += [
        "Var = mean variance / the first estimator's; mean variance = pixel mean of "
        "(per-pass variance / passes), the variance of the final image. 'Var, equal photons' "
        "compares per-pass variance x photons per pass instead (no time involved). relMSE = "
        f"mean over pixels and channels of (I - R)^2 / (R^2 + {study['relmse_eps']:g} "
        "mean(R)^2) against the reference R, averaged over runs; relVar is the same mean with "
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
    target = im._atomic_target(path)
    try:
        fig.savefig(target, format="png")
        os.replace(target, path)
    finally:
        if os.path.exists(target):
            os.remove(target)


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
    target = im._atomic_target(path)
    try:
        with open(target, "wb") as f:
            np.savez_compressed(f, **data)
        os.replace(target, path)
    finally:
        if os.path.exists(target):
            os.remove(target)


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
