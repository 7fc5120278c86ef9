"""``python app.py serve`` in a real browser (headless Chromium, selenium), and its checks.

One server for the module (``mis:plane-t1t2+planes``: two members to toggle, cheap; 200
photons, 2 passes per estimator, so the pictures are the same every run), at most 3 sessions.
The 3D view and the panels are compared with ``tests/baselines/web_*.png`` by SSIM (>= 0.95,
as the window's screenshots); ``PSURF_UPDATE_BASELINES=1`` rewrites them. The checks that
need no browser are in ``test_web_session.py``.
"""

from __future__ import annotations

import io
import os
import urllib.error
import urllib.request
from pathlib import Path

import numpy as np
import pytest
from app_support import run_app
from web_support import (
    READY_TIMEOUT,
    ROOT,
    Server,
    browser,
    compare,
    stable_png,
    wait_for,
    warm_up,
)

ESTIMATORS = "mis:plane-t1t2+planes"
SERVE = ("--estimators", ESTIMATORS, "--photons", "200", "--passes", "2",
         "--max-sessions", "3", "--spare", "0")


# --------------------------------------------------------------------------- in a browser
@pytest.fixture(scope="module")
def server():
    warm_up(ESTIMATORS.split(","))
    with Server(*SERVE) as s:
        yield s


@pytest.fixture(scope="module")
def driver(server):
    d = browser()
    yield d
    d.quit()


def probe(d) -> dict:
    from selenium.webdriver.common.by import By

    text = d.find_element(By.ID, "probe").get_attribute("textContent")
    stage, pixel, passes, spec, busy, token = text.split("|")
    return {"stage": stage, "pixel": tuple(int(v) for v in pixel.split(",")),
            "passes": int(passes), "spec": spec, "busy": busy == "true", "token": int(token)}


def open_session(d, server, timeout=READY_TIMEOUT) -> str:
    """Open a new session in the current tab; wait until both passes are in; its URL."""
    d.get(server.url)
    wait_for(lambda: probe(d)["passes"] >= 2 and not probe(d)["busy"], timeout,
             "the session's first two passes")
    return d.current_url


def click(d, element_id):
    from selenium.webdriver.common.by import By

    d.find_element(By.ID, element_id).click()


def text_of(d, element_id) -> str:
    from selenium.webdriver.common.by import By

    return d.find_element(By.ID, element_id).text


def step_to(d, stage: str, tmp_path, token: int):
    wait_for(lambda: probe(d)["stage"] == stage and probe(d)["token"] > token
             and not probe(d)["busy"], 120, f"stage {stage}")
    return stable_png(d, "view3d")


