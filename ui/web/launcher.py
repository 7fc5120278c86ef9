"""The front server of ``python app.py serve``: one session process per browser tab.

A trame server holds one state for all its clients, so each tab gets a server of its own:
``GET /`` starts (or takes a ready spare of) ``python -m ui.web.session`` bound to 127.0.0.1 on a
free port and redirects to ``/s/<id>/``, which this server proxies (HTTP and the websocket)
to that process. A tab's state, its pictures and its background render worker live and die
with its process: one session's exception or crash cannot reach another or this server.

Bounds: at most ``max_sessions`` sessions (a further tab gets the "server busy" page, which
retries by itself); each session renders with one background worker at a lower priority
(``ui.cli.progressive``: the pages' own work comes first) and pauses it after
:data:`ui.web.page.IDLE_PAUSE` seconds without input; a session whose websockets stayed
closed for ``grace`` seconds (a closed tab; a reload reconnects sooner) is stopped.
Websocket messages are capped at :data:`MAX_MESSAGE` bytes.
"""

from __future__ import annotations

import asyncio
import html
import os
import secrets
import sys
import time
from dataclasses import dataclass, field

from aiohttp import ClientSession, WSMsgType, web

#: Largest websocket message from a page (an upload's text is far below it).
MAX_MESSAGE = 1 << 20
#: Seconds a session is kept after its last websocket closed.
GRACE = 30.0
#: Seconds a new session may take to start before it is given up.
START_TIMEOUT = 180.0
_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
_HOP = {"connection", "keep-alive", "transfer-encoding", "content-encoding", "content-length",
        "upgrade", "host"}


@dataclass
class Session:
    """One tab's process and what the front knows of it."""

    sid: str
    proc: asyncio.subprocess.Process
    port: int | None = None
    ready: asyncio.Event = field(default_factory=asyncio.Event)
    sockets: int = 0
    started: float = field(default_factory=time.monotonic)
    #: Last sign of its tab: given to it, ready, a page request, a websocket closed.
    last_seen: float = field(default_factory=time.monotonic)
    assigned: bool = False
    failed: str = ""


def _page(title: str, body: str, *, refresh: int | None = None, status: int = 200):
    meta = f'<meta http-equiv="refresh" content="{refresh}">' if refresh else ""
    return web.Response(status=status, content_type="text/html", text=(
        f"<!doctype html><html><head><meta charset='utf-8'>{meta}<title>psurf: "
        f"{html.escape(title)}</title></head><body style='font-family: sans-serif; margin: "
        f"3em'><h2>psurf: {html.escape(title)}</h2><p id='message'>{body}</p></body></html>"))


