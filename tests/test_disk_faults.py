"""A disk that fills up, turns read-only or loses a folder while a render writes.

On a small tmpfs (mounted here; skipped, with the reason, where mounting is not allowed, as
on most CI runners): before rendering, ``--out``/``--checkpoint`` on a read-only or full
filesystem are one line and exit code 2, nothing rendered. Mid-run (the disk filled, or the
mount turned read-only, during a pass): one line naming the checkpoint and why, exit code 1,
the previous checkpoint intact and loadable, no temporary file left, and ``--resume`` (once
the disk has room) gives the uninterrupted result bit for bit. A checkpoint directory
removed mid-run and an output that cannot be written at the end need no mount.
"""

from __future__ import annotations

import importlib
import os
import shutil
import subprocess
import sys
import uuid
from pathlib import Path

import numpy as np
import pytest

import app
from psurf_core import checkpoint as ck

ROOT = Path(__file__).resolve().parent.parent
RENDER = importlib.import_module("psurf_core.render")
FAST = ["--estimator", "planes", "--photons", "300", "--seed", "5"]


@pytest.fixture
def work(tmp_path, monkeypatch):
    """A working directory holding ``scene.toml``: the default scene at 24x18 pixels."""
    text = (ROOT / "scenes" / "area.toml").read_text().replace("[64, 48]", "[24, 18]")
    (tmp_path / "scene.toml").write_text(text)
    monkeypatch.chdir(tmp_path)
    return tmp_path


def _mount(point: Path, size: str):
    if sys.platform != "linux":
        pytest.skip("tmpfs mounts are Linux's")
    point.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(point)],
                       capture_output=True, text=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here (needs root or CAP_SYS_ADMIN, as CI runners "
                    f"often do not allow): {r.stderr.strip() or r.returncode}")


@pytest.fixture
def small_fs(tmp_path):
    """A 1 MiB tmpfs (room for a few 24x18 checkpoints), unmounted afterwards."""
    point = tmp_path / f"fs-{uuid.uuid4().hex[:6]}"
    _mount(point, "1m")
    try:
        yield point
    finally:
        subprocess.run(["mount", "-o", "remount,rw", str(point)], capture_output=True)
        subprocess.run(["umount", "-l", str(point)], capture_output=True)


def fill(folder: Path) -> Path:
    """Fill the filesystem of ``folder`` to the last byte."""
    filler = folder / "filler"
    with open(filler, "ab", buffering=0) as f:
        try:
            while True:
                f.write(b"\0" * 4096)
        except OSError:
            pass
    return filler


def run(capsys, *argv):
    code = app.main(["render", "scene.toml", *map(str, argv)])
    out, err = capsys.readouterr()
    return code, out, err


def one_line(err: str) -> str:
    lines = [ln for ln in err.strip().splitlines() if not ln.startswith("psurf: note:")]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def same_image(a, b) -> None:
    with np.load(a) as x, np.load(b) as y:
        assert int(x["passes"]) == int(y["passes"])
        np.testing.assert_array_equal(x["mean"], y["mean"])
        np.testing.assert_array_equal(x["var"], y["var"])


def during_pass(monkeypatch, index: int, action) -> list:
    """Run ``action()`` while pass ``index`` renders (once); returns the passes seen."""
    real = RENDER.render_pass
    seen = []

    def patched(scene, est, i, *a, **kw):
        seen.append(i)
        if i == index and seen.count(i) == 1:
            action()
        return real(scene, est, i, *a, **kw)

    monkeypatch.setattr(RENDER, "render_pass", patched)
    return seen


def no_temporaries(folder: Path) -> None:
    assert [p for p in os.listdir(folder) if p.endswith(".tmp")] == [], os.listdir(folder)


# --------------------------------------------------------------------------- before rendering


def test_out_and_checkpoint_on_a_read_only_mount_are_refused_first(work, small_fs, capsys):
    subprocess.run(["mount", "-o", "remount,ro", str(small_fs)], check=True)
    refusal = ("not writable", "Read-only file system")
    code, _, err = run(capsys, *FAST, "--passes", "2", "--out", small_fs / "o.npz")
    line = one_line(err)
    assert code == 2 and "--out" in line and any(r in line for r in refusal), err
    code, _, err = run(capsys, *FAST, "--passes", "2", "--out", "o.npz", "--checkpoint",
                       small_fs / "ck")
    line = one_line(err)
    assert code == 2 and "--checkpoint" in line and any(r in line for r in refusal), err
    assert not (work / "o.npz").exists()


