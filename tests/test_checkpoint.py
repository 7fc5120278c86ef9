"""Long renders survive interruption: checkpoints, Ctrl-C and ``--resume``.

* ``psurf_core.checkpoint``: bit-exact round trip, atomic replacement, one-line errors for
  missing / corrupt / foreign files, identity differences.
* ``render --checkpoint DIR``: the checkpoint holds the Welford state, seed, estimator,
  settings, scene hash and version; ``--resume DIR`` continues to exactly (bit for bit) the
  mean and variance of an uninterrupted run with the same seed.
* Ctrl-C (``KeyboardInterrupt`` in-process, and a real SIGINT sent to a subprocess
  mid-render): exit code 130, one line, the completed passes saved, no ``--out`` written;
  an interrupt that lands inside the accumulator update saves the last consistent state.
* ``--resume`` refuses (exit 2, one line naming the flag) a checkpoint made with another
  scene file, estimator, seed or setting.
"""

from __future__ import annotations

import importlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import app
import psurf_core
from psurf_core import checkpoint as ck
from psurf_core.accumulate import Welford

ROOT = Path(__file__).resolve().parent.parent
# The module (not its render() function): its render_pass is patched to interrupt a render.
RENDER = importlib.import_module("psurf_core.render")
FAST = ["--estimator", "planes", "--photons", "300", "--seed", "7"]


@pytest.fixture
def work(tmp_path, monkeypatch):
    """A working directory holding ``scene.toml``: the default scene at 24x18 pixels."""
    text = (ROOT / "scenes" / "area.toml").read_text().replace("[64, 48]", "[24, 18]")
    assert "[24, 18]" in text
    (tmp_path / "scene.toml").write_text(text)
    monkeypatch.chdir(tmp_path)
    return tmp_path


def run(capsys, *argv) -> tuple[int, str, str]:
    code = app.main(["render", "scene.toml", *map(str, argv)])
    out, err = capsys.readouterr()
    return code, out, err


def load(path) -> dict:
    with np.load(path) as d:
        return {k: d[k] for k in d.files}


def same_image(a: dict, b: dict) -> None:
    assert int(a["passes"]) == int(b["passes"])
    np.testing.assert_array_equal(a["mean"], b["mean"])
    np.testing.assert_array_equal(a["var"], b["var"])


def one_line(err: str) -> str:
    """The one line that matters; informational ``psurf: note:`` lines are allowed beside it."""
    lines = [ln for ln in err.strip().splitlines() if not ln.startswith("psurf: note:")]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


# --------------------------------------------------------------------------- the module


def test_save_load_round_trip_is_exact_and_atomic(tmp_path):
    rng = np.random.default_rng(1)
    acc = Welford(5, rng.normal(size=(3, 4, 3)), rng.random((3, 4, 3)))
    ident = {"estimator": "planes", "seed": 3, "scene_sha256": "ab"}
    path = ck.save_checkpoint(tmp_path, acc, ident, seconds=1.5, version="x",
                              extra={"scene": "s.toml"})
    assert path == str(tmp_path / "checkpoint.npz")
    got = ck.load_checkpoint(tmp_path)
    assert got.accumulator.n == 5 and got.identity == ident and got.seconds == 1.5
    assert got.meta["version"] == "x" and got.meta["format"] == ck.FORMAT
    assert got.meta["scene"] == "s.toml" and got.meta["passes"] == 5
    np.testing.assert_array_equal(got.accumulator.mean, acc.mean)
    np.testing.assert_array_equal(got.accumulator.m2, acc.m2)
    acc.add(rng.normal(size=(3, 4, 3)))
    ck.save_checkpoint(tmp_path, acc, ident, seconds=2.0, version="x")
    assert ck.load_checkpoint(tmp_path).accumulator.n == 6
    assert os.listdir(tmp_path) == ["checkpoint.npz"]  # replaced in place, no temporary left


