"""Sizes beyond the machine: every size a user controls is checked before anything is allocated.

* :mod:`psurf_core.budget` and :mod:`psurf_core.budget_check`, pure: the need is linear in
  each size, counts every array of the accumulator, does not grow with the pass count,
  multiplies with worker processes; the message names the need, the limit and what to
  change (how far); :func:`photon_limit` (the window's photon slider) is monotone and 0 when
  nothing fits; checkpoint bytes are the file's.
* The commands, one size at a time (resolution, spp, photons, mesh triangles, ``--jobs``,
  the picture, compare's estimators and runs): exit code 2, one ``psurf: error:`` line
  naming the size, no traceback, nothing written, and quickly (no allocation is attempted:
  a 200000x200000 image would be ~900 GiB).
* :mod:`psurf_core.mesh_files`: triangle counts from headers and face records, no loading.
"""

from __future__ import annotations

import json
import os
import re
import struct
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import app
from psurf_core import budget, budget_check, load_scene, parse_estimator
from psurf_core.accumulate import Welford
from psurf_core.checkpoint import save_checkpoint
from psurf_core.mesh_files import scene_mesh_files, triangle_count
from psurf_core.render import PHOTON_BATCH, RenderSettings

ROOT = Path(__file__).resolve().parent.parent
AREA = (ROOT / "scenes" / "area.toml").read_text()
MIB = 1 << 20


def scene_at(w, h, text=AREA):
    sc = load_scene(str(ROOT / "scenes" / "area.toml"))
    return replace(sc, camera=replace(sc.camera, width=w, height=h))


def number_after(text: str, prefix: str) -> int:
    m = re.search(re.escape(prefix) + r"([0-9,]+)", text)
    assert m, (prefix, text)
    return int(m.group(1).replace(",", ""))


def one_line(err: str) -> str:
    lines = [ln for ln in err.strip().splitlines() if not ln.startswith("psurf: note:")]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


# --------------------------------------------------------------------------- the model


def test_need_is_linear_in_every_size():
    est = parse_estimator("planes", scene_at(64, 48))
    base = budget.render_need(scene_at(64, 48), est, RenderSettings(photons=1000))
    wide = budget.render_need(scene_at(128, 48), est, RenderSettings(photons=1000))
    spp = budget.render_need(scene_at(64, 48), est, RenderSettings(photons=1000, spp=3))
    more = budget.render_need(scene_at(64, 48), est, RenderSettings(photons=2000))
    px = 64 * 48
    assert wide.total - base.total == pytest.approx(px * (base.per_pixel + base.per_ray))
    assert spp.total - base.total == pytest.approx(2 * px * base.per_ray)
    assert more.total - base.total == pytest.approx(1000 * base.per_photon)
    # Photons are traced in batches: past one batch the need stays flat.
    a = budget.render_need(scene_at(64, 48), est, RenderSettings(photons=PHOTON_BATCH))
    b = budget.render_need(scene_at(64, 48), est, RenderSettings(photons=50 * PHOTON_BATCH))
    assert a.total == b.total


def test_accumulator_bytes_count_every_array_of_welford():
    # Every array grows with the image (4 pixels: 4x the bytes) or not at all (the (C,)
    # image-sum moment); the per-pixel ones are counted.
    one, four = Welford.empty((1, 1, 3)), Welford.empty((2, 2, 3))
    sizes = [(a.nbytes, getattr(four, k).nbytes) for k, a in vars(one).items()
             if isinstance(a, np.ndarray)]
    assert all(b in (a, 4 * a) for a, b in sizes)
    grows = sum(a for a, b in sizes if b == 4 * a)
    assert budget.accumulator_bytes_per_pixel() == grows >= 48


