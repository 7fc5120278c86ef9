"""The bad-input corpus's machinery (``test_bad_*.py``): scenes as dicts edited one key at a
time, command lines, and the one check every case must pass.

Every case of ``python app.py render`` with bad input must end with exactly one stderr line
``psurf: error: ...`` that names the file or flag, the key and the problem, exit code 2, no
traceback, and leave the working directory exactly as it was (no output, no temporary file,
no checkpoint directory). The corpus runs in-process through ``app.main(argv)`` (fast)
(:func:`assert_rejected`); a handful of cases also run as real subprocesses to prove the exit
status and the absence of a traceback end to end (:func:`assert_rejected_by_subprocess`).
"""

from __future__ import annotations

import contextlib
import copy
from pathlib import Path

from app_support import run_app
from toml_writer import dumps

import app

ROOT = Path(__file__).resolve().parent.parent
AREA = ROOT / "scenes" / "area.toml"
POINT = ROOT / "scenes" / "point.toml"

# --------------------------------------------------------------------------- scenes as dicts

BASE = {
    "camera": {"position": [0.0, 0.0, -4.0], "look_at": [0.0, 0.0, 0.0], "up": [0.0, 1.0, 0.0],
               "fov_y": 40.0, "resolution": [16, 12]},
    "medium": {"bounds_min": [-1.0, -1.0, -1.0], "bounds_max": [1.0, 1.0, 1.0],
               "sigma_s": 0.8, "sigma_a": 0.2, "phase": {"type": "isotropic"}},
    "lights": [{"type": "point", "position": [0.3, 0.4, 0.1], "intensity": [4.0, 4.0, 4.0]}],
}
AREA_LIGHT = {"type": "area", "corner": [-0.3, 0.95, -0.3], "edge_u": [0.6, 0.0, 0.0],
              "edge_v": [0.0, 0.0, 0.6], "radiance": [3.0, 3.0, 3.0]}

#: The value that removes a key (:func:`edit`).
DELETE = object()


def edit(*changes):
    """A scene-building function: ``(path, value)`` pairs applied to a copy of BASE.

    ``path`` is a tuple of keys/indices; value ``DELETE`` removes the key.
    """
    def build(tmp: Path) -> str:
        doc = copy.deepcopy(BASE)
        for path, value in changes:
            value = _resolve(value, tmp)
            node = doc
            for k in path[:-1]:
                node = node[k]
            if value is DELETE:
                del node[path[-1]]
            else:
                node[path[-1]] = value
        return dumps(doc)

    return build


def _resolve(v, tmp: Path):
    """Call the file-making functions nested in a value (they return the path to use)."""
    if v is DELETE:
        return v
    if callable(v):
        return v(tmp)
    if isinstance(v, dict):
        return {k: _resolve(x, tmp) for k, x in v.items()}
    if isinstance(v, list):
        return [_resolve(x, tmp) for x in v]
    return v


def light(**kw):
    """The change that makes the scene's only light ``kw`` (for :func:`edit`)."""
    return (("lights",), [kw])


def write_scene(tmp: Path, build) -> Path:
    """``tmp/scene.toml`` from a scene builder (tmp -> TOML text or bytes)."""
    text = build(tmp)
    p = tmp / "scene.toml"
    if isinstance(text, bytes):
        p.write_bytes(text)
    else:
        p.write_text(text)
    return p


# --------------------------------------------------------------------------- command lines

def render_argv(tmp: Path, spec) -> list[str]:
    """``render`` argv from extra flags (a list, or tmp -> list): the scene is AREA unless the
    flags name another ``.toml``; ``--out out.npz --png out.png`` are added unless given."""
    extra = spec(tmp) if callable(spec) else list(spec)
    extra = [str(a) for a in extra]
    scene = [a for a in extra if a.endswith(".toml")]
    extra = [a for a in extra if not a.endswith(".toml")]
    outs = [] if "--out" in extra else ["--out", "out.npz"]
    outs += [] if "--png" in extra else ["--png", "out.png"]
    return ["render", *(scene or [str(AREA)]), *extra, *outs]


def bad_scene_argv(scene: Path) -> list[str]:
    """``render`` argv of a scene-file case: every output flag given, none may be written."""
    return ["render", str(scene), "--estimator", "planes", "--passes", "1",
            "--out", "out.npz", "--png", "out.png", "--checkpoint", "ck"]


# --------------------------------------------------------------------------- the check

def tree(tmp: Path) -> set:
    """Every path below ``tmp`` with its size (-1: a directory)."""
    return {(str(p.relative_to(tmp)), p.stat().st_size if p.is_file() else -1)
            for p in tmp.rglob("*")}


def one_error_line(err: str) -> str:
    """The only stderr line, which must be ``psurf: error: ...`` (no traceback)."""
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("psurf: error: "), err
    assert "Traceback" not in err
    return lines[0]


def assert_rejected(argv: list[str], needles, work: Path, capsys) -> None:
    """``app.main(argv)`` run in the directory ``work``: exit 2, one error line holding every
    needle, and the directory exactly as before."""
    before = tree(work)
    with contextlib.chdir(work):  # relative outputs and checkpoints land in work
        code = app.main(argv)
    out, err = capsys.readouterr()
    assert code == 2, (argv, out, err)
    line = one_error_line(err)
    for needle in needles:
        assert needle in line, (needle, line)
    assert tree(work) == before  # no output, no temporary file, no checkpoint directory


def assert_rejected_by_subprocess(argv: list[str], needles, tmp: Path) -> None:
    """As :func:`assert_rejected`, but ``python app.py`` in a subprocess (no display)."""
    before = tree(tmp)
    r = run_app(*argv, cwd=tmp)
    assert r.returncode == 2, (r.stdout, r.stderr)
    assert r.stdout == ""
    line = one_error_line(r.stderr)
    for needle in needles:
        assert needle in line, (needle, line)
    assert tree(tmp) == before
