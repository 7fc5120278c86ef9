"""Ten sessions of ``serve`` at once for 60 s (``make test-slow``): every page stays
responsive and no session is lost.

Each session is a trame client in this process (``trame_server.client.Client``: the page's
own protocol, through the front's proxy, loopback only) that steps through the stages and
now and then picks a pixel, at a brisk student's pace (a seeded 1-3 s between actions), while
all ten background renders run. The step response is the round trip of a ``step`` trigger:
the stage changed, the 3D view composed and the page's state sent back (the streamed frame
follows it). Bounded: 60 s of actions, then every client disconnects and the server stops.
"""

from __future__ import annotations

import asyncio
import json
import statistics
import time
import urllib.error
import urllib.request

import numpy as np
import pytest
from web_support import READY_TIMEOUT, Server, warm_up

SESSIONS = 10
SECONDS = 60.0
MEDIAN_MAX = 1.0


class NoRedirect(urllib.request.HTTPRedirectHandler):
    def redirect_request(self, *a, **k):
        return None


def new_session(url: str) -> str:
    """``GET /`` without following the redirect: the session's path ``/s/<id>/``."""
    try:
        urllib.request.build_opener(NoRedirect).open(url, timeout=120).close()
    except urllib.error.HTTPError as e:
        with e:
            assert e.code == 302, f"GET / answered {e.code}"
            return e.headers["Location"]
    raise AssertionError("GET / did not redirect to a session")


async def student(i: int, ws_url: str, t_end_box: list, out: dict) -> None:
    from trame_server.client import Client, ConnectionStatus

    rng = np.random.default_rng([7, i])
    c = Client(url=ws_url, config={"secret": "wslink-secret"})
    task = asyncio.ensure_future(c.connect())
    t0 = time.monotonic()
    while c.connected != ConnectionStatus.CONNECTED:
        assert not task.done(), f"session {i}: connection failed: {task.exception()!r}"
        assert time.monotonic() - t0 < READY_TIMEOUT, f"session {i}: no connection"
        await asyncio.sleep(0.2)
    assert await c.call_trigger("step", [0]) == "trace"  # ready (compose works)
    out["ready"][i] = True
    while t_end_box[0] is None:  # every session connected: the 60 s start together
        await asyncio.sleep(0.1)
    stage, d = 0, 1
    while time.monotonic() < t_end_box[0]:
        await asyncio.sleep(float(rng.uniform(1.0, 3.0)))
        if rng.random() < 0.2:
            x, y = float(rng.uniform(80, 450)), float(rng.uniform(60, 370))
            t = time.perf_counter()
            await c.call_trigger("pick", [x, y, 1100, 430])
            out["pick"].append(time.perf_counter() - t)
            continue
        if not 0 <= stage + d <= 4:
            d = -d
        t = time.perf_counter()
        got = await c.call_trigger("step", [d])
        out["step"].append(time.perf_counter() - t)
        stage += d
        expected = ("trace", "create", "intersect", "evaluate", "reconstruct")[stage]
        if got != expected:
            out["errors"].append(f"session {i}: step returned {got!r}, expected {expected!r}")
    out["alive"][i] = c.connected == ConnectionStatus.CONNECTED
    await c.disconnect()
    task.cancel()


@pytest.mark.slow
def test_ten_sessions_for_a_minute():
    warm_up(["planes"], photons=2000)
    with Server("--max-sessions", str(SESSIONS), "--spare", "0") as server:
        paths = [new_session(server.url) for _ in range(SESSIONS)]
        ws = [f"ws://127.0.0.1:{server.port}{p}ws" for p in paths]
        out = {"step": [], "pick": [], "errors": [], "ready": [False] * SESSIONS,
               "alive": [False] * SESSIONS}
        t_end = [None]

        async def main():
            tasks = [asyncio.ensure_future(student(i, u, t_end, out)) for i, u in enumerate(ws)]
            t0 = time.monotonic()
            while not all(out["ready"]):
                for t in tasks:
                    if t.done() and t.exception():
                        raise t.exception()
                assert time.monotonic() - t0 < READY_TIMEOUT, "sessions not ready"
                await asyncio.sleep(0.2)
            out["startup"] = time.monotonic() - t0
            t_end[0] = time.monotonic() + SECONDS
            await asyncio.wait_for(asyncio.gather(*tasks), SECONDS + 120)

        asyncio.run(main())
        with urllib.request.urlopen(server.url + "status", timeout=30) as r:
            status = json.loads(r.read())
    steps, picks = sorted(out["step"]), sorted(out["pick"])
    summary = {"sessions": SESSIONS, "seconds": SECONDS, "startup_s": round(out["startup"], 1),
               "steps": len(steps), "step_median_s": round(statistics.median(steps), 3),
               "step_p95_s": round(steps[int(0.95 * (len(steps) - 1))], 3),
               "step_max_s": round(steps[-1], 3), "picks": len(picks),
               "pick_median_s": round(statistics.median(picks), 3) if picks else None,
               "sessions_alive": sum(out["alive"]), "server_sessions": status["sessions"]}
    print("load:", json.dumps(summary))
    assert not out["errors"], out["errors"][:3]
    assert all(out["alive"]) and status["sessions"] == SESSIONS, summary
    assert summary["step_median_s"] < MEDIAN_MAX, summary