def test_a_checkpoint_is_as_large_as_the_model_says(tmp_path):
    sc = scene_at(40, 30)
    acc = Welford.empty((30, 40, 3))
    acc.add(np.ones((30, 40, 3)))
    save_checkpoint(tmp_path, acc, {"x": 1}, seconds=1.0, version="t",
                    extra={"argv": ["x"] * 50})
    size = (tmp_path / "checkpoint.npz").stat().st_size
    assert size <= budget.checkpoint_bytes(sc) <= size + budget.CHECKPOINT_META_BYTES


def test_checkpoints_and_workers_add_their_parts():
    sc = scene_at(64, 48)
    est = parse_estimator("planes", sc)
    st = RenderSettings(photons=1000)
    one = budget.render_need(sc, est, st)
    ck = budget.render_need(sc, est, st, checkpoint=True)
    assert ck.total - one.total == pytest.approx(64 * 48 * budget.accumulator_bytes_per_pixel())
    jobs = budget.render_need(sc, est, st, jobs=2)
    assert jobs.total > 2 * one.total and jobs.workers == 2 * budget.WORKER_PROCESS_BYTES
    remote = budget.render_need(sc, est, st, remote=True)
    assert remote.per_photon == 0 and remote.per_ray == 0  # passes render elsewhere
    ref = budget.render_need(sc, parse_estimator("reference", sc), st)
    assert ref.per_photon == 0 and ref.pairs == 0


