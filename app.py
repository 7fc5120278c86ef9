"""psurf command line: ``python app.py [demo] [SCENE.toml]`` opens the window (or, headless,
writes the showcase comparison), ``render``, ``compare``, ``screenshot``, ``record``,
``breakdown``, ``lecture``, ``serve`` (the web page).

A thin layer over :mod:`psurf_core` (argument parsing, progress, writing files); the core never
imports it. Every subcommand lives in :mod:`ui.cli` (``render`` in :mod:`ui.cli.render`,
``demo`` in :mod:`ui.cli.demo`, the flag types and output helpers they share in
:mod:`ui.cli.common`); this file builds the parser. Every bad input ends with one line
``psurf: error: <what>`` on stderr (with a "did you mean" for a mistyped name) and exit code
2, before anything is written.
"""

from __future__ import annotations

import argparse
import sys
import textwrap

from ui.cli.common import CliError, OutputWriteError, Parser, join_negative_values
from ui.cli.compare import add_compare_parser
from ui.cli.demo import add_demo_parser
from ui.cli.lecture import add_lecture_parser
from ui.cli.parallel import WorkersLost
from ui.cli.record import add_record_parsers
from ui.cli.render import (  # noqa: F401 - DEFAULT_* are part of app's interface
    DEFAULT_PASSES,
    DEFAULT_PHOTONS,
    DEFAULT_SEED,
    DEFAULT_SPP,
    add_render_parser,
)
from ui.cli.screenshot import add_screenshot_parser
from ui.cli.serve import add_serve_parser

PROG = "psurf"


# --------------------------------------------------------------------------- parser


def _estimator_help() -> str:
    try:
        from psurf_core.estimators import estimator_help

        text = estimator_help()
    except Exception as e:  # --help must work even while a technique module is broken
        text = f"(estimator list unavailable: {type(e).__name__}: {e})"
    return "\n".join("  " + line for line in text.splitlines())


def build_parser() -> Parser:
    """The ``psurf`` argument parser (``render`` and ``demo`` subcommands)."""
    from psurf_core import __version__

    estimators = _estimator_help()
    top = Parser(
        prog=PROG,
        allow_abbrev=False,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=textwrap.dedent("""\
            Unbiased volumetric photon density estimation (photon surfaces, Deng et al. 2019).

            subcommands:
              render SCENE.toml --estimator NAME --out OUT.npz   render a scene progressively
              demo [SCENE.toml] [--out DIR]                      the window on the showcase
                                                                 comparison, or (without a
                                                                 display) its pictures in DIR
              screenshot SCENE.toml --stage STAGE --pixel X,Y    one step of the app, off-screen
              compare SCENE.toml --estimators A,B --time S       equal-time variance study
              lecture [--state N] [--screenshot OUT.png]         the tutorials' key states,
                                                                 full-screen (-> / <-)
              record SCENE.toml --estimators A,B --passes N      GIF/MP4 of the converging
                     --out conv.gif [--mode render|techniques|bounces]   image panels
              breakdown SCENE.toml --estimator SPEC --out DIR    per-technique, weight and
                                                                 per-K PNGs of an MIS set
              serve [SCENE.toml] [--port 8080] [--host H]        the app as a web page, one
                                                                 session per browser tab

            Run 'python app.py render --help' for the render options."""),
        epilog=f"estimators (--estimator NAME):\n{estimators}",
    )
    top.add_argument("--version", action="version", version=f"{PROG} {__version__}")
    sub = top.add_subparsers(
        dest="command", parser_class=Parser,
        metavar="{render,demo,screenshot,compare,lecture,record,breakdown,serve}")

    add_render_parser(sub, estimators)  # with --dask/--workers/--jobs

    add_demo_parser(sub)  # the window, or the showcase comparison as pictures
    add_screenshot_parser(sub)  # one stage of the window, off-screen
    add_compare_parser(sub)  # equal-time study
    add_lecture_parser(sub)  # lecture mode: the tutorials' key states
    add_record_parsers(sub)  # record (GIF/MP4), breakdown (MIS PNGs)
    add_serve_parser(sub)  # the web page (ui.web)
    return top


# --------------------------------------------------------------------------- main


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit code (2 for every bad input)."""
    from psurf_core import SceneError

    argv = join_negative_values(sys.argv[1:] if argv is None else list(argv))
    if not argv or argv[0].endswith(".toml"):
        # `python app.py [SCENE.toml]` opens the app (the demo: a window, or PNGs headless).
        argv = ["demo", *argv]
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
        if getattr(args, "func", None) is None:
            raise CliError("a subcommand is required: render, demo, screenshot, compare, "
                           "lecture, record, breakdown or serve (see --help)")
        return args.func(args)
    except (CliError, SceneError) as e:
        print(f"{PROG}: error: {' '.join(str(e).split())}", file=sys.stderr)
        return 2
    except (OutputWriteError, WorkersLost) as e:  # a disk or a cluster failed mid-run
        print(f"{PROG}: error: {' '.join(str(e).split())}", file=sys.stderr)
        return 1
    except MemoryError:
        print(f"{PROG}: error: out of memory (lower the resolution, --spp or --photons)",
              file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted; nothing written", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
