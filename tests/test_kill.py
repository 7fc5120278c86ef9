"""``kill -9`` at any moment of a checkpointed render loses nothing already saved.

* At each point of the checkpoint write (half the archive written, written and synced but
  not yet renamed, renamed): the checkpoint directory then holds a checkpoint that loads and
  is the previous or the new one (never a torn file), and ``--resume`` gives the
  uninterrupted ``.npz`` bit for bit; the killed writer's temporary file is removed.
* At random moments (seeded, so the moments are the same every run; a bounded loop): after
  every kill the checkpoint, if any, loads and equals the uninterrupted render's accumulator
  after as many passes, bit for bit; resuming to the end gives the uninterrupted ``.npz``.
  Two kills in ``make test``, a longer loop in ``make test-slow``.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from psurf_core import checkpoint as ck
from psurf_core import load_scene, parse_estimator
from psurf_core.render import RenderSettings, render

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")

ROOT = Path(__file__).resolve().parent.parent
SEED = 13
PHOTONS = 200
#: 160x120: a checkpoint (2 x 450 KiB, written and synced) takes ~15% of a pass here, so
#: random kills land in writes too.
RES = (160, 120)
ARGS = ["--estimator", "planes", "--photons", str(PHOTONS), "--seed", str(SEED)]

#: A child that runs ``app.main`` and SIGKILLs itself at one point of its ``at``-th
#: checkpoint write.
CHILD = textwrap.dedent("""\
    import io, os, signal, sys
    import numpy as np
    point, at = sys.argv[1], int(sys.argv[2])
    calls = [0]
    real_savez, real_replace = np.savez, os.replace

    def die():
        os.kill(os.getpid(), signal.SIGKILL)

    def savez(f, **arrays):
        calls[0] += 1
        if point == "mid-write" and calls[0] == at:
            buf = io.BytesIO()
            real_savez(buf, **arrays)
            f.write(buf.getvalue()[: len(buf.getvalue()) // 2])
            f.flush()
            die()
        return real_savez(f, **arrays)

    def replace(a, b):
        if point == "before-rename" and calls[0] == at and a.endswith(".tmp"):
            die()
        real_replace(a, b)
        if point == "after-rename" and calls[0] == at:
            die()

    np.savez, os.replace = savez, replace
    sys.path.insert(0, {root!r})
    import app
    sys.exit(app.main(sys.argv[3:]))
""").format(root=str(ROOT))


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    d = tmp_path_factory.mktemp("kill")
    text = (ROOT / "scenes" / "area.toml").read_text().replace("[64, 48]",
                                                              f"[{RES[0]}, {RES[1]}]")
    (d / "scene.toml").write_text(text)
    return d


@pytest.fixture(scope="module")
def uninterrupted(work):
    """Per pass count n: the uninterrupted render's accumulator (n, mean, m2) after n passes,
    and the .npz of 8 passes written by the command line."""
    sc = load_scene(str(work / "scene.toml"))
    states = {}

    def keep(i, acc, elapsed):
        states[acc.n] = (acc.mean.copy(), acc.m2.copy())

    render(sc, parse_estimator("planes", sc), RenderSettings(photons=PHOTONS), passes=40,
           seed=SEED, on_pass=keep)
    r = cli(work, [*ARGS, "--passes", "8", "--out", "full8.npz"])
    _, err = r.communicate(timeout=300)
    assert r.returncode == 0, err
    return states, work / "full8.npz"


def env():
    return {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}


def cli(cwd, args, child=None):
    cmd = [sys.executable, "-c", CHILD, *child] if child else [sys.executable,
                                                               str(ROOT / "app.py")]
    return subprocess.Popen([*cmd, "render", "scene.toml", *map(str, args)], cwd=cwd,
                            env=env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)


def same_npz(a, b) -> None:
    with np.load(a) as x, np.load(b) as y:
        assert int(x["passes"]) == int(y["passes"])
        np.testing.assert_array_equal(x["mean"], y["mean"])
        np.testing.assert_array_equal(x["var"], y["var"])


def check_saved(ckdir: Path, states: dict) -> int:
    """The checkpoint in ``ckdir`` (if any) loads and is the uninterrupted accumulator."""
    if not (ckdir / ck.CHECKPOINT_FILE).exists():
        return 0
    acc = ck.load_checkpoint(ckdir).accumulator  # never a file that does not load
    mean, m2 = states[acc.n]
    np.testing.assert_array_equal(acc.mean, mean)
    np.testing.assert_array_equal(acc.m2, m2)
    return acc.n


def temporaries(ckdir: Path) -> list[str]:
    return [p for p in os.listdir(ckdir) if p.endswith(".tmp")] if ckdir.is_dir() else []


def resume_to_the_end(work: Path, ckdir: Path, full: Path, out: str) -> None:
    started = ckdir.is_dir() and (ckdir / ck.CHECKPOINT_FILE).exists()
    flag = ["--resume", ckdir] if started else ["--checkpoint", ckdir]
    r = cli(work, [*ARGS, "--passes", "8", "--out", out, *flag, "--checkpoint-every", "0"])
    _, err = r.communicate(timeout=300)
    assert r.returncode == 0, err
    assert temporaries(ckdir) == []  # a killed writer's temporary file is gone
    same_npz(work / out, full)


#: (where the child kills itself during its 3rd checkpoint write, the passes then on disk)
POINTS = [("mid-write", 2), ("before-rename", 2), ("after-rename", 3)]


def test_kill_during_the_checkpoint_write(work, uninterrupted):
    """The three kill points run side by side (one process each), then their resumes."""
    states, full = uninterrupted
    procs = {point: cli(work, [*ARGS, "--passes", "8", "--out", f"never-{point}.npz",
                               "--checkpoint", work / f"ck-{point}", "--checkpoint-every", "0"],
                        child=[point, "3"]) for point, _ in POINTS}
    for point, kept in POINTS:
        _, err = procs[point].communicate(timeout=300)
        assert procs[point].returncode == -signal.SIGKILL, err
        ckdir = work / f"ck-{point}"
        assert check_saved(ckdir, states) == kept, point
        assert (temporaries(ckdir) != []) == (point != "after-rename"), point
        assert not (work / f"never-{point}.npz").exists()
    resumes = {point: cli(work, [*ARGS, "--passes", "8", "--out", f"resumed-{point}.npz",
                                 "--resume", work / f"ck-{point}", "--checkpoint-every", "0"])
               for point, _ in POINTS}
    for point, _ in POINTS:
        _, err = resumes[point].communicate(timeout=300)
        assert resumes[point].returncode == 0, err
        assert temporaries(work / f"ck-{point}") == []  # the killed writer's file is gone
        same_npz(work / f"resumed-{point}.npz", full)


def check_final(path: Path, states: dict, n: int) -> None:
    """The render .npz of ``n`` passes is the uninterrupted one (float32 mean and var)."""
    mean, m2 = states[n]
    with np.load(path) as d:
        assert int(d["passes"]) == n
        np.testing.assert_array_equal(d["mean"], mean.astype(np.float32))
        np.testing.assert_array_equal(d["var"], (m2 / (n - 1)).astype(np.float32))


def kill_loop(work: Path, states: dict, kills: int, seconds: float, name: str) -> None:
    """SIGKILL renders of 40 passes at seeded random moments (each some time after the
    session's first checkpoint) until ``kills`` kills or ``seconds``; a render that
    finishes is checked and a new one started in a fresh directory. Then the last one is
    resumed to the end."""
    rng = np.random.default_rng(2024)
    deadline = time.monotonic() + seconds
    done = mid_write = rounds = 0
    ckdir = work / f"{name}-0"
    while done < kills and time.monotonic() < deadline:
        started = (ckdir / ck.CHECKPOINT_FILE).exists()
        flag = ["--resume", ckdir] if started else ["--checkpoint", ckdir]
        out = work / f"{ckdir.name}.npz"
        r = cli(work, [*ARGS, "--passes", "40", "--out", out, *flag, "--checkpoint-every", "0"])
        before = (ckdir / ck.CHECKPOINT_FILE).stat().st_mtime_ns if started else None
        t0 = time.monotonic()
        while r.poll() is None and time.monotonic() - t0 < 120:  # this session's first write
            path = ckdir / ck.CHECKPOINT_FILE
            if path.exists() and path.stat().st_mtime_ns != before:
                break
            time.sleep(0.01)
        time.sleep(float(rng.uniform(0.0, 0.6)))
        if r.poll() is not None:  # finished all 40 passes: check it, start another render
            _, err = r.communicate()
            assert r.returncode == 0, err
            check_final(out, states, 40)
            rounds += 1
            ckdir = work / f"{name}-{rounds}"
            continue
        r.send_signal(signal.SIGKILL)
        r.communicate(timeout=60)
        done += 1
        mid_write += bool(temporaries(ckdir))
        assert 0 < check_saved(ckdir, states) <= 40
    print(f"\n{done} kills ({mid_write} during a checkpoint write), {rounds} renders "
          f"finished between kills")
    assert done >= min(kills, 2)
    started = (ckdir / ck.CHECKPOINT_FILE).exists()
    flag = ["--resume", ckdir] if started else ["--checkpoint", ckdir]
    r = cli(work, [*ARGS, "--passes", "40", "--out", f"{ckdir.name}.npz", *flag])
    _, err = r.communicate(timeout=600)
    assert r.returncode == 0, err
    assert temporaries(ckdir) == []
    check_final(work / f"{ckdir.name}.npz", states, 40)


def test_random_kills(work, uninterrupted):
    states, _ = uninterrupted
    kill_loop(work, states, kills=2, seconds=40, name="loop-fast")


@pytest.mark.slow
def test_random_kills_long(work, uninterrupted):
    states, _ = uninterrupted
    kill_loop(work, states, kills=25, seconds=300, name="loop-slow")
