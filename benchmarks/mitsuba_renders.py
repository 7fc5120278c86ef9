"""The renders ``benchmarks/vs_mitsuba.py`` makes: psurf's, Mitsuba's and the cached reference.

* :func:`psurf_plan`: psurf's estimator and photons per pass for an equal-time render,
  measured as ``app.py compare --photons auto`` does (``psurf_core.share_pilot.piloted``);
* :func:`psurf_render`: ``app.py render`` in a subprocess, loaded back from its .npz;
* :func:`mitsuba_render`: Mitsuba's ``volpath`` for a wall time, in passes of a calibrated
  number of samples per pixel (:func:`calibrate_spp`);
* :func:`reference`: the sum of a case's :func:`reference_parts`, each rendered once and cached
  in ``WORK/refs/``, and written summed as one ``app.py compare --reference`` file
  (:func:`composite_path`).

A reference part's budget is wall time (``ref_clock = "wall"``: ``--ref-time`` seconds on
``--jobs`` cores) or CPU time (``"cpu"``: ``--ref-time x --jobs`` CPU seconds, what the wall
budget buys on an idle machine, turned into a pass count by timing passes in CPU time), so
that references rendered at low priority on a busy machine are as good as the idle machine's.
"""

from __future__ import annotations

import math
import shlex
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path
from types import SimpleNamespace

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import mitsuba_scene as ms  # noqa: E402

from psurf_core import pass_size  # noqa: E402
from psurf_core.estimators import parse_estimator  # noqa: E402
from psurf_core.render import RenderSettings, render_pass, warm_up  # noqa: E402
from psurf_core.share_pilot import piloted  # noqa: E402

#: Seed of the reference renders (contestants use ``--seed``, default 0).
REFERENCE_SEED = 1000


@contextmanager
def _cpu_clock():
    """``psurf_core.pass_size`` times its pilot passes in CPU time (this process, all its
    threads) instead of wall time: other processes on the cores then change the pass model
    little."""
    real = pass_size.time
    pass_size.time = SimpleNamespace(perf_counter=time.process_time)
    try:
        yield
    finally:
        pass_size.time = real


def psurf_plan(scene, spec: str, seconds: float, clock: str = "wall") -> tuple[str,
                                                                             int | None]:
    """The estimator and the photons per pass for ``seconds`` of ``spec`` on ``scene`` (its
    scatter window), chosen by pilot passes in this process as ``app.py compare`` chooses them
    by default (``psurf_core.share_pilot.piloted``): ``fast-full``'s single-scattering share
    first (the spec returned is then ``fast-full@S``), then the pass model's ``N*``
    (``app.py render`` has a fixed default, 4000, far above ``N*`` for the photon surfaces:
    docs/vs_mitsuba.md). Photons ``None`` for the path tracer (no photons)."""
    est = parse_estimator(spec, scene)
    if est.reference:
        return spec, None
    if clock == "cpu":
        with _cpu_clock():
            est, m = piloted(scene, est, RenderSettings(), seconds)
    else:
        est, m = piloted(scene, est, RenderSettings(), seconds)
    return est.spec, m["photons"]


def _cpu_seconds(fn, repeats: int = 3) -> float:
    """Median CPU seconds (this process, all threads) of ``fn()``."""
    t = []
    for _ in range(repeats):
        a = time.process_time()
        fn()
        t.append(time.process_time() - a)
    return max(float(np.median(t)), 1e-6)


def psurf_cpu_passes(scene, spec: str, photons: int | None, cpu_seconds: float) -> int:
    """Passes of ``photons`` photons of ``spec`` that take about ``cpu_seconds`` of CPU time
    (passes timed here after the kernels compiled; at least 2)."""
    est = parse_estimator(spec, scene)
    st = RenderSettings() if photons is None else RenderSettings(photons=photons)
    warm_up(scene, est, st)
    seeds = iter(range(1 << 30, (1 << 30) + 100))
    t = _cpu_seconds(lambda: render_pass(scene, est, 0, next(seeds), st))
    return max(2, math.ceil(cpu_seconds / t))


def mitsuba_cpu_plan(scene, cpu_seconds: float, threads: int, spp: int | None = None,
                     target_passes: int = 40) -> tuple[int, int]:
    """``(spp, passes)`` of a Mitsuba render taking about ``cpu_seconds`` of CPU time, a pass
    about a ``target_passes``-th of it (unless ``spp`` is given); passes timed in CPU time."""
    r = ms.MitsubaRenderer(scene, spp=16, threads=threads)
    seeds = iter(range(100))
    r.pass_image(seed=ms.pass_seed(0, next(seeds), tag=2))  # compiles
    if spp is None:
        t16 = _cpu_seconds(lambda: r.pass_image(seed=ms.pass_seed(0, next(seeds), tag=2)), 1)
        spp = int(16 * (cpu_seconds / target_passes) / t16)
        spp = int(np.clip(1 << max(int(np.log2(max(spp, 1))), 0), 1, 1 << 14))
    r = ms.MitsubaRenderer(scene, spp=spp, threads=threads)
    r.pass_image(seed=ms.pass_seed(0, next(seeds), tag=2))
    t = _cpu_seconds(lambda: r.pass_image(seed=ms.pass_seed(0, next(seeds), tag=2)), 2)
    return spp, max(2, math.ceil(cpu_seconds / t))


