"""One session's process: ``python -m ui.web.session --port 0 --scene NAME ...``.

The launcher (:mod:`ui.web.launcher`) starts one per browser tab. It builds the session
(:class:`ui.web.model.WebSession`), its page (:mod:`ui.web.page`, :mod:`ui.web.layout`) and
the download routes, serves them with trame on 127.0.0.1 (never another address: the front
proxies to it), and prints ``psurf-web-ready PORT`` once it listens. Module level imports
nothing heavy: the render worker (``multiprocessing`` spawn) imports this module again.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import sys
import tempfile
import traceback

from .page import Page, bind, one_line


def add_downloads(page: Page) -> None:
    """``GET download/figure.png`` and ``download/render.npz`` on this session's server."""
    from aiohttp import web

    def handler(kind):
        async def get(_request):
            try:
                async with page.lock:
                    if kind == "png":
                        body, ctype, name = page.m.figure_png(), "image/png", "psurf-figure.png"
                    else:
                        body, ctype, name = (page.m.render_npz(), "application/octet-stream",
                                             "psurf-render.npz")
            except Exception as e:
                traceback.print_exc(file=sys.stderr)
                return web.Response(status=500, text=f"psurf: error: {one_line(e)}")
            return web.Response(body=body, content_type=ctype, headers={
                "Content-Disposition": f'attachment; filename="{name}"'})
        return get

    def on_bind(wslink_server):
        app = wslink_server.app
        app.router.add_get("/download/figure.png", handler("png"))
        app.router.add_get("/download/render.npz", handler("npz"))

    page.server.controller.on_server_bind.add(on_bind)


def main(argv=None) -> int:
    """``python -m ui.web.session --port P --scene NAME --estimators A,B``: one session."""
    ap = argparse.ArgumentParser(prog="psurf-web-session")
    ap.add_argument("--port", type=int, default=0)
    ap.add_argument("--scene", required=True, help="a bundled scene name or a scene file")
    ap.add_argument("--estimators", default="planes")
    ap.add_argument("--photons", type=int, default=None)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--passes", type=int, default=None)
    args = ap.parse_args(argv)
    import faulthandler
    import signal

    faulthandler.register(signal.SIGUSR1, all_threads=True)  # kill -USR1: where it hangs

    from trame.app import get_server

    from ui.views.stepper import DEFAULT_PHOTONS

    from . import layout, scenes
    from .model import WebSession
    from .scenes import parse_specs

    if args.scene in scenes.bundled():
        path, label = scenes.bundled_path(args.scene), args.scene
    else:  # the lecturer's own file from the command line (never the client's)
        path, label = args.scene, os.path.basename(args.scene)
    from psurf_core import load_scene

    specs = parse_specs(args.estimators, load_scene(path))
    session = WebSession(path, specs, photons=args.photons or DEFAULT_PHOTONS,
                         workers=args.workers, label=label, max_passes=args.passes)
    server = get_server(name="psurf", client_type="vue3")
    upload_dir = tempfile.mkdtemp(prefix="psurf-web-")
    page = Page(server, session, upload_dir)
    items = scenes.bundled() if label in scenes.bundled() else [*scenes.bundled(), label]
    page.initial_state(items, label)
    bind(page)
    add_downloads(page)
    ui, page.view = layout.build(server, session.view)
    page.push_all(keep_camera=False)

    @server.controller.on_server_ready.add
    def ready(**_):
        print(f"psurf-web-ready {server.port}", flush=True)
        asyncio.ensure_future(page.tick_forever())

    try:
        server.start(port=args.port, host="127.0.0.1", open_browser=False,
                     show_connection_info=False, disable_logging=True, timeout=0)
    finally:
        session.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
