"""UI-thread frame times of the window while an MIS set is inspected and the panels render in
the background (not a test).

Drives the window (``ui.views.interactive.App`` on an off-screen plotter at the window's size,
with the window's own wiring: the progressive renderer in one worker process, the stages'
inspections in another, ``ui.cli.inspector``) and calls its timer (``App.tick``) every
``--period`` seconds, timing what the UI thread does:

* ``frames``: the ticks that merged new passes (poll, the image panels and the stage text
  redrawn in place, one ``plotter.render()`` that leaves the 3D view's pixels as they were);
* ``ticks``: every tick (most only poll and find nothing);
* ``inspection frames``: the ticks that took a new inspection from the inspector process and
  drew the stage again (after a pixel move);
* ``keys``: the stage steps (``n``), pixel moves and the ``m`` key, each a full redraw; the
  inspection they ask for is computed in the inspector process, not here.

Both with VTK's default multisampling and with multisampling off: software OpenGL (no GPU,
EGL/llvmpipe) spends most of a frame on it, and the window turns it off on its first tick
when it finds software OpenGL (``ui.views.window.software_opengl``), so ``window/no-msaa`` is
what the window does here. For comparison, ``synchronous``: what the timer once did, a
``render_pass`` inside the callback.

Run::

    .venv/bin/python benchmarks/ui_frames.py [--frames 100] [--out out/ui_frames.json]

Writes ``out/ui_frames.json`` (per configuration: median, p95, max milliseconds, frames over
100 ms, passes merged per estimator, the machine's load) and prints a table.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)


def _stats(ms: list[float]) -> dict:
    a = np.asarray(ms if ms else [0.0])
    return {"frames": int(len(ms)), "median_ms": float(np.median(a)),
            "p95_ms": float(np.percentile(a, 95)), "max_ms": float(a.max()),
            "over_100ms": int((a > 100.0).sum())}


def _window(args, msaa: bool) -> dict:
    """``App.tick`` of the window with its own wiring, an MIS set inspected."""
    from ui.views import interactive, window

    specs = args.estimators.split(",")
    state = window.build_state(args.scene, seed=0, photons=args.photons, render_passes=False,
                               estimators=specs, inspector_workers=1)
    window.attach_progressive(state, workers=1)
    plotter = window.make_plotter(tuple(args.size), off_screen=True)
    if not msaa:
        plotter.ren_win.SetMultiSamples(0)
    app = interactive.App(plotter, state)
    if msaa:
        # Keep multisampling: the window itself switches it off in software OpenGL on its
        # first tick; this configuration shows what that saves.
        app._gl_checked = True
    ticks, frames, insp, keys = [], [], [], {"n": [], "pixel": [], "m": []}
    cam = state.scene.camera
    try:
        app.bind()
        app.redraw(keep_camera=False)
        plotter.screenshot(None, return_img=True)  # the first real render (window shown)
        t_start = time.perf_counter()
        while state.inspection is None and time.perf_counter() - t_start < 600:
            app.tick()
            time.sleep(args.period)
        for f in range(args.frames):
            if f and f % max(args.frames // 8, 1) == 0:  # a key now and then
                kind = ("n", "pixel", "m")[(f // max(args.frames // 8, 1)) % 3]
                t0 = time.perf_counter()
                if kind == "n":
                    app.next()
                elif kind == "m":
                    app.next_mode()
                else:
                    x = (state.pixel_xy[0] + 7) % cam.width
                    app.set_pixel((x, state.pixel_xy[1]))
                keys[kind].append(1000.0 * (time.perf_counter() - t0))
            n0 = sum(state.prog.passes)
            waiting = state.inspection is None
            t0 = time.perf_counter()
            app.tick()
            dt = 1000.0 * (time.perf_counter() - t0)
            ticks.append(dt)
            if waiting and state.inspection is not None:
                insp.append(dt)
            elif sum(state.prog.passes) > n0:
                frames.append(dt)
            time.sleep(max(0.0, args.period - dt / 1000.0))
        passes = dict(zip(specs, state.prog.passes, strict=True))
        inspected = state.estimator.spec
    finally:
        app.close()
        plotter.close()
    return {**_stats(frames), "ticks": _stats(ticks), "inspection_frames": _stats(insp),
            "keys_ms": keys, "passes": passes, "inspected": inspected}


def _synchronous(args) -> dict:
    """What the window's timer did before the worker process: a pass in the callback."""
    from psurf_core.render import render_pass
    from ui.views import window

    state = window.build_state(args.scene, args.estimators.split(",")[-1], seed=0,
                               photons=args.photons, passes=1)
    plotter = window.make_plotter(tuple(args.size), off_screen=True)
    plotter.ren_win.SetMultiSamples(0)
    times = []
    try:
        window.compose(plotter, state)
        plotter.screenshot(None, return_img=True)
        for _ in range(args.sync_frames):
            t0 = time.perf_counter()
            state.acc.add(render_pass(state.scene, state.estimator, state.acc.n, state.seed,
                                      state.settings))
            window.compose_images(plotter, state)
            plotter.render()
            times.append(1000.0 * (time.perf_counter() - t0))
    finally:
        plotter.close()
        state.inspector.close()
    return {**_stats(times), "estimator": state.estimator.spec}