def test_a_full_disk_is_refused_before_rendering(work, small_fs, capsys):
    fill(small_fs)
    code, _, err = run(capsys, *FAST, "--passes", "2", "--out", small_fs / "o.npz")
    line = one_line(err)
    assert code == 2 and "--out" in line and "No space left on device" in line, line
    no_temporaries(small_fs)


def test_checkpoint_room_is_checked_before_rendering(work, small_fs, capsys):
    # Room for the outputs but not for two checkpoints of a 120x90 image (2 x 259 KiB).
    big = (ROOT / "scenes" / "area.toml").read_text().replace("[64, 48]", "[120, 90]")
    (work / "scene.toml").write_text(big)
    filler = small_fs / "filler"
    free = shutil.disk_usage(small_fs).free
    filler.write_bytes(b"\0" * (free - 300 * 1024))
    code, _, err = run(capsys, *FAST, "--passes", "2", "--out", "o.npz", "--checkpoint",
                       small_fs / "ck")
    line = one_line(err)
    assert code == 2 and "--checkpoint" in line and "need about" in line and "free" in line
    assert not (small_fs / "ck").exists() and not (work / "o.npz").exists()


# --------------------------------------------------------------------------- mid-run


@pytest.mark.parametrize("fault", ["full", "read-only"])
def test_checkpoint_write_fails_mid_run(work, small_fs, capsys, monkeypatch, fault):
    ckdir = small_fs / "ck"

    def break_disk():
        if fault == "full":
            fill(small_fs)
        else:
            subprocess.run(["mount", "-o", "remount,ro", str(small_fs)], check=True)

    with monkeypatch.context() as m:
        during_pass(m, 2, break_disk)  # after two checkpoints (one after every pass)
        code, _, err = run(capsys, *FAST, "--passes", "6", "--out", "o.npz", "--checkpoint",
                           ckdir, "--checkpoint-every", "0")
    line = one_line(err)
    why = "No space left on device" if fault == "full" else "Read-only file system"
    assert code == 1, err
    assert "cannot write the checkpoint" in line and why in line, line
    assert "still holds the previous checkpoint (2 passes" in line and "--resume" in line, line
    assert not (work / "o.npz").exists()
    no_temporaries(ckdir)
    assert ck.load_checkpoint(ckdir).accumulator.n == 2

    # Room again: resume and compare with an uninterrupted run.
    subprocess.run(["mount", "-o", "remount,rw", str(small_fs)], check=True)
    if (small_fs / "filler").exists():
        (small_fs / "filler").unlink()
    code, _, err = run(capsys, *FAST, "--passes", "6", "--out", "resumed.npz", "--resume",
                       ckdir)
    assert code == 0, err
    code, _, err = run(capsys, *FAST, "--passes", "6", "--out", "full.npz")
    assert code == 0, err
    same_image(work / "resumed.npz", work / "full.npz")


def test_checkpoint_directory_removed_mid_run(work, capsys, monkeypatch):
    with monkeypatch.context() as m:
        during_pass(m, 2, lambda: shutil.rmtree(work / "ck"))
        code, _, err = run(capsys, *FAST, "--passes", "5", "--out", "o.npz", "--checkpoint",
                           "ck", "--checkpoint-every", "0")
    line = one_line(err)
    assert code == 1 and "cannot write the checkpoint" in line, line
    assert "no longer exists" in line and "No such file or directory" in line, line
    assert not (work / "o.npz").exists()


def test_output_that_cannot_be_written_at_the_end(work, small_fs, capsys, monkeypatch):
    with monkeypatch.context() as m:
        during_pass(m, 3, lambda: fill(small_fs))  # the last pass
        code, _, err = run(capsys, *FAST, "--passes", "4", "--out", small_fs / "o.npz",
                           "--png", small_fs / "o.png", "--checkpoint", "ck",
                           "--checkpoint-every", "0")
    line = one_line(err)
    assert code == 1 and "cannot write" in line and "No space left on device" in line, line
    assert "ck holds all 4 passes" in line and "--resume ck" in line, line
    assert sorted(os.listdir(small_fs)) == ["filler"]  # neither output, no temporary file
    (small_fs / "filler").unlink()
    with monkeypatch.context() as m:
        seen = during_pass(m, -1, lambda: None)
        code, out, err = run(capsys, *FAST, "--out", small_fs / "o.npz", "--resume", "ck")
    assert code == 0 and seen == [], (err, seen)  # written without rendering again
    code, _, err = run(capsys, *FAST, "--passes", "4", "--out", "full.npz")
    same_image(small_fs / "o.npz", work / "full.npz")
