"""UI-thread frame times while progressive rendering runs in the background (not a test).

Drives the window's composition off-screen (``ui.views.window.make_plotter`` + ``compose``: the
3D view, the stage panel and the image panels at the window's size) and then, every
``--period`` seconds (the window's timer), times what the UI thread does per frame:

* ``progressive``: every tick ``Progressive.poll()`` (non-blocking; passes come from a worker
  process) and, when passes arrived or the mode changed, ``PanelView.draw`` into the window's
  two image cells + ``plotter.render()`` (a "frame"; ``--every-tick`` draws on every tick).
  The panel mode cycles render -> techniques -> bounces (a third of the ticks each, so mode
  switches, i.e. rebuilds, are included). Reported: the frames, and every tick;
* ``window-tick``: ``ui.views.interactive.App.tick`` itself with the window's own progressive wiring
  (what its VTK timer calls: poll, and on new passes the panels, the stage text and a render);
  frames are the ticks that merged passes; the ``m`` key (a full redraw) is timed apart;
* ``synchronous`` (for comparison, fewer frames): what the window's timer did before, one
  ``render_pass`` in the callback + redraw of the image panels + ``plotter.render()``.

Both with VTK's default multisampling and with multisampling off, since software OpenGL (no
GPU, EGL/llvmpipe) spends most of a frame on it; the window itself turns it off on its first
tick when it finds software OpenGL (``ui.views.window.software_opengl``), so ``window-tick/no-msaa``
is what the window does here. On a new pass the window redraws the image panels and the stage
text only: the 3D view keeps its pixels (``App._frame``).

Run::

    .venv/bin/python benchmarks/ui_frames.py [--frames 100] [--out out/ui_frames.json]

Writes ``out/ui_frames.json`` (per configuration: median, p95, max frame milliseconds, frames
over 100 ms, passes merged per estimator) and prints a table.
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
    a = np.asarray(ms)
    return {"frames": int(a.size), "median_ms": float(np.median(a)),
            "p95_ms": float(np.percentile(a, 95)), "max_ms": float(a.max()),
            "over_100ms": int((a > 100.0).sum())}


def run(args) -> dict:
    from ui.views._vtk import pv

    pv.OFF_SCREEN = True
    from psurf_core.render import RenderSettings, render_pass
    from ui.cli.progressive import Progressive
    from ui.views import window
    from ui.views.image_panels import MODES, PanelView

    specs = args.estimators.split(",")
    state = window.build_state(args.scene, specs[0], seed=0, photons=args.photons, passes=1)
    settings = RenderSettings(photons=args.photons)
    cells = [window.CELL_RENDER, window.CELL_VARIANCE]
    results = {"scene": args.scene, "estimators": specs, "photons": args.photons,
               "period_s": args.period, "size": list(args.size), "machine": {
                   "cpus": os.cpu_count(), "python": platform.python_version(),
                   "platform": platform.platform(),
                   "load_average_at_start": list(os.getloadavg())}, "configs": {}}

    for msaa in (True, False):
        tag = "msaa" if msaa else "no-msaa"
        plotter = window.make_plotter(tuple(args.size), off_screen=True)
        if not msaa:
            plotter.ren_win.SetMultiSamples(0)
        window.compose(plotter, state)
        plotter.screenshot(None, return_img=True)  # first real render (window shown)

        # ---- progressive: worker process, non-blocking poll
        prog = Progressive(state.scene, specs, settings, seed=0, workers=1, breakdown=True)
        view = PanelView()
        times, ticks, by_mode = [], [], {m: [] for m in MODES}
        time.sleep(1.0)  # the worker starts (spawn) and sends its first passes
        shown = None
        try:
            for f in range(args.frames):
                mode = MODES[min(3 * f // args.frames, 2)]
                t0 = time.perf_counter()
                # What the window's timer does: poll; redraw only for new passes / a new mode
                # ("--every-tick" redraws every tick: the worst case).
                if prog.poll() or mode != shown or args.every_tick:
                    view.draw(plotter, cells, prog, mode, state.pixel_xy)
                    plotter.render()
                    shown = mode
                    dt = 1000.0 * (time.perf_counter() - t0)
                    times.append(dt)
                    by_mode[mode].append(dt)
                else:
                    dt = 1000.0 * (time.perf_counter() - t0)
                ticks.append(dt)
                time.sleep(max(0.0, args.period - dt / 1000.0))
            passes = dict(zip(specs, prog.passes, strict=True))
            seconds = {r.spec: round(r.seconds, 2) for r in prog.runs}
            errors = list(prog.errors)
        finally:
            prog.close()
        results["configs"][f"progressive/{tag}"] = {
            **_stats(times), "ticks": _stats(ticks),
            "by_mode": {m: _stats(v) for m, v in by_mode.items() if v},
            "passes": passes, "worker_seconds": seconds, "errors": errors}

        # ---- the window itself: App.tick() (poll; on new passes redraw panels + text, render)
        results["configs"][f"window-tick/{tag}"] = _window_ticks(args, specs, plotter, msaa)

        # ---- synchronous: the pass is rendered inside the timer callback
        times = []
        acc = state.acc
        for _ in range(args.sync_frames):
            t0 = time.perf_counter()
            acc.add(render_pass(state.scene, state.estimator, acc.n, state.seed, settings))
            window.compose_images(plotter, state)
            plotter.render()
            times.append(1000.0 * (time.perf_counter() - t0))
        results["configs"][f"synchronous/{tag}"] = {**_stats(times),
                                                    "estimator": specs[0]}
        plotter.close()
    return results


def _window_ticks(args, specs, old_plotter, msaa: bool) -> dict:
    """Time ``ui.views.interactive.App.tick`` itself (what the window's VTK timer calls), with the
    window's own progressive wiring (``attach_progressive``, one worker process); the ``m``
    key (``App.next_mode``: a full redraw) is timed apart, a third of the way and two thirds."""
    from ui.views import interactive, window

    state = window.build_state(args.scene, specs[0], seed=0, photons=args.photons,
                               render_passes=False)
    state.extra_specs = tuple(specs[1:])
    window.attach_progressive(state, workers=1)
    plotter = window.make_plotter(tuple(args.size), off_screen=True)
    if not msaa:
        plotter.ren_win.SetMultiSamples(0)
    app = interactive.App(plotter, state)
    if msaa:
        # Keep multisampling: the window itself switches it off in software OpenGL on its
        # first tick; this configuration shows what that saves.
        app._gl_checked = True
    ticks, frames, keys = [], [], []
    try:
        app.bind()
        window.compose(plotter, state)
        plotter.screenshot(None, return_img=True)
        time.sleep(1.0)
        for f in range(args.frames):
            if f in (args.frames // 3, 2 * args.frames // 3):
                t0 = time.perf_counter()
                app.next_mode()
                keys.append(1000.0 * (time.perf_counter() - t0))
            n0 = sum(state.prog.passes)
            t0 = time.perf_counter()
            app.tick()
            dt = 1000.0 * (time.perf_counter() - t0)
            ticks.append(dt)
            if sum(state.prog.passes) > n0:
                frames.append(dt)
            time.sleep(max(0.0, args.period - dt / 1000.0))
        passes = dict(zip(specs, state.prog.passes, strict=True))
    finally:
        app.close()
        plotter.close()
    out = {**(_stats(frames) if frames else {"frames": 0}), "ticks": _stats(ticks),
           "mode_key_ms": keys, "passes": passes}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default=os.path.join(ROOT, "scenes", "area.toml"))
    ap.add_argument("--estimators", default="planes,mis:plane-t1t2+sphere")
    ap.add_argument("--photons", type=int, default=2000)
    ap.add_argument("--frames", type=int, default=100)
    ap.add_argument("--sync-frames", type=int, default=10)
    ap.add_argument("--period", type=float, default=0.1, help="timer period, seconds")
    ap.add_argument("--every-tick", action="store_true",
                    help="redraw the panels on every tick, not only when passes arrived")
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
    print(f"{'configuration':28s} {'frames':>6s} {'median':>8s} {'p95':>8s} {'max':>8s} "
          f"{'>100ms':>6s}  passes")
    for name, c in res["configs"].items():
        if c["frames"]:
            print(f"{name:28s} {c['frames']:6d} {c['median_ms']:7.1f}ms {c['p95_ms']:7.1f}ms "
                  f"{c['max_ms']:7.1f}ms {c['over_100ms']:6d}  {c.get('passes', '')}")
        else:
            print(f"{name:28s} {0:6d}  (no pass arrived)  {c.get('passes', '')}")
        if "ticks" in c:
            t = c["ticks"]
            print(f"  {'every timer tick':26s} {t['frames']:6d} {t['median_ms']:7.1f}ms "
                  f"{t['p95_ms']:7.1f}ms {t['max_ms']:7.1f}ms {t['over_100ms']:6d}")
        if "mode_key_ms" in c:
            print(f"  {'m key (full redraw)':26s} " + ", ".join(f"{k:.0f}ms"
                                                               for k in c["mode_key_ms"]))
        for m, s in c.get("by_mode", {}).items():
            print(f"  {m:26s} {s['frames']:6d} {s['median_ms']:7.1f}ms {s['p95_ms']:7.1f}ms "
                  f"{s['max_ms']:7.1f}ms {s['over_100ms']:6d}")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
