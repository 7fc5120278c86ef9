"""``render --checkpoint DIR`` and ``--resume DIR``.

* The checkpoint holds the Welford state, seed, estimator, settings, scene hash and version;
  ``--resume DIR`` continues to exactly (bit for bit) the mean, variance and pass moments of
  an uninterrupted run with the same seed, also into another checkpoint directory.
* ``--resume`` refuses (exit 2, one line naming the flag) a checkpoint made with another
  scene file, estimator, seed or setting, by another version, with more passes than asked
  for, or by the reference path tracer's old sampler; ``--checkpoint`` never overwrites one.
"""

from __future__ import annotations

import os

import numpy as np
import pytest
from checkpoint_support import FAST, format_1, load, one_line, run, same_image, scene_dir

import psurf_core
from psurf_core import checkpoint as ck


@pytest.fixture
def work(tmp_path, monkeypatch):
    """A working directory holding ``scene.toml`` (:func:`checkpoint_support.scene_dir`)."""
    return scene_dir(tmp_path, monkeypatch)


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



def test_resume_keeps_the_pass_moments_bit_identical(work, capsys):
    """The output .npz carries m2, m3, m4, the peak and the image sum's variance; a resumed
    render gives the same bits as an uninterrupted one, and one resumed from a format-1
    checkpoint the same image (its moments unknown, so its .npz has none)."""
    assert run(capsys, *FAST, "--passes", "4", "--out", "full.npz")[0] == 0
    assert run(capsys, *FAST, "--passes", "2", "--out", "a.npz", "--checkpoint", "ck")[0] == 0
    assert run(capsys, *FAST, "--passes", "4", "--out", "b.npz", "--resume", "ck")[0] == 0
    full, b = load(work / "full.npz"), load(work / "b.npz")
    same_image(b, full)
    for k in ("m2", "m3", "m4", "peak", "sum_var"):
        assert full[k].dtype == np.float64
        np.testing.assert_array_equal(b[k], full[k])
    assert run(capsys, *FAST, "--passes", "2", "--out", "a.npz", "--checkpoint", "old")[0] == 0
    format_1(work / "old")
    code, _, err = run(capsys, *FAST, "--passes", "4", "--out", "c.npz", "--resume", "old")
    assert code == 0, err
    c = load(work / "c.npz")
    same_image(c, full)
    assert "m3" not in c and "sum_var" not in c


def test_resume_refuses_a_reference_checkpoint_of_the_old_sampler(work, capsys):
    """A path-tracer checkpoint from before issue 15's sampler (no ``reference_sampler`` in
    its identity) would resume into a mix of two samplers: refused, in one line."""
    ref = ["--estimator", "reference", "--seed", "3"]
    assert run(capsys, *ref, "--passes", "2", "--out", "a.npz", "--checkpoint", "ck")[0] == 0
    assert ck.load_checkpoint(work / "ck").identity["reference_sampler"]
    format_1(work / "ck")
    code, _, err = run(capsys, *ref, "--passes", "3", "--out", "b.npz", "--resume", "ck")
    assert code == 2
    line = one_line(err)
    assert "another version of the reference path tracer" in line and "without --resume" in line
    assert not (work / "b.npz").exists()
