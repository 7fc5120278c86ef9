"""The front of ``serve`` (:mod:`ui.web.launcher`) without a browser or a real session: a
stand-in session process (a tiny HTTP server that says it is ready after a delay) behind the
front's proxy, on loopback ports."""

from __future__ import annotations

import asyncio
import sys
import textwrap

from aiohttp import ClientSession, web

from ui.web.launcher import Launcher

#: The stand-in session: ready after DELAY seconds, then "the page" for every path.
FAKE_SESSION = textwrap.dedent("""\
    import asyncio, sys
    from aiohttp import web

    async def page(_request):
        return web.Response(text="the page")

    async def main():
        await asyncio.sleep(float(sys.argv[1]))
        app = web.Application()
        app.router.add_get("/{tail:.*}", page)
        runner = web.AppRunner(app)
        await runner.setup()
        site = web.TCPSite(runner, "127.0.0.1", 0)
        await site.start()
        print("psurf-web-ready", site._server.sockets[0].getsockname()[1], flush=True)
        await asyncio.Event().wait()

    asyncio.run(main())
""")



class FakeLauncher(Launcher):
    """A launcher whose sessions are :data:`FAKE_SESSION`, ready after ``delay`` s."""

    def __init__(self, delay: float, **kwargs):
        super().__init__("area.toml", "planes", spare=0, **kwargs)
        self.delay = delay

    def _command(self) -> list[str]:
        return [sys.executable, "-c", FAKE_SESSION, str(self.delay)]


async def _front(launcher: Launcher):
    runner = web.AppRunner(launcher.app(), access_log=None)
    await runner.setup()
    site = web.TCPSite(runner, "127.0.0.1", 0)
    await site.start()
    return runner, f"http://127.0.0.1:{site._server.sockets[0].getsockname()[1]}"


async def _get(client: ClientSession, url: str) -> tuple[int, str]:
    async with client.get(url, allow_redirects=False) as r:
        return r.status, await r.text()


def test_a_slow_start_does_not_cost_the_tab_its_session():
    """A session that takes longer than the grace to start (ten starting at once on a busy
    machine) lives on while its tab loads the page, and is stopped once the tab is gone."""
    grace, delay = 5.0, 6.0

    async def main():
        runner, url = await _front(FakeLauncher(delay, grace=grace))
        try:
            async with ClientSession() as client:
                async with client.get(url + "/", allow_redirects=False) as r:
                    assert r.status == 302
                    path = r.headers["Location"]
                while True:  # the browser reloads "starting" until the session is ready
                    status, body = await _get(client, url + path)
                    assert status == 200, body
                    if "psurf: starting" not in body:
                        break
                    await asyncio.sleep(0.2)
                assert body == "the page"
                # The page's scripts load and its websocket connects a moment later (the
                # reaper looks every 2 s): the session is still there.
                await asyncio.sleep(3.0)
                assert await _get(client, url + path + "app.js") == (200, "the page")
                async with client.get(url + path.rstrip("/"), allow_redirects=False) as r:
                    assert r.status == 302 and r.headers["Location"] == path
                # No request and no websocket for longer than the grace: stopped.
                await asyncio.sleep(grace + 3.0)
                status, body = await _get(client, url + path)
                assert status == 404 and "session ended" in body
        finally:
            await runner.cleanup()

    asyncio.run(main())
