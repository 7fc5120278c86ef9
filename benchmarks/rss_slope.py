"""Memory of long runs over time: resident set size sampled, its slope fitted.

Usage::

    python benchmarks/rss_slope.py render [--seconds 1800] [--scene S] [--estimator E]
        [--photons N] [--checkpoint-every C] [--jobs J] [--interval 1] [--json OUT.json]
    python benchmarks/rss_slope.py progressive [--seconds 1800] [--estimators A,B] ...
    xvfb-run -a -s "-screen 0 1700x1000x24" python benchmarks/rss_slope.py window \
        [--seconds 1800] [--scene S] [--estimators A,B] [--photons N]

``render`` runs ``app.py render --time SECONDS --checkpoint DIR`` in a subprocess (the
command a user leaves running) and samples the summed ``VmRSS`` of it and its children
(``--jobs`` workers) every ``--interval`` seconds. ``progressive`` drives the window's
background render (:class:`ui.cli.progressive.Progressive`, one worker process, polled ten
times a second as the window's timer does, every estimator accumulating) in this process
and samples this process plus its worker; the VTK window itself is not opened. Its clock
starts once every estimator has its first pass (compiling is reported apart). ``window``
opens the window itself (``app.py SCENE --estimators A,B``, on the display in ``DISPLAY``:
run it under ``xvfb-run`` without one), samples it and its children (the render worker,
the stage inspector) from outside for ``--seconds`` after a ``--warmup`` and closes it
(SIGTERM); its passes are not checked (``progressive`` checks the same render's).

Reported (and written to ``--json``, with every sample): RSS at the start of the fit,
at the end, its minimum and maximum, and slopes in MiB per hour over the samples after the
first ``--warmup`` seconds (compilation, first allocations): least squares over every sample
(with its standard error), over the floor (the lowest sample of every ``--floor-window``
seconds: what stays allocated between the passes' transient peaks, the number to read for
the window) and over the level (each window's median: robust to a dip sampled right after
``render``'s ``malloc_trim``, which the next pass fills again), each also over the second
half alone (a drift that levels off has a second half near 0); and
that no pass was lost: ``render``'s ``.npz`` holds as many passes as its last checkpoint,
``progressive``'s accumulators equal a serial render of as many passes, bit for bit
(``--verify``, default on). The numbers depend on the machine and what else runs on it.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def rss_bytes(pid: int) -> int:
    """``VmRSS`` of ``pid`` plus its children's (0 once it is gone)."""
    total = 0
    pids = [pid]
    try:
        with open(f"/proc/{pid}/task/{pid}/children") as f:
            pids += [int(p) for p in f.read().split()]
    except OSError:
        pass
    for p in pids:
        try:
            with open(f"/proc/{p}/status") as f:
                for line in f:
                    if line.startswith("VmRSS:"):
                        total += int(line.split()[1]) * 1024
                        break
        except OSError:
            pass
    return total


def _slope(t: np.ndarray, r: np.ndarray) -> float:
    """Least-squares slope of ``r`` (MiB) over ``t`` (s) in MiB per hour (NaN below 3)."""
    return float(np.polyfit(t, r, 1)[0] * 3600) if t.size >= 3 else float("nan")


def _windows(t: np.ndarray, r: np.ndarray, window: float, how) -> tuple[np.ndarray, ...]:
    """``(times, values)``: ``how`` (np.min, np.median) of the samples of every ``window``
    seconds, at the window's middle."""
    edges = np.arange(t[0], t[-1] + window, window)
    wt, wr = [], []
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        sel = (t >= a) & (t < b)
        if sel.any():
            wt.append(float(t[sel].mean()))
            wr.append(float(how(r[sel])))
    return np.array(wt), np.array(wr)