def psurf_render(scene_path, kmin, kmax, estimator, seconds, seed, jobs, photons, out,
                 passes=None):
    """Run ``app.py render`` for ``seconds`` (or ``passes``) and load its .npz (dict of mean,
    var, ``sum_var``: the per-pass variance of the image sum, ``None`` when the file has none,
    passes, seconds, ...).

    A timed render is preceded by an untimed one of ``2 x jobs`` passes of the same command:
    ``render`` compiles its kernels before its clock starts, but on a small warm-up pass; the
    quick run after a fresh checkout spent 289 s of a 3 s budget on its first case, passes
    that compiled what the warm-up had not (docs/vs_mitsuba.md). The untimed render fills
    numba's on-disk cache with the real pass's kernels, which the timed one then loads."""
    budget = ["--time", f"{seconds:g}"] if passes is None else ["--passes", str(passes)]
    rest = ["--seed", str(seed), "--min-scatter", str(kmin), "--max-scatter", str(kmax)]
    if jobs > 1:
        rest += ["--jobs", str(jobs)]
    if photons is not None and estimator != "reference":
        rest += ["--photons", str(photons)]
    head = [sys.executable, str(ROOT / "app.py"), "render", str(ROOT / scene_path),
            "--estimator", estimator]
    if passes is None:
        scratch = Path(str(out) + ".warm.npz")
        subprocess.run([*head, "--passes", str(2 * max(jobs, 1)), *rest, "--out", str(scratch)],
                       check=True, cwd=ROOT, stdout=subprocess.DEVNULL)
        scratch.unlink(missing_ok=True)
    cmd = [*head, *budget, *rest, "--out", str(out)]
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, cwd=ROOT, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    with np.load(out) as z:
        d = {k: z[k] for k in ("mean", "var", "passes", "seconds", "photons_per_pass", "spp")}
        sum_var = np.asarray(z["sum_var"], np.float64) if "sum_var" in z.files else None
    return {"mean": d["mean"].astype(np.float64), "var": d["var"].astype(np.float64),
            "sum_var": sum_var,
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
    return {"mean": r.mean, "var": r.var, "sum_var": r.sum_var, "passes": r.passes,
            "seconds": r.seconds,
            "spp": r.spp, "warmup_seconds": r.warmup_seconds, "variant": r.variant}


def load_npz(path: Path) -> dict:
    """An ``app.py render``-style .npz as a dict (0-d arrays as Python scalars)."""
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


def part_path(work, case: str, renderer: str, kmin: int, kmax: int, ref_time: float) -> Path:
    """Cache file of one reference part."""
    return Path(work) / "refs" / f"{case}_{renderer}_K{kmin}-{kmax}_{ref_time:g}s.npz"


def composite_path(work, case: str, kind: str, kmin: int, kmax: int, ref_time: float) -> Path:
    """The summed reference of a case, readable by ``app.py compare --reference``."""
    return Path(work) / "refs" / f"{case}_sum-{kind}_K{kmin}-{kmax}_{ref_time:g}s.npz"


def render_part(renderer, case, scene, scene_path, kmin, kmax, args) -> dict:
    """One reference part, cached as :func:`part_path` (an ``app.py render``-style .npz;
    delete it to render anew). ``args``: ``work``, ``ref_time``, ``ref_clock`` (module
    docstring), ``jobs``, ``mitsuba_spp``. A part rendered here also gets ``render_seconds``,
    the wall time it took (compiling and calibrating included)."""
    path = part_path(args.work, case, renderer, kmin, kmax, args.ref_time)
    path.parent.mkdir(parents=True, exist_ok=True)
    took = None
    if not path.exists():
        t0 = time.perf_counter()
        sc = scene.with_scatter(kmin, kmax)
        cpu = args.ref_time * args.jobs if args.ref_clock == "cpu" else None
        if renderer == "mitsuba":
            if cpu is None:
                spp = args.mitsuba_spp or calibrate_spp(
                    lambda s: ms.MitsubaRenderer(sc, spp=s, threads=args.jobs), args.ref_time)
                budget = {"seconds": args.ref_time}
            else:
                spp, n = mitsuba_cpu_plan(sc, cpu, args.jobs, args.mitsuba_spp)
                budget = {"passes": n}
            r = ms.MitsubaRenderer(sc, spp=spp, threads=args.jobs).render(
                seed=REFERENCE_SEED, **budget)
            ms.save_npz(path, r, sc, REFERENCE_SEED)
        else:
            estimator = "reference" if renderer == "psurf" else renderer
            estimator, photons = psurf_plan(sc, estimator, args.ref_time, args.ref_clock)
            n = None if cpu is None else psurf_cpu_passes(sc, estimator, photons, cpu)
            psurf_render(scene_path, kmin, kmax, estimator, args.ref_time, REFERENCE_SEED,
                         args.jobs, photons, path, passes=n)
        took = time.perf_counter() - t0
    d = load_npz(path)
    if (int(d["min_scatter"]), int(d["max_scatter"])) != (kmin, kmax):
        raise SystemExit(f"{path}: rendered for another scatter window; delete it")
    return d | {"path": str(path), "render_seconds": took}


def reference_from_file(path, kmin: int, kmax: int) -> dict:
    """A case's reference read from an ``app.py render``-style .npz (``--reference-file``):
    the dict of :func:`reference`, its one part the file's renderer. The file must be for the
    case's scatter window; it should come from no contestant (another estimator, another seed).
    """
    path = Path(path)
    try:
        d = load_npz(path)
    except (OSError, ValueError, KeyError) as e:
        raise SystemExit(f"--reference-file {path}: not a render .npz ({e})") from None
    if (int(d["min_scatter"]), int(d["max_scatter"])) != (kmin, kmax):
        raise SystemExit(f"--reference-file {path}: rendered for K={d['min_scatter']}.."
                         f"{d['max_scatter']}, the case is K={kmin}..{kmax}")
    passes = max(int(d["passes"]), 1)
    part = {"renderer": "file", "min_scatter": kmin, "max_scatter": kmax,
            "estimator": str(d.get("estimator", "?")), "passes": passes,
            "spp": int(d.get("spp", 1)),
            "photons_per_pass": (int(d["photons_per_pass"]) if "photons_per_pass" in d
                                 else None),
            "seed": (int(d["seed"]) if "seed" in d else None),
            "seconds": float(d.get("seconds", 0.0)), "file": str(path), "render_seconds": None}
    return {"mean": d["mean"], "var_mean": d["var"] / passes,
            "sum_var_mean": _sum_var_mean(d), "seconds": part["seconds"], "parts": [part],
            "file": str(path)}


def _sum_var_mean(d: dict) -> np.ndarray | None:
    """(3,) variance of a render's mean image sum, ``sum_var / passes`` (``None`` when the
    .npz has no ``sum_var``: written before it was kept)."""
    if d.get("sum_var") is None:
        return None
    return np.asarray(d["sum_var"], np.float64) / max(int(d["passes"]), 1)


def reference(case, scene, scene_path, kmin, kmax, args) -> dict:
    """The case's reference: the sum of its :func:`reference_parts`, each ``--ref-time``
    seconds (independent renders, so the variances of their means add, and so do those of
    their image sums), also written to :func:`composite_path` (``var`` and ``sum_var`` there
    are the variances of the mean, with ``passes = 1``).

    Returns
    -------
    dict
        ``mean`` and ``var_mean`` (variance of the mean, per pixel) as (H, W, 3) arrays,
        ``sum_var_mean`` (3,), the variance of the mean image's sum (``None`` unless every
        part stores its ``sum_var``; parts cached before it was kept do not), ``seconds``
        (all parts), ``parts`` (renderer, window, passes, spp, seconds, file,
        ``render_seconds``: ``None`` when read from the cache) and ``file`` (the sum).
    """
    mean = var_mean = None
    sum_vars = []  # each part's (3,) sum_var / passes, None when it has none
    parts, seconds = [], 0.0
    for renderer, a, b in reference_parts(args.reference, kmin, kmax):
        d = render_part(renderer, case, scene, scene_path, a, b, args)
        vm = d["var"] / max(int(d["passes"]), 1)
        mean = d["mean"] if mean is None else mean + d["mean"]
        var_mean = vm if var_mean is None else var_mean + vm
        sum_vars.append(_sum_var_mean(d))
        seconds += float(d["seconds"])
        parts.append({"renderer": renderer, "min_scatter": a, "max_scatter": b,
                      "estimator": str(d.get("estimator", renderer)),
                      "passes": int(d["passes"]), "spp": int(d["spp"]),
                      "photons_per_pass": (int(d["photons_per_pass"])
                                           if "photons_per_pass" in d else None),
                      "seconds": float(d["seconds"]), "file": d["path"],
                      "render_seconds": d["render_seconds"]})
    out = composite_path(args.work, case, args.reference, kmin, kmax, args.ref_time)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + ".tmp.npz")
    sum_var_mean = (None if any(v is None for v in sum_vars)
                    else np.sum(sum_vars, axis=0))
    sums = {} if sum_var_mean is None else {"sum_var": sum_var_mean}
    np.savez_compressed(tmp, mean=mean, var=var_mean, passes=np.int64(1), **sums,
                        seconds=np.float64(seconds), min_scatter=np.int64(kmin),
                        max_scatter=np.int64(kmax), seed=np.int64(REFERENCE_SEED),
                        estimator=np.str_("+".join(f"{p['renderer']}[{p['min_scatter']}.."
                                                   f"{p['max_scatter']}]" for p in parts)))
    tmp.replace(out)
    return {"mean": mean, "var_mean": var_mean, "sum_var_mean": sum_var_mean,
            "seconds": seconds, "parts": parts, "file": str(out)}
