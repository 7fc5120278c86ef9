"""Helpers of the browser tests (``test_web.py``, ``test_web_load.py``): a ``serve`` process
on a free loopback port, headless Chromium driven by selenium, SSIM against baselines.

Chromium and its driver are Debian's (``make test`` installs them: ``apt-get install
chromium chromium-driver``); selenium is told where they are, so it never downloads a
browser of its own. Without them the browser tests skip, saying so.
"""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
BASELINES = Path(__file__).resolve().parent / "baselines"
SSIM_MIN = 0.95
UPDATE = os.environ.get("PSURF_UPDATE_BASELINES") == "1"
CHROMIUM = "/usr/bin/chromium"
CHROMEDRIVER = "/usr/bin/chromedriver"
#: Flags this machine needs (no GPU, no sandbox as root, no network).
CHROME_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                "--no-first-run", "--disable-background-networking",
                "--disable-component-update", "--disable-sync", "--window-size=1600,1000",
                "--hide-scrollbars", "--force-device-scale-factor=1"]
#: Seconds a session may take to be ready (a cold numba compile of the MIS kernels).
READY_TIMEOUT = 420.0


def warm_up(specs, scene: str = "area.toml", photons: int = 200) -> None:
    """Compile (or load from numba's on-disk cache) the kernels of ``specs`` here, once,
    before sessions start: two session processes compiling the same cold kernels at once
    on a busy 2-core machine take minutes; afterwards each loads them in about a second."""
    from psurf_core import load_scene, parse_estimator
    from psurf_core.inspect import inspect_pixel
    from psurf_core.render import RenderSettings, render_pass

    sc = load_scene(str(ROOT / "scenes" / scene))
    settings = RenderSettings(photons=photons, spp=1)
    for spec in specs:
        est = parse_estimator(spec, sc)
        render_pass(sc, est, 0, 0, settings)
        inspect_pixel(sc, est, 0, 0, (sc.camera.width // 2, sc.camera.height // 2), settings)


def free_port() -> int:
    """A TCP port free on 127.0.0.1 now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Server:
    """``python app.py serve`` on a free loopback port, stopped (with its sessions) on exit."""

    def __init__(self, *args: str):
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}/"
        self.log = tempfile.NamedTemporaryFile("w+", prefix="psurf-serve-", suffix=".log",
                                               delete=False)
        self.proc = subprocess.Popen(
            [sys.executable, str(ROOT / "app.py"), "serve", "--port", str(self.port), *args],
            cwd=ROOT, stdout=self.log, stderr=subprocess.STDOUT, start_new_session=True)
        t0 = time.monotonic()
        while "psurf: serving" not in Path(self.log.name).read_text():
            if self.proc.poll() is not None or time.monotonic() - t0 > 60:
                self.stop()
                raise RuntimeError(f"serve did not start:\n{self.output()}")
            time.sleep(0.1)

    def output(self) -> str:
        return Path(self.log.name).read_text()

    def stop(self) -> None:
        """Ctrl-C, as a person would; the front stops its sessions."""
        try:
            self._stop()
        finally:
            self.log.close()

    def _stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.stop()


def browser():
    """A headless Chromium (selenium), or a skip saying what is missing."""
    webdriver = pytest.importorskip("selenium.webdriver", reason="selenium is not installed "
                                    "(pip install -e '.[dev]')")
    from selenium.webdriver.chrome.service import Service

    for path, pkg in ((CHROMIUM, "chromium"), (CHROMEDRIVER, "chromium-driver")):
        if not (os.path.exists(path) or shutil.which(os.path.basename(path))):
            pytest.skip(f"{path} missing: apt-get install chromium chromium-driver "
                        f"(make test does, as root; here {pkg} could not be installed)")
    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    for flag in [*CHROME_FLAGS, f"--user-data-dir={tempfile.mkdtemp(prefix='psurf-chrome-')}"]:
        opts.add_argument(flag)
    return webdriver.Chrome(service=Service(CHROMEDRIVER), options=opts)


def wait_for(predicate, timeout: float = 60.0, what: str = "condition", poll: float = 0.2):
    """``predicate()``'s first value that is True or another non-None object (a string must
    be non-empty), polled; AssertionError after ``timeout``."""
    t0 = time.monotonic()
    last = None
    while time.monotonic() - t0 < timeout:
        try:
            last = predicate()
            if isinstance(last, str) and not last:
                last = None
        except Exception as e:  # an element not there yet
            last = e
        if last is not None and not isinstance(last, (Exception, bool)) or last is True:
            return last
        time.sleep(poll)
    raise AssertionError(f"timed out after {timeout:g} s waiting for {what} (last: {last!r})")


def element_png(driver, element_id: str) -> np.ndarray:
    """(H, W, 3) uint8 screenshot of one element."""
    import imageio.v3 as iio
    from selenium.webdriver.common.by import By

    png = driver.find_element(By.ID, element_id).screenshot_as_png
    return np.asarray(iio.imread(png))[..., :3]


def stable_png(driver, element_id: str, timeout: float = 60.0) -> np.ndarray:
    """The element's screenshot once two in a row, 0.5 s apart, are the same (the streamed
    frame has arrived and nothing is drawing)."""
    state = {"last": None}

    def same():
        img = element_png(driver, element_id)
        prev, state["last"] = state["last"], img
        return img if prev is not None and prev.shape == img.shape and \
            np.array_equal(prev, img) and img.std() > 0 else None

    return wait_for(same, timeout, f"a still picture of #{element_id}", poll=0.5)


def compare(img: np.ndarray, name: str, tmp_path) -> float:
    """SSIM of ``img`` against ``tests/baselines/<name>.png`` (written when updating)."""
    import imageio.v3 as iio
    from skimage.metrics import structural_similarity

    out = Path(tmp_path) / f"{name}.png"
    iio.imwrite(out, img)
    baseline = BASELINES / f"{name}.png"
    if UPDATE:
        baseline.write_bytes(out.read_bytes())
        return 1.0
    if not baseline.exists():
        pytest.fail(f"missing baseline {baseline}; create it with PSURF_UPDATE_BASELINES=1")
    ref = np.asarray(iio.imread(baseline))[..., :3]
    assert ref.shape == img.shape, f"{name}: {img.shape} != baseline {ref.shape} ({out})"
    ssim = structural_similarity(ref, img, channel_axis=2, data_range=255)
    assert ssim >= SSIM_MIN, f"{name}: SSIM {ssim:.3f} < {SSIM_MIN} (new picture: {out})"
    return ssim


def page_screenshot(out: str, scene: str = "point.toml",
                    estimators: str = "mis:plane-t1t2+planes,beams", stage: int = 3,
                    passes: int = 12) -> None:
    """The README's picture of the page: ``serve SCENE --estimators ...`` in headless
    Chromium (the tests' set-up, 1600x1000), at stage ``stage`` (0-4) once the inspected
    estimator has ``passes`` passes, the render then paused, written to ``out`` (PNG)."""
    from selenium.webdriver.common.by import By

    def probe(d):
        text = d.find_element(By.ID, "probe").get_attribute("textContent")
        stage_, _, passes_, _, busy, token = text.split("|")
        return {"stage": stage_, "passes": int(passes_), "busy": busy == "true",
                "token": int(token)}

    with Server(scene, "--estimators", estimators, "--max-sessions", "1", "--spare", "0") as s:
        d = browser()
        try:
            d.get(s.url)
            wait_for(lambda: probe(d)["passes"] >= passes and not probe(d)["busy"],
                     READY_TIMEOUT + 300, f"{passes} passes")
            d.find_element(By.ID, "play").click()  # pause: the numbers stop moving
            token = probe(d)["token"]
            d.find_element(By.ID, f"stage-{stage}").click()
            wait_for(lambda: probe(d)["token"] > token and not probe(d)["busy"], 120,
                     "the stage")
            stable_png(d, "view3d")
            stable_png(d, "panels")
            d.save_screenshot(out)
        finally:
            d.quit()


if __name__ == "__main__":  # python tests/web_support.py docs/web.png
    page_screenshot(sys.argv[1] if len(sys.argv) > 1 else "docs/web.png")