class Launcher:
    """Sessions (one process each), the proxy to them and their clean-up.

    Parameters
    ----------
    scene : str
        A bundled scene name or the lecturer's scene file (new sessions open it).
    estimators : str
        ``A,B`` (checked by the caller).
    max_sessions : int
        Sessions at once; a further tab gets the busy page (HTTP 503).
    spare : int
        Sessions started ahead of time, so a new tab opens at once.
    photons, passes : int, optional
        Photons per pass and passes per estimator of every session (tests: fixed pictures).
    grace : float
        Seconds a session outlives its last closed websocket.
    """

    def __init__(self, scene: str, estimators: str, *, max_sessions: int = 10,
                 spare: int = 1, photons: int | None = None, passes: int | None = None,
                 grace: float = GRACE):
        self.scene, self.estimators, self.photons = scene, estimators, photons
        self.passes = passes
        self.max_sessions, self.spare, self.grace = int(max_sessions), int(spare), grace
        self.sessions: dict[str, Session] = {}
        self.client: ClientSession | None = None
        self._tasks: set = set()
        self._failed_at = -1e9  # a session that failed to start: no spare for a while

    # ------------------------------------------------------------------ processes
    def _command(self) -> list[str]:
        cmd = [sys.executable, "-m", "ui.web.session", "--port", "0", "--scene", self.scene,
               "--estimators", self.estimators]
        cmd += ["--photons", str(self.photons)] if self.photons else []
        return cmd + (["--passes", str(self.passes)] if self.passes else [])

    async def _spawn(self) -> Session:
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(
            [_ROOT, *filter(None, [os.environ.get("PYTHONPATH")])]))
        proc = await asyncio.create_subprocess_exec(
            *self._command(), cwd=_ROOT, env=env, stdin=asyncio.subprocess.DEVNULL,
            stdout=asyncio.subprocess.PIPE)
        s = Session(secrets.token_urlsafe(12), proc)
        self.sessions[s.sid] = s
        self._spawn_task(self._watch(s))
        return s

    async def _watch(self, s: Session) -> None:
        """Read the session's stdout: its ready line, then until it exits."""
        while True:
            line = await s.proc.stdout.readline()
            if not line:
                break
            text = line.decode(errors="replace").strip()
            if text.startswith("psurf-web-ready "):
                s.port = int(text.split()[1])
                s.last_seen = time.monotonic()  # its tab is still loading "starting"
                s.ready.set()
        await s.proc.wait()
        if not s.ready.is_set():
            s.failed = f"the session process exited (code {s.proc.returncode}) before it was ready"
            s.ready.set()
            self._failed_at = time.monotonic()
        self.sessions.pop(s.sid, None)

    def _spawn_task(self, coro) -> None:
        t = asyncio.ensure_future(coro)
        self._tasks.add(t)
        t.add_done_callback(self._tasks.discard)

    @property
    def live(self) -> int:
        """Sessions given to a tab."""
        return sum(1 for s in self.sessions.values() if s.assigned)

    async def _keep_spares(self) -> None:
        if time.monotonic() - self._failed_at < START_TIMEOUT / 6:
            return
        idle = sum(1 for s in self.sessions.values() if not s.assigned)
        room = self.max_sessions - self.live
        for _ in range(max(0, min(self.spare, room) - idle)):
            await self._spawn()

    async def _stop(self, s: Session) -> None:
        self.sessions.pop(s.sid, None)
        if s.proc.returncode is None:
            s.proc.terminate()
            try:
                await asyncio.wait_for(s.proc.wait(), 10.0)
            except TimeoutError:
                s.proc.kill()
                await s.proc.wait()

    async def reap_forever(self, period: float = 2.0) -> None:
        """Stop sessions whose tab is gone; keep the spares ready."""
        while True:
            now = time.monotonic()
            for s in list(self.sessions.values()):
                # Counted from the last sign of the tab, not from the start: a session that
                # took longer than the grace to start must live until its page connects.
                if s.assigned and s.sockets == 0 and now - s.last_seen > self.grace + (
                        START_TIMEOUT if s.port is None else 0):
                    await self._stop(s)
            await self._keep_spares()
            await asyncio.sleep(period)

    async def close(self) -> None:
        for s in list(self.sessions.values()):
            await self._stop(s)
        if self.client is not None:
            await self.client.close()

    # ------------------------------------------------------------------ routes
    async def new_session(self, _request) -> web.StreamResponse:
        """``GET /``: a session of its own for this tab, or the busy page."""
        if self.live >= self.max_sessions:
            return _page("server busy", f"All {self.max_sessions} sessions are in use (one "
                         "per open tab). This page tries again every 10 seconds; closing an "
                         "unused tab frees its place.", refresh=10, status=503)
        spare = next((s for s in self.sessions.values() if not s.assigned and not s.failed),
                     None)
        s = spare or await self._spawn()
        s.assigned = True
        s.started = s.last_seen = time.monotonic()
        self._spawn_task(self._keep_spares())
        raise web.HTTPFound(f"/s/{s.sid}/")

    async def status(self, _request) -> web.Response:
        """``GET /status``: sessions in use, ready and the limit (JSON)."""
        ss = list(self.sessions.values())
        return web.json_response({"sessions": self.live, "max_sessions": self.max_sessions,
                                  "ready": sum(1 for s in ss if s.assigned and s.port),
                                  "spares": sum(1 for s in ss if not s.assigned)})

    async def slash(self, request: web.Request) -> web.StreamResponse:
        """``/s/<id>``: to ``/s/<id>/`` (the page's relative links need the slash)."""
        raise web.HTTPFound(f"/s/{request.match_info['sid']}/")

    async def proxy(self, request: web.Request) -> web.StreamResponse:
        """``/s/<id>/...``: this tab's session (HTTP and websocket)."""
        s = self.sessions.get(request.match_info["sid"])
        if s is None or not s.assigned:
            return _page("session ended", "This session has ended (its tab was closed, or "
                         "the server restarted). <a href='/'>Open a new one</a>.", status=404)
        tail = request.match_info["tail"]
        s.last_seen = time.monotonic()
        if not s.ready.is_set():
            if tail in ("", "index.html"):
                return _page("starting", "Starting your session (a few seconds)...",
                             refresh=1)
            await asyncio.wait_for(s.ready.wait(), START_TIMEOUT)
        if s.failed:
            return _page("session failed", html.escape(s.failed), status=500)
        url = f"http://127.0.0.1:{s.port}/{tail}"
        if request.headers.get("upgrade", "").lower() == "websocket":
            return await self._proxy_ws(request, s, url.replace("http:", "ws:", 1))
        async with self.client.request(
                request.method, url, params=request.query, data=await request.read(),
                headers={k: v for k, v in request.headers.items()
                         if k.lower() not in _HOP}) as r:
            body = await r.read()
            return web.Response(status=r.status, body=body, headers={
                k: v for k, v in r.headers.items() if k.lower() not in _HOP})

    async def _proxy_ws(self, request, s: Session, url: str) -> web.WebSocketResponse:
        ws = web.WebSocketResponse(max_msg_size=MAX_MESSAGE, heartbeat=None)
        await ws.prepare(request)
        s.sockets += 1
        try:
            async with self.client.ws_connect(url, max_msg_size=0) as up:
                async def down():
                    async for msg in up:
                        if msg.type == WSMsgType.TEXT:
                            await ws.send_str(msg.data)
                        elif msg.type == WSMsgType.BINARY:
                            await ws.send_bytes(msg.data)
                    await ws.close()

                pump = asyncio.ensure_future(down())
                async for msg in ws:
                    if msg.type == WSMsgType.TEXT:
                        await up.send_str(msg.data)
                    elif msg.type == WSMsgType.BINARY:
                        await up.send_bytes(msg.data)
                pump.cancel()
        except Exception as e:  # the session died: this tab's socket closes, nothing else
            print(f"psurf serve: session {s.sid}: websocket ended ({type(e).__name__})",
                  file=sys.stderr)
        finally:
            s.sockets -= 1
            s.last_seen = time.monotonic()
        return ws

    def app(self) -> web.Application:
        """The aiohttp application (routes above; sessions stopped on cleanup)."""
        app = web.Application(client_max_size=MAX_MESSAGE)
        app.router.add_get("/", self.new_session)
        app.router.add_get("/status", self.status)
        app.router.add_get("/s/{sid}", self.slash)
        app.router.add_route("*", "/s/{sid}/{tail:.*}", self.proxy)

        async def startup(_app):
            self.client = ClientSession(auto_decompress=False)
            self._spawn_task(self.reap_forever())

        async def cleanup(_app):
            for t in list(self._tasks):
                t.cancel()
            await self.close()

        app.on_startup.append(startup)
        app.on_cleanup.append(cleanup)
        return app


async def serve(launcher: Launcher, host: str, port: int, on_ready=None) -> None:
    """Run the front server until cancelled; ``on_ready(url)`` once it listens (OSError when
    the address cannot be bound)."""
    runner = web.AppRunner(launcher.app(), handle_signals=False, access_log=None)
    await runner.setup()
    try:
        site = web.TCPSite(runner, host, port)
        await site.start()
        bound = site._server.sockets[0].getsockname()[1]
        if on_ready is not None:
            on_ready(f"http://{host if ':' not in host else '[' + host + ']'}:{bound}/")
        await asyncio.Event().wait()
    finally:
        await runner.cleanup()