def test_a_failed_write_keeps_the_previous_checkpoint(tmp_path, monkeypatch):
    acc = Welford(2, np.ones((2, 2, 3)), np.zeros((2, 2, 3)))
    ck.save_checkpoint(tmp_path, acc, {"seed": 1}, seconds=1.0, version="x")

    def broken(f, **arrays):
        f.write(b"half a file")
        raise KeyboardInterrupt  # e.g. Ctrl-C in the middle of the write

    monkeypatch.setattr(np, "savez", broken)
    with pytest.raises(KeyboardInterrupt):
        ck.save_checkpoint(tmp_path, Welford(3, acc.mean, acc.m2), {"seed": 1}, seconds=2.0,
                           version="x")
    monkeypatch.undo()
    assert os.listdir(tmp_path) == ["checkpoint.npz"]
    assert ck.load_checkpoint(tmp_path).accumulator.n == 2


@pytest.mark.parametrize("content, needle", [
    (None, "no checkpoint here"),
    (b"not a zip", "unreadable checkpoint"),
    ("npy", "not an .npz archive"),
    ("foreign", "missing m2, meta, n"),
    ("format", "checkpoint format 99"),
    ("nan", "non-finite"),
])
def test_load_errors_are_one_line_naming_the_file(tmp_path, content, needle):
    f = tmp_path / "checkpoint.npz"
    good = {"n": np.int64(1), "mean": np.zeros((2, 2, 3)), "m2": np.zeros((2, 2, 3)),
            "meta": np.str_(json.dumps({"format": ck.FORMAT, "identity": {}}))}
    if isinstance(content, bytes):
        f.write_bytes(content)
    elif content == "npy":
        with open(f, "wb") as fh:
            np.save(fh, np.zeros(3))
    elif content == "foreign":
        with open(f, "wb") as fh:
            np.savez(fh, mean=np.zeros(3))
    elif content is not None:
        bad = dict(good)
        if content == "format":
            bad["meta"] = np.str_(json.dumps({"format": 99, "identity": {}}))
        else:
            bad["mean"] = np.full((2, 2, 3), np.nan)
        with open(f, "wb") as fh:
            np.savez(fh, **bad)
    with pytest.raises(ck.CheckpointError) as e:
        ck.load_checkpoint(tmp_path)
    msg = str(e.value)
    assert needle in msg and "\n" not in msg
    assert str(tmp_path) in msg


def test_identity_differences():
    a = {"seed": 1, "estimator": "planes", "photons": 10}
    b = {"seed": 2, "estimator": "planes", "spp": 1}
    assert ck.identity_differences(a, a) == []
    assert ck.identity_differences(a, b) == [("seed", 1, 2), ("spp", None, 1),
                                             ("photons", 10, None)]


# --------------------------------------------------------------------------- the CLI


def test_checkpoint_contents_and_resume_is_bit_identical(work, capsys):
    code, _, err = run(capsys, *FAST, "--passes", "5", "--out", "full.npz")
    assert code == 0, err
    code, out, err = run(capsys, *FAST, "--passes", "2", "--out", "part.npz",
                         "--checkpoint", "ck", "--checkpoint-every", "0")
    assert code == 0, err
    got = ck.load_checkpoint(work / "ck")
    assert got.accumulator.n == 2
    ident = got.identity
    assert ident["estimator"] == "planes" and ident["seed"] == 7 and ident["photons"] == 300
    assert ident["spp"] == 1 and ident["resolution"] == [24, 18]
    assert ident["scene_sha256"] == ck.file_sha256(work / "scene.toml")
    assert got.meta["version"] == psurf_core.__version__
    assert got.meta["scene"] == str(work / "scene.toml")
    assert got.meta["budget"] == {"passes": 2}
    part = load(work / "part.npz")
    np.testing.assert_array_equal(part["mean"], got.accumulator.mean.astype(np.float32))

    code, out, err = run(capsys, *FAST, "--passes", "5", "--out", "resumed.npz",
                         "--resume", "ck")
    assert code == 0, err
    assert "continued from 2 passes" in out
    same_image(load(work / "resumed.npz"), load(work / "full.npz"))
    assert ck.load_checkpoint(work / "ck").accumulator.n == 5  # kept up to date


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


