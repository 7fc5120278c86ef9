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
* ``keys``: the stage steps (``n``), pixel moves and the ``m`` key (wall and CPU); in the
  window (``App.defer``) a key draws what it changed at once and the 3D view's first step
  (its scene, "drawing..."), and the next ticks build the rest of the 3D view;
  the inspection they ask for is computed in the inspector process, not here;
* ``3D view steps``: the ticks that added parts of a 3D view or rendered the completed view
  (after a key or a new inspection).

Both with VTK's default multisampling and with multisampling off: software OpenGL (no GPU,
EGL/llvmpipe) spends most of a frame on it, and the window turns it off on its first tick
when it finds software OpenGL (``ui.views.window.software_opengl``), so ``window/no-msaa`` is
what the window does here. For comparison, ``synchronous``: what the timer once did, a
``render_pass`` inside the callback.

Under a display (``xvfb-run``) the window is a real on-screen window (VTK's X window),
otherwise an off-screen one (EGL).

``--first-picture N`` measures instead how soon the window shows something useful after a
launch: it starts ``python app.py SCENE --estimators A,B`` N times (after one launch that is
not counted: it warms numba's cache and the file cache), each with a script that quits once
the inspected estimator has a pass and the stage's inspection arrived, and reads the times the
window prints (``ui.views.script.TIMES_ENV``, seconds since the launch): ``window`` (the first
frame on screen), ``first-pass`` (a render in the image panels: the first useful picture),
``all-passes`` (every estimator's render), ``inspection`` (the stage's numbers), and ``quit``
(when the quit line arrived). ``--roots A,B`` alternates the launches between checkouts (a
before/after comparison in one run on a shared machine; a checkout whose window prints no
times has only ``quit``). Needs a display: run it under ``xvfb-run``.

Run::

    xvfb-run -a -s "-screen 0 1700x1000x24" .venv/bin/python benchmarks/ui_frames.py \
        [--frames 100] [--out out/ui_frames.json]
    xvfb-run -a -s "-screen 0 1700x1000x24" .venv/bin/python benchmarks/ui_frames.py \
        --first-picture 5 [--roots .,/tmp/old] [--out out/first_picture.json]

Writes ``out/ui_frames.json`` (per configuration: median, p95, max milliseconds, frames over
100 ms, passes merged per estimator, the machine's load) and prints a table; with
``--first-picture``, ``out/first_picture.json`` (every launch's times and the load averages
before and after it; medians per checkout).
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import platform
import subprocess
import sys
import threading
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
    # As the window does (``ui.views.interactive.run``): breakdowns only in the modes that
    # show them (the ``m`` key switches them on).
    window.attach_progressive(state, workers=1, breakdown=False)
    plotter = window.make_plotter(tuple(args.size), off_screen=not _has_display())
    if not msaa:
        plotter.ren_win.SetMultiSamples(0)
    app = interactive.App(plotter, state)
    if msaa:
        # Keep multisampling: the window itself switches it off in software OpenGL on its
        # first tick; this configuration shows what that saves.
        app._gl_checked = True
    ticks, frames, insp, keys = [], [], [], {"n": [], "pixel": [], "m": []}
    keys_cpu = {k: [] for k in keys}
    cpu = {"ticks": [], "frames": [], "build": []}
    build = []  # ticks that added parts of a 3D view or rendered it (App.defer: the window)
    slow, last_key = [], None  # ticks over 100 ms: what they did, the key before them
    cam = state.scene.camera

    def timer():
        # What the window's timer does, through its own event: the TimerEvent's observers
        # (App.tick, and whatever the binding adds: pyvista's add_timer_event also renders
        # the whole window after every callback). Off-screen (no interactor): App.tick.
        if plotter.iren is not None:
            plotter.iren.interactor.InvokeEvent("TimerEvent")
        else:
            app.tick()

    gc_ms, gc_t0 = [], [0.0]

    def gc_watch(phase, info):  # the garbage collector's pauses (the UI thread's too)
        if phase == "start":
            gc_t0[0] = time.perf_counter()
        elif info.get("generation") == 2:
            gc_ms.append(1000.0 * (time.perf_counter() - gc_t0[0]))

    gc.callbacks.append(gc_watch)
    try:
        app.bind()
        app.redraw(keep_camera=False)
        if _has_display():  # the window on the screen, its events left to this loop
            plotter.show(interactive_update=True, auto_close=False)
        else:
            plotter.screenshot(None, return_img=True)  # the first real render
        t_start = time.perf_counter()
        while state.inspection is None and time.perf_counter() - t_start < 600:
            timer()
            time.sleep(args.period)
        for f in range(args.frames):
            if f and f % max(args.frames // 8, 1) == 0:  # a key now and then
                kind = ("n", "pixel", "m")[(f // max(args.frames // 8, 1)) % 3]
                t0, c0 = time.perf_counter(), time.process_time()
                if kind == "n":
                    app.next()
                elif kind == "m":
                    app.next_mode()
                else:
                    x = (state.pixel_xy[0] + 7) % cam.width
                    app.set_pixel((x, state.pixel_xy[1]))
                keys[kind].append(1000.0 * (time.perf_counter() - t0))
                keys_cpu[kind].append(1000.0 * (time.process_time() - c0))
                last_key = (f, kind)
            n0 = sum(state.prog.passes)
            waiting = state.inspection is None
            building = (getattr(app, "_job", None) is not None
                        or bool(getattr(app, "_render_due", False)))
            t0, c0 = time.perf_counter(), time.process_time()
            timer()
            dt = 1000.0 * (time.perf_counter() - t0)
            dc = 1000.0 * (time.process_time() - c0)  # this process: UI + Mesa's threads
            ticks.append(dt)
            cpu["ticks"].append(dc)
            if dt > 100.0 or dc > 100.0:
                slow.append({"tick": f, "wall_ms": round(dt, 1), "cpu_ms": round(dc, 1),
                             "passes": sum(state.prog.passes) - n0, "building": building,
                             "new_inspection": waiting and state.inspection is not None,
                             "mode": state.mode, "stage": state.stage,
                             "after_key": last_key})
            if waiting and state.inspection is not None:
                insp.append(dt)
            elif building:
                build.append(dt)
                cpu["build"].append(dc)
            elif sum(state.prog.passes) > n0:
                frames.append(dt)
                cpu["frames"].append(dc)
            time.sleep(max(0.0, args.period - dt / 1000.0))
        passes = dict(zip(specs, state.prog.passes, strict=True))
        inspected = state.estimator.spec
        # VTK falls back to an off-screen EGL window when it cannot talk to the X server
        # ("bad X server connection", seen under heavy load): say which one was measured.
        window_class = type(plotter.ren_win).__name__
    finally:
        gc.callbacks.remove(gc_watch)
        app.close()
        plotter.close()
    return {**_stats(frames), "ticks": _stats(ticks), "inspection_frames": _stats(insp),
            "build_ticks": _stats(build), "slow_ticks": slow,
            "gc_full_ms": [round(v, 1) for v in gc_ms],
            "cpu_ms": {k: _stats(v) for k, v in cpu.items()},
            "keys_ms": keys, "keys_cpu_ms": keys_cpu, "passes": passes, "inspected": inspected,
            "render_window": window_class,
            "load_average_after": list(os.getloadavg())}


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


def _has_display() -> bool:
    return bool(os.environ.get("DISPLAY"))


# --------------------------------------------------------------------------- first picture
#: The script of a launch: quit once the inspected estimator has a pass and the stage's
#: inspection arrived (the window prints its times on the way).
FIRST_PICTURE_SCRIPT = "inspected;passes>=1;quit"


def _launch(root: str, args, timeout: float = 300.0) -> dict:
    """One launch of ``root``'s window: the times it printed and when its quit line came."""
    env = dict(os.environ)
    env.pop("PSURF_WINDOW_SCRIPT", None)
    t_launch = time.time()
    env.update({"PSURF_WINDOW_TIMES": repr(t_launch),
                "PSURF_WINDOW_SCRIPT": FIRST_PICTURE_SCRIPT,
                "PSURF_WINDOW_SIZE": ",".join(str(v) for v in args.size)})
    load0 = list(os.getloadavg())
    cmd = [sys.executable, "app.py", args.scene, "--estimators", args.estimators,
           "--photons", str(args.photons)]
    proc = subprocess.Popen(cmd, cwd=root, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    times, lines = {}, []

    def read():
        for line in proc.stdout:
            arrived = time.time() - t_launch
            lines.append(line.rstrip())
            parts = line.split()
            if line.startswith("window: time ") and len(parts) >= 4:
                times[parts[2]] = float(parts[3])
                if len(parts) >= 7 and parts[5] == "cpu":  # the window's own CPU seconds
                    times[f"{parts[2]}-cpu"] = float(parts[6])
            elif line.startswith("window: quit"):
                times["quit"] = arrived

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
    reader.join(timeout=5.0)
    return {"root": os.path.abspath(root), "times_s": times, "exit": proc.returncode,
            "load_before": load0, "load_after": list(os.getloadavg()),
            "tail": lines[-5:] if proc.returncode else []}


def first_picture(args) -> dict:
    """``--first-picture N``: N launches per checkout (alternating), after a warm-up each."""
    if not _has_display():
        raise SystemExit("--first-picture needs a display: run it under xvfb-run")
    roots = [os.path.abspath(r) for r in args.roots.split(",")]
    warm = [_launch(r, args) for r in roots]  # numba's cache, the file cache: not counted
    runs = []
    for _ in range(args.first_picture):
        for r in roots:
            runs.append(_launch(r, args))
            print(f"{r}: " + ", ".join(f"{k} {v:.2f} s" for k, v in
                                       sorted(runs[-1]["times_s"].items(),
                                              key=lambda kv: kv[1]))
                  + f"  (load {runs[-1]['load_before'][0]:.1f})", flush=True)
    summary = {}
    for r in roots:
        mine = [x for x in runs if x["root"] == r]
        keys = sorted({k for x in mine for k in x["times_s"]})
        summary[r] = {k: {"median_s": float(np.median([x["times_s"][k] for x in mine
                                                       if k in x["times_s"]])),
                          "max_s": float(max(x["times_s"][k] for x in mine
                                             if k in x["times_s"])),
                          "runs": sum(k in x["times_s"] for x in mine)} for k in keys}
    return {"scene": args.scene, "estimators": args.estimators, "photons": args.photons,
            "size": list(args.size), "script": FIRST_PICTURE_SCRIPT,
            "machine": {"cpus": os.cpu_count(), "platform": platform.platform()},
            "warm_up": warm, "runs": runs, "summary": summary}


def run(args) -> dict:
    from ui.views._vtk import pv

    pv.OFF_SCREEN = not _has_display()
    results = {"scene": args.scene, "estimators": args.estimators.split(","),
               "window": "on-screen (X)" if _has_display() else "off-screen (EGL)",
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


def _write(out: str, res: dict) -> None:
    os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
    tmp = out + ".tmp"
    with open(tmp, "w") as f:
        json.dump(res, f, indent=2)
    os.replace(tmp, out)


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
    ap.add_argument("--out", default=None,
                    help="default out/ui_frames.json (out/first_picture.json with "
                         "--first-picture)")
    ap.add_argument("--first-picture", type=int, default=0, metavar="N",
                    help="time N launches of the window to its first picture instead")
    ap.add_argument("--roots", default=ROOT,
                    help="--first-picture: checkouts to launch, alternating (A,B)")
    args = ap.parse_args(argv)
    if args.first_picture:
        args.out = args.out or os.path.join(ROOT, "out", "first_picture.json")
        res = first_picture(args)
        _write(args.out, res)
        for root, keys in res["summary"].items():
            print(f"{root}: median over {args.first_picture} launches: " + ", ".join(
                f"{k} {v['median_s']:.2f} s (max {v['max_s']:.2f})"
                for k, v in sorted(keys.items(), key=lambda kv: kv[1]["median_s"])))
        print(f"wrote {args.out}")
        return 0
    args.out = args.out or os.path.join(ROOT, "out", "ui_frames.json")
    res = run(args)
    _write(args.out, res)
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
            row("  3D view steps", c["build_ticks"])
            row("  frames, CPU ms", c["cpu_ms"]["frames"])
            row("  ticks, CPU ms", c["cpu_ms"]["ticks"])
            row("  3D view steps, CPU ms", c["cpu_ms"]["build"])
            print("  keys: " + "; ".join(
                f"{k}: " + ", ".join(f"{v:.0f}ms" for v in vs)
                for k, vs in c["keys_ms"].items()) + f"  [inspecting {c['inspected']}; "
                f"{c['render_window']}]")
            print("  keys, CPU: " + "; ".join(
                f"{k}: " + ", ".join(f"{v:.0f}ms" for v in vs)
                for k, vs in c["keys_cpu_ms"].items()))
            g = c["gc_full_ms"]
            print(f"  full garbage collections: {len(g)}, longest "
                  f"{max(g, default=0.0):.0f}ms; ticks over 100 ms: " + ", ".join(
                      f"#{t['tick']} {t['wall_ms']:.0f}/{t['cpu_ms']:.0f}ms" for t in
                      c["slow_ticks"]))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
