"""``python app.py serve`` in a real browser (headless Chromium, selenium), and its checks.

One server for the module (``mis:plane-t1t2+planes``: two members to toggle, cheap; 200
photons, 2 passes per estimator, so the pictures are the same every run), at most 3 sessions.
The 3D view and the panels are compared with ``tests/baselines/web_*.png`` by SSIM (>= 0.95,
as the window's screenshots); ``PSURF_UPDATE_BASELINES=1`` rewrites them. Browser-free checks
(flags, uploads) come first.
"""

from __future__ import annotations

import io
import subprocess
import sys
import urllib.error
import urllib.request
from pathlib import Path

import numpy as np
import pytest
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


# --------------------------------------------------------------------------- no browser
@pytest.mark.parametrize("args, message", [
    (["--port", "70000"], "argument --port: must be a port 0..65535, got '70000'"),
    (["--estimators", "reference"], "--estimators: the first estimator is the one the "
                                    "stages inspect"),
    (["--estimators", "planes,nope"], "--estimators: estimator 'nope': unknown estimator"),
    (["missing.toml"], "missing.toml: no such scene file"),
    (["--host", "no.such.host.invalid"], "--host no.such.host.invalid: not an address"),
])
def test_serve_flags_one_line(args, message):
    r = subprocess.run([sys.executable, str(ROOT / "app.py"), "serve", *args], cwd=ROOT,
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("psurf: error: " + message), r.stderr


def test_upload_checks():
    from ui.web.scenes import MAX_UPLOAD, UploadError, check_upload

    text = (ROOT / "scenes" / "point.toml").read_text()
    assert check_upload("mine.toml", text.encode()) == text
    for name, content, why in [
        ("a.txt", b"x", "a scene is a .toml file"),
        ("big.toml", b"#" * (MAX_UPLOAD + 1), "more than the 64 KiB"),
        ("bin.toml", b"\xff\xfe", "not UTF-8"),
        ("m.toml", (ROOT / "scenes" / "mesh_light.toml").read_bytes(), "cannot reference files"),
    ]:
        with pytest.raises(UploadError, match=why):
            check_upload(name, content)


def test_bundled_names_only():
    from ui.web.scenes import UploadError, bundled, bundled_path

    assert "area.toml" in bundled()
    for bad in ("../app.py", "/etc/passwd", "scenes/area.toml"):
        with pytest.raises(UploadError):
            bundled_path(bad)


def test_one_frame_per_step(tmp_path):
    """Stepping composes the stage and streams the 3D view once: pyvista calls its render
    callbacks (trame's: render, JPEG-encode and send a frame) for every actor a stage adds,
    even while rendering is held; with ten sessions on two cores those frames cost seconds."""
    from trame.app import get_server

    from ui.views.stepper import STAGES
    from ui.web import _view3d
    from ui.web.model import WebSession
    from ui.web.page import Page

    m = WebSession(str(ROOT / "scenes" / "area.toml"), ["planes"], photons=200, workers=0)
    try:
        server = get_server(name="test_one_frame_per_step", client_type="vue3")
        page = Page(server, m, str(tmp_path))
        page.initial_state(["area.toml"], "area.toml")
        page.view = _view3d.remote_view(m.view, trame_server=server)
        frames = []
        page.view.update = lambda *a, **k: frames.append(m.s.stage)
        for stage in STAGES[1:]:
            m.step(1)
            page.push_view()
            assert frames == [stage], frames
            frames.clear()
        page.push_view(keep_camera=False)  # reset camera
        assert frames == ["reconstruct"]
    finally:
        m.close()


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
    compare(stable_png(d, "view3d"), "web_trace", tmp_path)
    compare(stable_png(d, "panels"), "web_panels", tmp_path)
    # The five stages with the buttons, each 3D view against its baseline.
    for stage in ("create", "intersect", "evaluate", "reconstruct"):
        token = probe(d)["token"]
        click(d, "next")
        compare(step_to(d, stage, tmp_path, token), f"web_{stage}", tmp_path)
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
    from selenium.webdriver.common.by import By
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
    # Downloads: the render (.npz of app.py render) and the window's figure (PNG).
    with urllib.request.urlopen(url + "download/render.npz", timeout=60) as r:
        data = np.load(io.BytesIO(r.read()))
        assert data["mean"].shape == (48, 64, 3) and int(data["passes"]) == 2
    with urllib.request.urlopen(url + "download/figure.png", timeout=120) as r:
        assert r.read(8) == b"\x89PNG\r\n\x1a\n"


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
        d.switch_to.window(first)
        after = probe(d)
        assert (after["stage"], after["pixel"], after["spec"]) == \
            (before["stage"], before["pixel"], before["spec"])
    finally:
        d.switch_to.window(first)


def test_bad_upload_then_good(server, driver, tmp_path):
    from selenium.webdriver.common.by import By

    d = driver
    bad = tmp_path / "broken.toml"
    bad.write_text((ROOT / "scenes" / "point.toml").read_text().replace(
        "sigma_s = 0.8", "sigma_s = -1.0", 1))
    cli = subprocess.run([sys.executable, str(ROOT / "app.py"), "render", str(bad),
                          "--estimator", "planes", "--out", str(tmp_path / "x.npz")],
                         capture_output=True, text=True, timeout=120)
    assert cli.returncode == 2
    expected = cli.stderr.strip().removeprefix("psurf: error: ").replace(str(bad), bad.name)
    d.find_element(By.ID, "upload").send_keys(str(bad))
    shown = wait_for(lambda: text_of(d, "upload-error"), 60, "the upload's error line")
    assert shown == expected.replace(str(tmp_path) + "/", "")
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


def test_busy_page_past_the_limit(server):
    import json

    with urllib.request.urlopen(server.url + "status", timeout=30) as r:
        live = json.loads(r.read())
    for _ in range(live["max_sessions"] - live["sessions"]):
        assert get(server.url)[0] == 302
    code, _, body = get(server.url)
    assert code == 503 and b"server busy" in body