def fit(samples: list[tuple[float, int]], warmup: float, floor_window: float = 30.0) -> dict:
    """Slopes of RSS over time after ``warmup`` seconds (MiB/hour).

    ``slope``: least squares over every sample, with its standard error. ``floor``: over the
    lowest sample of each ``floor_window`` seconds (what stays allocated between the passes'
    transient peaks). ``level``: over each window's median, which neither a pass's peak nor
    a dip sampled just after ``render``'s ``malloc_trim`` (the freed heap it hands back,
    touched again by the next pass) moves. Each also over the second half alone (the second
    hour of a two-hour run: a growth that levels off has a second-half slope near 0).
    """
    t = np.array([s[0] for s in samples], dtype=float)
    r = np.array([s[1] for s in samples], dtype=float) / 2**20
    keep = t >= warmup
    t, r = t[keep], r[keep]
    if t.size < 3:
        return {"samples": int(t.size)}
    a = np.vstack([t, np.ones_like(t)]).T
    coef, *_ = np.linalg.lstsq(a, r, rcond=None)
    dof = max(t.size - 2, 1)
    sigma2 = float(np.sum((r - a @ coef) ** 2) / dof)
    se = float(np.sqrt(sigma2 / np.sum((t - t.mean()) ** 2)))
    floor_t, floor_r = _windows(t, r, floor_window, np.min)
    level_t, level_r = _windows(t, r, floor_window, np.median)
    mid = (t[0] + t[-1]) / 2
    half, fhalf, lhalf = t >= mid, floor_t >= mid, level_t >= mid
    return {"samples": int(t.size), "fit_seconds": float(t[-1] - t[0]),
            "rss_start_mib": float(r[0]), "rss_end_mib": float(r[-1]),
            "rss_min_mib": float(r.min()), "rss_max_mib": float(r.max()),
            "slope_mib_per_hour": float(coef[0] * 3600),
            "slope_se_mib_per_hour": float(se * 3600),
            "slope_second_half_mib_per_hour": _slope(t[half], r[half]),
            "floor_slope_mib_per_hour": _slope(floor_t, floor_r),
            "floor_slope_second_half_mib_per_hour": _slope(floor_t[fhalf], floor_r[fhalf]),
            "level_slope_mib_per_hour": _slope(level_t, level_r),
            "level_slope_second_half_mib_per_hour": _slope(level_t[lhalf], level_r[lhalf]),
            "floor_window_s": floor_window,
            "floor_start_mib": float(floor_r[0]), "floor_end_mib": float(floor_r[-1]),
            "level_start_mib": float(level_r[0]), "level_end_mib": float(level_r[-1]),
            "level_second_half_start_mib": float(level_r[lhalf][0]) if lhalf.any() else None,
            "series_s_mib": [[round(float(a), 1), round(float(b), 2)]
                             for a, b in zip(t, r, strict=True)]}


def run_render(args) -> dict:
    """A long ``app.py render --time`` with checkpoints, sampled from outside."""
    with tempfile.TemporaryDirectory() as tmp:
        out, ckdir = os.path.join(tmp, "out.npz"), os.path.join(tmp, "ck")
        cmd = [sys.executable, str(ROOT / "app.py"), "render", args.scene, "--estimator",
               args.estimator, "--photons", str(args.photons), "--time", str(args.seconds),
               "--checkpoint", ckdir, "--checkpoint-every", str(args.checkpoint_every),
               "--out", out]
        if args.jobs > 1:
            cmd += ["--jobs", str(args.jobs)]
        env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
        p = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             text=True)
        t0 = time.monotonic()
        samples = []
        while p.poll() is None:
            samples.append((time.monotonic() - t0, rss_bytes(p.pid)))
            time.sleep(args.interval)
        stdout, stderr = p.communicate()
        if p.returncode != 0:
            raise SystemExit(f"render failed ({p.returncode}): {stderr.strip()}")
        from psurf_core.checkpoint import load_checkpoint

        with np.load(out) as d:
            passes = int(d["passes"])
        saved = load_checkpoint(ckdir).accumulator.n
    samples = [s for s in samples if s[1] > 0]
    return {"mode": "render", "command": " ".join(cmd[1:]), "passes": passes,
            "checkpoint_passes": saved, "no_pass_lost": passes == saved,
            **fit(samples, args.warmup, args.floor_window)}