def run(args) -> dict:
    from ui.views._vtk import pv

    pv.OFF_SCREEN = True
    results = {"scene": args.scene, "estimators": args.estimators.split(","),
               "photons": args.photons, "period_s": args.period, "size": list(args.size),
               "machine": {"cpus": os.cpu_count(), "python": platform.python_version(),
                           "platform": platform.platform(),
                           "load_average_at_start": list(os.getloadavg())}, "configs": {}}
    results["configs"]["window/no-msaa"] = _window(args, msaa=False)
    if not args.quick:
        results["configs"]["window/msaa"] = _window(args, msaa=True)
        results["configs"]["synchronous/no-msaa"] = _synchronous(args)
    results["machine"]["load_average_at_end"] = list(os.getloadavg())
    return results


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default=os.path.join(ROOT, "scenes", "showcase.toml"))
    ap.add_argument("--estimators", default="planes,paper-multi",
                    help="side by side; the stages inspect the first MIS set")
    ap.add_argument("--photons", type=int, default=1000)
    ap.add_argument("--frames", type=int, default=100)
    ap.add_argument("--sync-frames", type=int, default=5)
    ap.add_argument("--period", type=float, default=0.2, help="timer period, seconds")
    ap.add_argument("--quick", action="store_true", help="the window without MSAA only")
    ap.add_argument("--size", type=lambda s: tuple(int(v) for v in s.split(",")),
                    default=(1600, 900))
    ap.add_argument("--out", default=os.path.join(ROOT, "out", "ui_frames.json"))
    args = ap.parse_args(argv)
    res = run(args)
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    tmp = args.out + ".tmp"
    with open(tmp, "w") as f:
        json.dump(res, f, indent=2)
    os.replace(tmp, args.out)
    m = res["machine"]
    print(f"load average {m['load_average_at_start'][0]:.1f} -> "
          f"{m['load_average_at_end'][0]:.1f} on {m['cpus']} cores")
    print(f"{'configuration':24s} {'frames':>6s} {'median':>8s} {'p95':>8s} {'max':>8s} "
          f"{'>100ms':>6s}  passes")

    def row(name, c):
        print(f"{name:24s} {c['frames']:6d} {c['median_ms']:7.1f}ms {c['p95_ms']:7.1f}ms "
              f"{c['max_ms']:7.1f}ms {c['over_100ms']:6d}  {c.get('passes', '')}")

    for name, c in res["configs"].items():
        row(name, c)
        if "ticks" in c:
            row("  every timer tick", c["ticks"])
            row("  new inspection", c["inspection_frames"])
            print("  keys (full redraws): " + "; ".join(
                f"{k}: " + ", ".join(f"{v:.0f}ms" for v in vs)
                for k, vs in c["keys_ms"].items()) + f"  [inspecting {c['inspected']}]")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
