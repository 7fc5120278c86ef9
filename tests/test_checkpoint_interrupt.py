"""Long renders survive interruption: Ctrl-C and a bad pass.

Ctrl-C (``KeyboardInterrupt`` in-process, and a real SIGINT sent to a subprocess mid-render):
exit code 130, one line, the completed passes saved, no ``--out`` written, and ``--resume``
then gives the uninterrupted image; an interrupt that lands inside the accumulator update
saves the last consistent state. A non-finite pass stops the render the same way (exit 1).
"""

from __future__ import annotations

import importlib
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from checkpoint_support import FAST, ROOT, load, one_line, run, same_image, scene_dir

from psurf_core import checkpoint as ck
from psurf_core.accumulate import Welford

# The module (not its render() function): its render_pass is patched to interrupt a render.
RENDER = importlib.import_module("psurf_core.render")


@pytest.fixture
def work(tmp_path, monkeypatch):
    """A working directory holding ``scene.toml`` (:func:`checkpoint_support.scene_dir`)."""
    return scene_dir(tmp_path, monkeypatch)


def test_resume_without_budget_finishes_the_checkpoint_budget(work, capsys):
    assert run(capsys, *FAST, "--passes", "4", "--out", "full.npz")[0] == 0
    calls = []
    real = RENDER.render_pass

    def stop_at_pass_2(scene, est, i, *a, **k):
        calls.append(i)
        if i == 2:
            raise KeyboardInterrupt
        return real(scene, est, i, *a, **k)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(RENDER, "render_pass", stop_at_pass_2)
        code, out, err = run(capsys, *FAST, "--passes", "4", "--out", "x.npz",
                             "--checkpoint", "ck")
    assert code == 130
    line = one_line(err)
    assert "interrupted" in line and "2 passes" in line and "--resume ck" in line, line
    assert not (work / "x.npz").exists()
    assert ck.load_checkpoint(work / "ck").accumulator.n == 2
    code, out, err = run(capsys, *FAST, "--out", "x.npz", "--resume", "ck")  # no --passes
    assert code == 0, err
    same_image(load(work / "x.npz"), load(work / "full.npz"))


def test_interrupt_inside_the_accumulator_update_saves_a_consistent_state(work, capsys):
    assert run(capsys, *FAST, "--passes", "3", "--out", "three.npz")[0] == 0
    assert run(capsys, *FAST, "--passes", "2", "--out", "two.npz")[0] == 0
    real_add = Welford.add

    def torn_add(self, x):
        if self.n == 2:  # the third pass: n is bumped, mean and m2 are not
            self.n += 1
            raise KeyboardInterrupt
        real_add(self, x)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(Welford, "add", torn_add)
        code, _, err = run(capsys, *FAST, "--passes", "3", "--out", "x.npz", "--checkpoint",
                           "ck", "--checkpoint-every", "1000")
    assert code == 130 and "2 passes" in one_line(err)
    saved = ck.load_checkpoint(work / "ck").accumulator
    assert saved.n == 2
    np.testing.assert_array_equal(saved.mean.astype(np.float32), load(work / "two.npz")["mean"])
    assert run(capsys, *FAST, "--passes", "3", "--out", "x.npz", "--resume", "ck")[0] == 0
    same_image(load(work / "x.npz"), load(work / "three.npz"))


def test_interrupt_before_the_first_pass_writes_nothing(work, capsys, monkeypatch):
    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(RENDER, "render_pass", interrupted)
    code, out, err = run(capsys, *FAST, "--out", "x.npz", "--checkpoint", "ck")
    assert code == 130 and "nothing written" in one_line(err)
    assert not (work / "ck" / "checkpoint.npz").exists() and not (work / "x.npz").exists()


