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


# --------------------------------------------------------------------------- in a browser
@pytest.fixture(scope="module")
def server():
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
    # A bad estimator: the one-line message on the page; the session goes on.
    from selenium.webdriver.common.keys import Keys

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


def test_busy_page_past_the_limit(server):
    import json

    class NoRedirect(urllib.request.HTTPRedirectHandler):
        def redirect_request(self, *a, **k):
            return None

    opener = urllib.request.build_opener(NoRedirect)
    live = json.loads(urllib.request.urlopen(server.url + "status", timeout=30).read())
    for _ in range(live["max_sessions"] - live["sessions"]):
        with pytest.raises(urllib.error.HTTPError) as e:
            opener.open(server.url, timeout=60)
        assert e.value.code == 302
    with pytest.raises(urllib.error.HTTPError) as e:
        opener.open(server.url, timeout=60)
    assert e.value.code == 503 and b"server busy" in e.value.read()
