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
``image_variance``
    The variance of a run's final image that ``ratio`` compares: ``mean_variance``, or, with
    the ``r2`` pixel sampler or ``sobol-seq`` photons (whose passes are not independent,
    :mod:`.pixel_jitter`, :mod:`.photon_sampler`) and two or more runs, ``run_variance``
    (below). With them and one run it is ``mean_variance``, which then overstates it (a
    warning says so: only then).
``ratio``
    ``image_variance / image_variance`` of the first estimator ("Var: 0.23x");
    ``relmse_ratio`` likewise for ``relmse``. ``ratio_time_normalized`` multiplies each
    ``image_variance`` by its measured run time first (it corrects for the last pass's
    overshoot).
``relmse``
    ``mean((I - R)^2 / (R^2 + EPS * mean(R)^2))`` with ``I`` the run's final image, ``R`` the
    reference, ``EPS = RELMSE_EPS = 1e-2`` and ``mean(R)`` the mean of the reference over
    pixels and channels. The per-pixel relative error ``(I - R)^2 / R^2`` would explode in
    dark pixels; the ``EPS`` term bounds their weight. It includes bias (kernel estimators) and
    the reference's own noise: ``reference.relmse_floor = mean((var_R / n_R) / (R^2 + EPS
    mean(R)^2))`` is what a perfect estimator would score, and ``relmse_from_variance`` is the
    same formula with the estimator's ``var / passes``: what its noise alone explains (the
    relative variance of the final image; ``relmse_from_variance_ratio`` compares it with the
    first estimator's, free of bias and of the reference's noise). Where the passes are not
    independent and there are two or more runs it is ``run_relmse_from_variance``: the same
    formula with the per-pixel variance of the runs' final images.
``per_photon_variance``, ``ratio_equal_photons``
    ``per_pass_variance x photons_per_pass`` (the variance one photon's contribution would
    have; ``null`` for the path tracer) and its ratio to the first estimator's: the comparison
    at an equal photon count, free of implementation speed.
``run_variance``
    With two or more runs, ``mean`` of the per-pixel sample variance of the runs' final images
    (a check on ``mean_variance`` that does not trust the per-pass variance of a heavy-tailed
    estimator, and the variance of the image where the passes are not independent: the
    ``r2`` pixel sampler, :mod:`psurf_core.pixel_jitter`); ``null`` with one run.
    ``run_variance_ratio`` ("Var across runs") compares it with the first estimator's.
``curve``
    Per run, ``[seconds, passes, relmse]`` after passes 1, 2, 3, ... (thinned to at most
    :data:`CURVE_POINTS` points, log-spaced in passes), from ``render``'s ``on_pass``.

The budget is wall time by default. ``clock="cpu"`` measures this process's CPU time instead
(checked after every pass), so that other processes competing for the cores on a shared machine
do not shorten some runs more than others.

Without a reference image, :func:`compare` first renders the path tracer (``reference``) on the
same scene and scatter range for ``reference_seconds`` (default :func:`default_reference_seconds`)
with seed ``S + runs`` (no run uses it), and reports its passes and time.

``reference.reliability``
    Whether the reference's own per-pixel error estimate can be trusted
    (:func:`psurf_core.reliability.summarize` of its pass moments: the pixels whose passes
    are so heavy-tailed that ``var / passes`` understates the error of their mean). When
    too many pixels are flagged, or the check cannot be made (an .npz written before the
    moments were recorded), its message is also in the study's ``warnings``, which
    ``compare.md`` lists and the command line prints.

numpy and matplotlib only (figures through :mod:`psurf_core.images`, no pyplot).
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from . import reliability as rl
from .estimators import Estimator, parse_estimator
from .metrics import RELMSE_EPS, relmse, relmse_map, var_relmse
from .render import RenderSettings, render
from .scene import Scene
from .share_pilot import piloted, share_notes
from .study_ratios import add_ratios
from .study_reference import Reference, default_reference_seconds, load_reference
from .study_report import (  # the writers; re-exported so ``study`` stays the one entry point
    OUTPUT_FILES,
    format_table,
    to_json,
    write_compare_json,
    write_compare_md,
    write_error_png,
    write_error_vs_time_png,
    write_outputs,
    write_reference_npz,
    write_renders_png,
    write_variance_png,
)

