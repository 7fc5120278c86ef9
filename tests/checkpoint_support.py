"""What the checkpoint tests (``test_checkpoint_*.py``) share: a working directory with a
small scene, an in-process ``render``, the .npz images, the one-line error check, and a
checkpoint rewritten in the older format 1."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

import app

ROOT = Path(__file__).resolve().parent.parent
#: A fast, seeded render (planes, 300 photons per pass).
FAST = ["--estimator", "planes", "--photons", "300", "--seed", "7"]


def scene_dir(tmp_path: Path, monkeypatch) -> Path:
    """``tmp_path`` as the working directory, holding ``scene.toml``: the default scene at
    24x18 pixels (the body of each test module's ``work`` fixture)."""
    text = (ROOT / "scenes" / "area.toml").read_text().replace("[64, 48]", "[24, 18]")
    assert "[24, 18]" in text
    (tmp_path / "scene.toml").write_text(text)
    monkeypatch.chdir(tmp_path)
    return tmp_path


def run(capsys, *argv) -> tuple[int, str, str]:
    """``app.py render scene.toml ARGV`` in-process: (exit code, stdout, stderr)."""
    code = app.main(["render", "scene.toml", *map(str, argv)])
    out, err = capsys.readouterr()
    return code, out, err


def load(path) -> dict:
    """Every array of an .npz file."""
    with np.load(path) as d:
        return {k: d[k] for k in d.files}


def same_image(a: dict, b: dict) -> None:
    """The two renders have the same passes, and bit for bit the same mean and variance."""
    assert int(a["passes"]) == int(b["passes"])
    np.testing.assert_array_equal(a["mean"], b["mean"])
    np.testing.assert_array_equal(a["var"], b["var"])


def one_line(err: str) -> str:
    """The one line that matters; informational ``psurf: note:`` lines are allowed beside it."""
    lines = [ln for ln in err.strip().splitlines() if not ln.startswith("psurf: note:")]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def format_1(directory) -> None:
    """Rewrite DIR/checkpoint.npz as a format-1 checkpoint (before the pass moments)."""
    path = Path(directory) / "checkpoint.npz"
    with np.load(path) as d:
        data = {k: d[k] for k in ("n", "mean", "m2")}
        meta = json.loads(str(d["meta"]))
    meta["format"] = 1
    meta.pop("tails")
    meta.pop("sums", None)
    meta["identity"].pop("reference_sampler", None)
    with open(path, "wb") as f:
        np.savez(f, **data, meta=np.str_(json.dumps(meta)))