def test_page_steps_picks_and_toggles(server, driver, tmp_path):
    d = driver
    url = open_session(d, server)
    assert "/s/" in url and url.startswith(server.url)
    p = probe(d)
    assert p["stage"] == "trace" and p["pixel"] == (32, 24) and p["spec"] == ESTIMATORS
    assert d.title == "psurf: area.toml"  # the tab says what it shows, among a class's tabs
    compare(stable_png(d, "view3d"), "web_trace", tmp_path)
    compare(stable_png(d, "panels"), "web_panels", tmp_path)
    from ui.views.stepper import CAPTIONS, TITLES

    assert (text_of(d, "stage-title"), text_of(d, "caption")) == \
        (TITLES["trace"], CAPTIONS["trace"])
    # The stage text's "+/- to change": the keys draw twice / half as many subpaths.
    from selenium.webdriver.common.by import By

    assert "the first 24 subpaths (+/- to change)" in text_of(d, "panel-text")
    for key, n in (("+", 48), ("-", 24)):
        token = probe(d)["token"]
        d.find_element(By.TAG_NAME, "body").send_keys(key)
        wait_for(lambda t=token, n=n: probe(d)["token"] > t and f"the first {n} subpaths"
                 in text_of(d, "panel-text"), 120, f"{n} subpaths")
    # The five stages with the buttons, each 3D view against its baseline, the stage's
    # title and caption beside it.
    for stage in ("create", "intersect", "evaluate", "reconstruct"):
        token = probe(d)["token"]
        click(d, "next")
        compare(step_to(d, stage, tmp_path, token), f"web_{stage}", tmp_path)
        assert (text_of(d, "stage-title"), text_of(d, "caption")) == \
            (TITLES[stage], CAPTIONS[stage])
        if stage == "evaluate":
            assert "plane-t1t2" in text_of(d, "evaluate-table")
            assert "check ok" in text_of(d, "evaluate-table")
        if stage == "reconstruct":
            table = text_of(d, "reconstruct-table")
            assert "MIS weighting" in table and "weights sum to 1.000" in table
    token = probe(d)["token"]
    click(d, "stage-2")  # a stage button goes straight there
    step_to(d, "intersect", tmp_path, token)
    # A click on the render panel picks the pixel under it.
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.keys import Keys

    img = d.find_element(By.ID, "panels")
    w = img.size["width"]
    ActionChains(d).move_to_element_with_offset(img, -w // 4, 0).click().perform()
    wait_for(lambda: probe(d)["pixel"] != (32, 24) and not probe(d)["busy"], 120, "a new pixel")
    picked = probe(d)["pixel"]
    assert f"pixel ({picked[0]}, {picked[1]})" in text_of(d, "pixel")
    # Switch the member planes off: the estimator becomes SPEC~member, the render restarts.
    click(d, "member-1")
    wait_for(lambda: probe(d)["spec"] == ESTIMATORS + "~plane-t1t2-short"
             and probe(d)["passes"] >= 2 and not probe(d)["busy"], 300, "the member toggle")
    assert probe(d)["pixel"] == picked
    # A slider moved with the keyboard: applied once it rests; the render starts over.
    panels_before = stable_png(d, "panels")
    thumb = d.find_elements(By.CSS_SELECTOR, ".v-slider-thumb")[0]  # sigma_s
    value = float(thumb.get_attribute("aria-valuenow"))
    token = probe(d)["token"]
    thumb.send_keys(*[Keys.ARROW_RIGHT] * 5)
    wait_for(lambda: probe(d)["token"] > token and probe(d)["passes"] >= 2
             and not probe(d)["busy"], 300, "the slider's restart")
    assert float(thumb.get_attribute("aria-valuenow")) == pytest.approx(value + 0.05)
    assert f"σs {value + 0.05:.2f}" in text_of(d, "slider-sigma_s-row")  # its value shown
    # Panel modes: the MIS techniques' contributions and weights instead of the renders.
    click(d, "mode-techniques")
    wait_for(lambda: not np.array_equal(stable_png(d, "panels"), panels_before), 120,
             "the techniques panels")
    click(d, "mode-render")
    # A bad estimator: the one-line message on the page; the session goes on.

    box = d.find_element(By.ID, "estimators")  # Vuetify puts the id on the input
    box.send_keys(Keys.CONTROL, "a")
    box.send_keys("planes,nope")
    click(d, "apply-estimators")
    wait_for(lambda: "estimator 'nope': unknown estimator" in text_of(d, "error"), 60,
             "the error line")
    assert probe(d)["spec"] == ESTIMATORS + "~plane-t1t2-short"
    # The next action that works clears the error line (it was about the last one).
    token = probe(d)["token"]
    click(d, "prev")
    wait_for(lambda: probe(d)["token"] > token and not d.find_elements(By.ID, "error"), 120,
             "the error line gone after a step")
    # Downloads: the render (.npz of app.py render) and the window's figure (PNG).
    with urllib.request.urlopen(url + "download/render.npz", timeout=60) as r:
        data = np.load(io.BytesIO(r.read()))
        assert data["mean"].shape == (48, 64, 3) and int(data["passes"]) == 2
    with urllib.request.urlopen(url + "download/figure.png", timeout=120) as r:
        assert r.read(8) == b"\x89PNG\r\n\x1a\n"


def _ssim(a, b) -> float:
    from skimage.metrics import structural_similarity

    return structural_similarity(a, b, channel_axis=2, data_range=255)


def test_the_3d_view_rotates_zooms_and_resets(server, driver):
    """The 3D view is rendered on the server: a drag rotates it, the wheel zooms, and
    "reset camera" brings back the view the stages open with."""
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.actions.wheel_input import ScrollOrigin
    from selenium.webdriver.common.by import By

    d = driver
    wait_for(lambda: not probe(d)["busy"], 120, "an idle page")
    start = stable_png(d, "view3d")
    view = d.find_element(By.ID, "view3d")
    ActionChains(d).move_to_element(view).click_and_hold().move_by_offset(120, 40) \
        .pause(0.3).move_by_offset(60, 10).release().perform()
    rotated = wait_for(lambda: (lambda img: img if _ssim(img, start) < 0.8 else None)(
        stable_png(d, "view3d")), 60, "a rotated view")
    ActionChains(d).scroll_from_origin(ScrollOrigin.from_element(view), 0, -300).perform()
    wait_for(lambda: _ssim(stable_png(d, "view3d"), rotated) < 0.8, 60, "a zoomed view")
    click(d, "reset-camera")
    wait_for(lambda: _ssim(stable_png(d, "view3d"), start) >= 0.95, 60, "the view as opened")


def test_two_tabs_hold_their_own_state(server, driver):
    d = driver
    first = d.current_window_handle
    before = probe(d)
    d.switch_to.new_window("tab")
    try:
        open_session(d, server)
        assert d.current_url != server.url and probe(d)["stage"] == "trace"
        assert probe(d)["pixel"] == (32, 24) and probe(d)["spec"] == ESTIMATORS
        from selenium.webdriver.common.by import By

        token = probe(d)["token"]
        d.find_element(By.TAG_NAME, "body").send_keys("n")  # the window's key for next
        wait_for(lambda: probe(d)["stage"] == "create" and probe(d)["token"] > token, 120,
                 "stage create in the second tab")
        # An error in this tab's callback is this tab's.
        from selenium.webdriver.common.keys import Keys

        box = d.find_element(By.ID, "estimators")
        box.send_keys(Keys.CONTROL, "a")
        box.send_keys("nope")
        click(d, "apply-estimators")
        wait_for(lambda: "estimator 'nope'" in text_of(d, "error"), 60,
                 "the second tab's error line")
        d.switch_to.window(first)
        after = probe(d)
        assert (after["stage"], after["pixel"], after["spec"]) == \
            (before["stage"], before["pixel"], before["spec"])
        assert not d.find_elements(By.ID, "error")
    finally:
        d.switch_to.window(first)


def test_bad_upload_then_good(server, driver, tmp_path):
    from selenium.webdriver.common.by import By

    from ui.web.scenes import MAX_UPLOAD

    d = driver
    bad = tmp_path / "broken.toml"
    bad.write_text((ROOT / "scenes" / "point.toml").read_text().replace(
        "sigma_s = 0.8", "sigma_s = -1.0", 1))
    cli = run_app("render", bad, "--estimator", "planes", "--out", tmp_path / "x.npz")
    assert cli.returncode == 2
    expected = cli.stderr.strip().removeprefix("psurf: error: ").replace(str(bad), bad.name)
    d.find_element(By.ID, "upload").send_keys(str(bad))
    shown = wait_for(lambda: text_of(d, "upload-error"), 60, "the upload's error line")
    assert shown == expected.replace(str(tmp_path) + "/", "")
    big = tmp_path / "big.toml"  # refused in the browser, before it is sent
    big.write_text("#" * (MAX_UPLOAD + 1))
    d.find_element(By.ID, "upload").send_keys(str(big))
    wait_for(lambda: text_of(d, "upload-error") == f"big.toml: {MAX_UPLOAD + 1} bytes, more "
             "than the 64 KiB an uploaded scene may have", 60, "the size limit's line")
    good = tmp_path / "my_point.toml"
    good.write_text((ROOT / "scenes" / "point.toml").read_text())
    d.find_element(By.ID, "upload").send_keys(str(good))
    wait_for(lambda: "my_point.toml (uploaded)" in text_of(d, "status")
             and probe(d)["passes"] >= 2 and not probe(d)["busy"], 300, "the uploaded scene")
    assert not d.find_elements(By.ID, "upload-error")


def get(url: str):
    """``(status, headers, body)`` of a GET that follows no redirect (closed after)."""

    class NoRedirect(urllib.request.HTTPRedirectHandler):
        def redirect_request(self, *a, **k):
            return None

    try:
        with urllib.request.build_opener(NoRedirect).open(url, timeout=60) as r:
            return r.status, r.headers, r.read()
    except urllib.error.HTTPError as e:
        with e:
            return e.code, e.headers, e.read()


def _children(pid: int) -> list[int]:
    """Processes whose parent is ``pid`` (from /proc)."""
    out = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                stat = (d / "stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                out.append(int(d.name))
    return out


def test_a_crashed_session_leaves_the_others(server, driver):
    import os
    import signal

    before = set(_children(server.proc.pid))
    code, headers, _ = get(server.url)
    assert code == 302
    path = headers["Location"]
    new = wait_for(lambda: sorted(set(_children(server.proc.pid)) - before), 60,
                   "the new session's process")
    os.kill(new[-1], signal.SIGKILL)
    code = wait_for(lambda: get(server.url.rstrip("/") + path)[0] in (404, 500) or None, 30,
                    "the dead session's page")
    assert code is True
    # The first tab's session goes on.
    token = probe(driver)["token"]
    click(driver, "prev")
    wait_for(lambda: probe(driver)["token"] > token, 120, "a step in the first tab")
    assert server.proc.poll() is None


def _listening(pids) -> list[str]:
    """``address:port`` of the TCP sockets processes ``pids`` listen on (from /proc)."""
    import socket

    inodes = set()
    for pid in pids:
        try:
            fds = list(Path(f"/proc/{pid}/fd").iterdir())
        except OSError:
            continue
        for fd in fds:
            try:
                target = os.readlink(fd)
            except OSError:
                continue
            if target.startswith("socket:["):
                inodes.add(target[8:-1])
    out = []
    for table, family in (("tcp", socket.AF_INET), ("tcp6", socket.AF_INET6)):
        for line in Path(f"/proc/net/{table}").read_text().splitlines()[1:]:
            f = line.split()
            if f[3] == "0A" and f[9] in inodes:  # 0A: LISTEN
                addr, port = f[1].split(":")
                raw = bytes.fromhex(addr)
                # /proc prints the address as 32-bit words in host (little-endian) order.
                raw = b"".join(raw[i:i + 4][::-1] for i in range(0, len(raw), 4))
                out.append(f"{socket.inet_ntop(family, raw)}:{int(port, 16)}")
    return out


def _tree(pid: int) -> list[int]:
    out, stack = [], [pid]
    while stack:
        p = stack.pop()
        out.append(p)
        stack += _children(p)
    return out


def test_binds_loopback_only_by_default(server):
    """Without --host the front and every session listen on 127.0.0.1 only."""
    get(server.url)  # a session at least
    wait_for(lambda: len(_listening(_tree(server.proc.pid))) >= 2, 60, "a session's socket")
    listening = _listening(_tree(server.proc.pid))
    assert f"127.0.0.1:{server.port}" in listening
    assert all(a.startswith("127.0.0.1:") for a in listening), listening


def test_no_client_path_reaches_the_file_system(server, driver):
    """Paths that climb out of a session's URL (as sent, not normalized by a browser) get
    nothing: the proxy and the session serve their own routes and files only."""
    import http.client

    path = driver.current_url.removeprefix(server.url.rstrip("/"))
    for tail in ("../../../../etc/passwd", "%2e%2e/%2e%2e/%2e%2e/%2e%2e/etc/passwd",
                 "..%2f..%2f..%2f..%2fetc%2fpasswd", "download/../../../../../etc/passwd",
                 "download/..%2f..%2f..%2f..%2fetc%2fpasswd"):
        conn = http.client.HTTPConnection("127.0.0.1", server.port, timeout=60)
        try:
            conn.request("GET", path + tail)
            r = conn.getresponse()
            body = r.read()
        finally:
            conn.close()
        assert b"root:" not in body and r.status in (400, 403, 404), (tail, r.status)


def test_busy_page_past_the_limit(server):
    import json

    with urllib.request.urlopen(server.url + "status", timeout=30) as r:
        live = json.loads(r.read())
    for _ in range(live["max_sessions"] - live["sessions"]):
        assert get(server.url)[0] == 302
    code, _, body = get(server.url)
    assert code == 503 and b"server busy" in body
