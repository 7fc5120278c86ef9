"""``python app.py record`` (GIF/MP4 of the converging panels) and ``breakdown`` (PNGs):
one-line errors with exit code 2 and nothing written; tiny animations with the right number
of frames."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

pv = pytest.importorskip("pyvista")
pv.OFF_SCREEN = True

import app  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
POINT = str(ROOT / "scenes" / "point.toml")
TINY = ["--photons", "80", "--size", "320,240"]


def _error(capsys, argv) -> str:
    assert app.main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("psurf: error: "), err
    return err[0]


@pytest.mark.parametrize("argv, words", [
    (["--estimator", "planes", "--passes", "2", "--out", "{d}/a.avi"], ".gif or .mp4"),
    (["--estimator", "planes", "--passes", "2", "--out", "{d}/no/a.gif"], "does not exist"),
    (["--estimator", "nope", "--passes", "2", "--out", "{d}/a.gif"], "nope"),
    (["--estimator", "planes", "--out", "{d}/a.gif"], "--passes"),
    (["--estimator", "planes", "--passes", "2", "--time", "1", "--out", "{d}/a.gif"],
     "not allowed"),
    (["--estimator", "planes", "--estimators", "a,b", "--passes", "2", "--out", "{d}/a.gif"],
     "not allowed"),
    (["--estimators", "planes,planes", "--passes", "2", "--out", "{d}/a.gif"], "twice"),
    (["--estimator", "planes", "--passes", "0", "--out", "{d}/a.gif"], "> 0"),
    (["--estimator", "reference", "--passes", "2", "--mode", "techniques",
      "--out", "{d}/a.gif"], "photon estimator"),
    (["--estimator", "planes", "--passes", "2", "--mode", "bounces", "--technique", "cone",
      "--out", "{d}/a.gif"], "--technique cone"),
    (["--estimator", "planes", "--passes", "2", "--pixel", "64,0", "--out", "{d}/a.gif"],
     "outside"),
    (["--estimator", "planes", "--passes", "2", "--reference", "{d}/missing.npz",
      "--out", "{d}/a.gif"], "not found"),
])
def test_record_errors(capsys, tmp_path, argv, words):
    argv = [a.replace("{d}", str(tmp_path)) for a in argv]
    line = _error(capsys, ["record", POINT, *argv])
    assert words in line
    assert os.listdir(tmp_path) == []  # nothing written, not even a temporary file


def test_breakdown_errors(capsys, tmp_path):
    (tmp_path / "file").write_text("x")
    assert "not a directory" in _error(
        capsys, ["breakdown", POINT, "--estimator", "planes", "--out", str(tmp_path / "file")])
    assert "photon estimator" in _error(
        capsys, ["breakdown", POINT, "--estimator", "reference", "--out", str(tmp_path / "o")])
    assert not (tmp_path / "o").exists()


def test_record_gif_frames(capsys, tmp_path):
    import imageio.v3 as iio

    out = tmp_path / "conv.gif"
    assert app.main(["record", POINT, "--estimators", "planes,beams", "--passes", "3",
                     "--out", str(out), *TINY]) == 0
    frames = iio.imread(out, index=None)
    assert frames.shape == (3, 240, 320, 3)
    assert np.abs(frames[0].astype(int) - frames[-1]).sum() > 0  # it converges visibly
    assert "3 frames" in capsys.readouterr().out
    assert sorted(os.listdir(tmp_path)) == ["conv.gif"]
    # one frame per 2 rounds, and the last round always
    out2 = tmp_path / "every.gif"
    assert app.main(["record", POINT, "--estimator", "planes", "--passes", "3", "--every", "2",
                     "--out", str(out2), *TINY]) == 0
    assert iio.imread(out2, index=None).shape[0] == 2


def test_record_mp4_frames(tmp_path):
    imageio_ffmpeg = pytest.importorskip("imageio_ffmpeg")
    out = tmp_path / "conv.mp4"
    assert app.main(["record", POINT, "--estimator", "mis:plane-t1t2+sphere", "--passes", "2",
                     "--mode", "techniques", "--out", str(out), *TINY]) == 0
    n, _ = imageio_ffmpeg.count_frames_and_secs(str(out))
    assert n == 2
    assert sorted(os.listdir(tmp_path)) == ["conv.mp4"]


def test_breakdown_writes_pngs(capsys, tmp_path):
    import imageio.v3 as iio

    out = tmp_path / "bd"
    assert app.main(["breakdown", POINT, "--estimator", "mis:plane-t1t2+sphere", "--passes",
                     "2", "--out", str(out), *TINY]) == 0
    names = set(os.listdir(out))
    for n in ("technique_plane-t1t2.png", "weight_sphere.png", "bounce_K2.png",
              "unweighted_sphere_K2.png", "weighted_sphere_K2.png", "panels_techniques.png",
              "panels_bounces.png", "breakdown.npz"):
        assert n in names, n
    assert not [n for n in names if n.startswith(".")]
    with np.load(out / "breakdown.npz") as z:
        w = z["weights"]
        lit = z["weighted"].sum(axis=(0, 1)).sum(axis=-1) > 0
        assert np.allclose(w.sum(axis=0)[lit], 1.0, atol=1e-5)
        assert list(z["techniques"]) == ["plane-t1t2", "sphere"]
    assert iio.imread(out / "panels_bounces.png").shape[:2] == (240, 320)