def _refusal(work, capsys, argv, needles, between=None):
    assert run(capsys, *FAST, "--passes", "1", "--out", "a.npz", "--checkpoint", "ck")[0] == 0
    if between is not None:
        between()
    before = sorted(os.listdir(work)), (work / "ck" / "checkpoint.npz").read_bytes()
    code, out, err = run(capsys, *argv, "--out", "b.npz", "--resume", "ck")
    assert code == 2, (out, err)
    line = one_line(err)
    assert line.startswith("psurf: error: --resume ck: "), line
    for n in needles:
        assert n in line, (n, line)
    assert (sorted(os.listdir(work)), (work / "ck" / "checkpoint.npz").read_bytes()) == before


REFUSALS = {
    "seed": (["--estimator", "planes", "--photons", "300", "--seed", "8"], ["--seed 7", "8"]),
    "estimator": (["--estimator", "plane-t1t2", "--photons", "300", "--seed", "7"],
                  ["--estimator 'planes'", "'plane-t1t2'"]),
    "photons": ([*FAST[:2], "--photons", "301", "--seed", "7"], ["--photons 300", "301"]),
    "spp": ([*FAST, "--spp", "2"], ["--spp 1", "2"]),
    "scatter range": ([*FAST, "--max-scatter", "3"], ["--max-scatter -1", "3"]),
    "memory budget": ([*FAST, "--memory-budget", "64"], ["--memory-budget", "64"]),
}


@pytest.mark.parametrize("case", sorted(REFUSALS))
def test_resume_refuses_other_settings(work, capsys, case):
    argv, needles = REFUSALS[case]
    _refusal(work, capsys, argv, ["the checkpoint was made with", *needles])


def test_resume_refuses_an_edited_scene_file(work, capsys):
    def edit():
        with open(work / "scene.toml", "a") as f:
            f.write("# edited\n")

    _refusal(work, capsys, FAST, ["scene.toml", "is not the one the checkpoint was made from",
                                  "SHA-256"], between=edit)


def test_resume_refuses_another_version(work, capsys, monkeypatch):
    _refusal(work, capsys, FAST, ["written by psurf", "this is psurf 9.9.9"],
             between=lambda: monkeypatch.setattr(psurf_core, "__version__", "9.9.9"))


def test_resume_refuses_fewer_passes_than_saved(work, capsys):
    assert run(capsys, *FAST, "--passes", "2", "--out", "a.npz", "--checkpoint", "ck")[0] == 0
    code, _, err = run(capsys, *FAST, "--passes", "1", "--out", "b.npz", "--resume", "ck")
    assert code == 2 and "already holds 2 passes" in one_line(err)
    assert not (work / "b.npz").exists()


def test_checkpoint_directory_with_a_checkpoint_is_not_overwritten(work, capsys):
    assert run(capsys, *FAST, "--passes", "1", "--out", "a.npz", "--checkpoint", "ck")[0] == 0
    code, _, err = run(capsys, *FAST, "--passes", "2", "--out", "b.npz", "--checkpoint", "ck")
    assert code == 2 and "already holds a checkpoint" in one_line(err)
    assert ck.load_checkpoint(work / "ck").accumulator.n == 1


def test_resume_into_another_checkpoint_directory(work, capsys):
    assert run(capsys, *FAST, "--passes", "3", "--out", "full.npz")[0] == 0
    assert run(capsys, *FAST, "--passes", "1", "--out", "a.npz", "--checkpoint", "ck1")[0] == 0
    code, _, err = run(capsys, *FAST, "--passes", "3", "--out", "b.npz", "--resume", "ck1",
                       "--checkpoint", "ck2")
    assert code == 0, err
    assert ck.load_checkpoint(work / "ck1").accumulator.n == 1
    assert ck.load_checkpoint(work / "ck2").accumulator.n == 3
    same_image(load(work / "b.npz"), load(work / "full.npz"))


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


# --------------------------------------------------------------------------- higher moments
def _format_1(directory) -> None:
    """Rewrite DIR/checkpoint.npz as a format-1 checkpoint (before the pass moments)."""
    path = Path(directory) / "checkpoint.npz"
    with np.load(path) as d:
        data = {k: d[k] for k in ("n", "mean", "m2")}
        meta = json.loads(str(d["meta"]))
    meta["format"] = 1
    meta.pop("tails")
    meta["identity"].pop("reference_sampler", None)
    with open(path, "wb") as f:
        np.savez(f, **data, meta=np.str_(json.dumps(meta)))


