"""``python app.py serve`` without a browser: its flags, upload checks, bundled names, the
3D view's frames per step and the render workers' priority (a session's app driven
directly, :class:`ui.web.model.WebSession`)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from app_support import run_app
from web_support import ROOT, wait_for


@pytest.mark.parametrize("args, message", [
    (["--port", "70000"], "argument --port: must be a port 0..65535, got '70000'"),
    (["--estimators", "reference"], "--estimators: the first estimator is the one the "
                                    "stages inspect"),
    (["--estimators", "planes,nope"], "--estimators: estimator 'nope': unknown estimator"),
    (["missing.toml"], "missing.toml: no such scene file"),
    (["--host", "no.such.host.invalid"], "--host no.such.host.invalid: not an address"),
])
def test_serve_flags_one_line(args, message):
    r = run_app("serve", *args)
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


def _sched(pid: int) -> tuple[int, int]:
    """``(nice, scheduling policy)`` of a process, from /proc (policy 5: ``SCHED_IDLE``)."""
    rest = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return int(rest[16]), int(rest[38])  # fields 19 and 41 of proc(5)


def test_render_workers_yield_to_the_pages():
    """A session's render worker runs at the lowest priority (nice 19, SCHED_IDLE), also
    after it died and was restarted: with ten sessions the pages' steps come first."""
    import signal
    import time

    from ui.web.model import WORKER_NICENESS, WebSession, worker_pids

    m = WebSession(str(ROOT / "scenes" / "area.toml"), ["planes"], photons=200, workers=1)
    try:
        (first,) = worker_pids(m.s.prog)
        assert _sched(first) == (WORKER_NICENESS, os.SCHED_IDLE)
        os.kill(first, signal.SIGKILL)

        def restarted():
            m.poll()
            pids = worker_pids(m.s.prog)
            return pids[0] if pids and pids[0] != first else None

        second = wait_for(restarted, 60, "the restarted worker", poll=0.1)
        assert _sched(second) == (WORKER_NICENESS, os.SCHED_IDLE)
        assert m.s.prog.restarts == 1
        time.sleep(0.1)
    finally:
        m.close()