def run_progressive(args) -> dict:
    """The window's background render, polled as the window's timer does."""
    sys.path.insert(0, str(ROOT))
    from psurf_core import load_scene, parse_estimator
    from psurf_core.render import RenderSettings, render
    from ui.cli.progressive import Progressive

    scene = load_scene(args.scene)
    specs = args.estimators.split(",")
    settings = RenderSettings(photons=args.photons)
    prog = Progressive(scene, specs, settings, seed=0, workers=1, breakdown=True)
    samples = []
    t_open = time.monotonic()
    try:
        # The clock starts once every estimator has a pass: compiling (minutes on a cold
        # numba cache) is neither the window's steady state nor part of --seconds.
        while min(r.acc.n for r in prog.runs) == 0:
            prog.poll()
            if prog.errors or time.monotonic() - t_open > args.compile_timeout:
                raise SystemExit(f"no first pass of every estimator after "
                                 f"{time.monotonic() - t_open:.0f} s: {prog.errors}")
            time.sleep(0.1)
        t0 = time.monotonic()
        first_passes = time.monotonic() - t_open
        while time.monotonic() - t0 < args.seconds:
            prog.poll()
            now = time.monotonic()
            if not samples or now - t0 - samples[-1][0] >= args.interval:
                samples.append((now - t0, rss_bytes(os.getpid())))
            time.sleep(0.1)
        prog.pause()
        time.sleep(1.0)
        prog.poll()
        runs = [(r.spec if hasattr(r, "spec") else specs[i], r.acc) for i, r in
                enumerate(prog.runs)]
    finally:
        prog.close()
    verified = None
    if args.verify:
        verified = True
        for spec, acc in runs:
            if acc.n == 0:
                continue
            ref = render(scene, parse_estimator(spec, scene), settings, passes=acc.n, seed=0)
            verified &= bool(np.array_equal(ref.accumulator.mean, acc.mean)
                             and np.array_equal(ref.accumulator.m2, acc.m2))
    return {"mode": "progressive", "estimators": specs, "photons": args.photons,
            "seconds_to_first_passes": round(first_passes, 1),
            "passes": {spec: int(acc.n) for spec, acc in runs},
            "no_pass_lost": verified, **fit(samples, args.warmup, args.floor_window)}


def run_window(args) -> dict:
    """The window left open, sampled from outside (module doc)."""
    if not os.environ.get("DISPLAY"):
        raise SystemExit("window: no DISPLAY (run under xvfb-run -a)")
    cmd = [sys.executable, str(ROOT / "app.py"), args.scene, "--estimators", args.estimators,
           "--photons", str(args.photons)]
    p = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    t0 = time.monotonic()
    samples = []
    try:
        while p.poll() is None and time.monotonic() - t0 < args.seconds + args.warmup:
            samples.append((time.monotonic() - t0, rss_bytes(p.pid)))
            time.sleep(args.interval)
    finally:
        alive = p.poll() is None
        p.terminate()
        try:
            _, stderr = p.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            p.kill()
            _, stderr = p.communicate()
    if not alive:
        raise SystemExit(f"the window ended early ({p.returncode}): {stderr.strip()[-500:]}")
    samples = [s for s in samples if s[1] > 0]
    return {"mode": "window", "command": " ".join(cmd[1:]), "no_pass_lost": None,
            **fit(samples, args.warmup, args.floor_window)}


def _commit() -> str | None:
    """The checkout's commit (``-dirty`` with uncommitted changes), or None outside git."""
    try:
        head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"],
                              capture_output=True, text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(ROOT), "status", "--porcelain", "-uno"],
                               capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None
    return head + ("-dirty" if dirty else "")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("mode", choices=("render", "progressive", "window"))
    p.add_argument("--seconds", type=float, default=1800.0)
    p.add_argument("--scene", default=str(ROOT / "scenes" / "area.toml"))
    p.add_argument("--estimator", default="planes")
    p.add_argument("--estimators", default="planes,paper-multi")
    p.add_argument("--photons", type=int, default=4000)
    p.add_argument("--checkpoint-every", type=float, default=5.0)
    p.add_argument("--jobs", type=int, default=1)
    p.add_argument("--interval", type=float, default=1.0)
    p.add_argument("--warmup", type=float, default=20.0,
                   help="seconds left out of the fit (default 20)")
    p.add_argument("--floor-window", type=float, default=30.0,
                   help="seconds per floor sample (default 30)")
    p.add_argument("--compile-timeout", type=float, default=1800.0,
                   help="progressive: seconds to wait for every estimator's first pass "
                        "(compilation), not counted in --seconds (default 1800)")
    p.add_argument("--no-verify", dest="verify", action="store_false")
    p.add_argument("--json", default=None, metavar="OUT.json")
    args = p.parse_args(argv)
    started, load_before = time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime()), os.getloadavg()
    run = {"render": run_render, "progressive": run_progressive, "window": run_window}
    result = run[args.mode](args)
    result.update(argv=sys.argv, commit=_commit(), started=started,
                  ended=time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime()),
                  load_average_before_after=[round(load_before[0], 2),
                                             round(os.getloadavg()[0], 2)])
    print(json.dumps({k: v for k, v in result.items() if k != "series_s_mib"}, indent=1))
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1))
    return 0 if result.get("no_pass_lost") in (True, None) else 1


if __name__ == "__main__":
    sys.exit(main())