def test_checkpoint_keeps_the_pass_moments_exactly(tmp_path):
    xs = np.random.default_rng(2).lognormal(size=(6, 3, 4, 3))
    acc = Welford.empty((3, 4, 3))
    for x in xs:
        acc.add(x)
    ck.save_checkpoint(tmp_path, acc, {"seed": 1}, seconds=1.0, version="x")
    got = ck.load_checkpoint(tmp_path)
    assert got.meta["format"] == 2 and got.meta["tails"] and got.accumulator.has_tails
    for k in ("mean", "m2", "m3", "m4", "peak"):
        np.testing.assert_array_equal(getattr(got.accumulator, k), getattr(acc, k))
    # Format 1 still loads; its accumulator does not know the moments.
    _format_1(tmp_path)
    old = ck.load_checkpoint(tmp_path).accumulator
    assert old.n == 6 and not old.has_tails
    np.testing.assert_array_equal(old.m2, acc.m2)
    # So does an accumulator without them, saved as format 2.
    ck.save_checkpoint(tmp_path, old, {"seed": 1}, seconds=1.0, version="x")
    assert not ck.load_checkpoint(tmp_path).accumulator.has_tails
    # A format-2 file that claims the moments but lacks them is refused, in one line.
    path = tmp_path / "checkpoint.npz"
    ck.save_checkpoint(tmp_path, acc, {"seed": 1}, seconds=1.0, version="x")
    with np.load(path) as d:
        data = {k: d[k] for k in d.files if k != "m4"}
    with open(path, "wb") as f:
        np.savez(f, **data)
    with pytest.raises(ck.CheckpointError, match="without its m4") as e:
        ck.load_checkpoint(tmp_path)
    assert "\n" not in str(e.value) and str(path) in str(e.value)


def test_resume_keeps_the_pass_moments_bit_identical(work, capsys):
    """The output .npz carries m2, m3, m4 and the peak; a resumed render gives the same bits
    as an uninterrupted one, and one resumed from a format-1 checkpoint the same image (its
    moments unknown, so its .npz has none)."""
    assert run(capsys, *FAST, "--passes", "4", "--out", "full.npz")[0] == 0
    assert run(capsys, *FAST, "--passes", "2", "--out", "a.npz", "--checkpoint", "ck")[0] == 0
    assert run(capsys, *FAST, "--passes", "4", "--out", "b.npz", "--resume", "ck")[0] == 0
    full, b = load(work / "full.npz"), load(work / "b.npz")
    same_image(b, full)
    for k in ("m2", "m3", "m4", "peak"):
        assert full[k].dtype == np.float64
        np.testing.assert_array_equal(b[k], full[k])
    assert run(capsys, *FAST, "--passes", "2", "--out", "a.npz", "--checkpoint", "old")[0] == 0
    _format_1(work / "old")
    code, _, err = run(capsys, *FAST, "--passes", "4", "--out", "c.npz", "--resume", "old")
    assert code == 0, err
    c = load(work / "c.npz")
    same_image(c, full)
    assert "m3" not in c


def test_resume_refuses_a_reference_checkpoint_of_the_old_sampler(work, capsys):
    """A path-tracer checkpoint from before issue 15's sampler (no ``reference_sampler`` in
    its identity) would resume into a mix of two samplers: refused, in one line."""
    ref = ["--estimator", "reference", "--seed", "3"]
    assert run(capsys, *ref, "--passes", "2", "--out", "a.npz", "--checkpoint", "ck")[0] == 0
    assert ck.load_checkpoint(work / "ck").identity["reference_sampler"]
    _format_1(work / "ck")
    code, _, err = run(capsys, *ref, "--passes", "3", "--out", "b.npz", "--resume", "ck")
    assert code == 2
    line = one_line(err)
    assert "another version of the reference path tracer" in line and "without --resume" in line
    assert not (work / "b.npz").exists()
