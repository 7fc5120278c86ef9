"""``python app.py lecture``: walk through the tutorials' key states, full-screen, or render
one off-screen (``--screenshot OUT.png``).

``app.py`` wires it in with::

    from ui.cli.lecture import add_lecture_parser
    add_lecture_parser(sub)      # sets func=run_lecture_cmd

and ``python app.py lecture [--state N] [--screenshot OUT.png] [--size W,H] [--windowed]
[--list]``. The states come from :mod:`ui.views.lecture_states` (plain data); the window
(:mod:`ui.views.lecture`, VTK) is imported only to show or draw one. Every bad input is one
line ``psurf: error: ...`` on stderr and exit code 2.
"""

from __future__ import annotations

import argparse
import os
import textwrap

from ui.views.lecture_states import STATES, state_list

from .common import fail, window_size


def _state_number(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer in 1..{len(STATES)}, "
                                         f"got {text!r}") from None
    if not 1 <= v <= len(STATES):
        raise argparse.ArgumentTypeError(f"must be in 1..{len(STATES)} (there are "
                                         f"{len(STATES)} states), got {v}")
    return v


def add_lecture_parser(subparsers) -> argparse.ArgumentParser:
    """Add the ``lecture`` subcommand to ``subparsers`` (``func=run_lecture_cmd``)."""
    p = subparsers.add_parser(
        "lecture",
        help="walk through the tutorials' key states, full-screen (-> / <-)",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=(textwrap.fill(
            "The tutorials' key states in the app, full-screen, with captions; -> / <- move "
            "between states. Every state is pinned (scene, seed, camera, stage, photons, "
            "passes): the same state shows the same picture.", width=88)
            + "\n\nstates:\n" + state_list()),
    )
    p.add_argument("--state", type=_state_number, default=1, metavar="N",
                   help=f"state to open (or to screenshot), 1..{len(STATES)} (default 1)")
    p.add_argument("--screenshot", default=None, metavar="OUT.png",
                   help="render state N off-screen to OUT.png instead of opening the window")
    p.add_argument("--size", type=window_size, default=None, metavar="W,H",
                   help="window / screenshot size (default: the screen, or 1600,900)")
    p.add_argument("--windowed", action="store_true", help="a window instead of full screen")
    p.add_argument("--list", action="store_true", help="print the states and exit")
    p.set_defaults(func=run_lecture_cmd)
    return p


def run_lecture_cmd(args) -> int:
    """Run ``lecture``; returns 0, or 2 after one ``psurf: error:`` line."""
    if getattr(args, "list", False):
        print(state_list())
        return 0
    index = int(args.state) - 1
    if args.screenshot is not None:
        out = args.screenshot
        if not out.lower().endswith(".png"):
            return fail(f"--screenshot {out}: must end in .png")
        folder = os.path.dirname(os.path.abspath(out))
        if not os.path.isdir(folder):
            return fail(f"--screenshot {out}: directory {folder} does not exist")
        try:
            from ui.views.lecture import DEFAULT_SIZE, lecture_screenshot

            lecture_screenshot(index, out, size=args.size or DEFAULT_SIZE)
        except (ImportError, RuntimeError) as e:
            return fail(f"off-screen rendering is unavailable ({type(e).__name__}: {e}); "
                         "it needs VTK with EGL or OSMesa (libegl1 / libosmesa6)")
        print(f"wrote {out}")
        return 0
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        return fail("lecture: no display (DISPLAY / WAYLAND_DISPLAY unset); use "
                     "--screenshot OUT.png to render a state off-screen")
    from ui.views.lecture import run_lecture

    run_lecture(index, size=args.size, full_screen=not args.windowed)
    return 0


