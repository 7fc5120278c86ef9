"""``psurf_core.checkpoint``, the module: a bit-exact round trip (the Welford state and the
pass moments), atomic replacement, one-line errors for missing / corrupt / foreign files,
identity differences, and format 1 files still loading. The command line's use of it is in
``test_checkpoint_resume.py`` and ``test_checkpoint_interrupt.py``."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
from checkpoint_support import format_1

from psurf_core import checkpoint as ck
from psurf_core.accumulate import Welford


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
    format_1(tmp_path)
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


def _rewrite(path, drop=(), meta_pop=(), **replace):
    """Rewrite a checkpoint file without the arrays ``drop`` and meta keys ``meta_pop``."""
    with np.load(path) as d:
        data = {k: d[k] for k in d.files if k not in drop}
    meta = json.loads(str(data["meta"]))
    for k in meta_pop:
        meta.pop(k)
    data.update(replace, meta=np.str_(json.dumps(meta)))
    with open(path, "wb") as f:
        np.savez(f, **data)


def test_checkpoint_keeps_the_image_sum_moment(tmp_path):
    """``sum_m2`` round-trips exactly; a checkpoint written before it was kept (and format 1)
    loads with it unknown, and a file that claims it but lacks it or holds a bad one is
    refused in one line."""
    xs = np.random.default_rng(6).lognormal(size=(7, 3, 4, 3))
    acc = Welford.empty((3, 4, 3))
    for x in xs[:5]:
        acc.add(x)
    ck.save_checkpoint(tmp_path, acc, {"seed": 1}, seconds=1.0, version="x")
    got = ck.load_checkpoint(tmp_path)
    assert got.meta["sums"] and got.meta["format"] == 2
    np.testing.assert_array_equal(got.accumulator.sum_m2, acc.sum_m2)
    for x in xs[5:]:  # resumed passes continue it exactly
        acc.add(x)
        got.accumulator.add(x)
    np.testing.assert_array_equal(got.accumulator.sum_m2, acc.sum_m2)
    np.testing.assert_allclose(acc.sum_variance, np.var(xs.sum(axis=(1, 2)), axis=0, ddof=1),
                               rtol=1e-10)
    path = tmp_path / "checkpoint.npz"
    # Written before it was kept: format 2 without the array or the flag.
    ck.save_checkpoint(tmp_path, acc, {"seed": 1}, seconds=1.0, version="x")
    _rewrite(path, drop=("sum_m2",), meta_pop=("sums",))
    old = ck.load_checkpoint(tmp_path).accumulator
    assert old.sum_m2 is None and old.sum_variance is None and old.has_tails and old.n == 7
    np.testing.assert_array_equal(old.m2, acc.m2)
    # Saved again unknown, it stays unknown (no array, the flag off).
    ck.save_checkpoint(tmp_path, old, {"seed": 1}, seconds=1.0, version="x")
    with np.load(path) as d:
        assert "sum_m2" not in d.files
    assert ck.load_checkpoint(tmp_path).accumulator.sum_m2 is None
    ck.save_checkpoint(tmp_path, acc, {"seed": 1}, seconds=1.0, version="x")
    format_1(tmp_path)
    assert ck.load_checkpoint(tmp_path).accumulator.sum_m2 is None
    for bad, needle in ((dict(drop=("sum_m2",)), "without its sum_m2"),
                        (dict(sum_m2=np.zeros(4)), "inconsistent accumulator (sum_m2"),
                        (dict(sum_m2=np.full(3, np.inf)), "non-finite")):
        ck.save_checkpoint(tmp_path, acc, {"seed": 1}, seconds=1.0, version="x")
        _rewrite(path, **bad)
        with pytest.raises(ck.CheckpointError) as e:
            ck.load_checkpoint(tmp_path)
        assert needle in str(e.value) and "\n" not in str(e.value) and str(path) in str(e.value)