__all__ = [
    "CURVE_POINTS",
    "OUTPUT_FILES",
    "RELMSE_EPS",
    "Reference",
    "compare",
    "default_reference_seconds",
    "format_table",
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

#: Points kept per run in the error-vs-time curve of ``compare.json``.
CURVE_POINTS = 64


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
    on_pilot: Callable[[str, dict | None], None] | None = None,
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
    on_pilot : callable(spec, pass model or None), optional
        Called with None as each ``"auto"`` estimator's pilot starts (its warm-up and pilot
        can take seconds for a slow estimator, before any progress bar), then with its model
        once it has chosen (the result's ``pass_model``). Not for the path tracer (no
        pilot).
    runner : callable, optional
        ``runner(scene, estimator, settings, time_budget=, seed=, on_pass=)`` returning a
        ``RenderResult``; :func:`psurf_core.render.render` by default (pass a partial of
        :func:`psurf_core.distributed.render_distributed` to use a Dask cluster).
    command : str, optional
        The command line, recorded in the outputs.
    photons : int, list of int or "auto", optional
        Photons per pass, for all estimators or one per estimator (each estimator is most
        efficient with its own pass size: large enough that the per-pass overhead is small,
        small enough for many passes); ``"auto"`` (or ``"auto"`` entries): measured per
        estimator (:func:`psurf_core.pass_size.auto_photons`; each result's
        ``pass_model`` records the pilot's numbers); ``settings.photons`` by default.
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
    if isinstance(photons, int | np.integer | str):
        photons = [photons] * len(ests)
    # The pilots' models, kept in the results ("auto" entries; None for a given count).
    pilots = [None] * len(ests)
    if len(photons) == len(ests):  # else the check below says so
        for k, (e, p) in enumerate(zip(ests, photons, strict=True)):
            if p == "auto":
                if on_pilot is not None and not e.reference:
                    on_pilot(e.spec, None)
                ests[k], pilots[k] = piloted(scene, e, settings, seconds)
                if on_pilot is not None and pilots[k] is not None:
                    on_pilot(ests[k].spec, pilots[k])
        photons = [(settings.photons if m is None else m["photons"]) if p == "auto"
                   else int(p) for m, p in zip(pilots, photons, strict=True)]
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
                              "render", "reference", ref_seed,
                              rl.npz_fields(res.accumulator) or None)
    ref = reference.mean
    floor = reference.floor
    # Heavy tails make the reference's own error bars (and so the floor) too small.
    ref_reliability = reference.reliability()
    warnings = [ref_reliability["message"]] if ref_reliability["warn"] else []
    if not settings.independent_passes and runs < 2:
        warnings.append(
            f"pixel sampler {settings.pixel_sampler!r}, photon sampler "
            f"{settings.photon_sampler!r} with one run: a run's passes share one "
            "low-discrepancy sequence, so Var (per-pass variance / passes) "
            "overstates the variance of its image; --runs 2 or more measures it across the "
            "runs' images (relMSE is unaffected)")

    # ---- the estimators
    results, arrays = [], {"reference": ref, "reference_var": reference.var,
                           "reference_moments": reference.moments, "estimators": []}
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
            tails = rl.summarize(rl.of_accumulator(res.accumulator), label)
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
                "relmse_from_variance": var_relmse(res.var / n, ref) if n >= 2 else
                float("nan"),
                "curve": _thin(curve),
                # The share of pixels whose error estimate its own passes flag (reliability).
                "heavy_tailed_fraction": tails.get("fraction"),
            })
            finals.append(res.mean)
            if r == 0:
                arrays["estimators"].append({"mean": res.mean.copy(), "var": res.var.copy(),
                                             "passes": int(n),
                                             "curves": []})
            arrays["estimators"][k]["curves"].append(curve)
        run_var_map = np.var(np.stack(finals), axis=0, ddof=1) if runs >= 2 else None
        run_var = None if run_var_map is None else float(np.mean(run_var_map))
        run_relvar = None if run_var_map is None else var_relmse(run_var_map, ref)
        correlated = not settings.independent_passes and run_var is not None
        mean_var = _mean_or_none([x["mean_variance"] for x in per_run])
        notes = list(est.notes) + share_notes(pilots[k], est)
        if not est.reference and _min_k(est) > scene.min_scatter:
            notes.append(f"covers K >= {_min_k(est)} only; the image has K >= "
                         f"{scene.min_scatter} (the missing part counts as error)")
        tail_note = rl.heavy_tail_note([x["heavy_tailed_fraction"] for x in per_run])
        if tail_note is not None:
            notes.append(tail_note)
        if any(run["passes"] < 2 for run in per_run):
            notes.append("a run finished fewer than 2 passes: no variance estimate "
                         "(lower --photons or raise --time)")
        passes = [run["passes"] for run in per_run]
        secs = [run["seconds" if clock == "wall" else "cpu_seconds"] for run in per_run]
        results.append({
            "estimator": est.spec,
            "photons_per_pass": None if est.reference else photons[k],
            "pass_model": pilots[k],
            "passes": float(np.mean(passes)),
            "passes_per_run": passes,
            "seconds_per_run": secs,
            "cpu_seconds_per_run": [run["cpu_seconds"] for run in per_run],
            "seconds_per_pass": float(np.sum(secs) / max(1, np.sum(passes))),
            "per_pass_variance": _mean_or_none([x["per_pass_variance"] for x in per_run]),
            "mean_variance": mean_var,
            "relmse": _mean_or_none([x["relmse"] for x in per_run]),
            # The runs' spread where the passes of a run are not independent (the r2 pixel
            # sampler, sobol-seq photons: per-pass variance / passes would count the noise
            # their sequences remove in full).
            "relmse_from_variance": (run_relvar if correlated else
                                     _mean_or_none([x["relmse_from_variance"]
                                                    for x in per_run])),
            "run_variance": run_var,
            "run_relmse_from_variance": run_relvar,
            "image_variance": run_var if correlated else mean_var,
            "notes": notes,
            "runs": [{k2: _nan_to_none(v) for k2, v in x.items()} for x in per_run],
        })

    add_ratios(results)

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
        "pixel_sampler": settings.pixel_sampler,
        "photon_sampler": settings.photon_sampler,
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
            "reliability": ref_reliability,
        },
        "warnings": warnings,
        "results": results,
        "arrays": arrays,
    }