def test_the_message_says_what_it_needs_and_what_to_change():
    sc = scene_at(2048, 1536)
    est = parse_estimator("planes", sc)
    need = budget.render_need(sc, est, RenderSettings(photons=100, memory_budget_mib=256))
    with pytest.raises(budget_check.BudgetError) as e:
        budget_check.check(need, 256)
    msg = str(e.value)
    assert "\n" not in msg and "--memory-budget 256 MiB" in msg, msg
    assert "lower camera.resolution" in msg and "pixels fit" in msg, msg
    assert f"raise --memory-budget to {int(np.ceil(need.total / MIB))} MiB" in msg, msg
    # The advice is true: the resolution it names fits.
    n = number_after(msg, "at most ~")
    w = int(np.sqrt(n * 4 / 3))
    fits = budget.render_need(scene_at(w, n // w), est, need_settings(256))
    budget_check.check(fits, 256)


def need_settings(mib):
    return RenderSettings(photons=100, memory_budget_mib=mib)


def test_photons_and_spp_advice_fits():
    sc = scene_at(64, 48)
    est = parse_estimator("paper-multi", sc)
    st = RenderSettings(photons=30000, memory_budget_mib=200)
    with pytest.raises(budget_check.BudgetError) as e:
        budget_check.check(budget.render_need(sc, est, st), 200)
    n = number_after(str(e.value), "--photons to at most ")
    assert 0 < n < 30000
    budget_check.check(budget.render_need(sc, est, replace(st, photons=n)), 200)
    with pytest.raises(budget_check.BudgetError):
        budget_check.check(budget.render_need(sc, est, replace(st, photons=n + 100)), 200)
    big = scene_at(512, 384)
    st = RenderSettings(photons=100, spp=64, memory_budget_mib=512)
    with pytest.raises(budget_check.BudgetError) as e:
        budget_check.check(budget.render_need(big, parse_estimator("planes", big), st), 512)
    k = number_after(str(e.value), "--spp to at most ")
    assert 1 <= k < 64
    budget_check.check(budget.render_need(big, parse_estimator("planes", big), replace(st, spp=k)),
                 512)


def test_photon_limit_for_the_window_slider():
    sc = scene_at(64, 48)
    ests = [parse_estimator("paper-multi", sc), parse_estimator("planes", sc)]
    st = RenderSettings()
    budgets = (768, 1024, 2048, 4096)
    limits = [budget_check.photon_limit(sc, ests, st, budget_mib=m) for m in budgets]
    assert limits == sorted(limits) and 0 < limits[0] < limits[-1], limits
    for m, n in zip(budgets, limits, strict=True):
        need = budget.progressive_need(sc, ests, replace(st, photons=n), inspect=True)
        assert need.total <= m * MIB
        need = budget.progressive_need(sc, ests, replace(st, photons=n + 1), inspect=True)
        assert need.total > m * MIB
    # The record of a whole pass keeps every photon; without it, batches make any count fit.
    assert budget_check.photon_limit(sc, ests, st, budget_mib=2048, inspect=False) == 1 << 62
    huge = scene_at(20000, 20000)
    assert budget_check.photon_limit(huge, ests, st, budget_mib=512) == 0


def test_limit_without_a_budget_is_the_memory_available():
    avail = budget_check.available_memory()
    assert avail is None or avail > 0
    cap, phrase = budget_check.limit(None)
    assert (cap is None) == (avail is None)
    assert budget_check.limit(300) == (300 * MIB, "--memory-budget 300 MiB")


def test_format_bytes():
    assert budget.format_bytes(512 * MIB) == "512 MiB"
    assert budget.format_bytes(1.5 * 2**40) == "1.5 TiB"
    assert budget.format_bytes(100) == "100 B"


# --------------------------------------------------------------------------- mesh files


def write_binary_stl(path: Path, n: int) -> None:
    rng = np.random.default_rng(0)
    rec = np.zeros(n, dtype=[("normal", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
    rec["v"] = rng.uniform(-0.3, 0.3, (n, 3, 3))
    with open(path, "wb") as f:
        f.write(b"\0" * 80 + struct.pack("<I", n))
        f.write(rec.tobytes())


def test_triangle_counts_without_loading(tmp_path):
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=3)
    for ext in ("obj", "ply", "stl", "off"):
        m.export(tmp_path / f"m.{ext}")
        assert triangle_count(str(tmp_path / f"m.{ext}")) == len(m.faces), ext
    m.export(tmp_path / "a.stl", file_type="stl_ascii")
    assert triangle_count(str(tmp_path / "a.stl")) == len(m.faces)
    write_binary_stl(tmp_path / "b.stl", 1234)
    assert triangle_count(str(tmp_path / "b.stl")) == 1234
    assert triangle_count(str(tmp_path / "missing.obj")) is None
    (tmp_path / "x.glb").write_bytes(b"glTF")
    assert triangle_count(str(tmp_path / "x.glb")) is None


def test_scene_mesh_files_resolve_like_the_loader():
    files = scene_mesh_files(str(ROOT / "scenes" / "mesh_light.toml"))
    assert files == [("lights[0].mesh", str(ROOT / "scenes" / "meshes" / "blob.obj"))]
    assert scene_mesh_files(str(ROOT / "nope.toml")) == []


# --------------------------------------------------------------------------- the commands


@pytest.fixture
def work(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    return tmp_path


def scene_file(work: Path, w: int, h: int, extra: str = "", name="s.toml") -> str:
    text = AREA.replace("[64, 48]", f"[{w}, {h}]")
    assert f"[{w}, {h}]" in text
    (work / name).write_text(text + extra)
    return name


def refused(capsys, argv, *needles) -> str:
    t = time.perf_counter()
    code = app.main(argv)
    seconds = time.perf_counter() - t
    _, err = capsys.readouterr()
    line = one_line(err)
    assert code == 2, err
    for needle in needles:
        assert needle in line, line
    assert seconds < 30, f"{seconds:.1f} s: the check came too late"
    return line


def test_render_resolution_beyond_the_machine(work, capsys):
    s = scene_file(work, 200000, 200000)
    refused(capsys, ["render", s, "--estimator", "planes", "--out", "o.npz", "--checkpoint",
                     "ck"], "would need about", "TiB", "200000x200000 image",
            "lower camera.resolution")
    assert sorted(os.listdir(work)) == ["s.toml"]  # no checkpoint directory, no output
    refused(capsys, ["render", s, "--estimator", "reference", "--out", "o.npz"],
            "200000x200000")


def test_render_resolution_beyond_the_budget(work, capsys):
    s = scene_file(work, 2048, 1536)
    refused(capsys, ["render", s, "--estimator", "planes", "--memory-budget", "256",
                     "--out", "o.npz"], "--memory-budget 256 MiB", "pixels fit",
            "raise --memory-budget to")


def test_render_spp_beyond_the_budget(work, capsys):
    s = scene_file(work, 256, 192)
    refused(capsys, ["render", s, "--estimator", "planes", "--spp", "64", "--memory-budget",
                     "512", "--out", "o.npz"], "spp 64", "lower --spp to at most")


def test_render_photons_beyond_the_budget(work, capsys):
    s = scene_file(work, 64, 48)
    refused(capsys, ["render", s, "--estimator", "paper-multi", "--photons", "30000",
                     "--memory-budget", "200", "--out", "o.npz"],
            "photons at a time", "lower --photons to at most")


def test_render_jobs_multiply_the_need(work, capsys):
    s = scene_file(work, 64, 48)
    refused(capsys, ["render", s, "--estimator", "planes", "--jobs", "3", "--memory-budget",
                     "400", "--out", "o.npz"], "3 worker processes")
    assert app.main(["render", s, "--estimator", "planes", "--passes", "1", "--photons", "200",
                     "--memory-budget", "400", "--out", "o.npz"]) == 0


def test_mesh_triangles_beyond_the_budget_are_refused_before_loading(work, capsys):
    write_binary_stl(work / "big.stl", 200_000)
    s = scene_file(work, 64, 48, '\n[[occluders]]\ntype = "mesh"\nmesh = "big.stl"\n')
    line = refused(capsys, ["render", s, "--estimator", "planes", "--memory-budget", "100",
                            "--out", "o.npz"], "occluders[0].mesh", "200,000 triangles",
                   "at most ~")
    assert "big.stl" in line


def test_compare_record_screenshot_and_demo_check_their_sizes(work, capsys):
    s = scene_file(work, 200000, 200000)
    refused(capsys, ["compare", s, "--estimators", "planes,beams", "--time", "1", "--out",
                     "cmp"], "the comparison would need", "200000x200000")
    assert not (work / "cmp").exists()
    refused(capsys, ["record", s, "--estimator", "planes", "--passes", "2", "--out",
                     "a.gif"], "the recording would need")
    refused(capsys, ["breakdown", s, "--estimator", "paper-multi", "--out", "bd"],
            "the breakdown would need")
    refused(capsys, ["screenshot", s, "--stage", "trace", "--pixel", "1,1", "--estimator",
                     "planes", "--out", "a.png"], "the screenshot would need")
    refused(capsys, ["demo", s, "--no-window", "--out", "demo"], "the demo would need")
    small = scene_file(work, 64, 48, name="small.toml")
    refused(capsys, ["screenshot", small, "--stage", "trace", "--pixel", "1,1", "--estimator",
                     "planes", "--size", "200000,200000", "--out", "a.png"], "lower --size")
    refused(capsys, ["screenshot", small, "--stage", "trace", "--pixel", "1,1", "--estimator",
                     "paper-multi", "--photons", "100000000", "--out", "a.png"],
            "photons kept", "lower --photons to at most")
    refused(capsys, ["compare", small, "--estimators", "planes,paper-multi", "--photons",
                     "1000,40000", "--memory-budget", "300", "--time", "1", "--out", "cmp"],
            "--memory-budget 300 MiB")
    assert not any(p.suffix in (".png", ".gif", ".npz") for p in work.iterdir())


def test_passes_and_checkpoints_do_not_grow_the_need(work, capsys):
    """The accumulator is the same after 10 passes or 10**12: no pass count is refused."""
    s = scene_file(work, 24, 18)
    assert app.main(["render", s, "--estimator", "planes", "--photons", "100", "--passes",
                     "3", "--memory-budget", "64", "--checkpoint", "ck", "--checkpoint-every",
                     "0", "--out", "o.npz"]) == 0
    meta = json.loads(str(np.load(work / "ck" / "checkpoint.npz")["meta"]))
    assert meta["passes"] == 3
