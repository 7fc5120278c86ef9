"""``python app.py serve [SCENE.toml] [--estimators A,B] [--port 8080] [--host 127.0.0.1]``:
the app as a web page for a class (:mod:`ui.web`), one session per browser tab.

Flags are checked before anything starts (a bad scene, estimator, port or host is one
``psurf: error:`` line, exit 2); trame and VTK load only in the session processes.
"""

from __future__ import annotations

import argparse
import os
import textwrap

from .common import CliError, positive_int

DEFAULT_PORT = 8080
DEFAULT_HOST = "127.0.0.1"
DEFAULT_ESTIMATORS = "planes"
DEFAULT_MAX_SESSIONS = 10


def port(text: str) -> int:
    """Flag type: a TCP port 0..65535 (0: any free port, printed at start)."""
    try:
        v = int(text)
    except ValueError:
        v = -1
    if not 0 <= v <= 65535:
        raise argparse.ArgumentTypeError(f"must be a port 0..65535, got {text!r}")
    return v


def add_serve_parser(sub) -> None:
    """The ``serve`` subcommand."""
    p = sub.add_parser(
        "serve", allow_abbrev=False, help="the app as a web page (one session per tab)",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=textwrap.dedent(f"""\
            Serve the interactive app as a web page (trame): students open the URL printed
            at start, each browser tab gets a session of its own (stages, pixel, members,
            sliders, uploads). Binds {DEFAULT_HOST} unless --host says otherwise; pages can
            open the bundled scenes and their own uploads only. At most --max-sessions tabs
            at once (the next one gets a "server busy" page that retries by itself)."""))
    p.add_argument("scene", nargs="?", default="area.toml", metavar="SCENE.toml",
                   help="scene new sessions open: a bundled scene name or a file "
                        "(default area.toml)")
    p.add_argument("--estimators", default=DEFAULT_ESTIMATORS, metavar="A,B",
                   help="estimators side by side; the first is inspected (default planes)")
    p.add_argument("--port", type=port, default=DEFAULT_PORT,
                   help=f"TCP port (default {DEFAULT_PORT}; 0: any free port)")
    p.add_argument("--host", default=DEFAULT_HOST,
                   help=f"address to bind (default {DEFAULT_HOST}: this machine only; "
                        "0.0.0.0 for a class on the network)")
    p.add_argument("--max-sessions", type=positive_int, default=DEFAULT_MAX_SESSIONS,
                   metavar="N", help=f"browser tabs at once (default {DEFAULT_MAX_SESSIONS})")
    p.add_argument("--photons", type=positive_int, default=None, help=argparse.SUPPRESS)
    p.add_argument("--passes", type=positive_int, default=None, help=argparse.SUPPRESS)
    p.add_argument("--spare", type=int, default=1, help=argparse.SUPPRESS)
    p.set_defaults(func=cmd_serve)


def _scene_arg(text: str) -> tuple[str, str]:
    """``(what the sessions get, the file)``: a bundled name stays a name."""
    from ui.web import scenes

    if text in scenes.bundled():
        return text, scenes.bundled_path(text)
    if not os.path.exists(text):
        raise CliError(f"{text}: no such scene file (bundled: {', '.join(scenes.bundled())})")
    return os.path.abspath(text), text


def cmd_serve(args) -> int:
    """Check the flags, then run the front server until Ctrl-C."""
    import asyncio
    import socket

    from psurf_core import load_scene
    from ui.web import scenes
    from ui.web.launcher import Launcher, serve

    name, path = _scene_arg(args.scene)
    scene = load_scene(path)  # SceneError: one line naming the file
    try:
        scenes.parse_specs(args.estimators, scene)
    except ValueError as e:
        raise CliError(f"--estimators: {e}") from None
    try:
        socket.getaddrinfo(args.host, args.port)
    except (socket.gaierror, UnicodeError):
        raise CliError(f"--host {args.host}: not an address of this machine") from None
    launcher = Launcher(name, args.estimators, max_sessions=args.max_sessions,
                        spare=max(0, args.spare), photons=args.photons, passes=args.passes)

    def ready(url: str) -> None:
        print(f"psurf: serving {url} ({args.max_sessions} sessions at most; Ctrl-C stops)",
              flush=True)

    try:
        asyncio.run(serve(launcher, args.host, args.port, on_ready=ready))
    except KeyboardInterrupt:  # the way to stop a server: the sessions were stopped
        print("psurf: server stopped", flush=True)
    except OSError as e:
        raise CliError(f"--host {args.host} --port {args.port}: cannot listen there "
                       f"({e.strerror or e})") from None
    return 0
