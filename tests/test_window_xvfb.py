"""The real interactive window under a virtual X server (skipped when ``xvfb-run`` is absent).

``python app.py scenes/area.toml`` opens the window; ``PSURF_WINDOW_SCRIPT`` (see
``ui.views.interactive.SCRIPT_ENV``) plays key presses and mouse clicks through VTK's
interactor, one per timer tick, takes screenshots and quits. The test checks that the window
opens, steps through every stage, picks pixels by clicking both image panels (the progressive
panels of ``ui.views.image_panels``), toggles coverage, the inspected pass, the panel mode and
the sliders, records a GIF, and closes with exit code 0 (the background render worker
stopped). By hand (Debian: ``apt-get install xvfb``)::

    PSURF_WINDOW_SCRIPT="n;n;n;n;click:render:10,30;shot:/tmp/w.png;q" \\
        xvfb-run -a -s "-screen 0 1700x1000x24" .venv/bin/python app.py scenes/area.toml
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]

# In the slow set (``make test-slow``): 20-70 s depending on the machine's load, and
# ``make test`` should not depend on an X server.
pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(shutil.which("xvfb-run") is None,
                                 reason="xvfb-run not installed (apt-get install xvfb)")]


def test_window_opens_steps_picks_and_closes(tmp_path):
    import imageio.v3 as iio

    shot1, shot2 = tmp_path / "reconstruct.png", tmp_path / "coverage.png"
    script = ";".join(["wait", "n", "n", "n", "n", "click:render:10,30", f"shot:{shot1}",
                       "p", "click:variance:40,10", "c", "passes>=2", "period", "m", "w",
                       f"shot:{shot2}", "v", "passes+1", "v", "q"])
    # 800 x 450: the same layout (fonts scale with the height), a quarter of the pixels to
    # rasterise in software
    env = dict(os.environ, PSURF_WINDOW_SCRIPT=script, PSURF_WINDOW_SIZE="800,450",
               MPLBACKEND="Agg")
    env.pop("DISPLAY", None)
    # ui/views/_vtk (imported by earlier tests in this process, which has no display) chose
    # VTK's EGL window; the child has Xvfb's display and must pick the X window itself.
    env.pop("VTK_DEFAULT_OPENGL_WINDOW", None)
    proc = subprocess.run(
        ["xvfb-run", "-a", "-s", "-screen 0 1700x1000x24", sys.executable,
         str(ROOT / "app.py"), str(ROOT / "scenes" / "area.toml")],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    out = proc.stdout
    log = f"stdout:\n{out[-3000:]}\nstderr:\n{proc.stderr[-3000:]}"
    assert proc.returncode == 0, log
    assert "Traceback" not in proc.stderr, log
    lines = [ln for ln in out.splitlines() if ln.startswith("window: key")]
    stages = [ln.split("stage ")[1].split(",")[0] for ln in lines]
    assert stages[:5] == ["create", "intersect", "evaluate", "reconstruct", "evaluate"], log
    assert "clicked render" in out and "pixel (10, 30)" in out, log
    assert "clicked variance" in out and "pixel (40, 10)" in out, log
    assert "key period: stage evaluate, pixel (40, 10), pass 1" in out, log
    assert lines[-1].startswith("window: key q"), log
    gifs = list(tmp_path.glob("psurf-record-*.gif"))  # v ... v recorded the window
    # the frame at the start and one per progressive frame (passes+1: at least one)
    assert len(gifs) == 1 and len(iio.imread(gifs[0], index=None)) >= 2, log
    for shot in (shot1, shot2):
        img = np.asarray(iio.imread(shot))
        assert img.shape[:2] == (450, 800)
        assert img.std() > 10  # a drawn window, not a blank frame