def test_a_nan_pass_never_reaches_the_image(work, capsys):
    """A non-finite pass (a bug upstream) stops the render: one line, exit 1, the completed
    passes saved, no output written."""
    real = RENDER.render_pass

    def nan_at_pass_2(scene, est, i, *a, **k):
        img = real(scene, est, i, *a, **k)
        if i == 2:
            img[3, 4, 1] = np.nan
        return img

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(RENDER, "render_pass", nan_at_pass_2)
        code, out, err = run(capsys, *FAST, "--passes", "4", "--out", "x.npz", "--checkpoint",
                             "ck")
    assert code == 1
    line = one_line(err)
    assert "non-finite" in line and "planes" in line and "2 completed passes" in line, line
    assert not (work / "x.npz").exists()
    assert ck.load_checkpoint(work / "ck").accumulator.n == 2


# --------------------------------------------------------------------------- real SIGINT
def _cli(args, cwd, **kw):
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    return subprocess.Popen([sys.executable, str(ROOT / "app.py"), "render", "scene.toml",
                             *map(str, args)], cwd=cwd, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, **kw)


def _default_sigint():
    # A shell may start background jobs with SIGINT ignored, and Python then installs no
    # KeyboardInterrupt handler: give the child the normal disposition.
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_sigint_mid_render_then_resume_gives_the_uninterrupted_npz(work):
    slow = ["--estimator", "planes", "--photons", "1500", "--seed", "11"]
    # Far more passes than can finish before the signal (a planes pass takes milliseconds).
    p = _cli([*slow, "--passes", "1000000", "--out", "never.npz", "--checkpoint", "ck",
              "--checkpoint-every", "0"], work, preexec_fn=_default_sigint)
    try:
        deadline = time.monotonic() + 90
        n = 0
        while n < 2:  # wait for two passes; every checkpoint on the way must be readable
            assert p.poll() is None, p.communicate()
            assert time.monotonic() < deadline, "no checkpoint after 90 s"
            time.sleep(0.05)
            if (work / "ck" / "checkpoint.npz").exists():
                n = ck.load_checkpoint(work / "ck").accumulator.n
        p.send_signal(signal.SIGINT)
        out, err = p.communicate(timeout=90)
    finally:
        if p.poll() is None:
            p.kill()
            p.communicate()
    assert p.returncode == 130, (out, err)
    line = one_line(err)
    assert "interrupted" in line and "--resume ck" in line, line
    assert not (work / "never.npz").exists()
    assert os.listdir(work / "ck") == ["checkpoint.npz"]  # no temporary file left
    k = ck.load_checkpoint(work / "ck").accumulator.n
    assert 2 <= k < 1000000 and f"{k} passes" in line

    resumed = _cli([*slow, "--passes", k + 1, "--out", "resumed.npz", "--resume", "ck"], work)
    full = _cli([*slow, "--passes", k + 1, "--out", "full.npz"], work)
    for proc in (resumed, full):
        out, err = proc.communicate(timeout=180)
        assert proc.returncode == 0, err
    same_image(load(work / "resumed.npz"), load(work / "full.npz"))


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_sigint_mid_compare_exits_130_at_once(work):
    # compare renders in this process under interrupt.held: Ctrl-C stops it promptly with
    # one line and exit 130, whichever stage it lands in (tests/test_interrupt.py holds the
    # safe points themselves).
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    p = subprocess.Popen([sys.executable, str(ROOT / "app.py"), "compare", "scene.toml",
                          "--estimators", "planes", "--time", "60", "--runs", "1",
                          "--out", "cmp"], cwd=work, env=env, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, preexec_fn=_default_sigint)
    try:
        time.sleep(8)  # past start-up: the reference or the timed render is running
        assert p.poll() is None, p.communicate()
        p.send_signal(signal.SIGINT)
        sent = time.monotonic()
        out, err = p.communicate(timeout=60)
        waited = time.monotonic() - sent
    finally:
        if p.poll() is None:
            p.kill()
            p.communicate()
    assert p.returncode == 130, (out, err)
    assert "interrupted" in one_line(err)
    assert waited < 30, waited  # not at the end of the 60 s render
    assert not (work / "cmp" / "compare.json").exists()
