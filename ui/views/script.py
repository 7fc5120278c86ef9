"""Scripted steps for the window (tests under Xvfb, demos): :data:`SCRIPT_ENV` holds steps
separated by ``;``, one per timer tick, each sent through the window's own event path like a
person's (the interactor's key presses and mouse clicks):

* a key sym: ``n``, ``space``, ``Right``, ``e``, ``1`` ...;
* ``click:render:X,Y`` / ``click:variance:X,Y``: a real mouse click on that image pixel's
  centre of the inspected estimator's tile; ``click:render:X,Y@I`` on estimator ``I``'s tile;
* ``size:W,H``: resize the window;
* ``shot:PATH.png``: save the window;
* ``passes>=N`` / ``passes+N``: wait until the panels hold N passes / N more;
* ``inspected``: wait until the stages' inspection has arrived;
* ``time>=S``: wait until S seconds have passed since the launch (:data:`TIMES_ENV`) or, without
  it, since the window was made;
* ``panels``: print what the image panels compare (each estimator's passes, seconds, "Var"
  at equal time, or what it waits for: "compiling kernels (first run)");
* ``kill-worker``: kill the background render process (SIGKILL; the window must restart it);
* ``wait`` (one tick) or ``quit``.

Every step prints one ``window: ...`` line (what happened, the stage, pixel, passes), which
the tests read.
"""

from __future__ import annotations

import os
import signal
import time

__all__ = ["SCRIPT_ENV", "SIZE_ENV", "TIMES_ENV", "launch_time", "panels_line",
           "play_step"]

#: Environment variable with a script for the window (see the module docstring).
SCRIPT_ENV = "PSURF_WINDOW_SCRIPT"
#: Environment variable ``W,H`` overriding the window size (a quicker scripted test).
SIZE_ENV = "PSURF_WINDOW_SIZE"
#: Environment variable: the launch time (``time.time()`` seconds, as the launching program
#: read it; any other value: the window's own start). When set, the window prints
#: ``window: time <milestone> <seconds since the launch> s`` the first time it has drawn
#: itself (``window``), a render (``first-pass``), every estimator's render
#: (``all-passes``) and the stage's inspection (``inspection``).
TIMES_ENV = "PSURF_WINDOW_TIMES"


def launch_time() -> float | None:
    """The launch time :data:`TIMES_ENV` gives (None when it is not set)."""
    text = os.environ.get(TIMES_ENV)
    if not text:
        return None
    try:
        return float(text)
    except ValueError:
        return time.time()


def _status(app) -> str:
    s = app.s
    return (f"stage {s.stage}, pixel {s.pixel_xy}, pass {s.pass_index}, passes {s.acc.n}, "
            f"inspecting {s.estimator.spec}  [{time.perf_counter() - app._t0:.1f} s]")


def panels_line(state) -> str:
    """The image panels' comparison in one line (the ``panels`` step)."""
    if state.prog is None:
        return f"{state.estimator.spec}: {state.acc.n} passes"
    rows = state.prog.summary(state.reference)
    out = []
    for run, row in zip(state.prog.runs, rows, strict=True):
        text = f"{run.spec}: {run.acc.n} passes, {run.seconds:.1f} s"
        if run.acc.n == 0:
            text += f" ({run.note() or 'no pass yet'})"
        elif row["ratio"] is not None:
            text += f", Var {row['ratio']:.3g}x"
        if run.compile_seconds:
            text += f", kernels {run.compile_seconds:.1f} s apart"
        out.append(text)
    return " | ".join(out)


def play_step(app, step: str) -> None:
    """Play one step of the script on the window ``app`` (an ``ui.views.interactive.App``)."""
    ii = app.p.iren.interactor
    s = app.s
    if step == "wait":
        return
    if step.startswith("passes>="):  # hold the script until the worker sent N passes
        if s.acc.n < int(step[8:]):
            app.script.insert(0, step)
        return
    if step.startswith("passes+"):  # ... until N more passes than now arrived
        app.script.insert(0, f"passes>={s.acc.n + int(step[7:])}")
        return
    if step == "inspected":
        if s.inspection is None:
            app.script.insert(0, step)
        return
    if step.startswith("time>="):  # hold the script until S seconds since the launch
        t0 = app._launched if app._launched is not None else None
        spent = time.time() - t0 if t0 is not None else time.perf_counter() - app._t0
        if spent < float(step[6:]):
            app.script.insert(0, step)
        return
    if step == "panels":
        print(f"window: panels: {panels_line(s)}  [{time.perf_counter() - app._t0:.1f} s]",
              flush=True)
        return
    if step == "quit":
        print("window: quit", flush=True)
        app.quit()
        return
    if step == "kill-worker":
        pid = s.prog.pids[0]
        os.kill(pid, signal.SIGKILL)
        print(f"window: killed render worker {pid} with {s.acc.n} passes merged", flush=True)
        return
    if step.startswith("shot:"):
        app.settle()  # the 3D view complete (the window builds it over several ticks)
        app.p.screenshot(step[5:])
        print(f"window: wrote {step[5:]}", flush=True)
        return
    if step.startswith("size:"):
        w, h = (int(v) for v in step[5:].split(","))
        app.p.window_size = (w, h)
        print(f"window: resized to {w}x{h}", flush=True)
        return
    if step.startswith("click:"):
        _, panel, xy = step.split(":")
        xy, _, tile = xy.partition("@")
        x, y = (int(v) for v in xy.split(","))
        pos = app.pixel_display(panel, (x, y), int(tile) if tile else None)
        dx, dy = (int(round(v)) for v in pos)
        ii.SetEventPosition(dx, dy)
        ii.MouseMoveEvent()
        ii.LeftButtonPressEvent()
        ii.LeftButtonReleaseEvent()
        print(f"window: clicked {panel} at display ({dx}, {dy}): {_status(app)}", flush=True)
        return
    ii.SetKeySym(step)
    ii.SetKeyCode(step if len(step) == 1 else "\0")
    ii.KeyPressEvent()
    ii.KeyReleaseEvent()
    print(f"window: key {step}: {_status(app)}; message: {s.message}", flush=True)
