"""Bad input to ``python app.py render``: one clear line, exit code 2, nothing written.

A corpus of malformed scenes (one or more per rule of SCENES.md "Required keys and
defaults", plus unreadable files and meshes) and malformed command lines (flags, estimator
names, ``-short`` misuse, MIS specs, budgets, outputs, checkpoints). Every case must end with
exactly one stderr line ``psurf: error: ...`` that names the file or flag, the key and the
problem, exit code 2, no traceback, and leave the working directory exactly as it was (no
output, no temporary file, no checkpoint directory).

The corpus runs in-process through ``app.main(argv)`` (fast); a handful of cases also run
as real subprocesses to prove the exit status and the absence of a traceback end to end.
"""

from __future__ import annotations

import copy
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest

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


def _val(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, int):
        return str(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(_val(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {_val(x)}" for k, x in v.items()) + " }"
    raise TypeError(v)


def dumps(doc: dict) -> str:
    """Tiny TOML writer: top-level scalars, [tables] and [[arrays of tables]]."""
    def aot(v):
        return isinstance(v, list) and v and all(isinstance(x, dict) for x in v)

    lines = [f"{k} = {_val(v)}" for k, v in doc.items() if not (isinstance(v, dict) or aot(v))]
    for k, v in doc.items():
        if isinstance(v, dict):
            lines += ["", f"[{k}]"] + [f"{kk} = {_val(vv)}" for kk, vv in v.items()]
        elif aot(v):
            for item in v:
                lines += ["", f"[[{k}]]"] + [f"{kk} = {_val(vv)}" for kk, vv in item.items()]
    return "\n".join(lines) + "\n"


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


DELETE = object()


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
    return (("lights",), [kw])


def _mesh_file(name: str, text: bytes):
    def make(tmp: Path) -> str:
        (tmp / "meshes").mkdir(exist_ok=True)
        (tmp / "meshes" / name).write_bytes(text)
        return f"meshes/{name}"

    return make


TRI = {"radiance": [1.0, 1.0, 1.0]}

#: name -> (scene builder (tmp -> TOML text), needles that must all be in the message).
#: The scene file is always "scene.toml"; its name is checked in every message too.
SCENES = {
    # -- sections and keys
    "missing camera section": (edit((("camera",), DELETE)), ["camera", "missing required"]),
    "missing medium section": (edit((("medium",), DELETE)), ["medium", "missing required"]),
    "missing lights": (edit((("lights",), DELETE)), ["lights", "missing required"]),
    "empty lights": (edit((("lights",), [])), ["lights"]),
    "unknown section": (edit((("lighting",), {"x": 1})), ["lighting", "unknown key"]),
    "missing camera.fov_y": (edit((("camera", "fov_y"), DELETE)),
                             ["camera.fov_y", "missing required"]),
    "typo camera.fov": (edit((("camera", "fov"), 40.0)), ["camera.fov", "unknown key"]),
    "missing medium.sigma_a": (edit((("medium", "sigma_a"), DELETE)),
                               ["medium.sigma_a", "missing required"]),
    "unknown render key": (edit((("render",), {"max_scatters": 3})),
                           ["render.max_scatters", "unknown key"]),
    "occluders not an array": (edit((("occluders",), 3)), ["occluders", "array of tables"]),
    # -- camera
    "resolution 0": (edit((("camera", "resolution"), [0, 12])), ["camera.resolution", ">= 1"]),
    "resolution of strings": (edit((("camera", "resolution"), ["16", 12])),
                              ["camera.resolution", "integers"]),
    "resolution of floats": (edit((("camera", "resolution"), [16.0, 12.0])),
                             ["camera.resolution", "integers"]),
    "fov_y 180": (edit((("camera", "fov_y"), 180.0)), ["camera.fov_y", "(0, 180)"]),
    "fov_y 0": (edit((("camera", "fov_y"), 0)), ["camera.fov_y", "(0, 180)"]),
    "up parallel to view": (edit((("camera", "up"), [0.0, 0.0, 2.0])), ["camera.up", "parallel"]),
    "up zero": (edit((("camera", "up"), [0.0, 0.0, 0.0])), ["camera.up", "zero"]),
    "look_at equals position": (edit((("camera", "look_at"), [0.0, 0.0, -4.0])),
                                ["camera.look_at", "must differ"]),
    "position of 2 numbers": (edit((("camera", "position"), [0.0, 0.0])),
                              ["camera.position", "3 finite numbers"]),
    "camera inside a sphere occluder": (
        edit((("occluders",), [{"type": "sphere", "center": [0.0, 0.0, -4.0], "radius": 0.5}])),
        ["camera.position", "inside occluders[0]"]),
    # -- medium
    "sigma_s NaN": (edit((("medium", "sigma_s"), float("nan"))), ["medium.sigma_s", "finite"]),
    "sigma_s inf": (edit((("medium", "sigma_s"), float("inf"))), ["medium.sigma_s", "finite"]),
    "sigma_a negative": (edit((("medium", "sigma_a"), -0.2)), ["medium.sigma_a", ">= 0"]),
    "sigma_s a string": (edit((("medium", "sigma_s"), "0.8")), ["medium.sigma_s", "number"]),
    "sigma_s a boolean": (edit((("medium", "sigma_s"), True)), ["medium.sigma_s", "number"]),
    "sigma_t zero": (edit((("medium", "sigma_s"), 0.0), (("medium", "sigma_a"), 0)),
                     ["medium", "sigma_t", "> 0"]),
    "g = 1": (edit((("medium", "phase"), {"type": "hg", "g": 1.0})),
              ["medium.phase.g", "|g| must be < 1"]),
    "g = -1.5": (edit((("medium", "phase"), {"type": "hg", "g": -1.5})),
                 ["medium.phase.g", "|g| must be < 1"]),
    "hg without g": (edit((("medium", "phase"), {"type": "hg"})),
                     ["medium.phase.g", "missing required"]),
    "unknown phase": (edit((("medium", "phase"), {"type": "rayleigh"})),
                      ["medium.phase.type", "unknown phase type"]),
    "isotropic with g": (edit((("medium", "phase"), {"type": "isotropic", "g": 0.3})),
                         ["medium.phase.g", "unknown key"]),
    "inverted box": (edit((("medium", "bounds_max"), [1.0, -2.0, 1.0])),
                     ["medium.bounds_max", "> bounds_min"]),
    # -- lights
    "unknown light type": (edit(light(type="spot", position=[0.0, 0.0, 0.0])),
                           ["lights[0].type", "unknown light type"]),
    "point light without intensity": (edit(light(type="point", position=[0.0, 0.0, 0.0])),
                                      ["lights[0].intensity", "missing required"]),
    "intensity all zero": (edit((("lights", 0, "intensity"), [0.0, 0.0, 0.0])),
                           ["lights[0].intensity", "all zero"]),
    "intensity negative": (edit((("lights", 0, "intensity"), [1.0, -1.0, 1.0])),
                           ["lights[0].intensity", ">= 0"]),
    "radiance inf": (edit(light(**{**AREA_LIGHT, "radiance": [1.0, float("inf"), 1.0]})),
                     ["lights[0].radiance", "finite"]),
    "point axis zero": (edit((("lights", 0, "axis"), [0.0, 0.0, 0.0])),
                        ["lights[0].axis", "zero vector"]),
    "zero-area light": (edit(light(**{**AREA_LIGHT, "edge_v": [1.2, 0.0, 0.0]})),
                        ["lights[0]", "zero-area"]),
    "light outside the box": (edit((("lights", 0, "position"), [0.0, 1.5, 0.0])),
                              ["lights[0].position", "outside the medium box"]),
    "area light sticking out of the box": (
        edit(light(**{**AREA_LIGHT, "corner": [0.7, 0.95, -0.3]})),
        ["lights[0]", "outside the medium box"]),
    "light inside an occluder": (
        edit((("occluders",), [{"type": "box", "min": [0.0, 0.0, 0.0], "max": [0.5, 0.5, 0.5]}])),
        ["lights[0].position", "inside occluders[0]"]),
    # -- occluders
    "sphere radius 0": (edit((("occluders",), [{"type": "sphere", "center": [0.0, -0.5, 0.0],
                                                "radius": 0}])),
                        ["occluders[0].radius", "> 0"]),
    "box max below min": (edit((("occluders",), [{"type": "box", "min": [0.0, 0.0, 0.0],
                                                  "max": [0.5, -0.5, 0.5]}])),
                          ["occluders[0].max", "> min"]),
    # -- meshes
    "mesh missing": (edit(light(type="mesh", mesh="meshes/nope.obj", **TRI)),
                     ["lights[0].mesh", "not found", "nope.obj"]),
    "mesh path not a string": (edit(light(type="mesh", mesh=3, **TRI)),
                               ["lights[0].mesh", "file path string"]),
    "mesh unreadable": (edit(light(type="mesh", mesh=_mesh_file("bad.xyz", b"hello\n"), **TRI)),
                        ["lights[0].mesh", "cannot load mesh file", "bad.xyz"]),
    "mesh of garbage": (edit(light(type="mesh", mesh=_mesh_file("junk.obj", b"\x00\xffjunk"),
                                   **TRI)),
                        ["lights[0].mesh", "junk.obj", "no triangles"]),
    "mesh empty": (edit(light(type="mesh", mesh=_mesh_file("empty.obj", b"v 0 0 0\nv 1 0 0\n"),
                              **TRI)),
                   ["lights[0].mesh", "empty.obj", "no triangles"]),
    "mesh of zero-area triangles": (
        edit(light(type="mesh", mesh=_mesh_file("flat.obj", b"v 0 0 0\nv .5 0 0\nv .9 0 0\n"
                                                b"f 1 2 3\n"), **TRI)),
        ["lights[0].mesh", "flat.obj", "non-zero area"]),
    "mesh scale negative": (
        edit(light(type="mesh", mesh=_mesh_file("ok.obj", b"v 0 0 0\nv .5 0 0\nv 0 .5 0\n"
                                                b"f 1 2 3\n"),
                   transform={"scale": -1.0}, **TRI)),
        ["lights[0].transform.scale", "> 0"]),
    "mesh occluder missing": (edit((("occluders",), [{"type": "mesh", "mesh": "gone.ply"}])),
                              ["occluders[0].mesh", "not found", "gone.ply"]),
    # -- render
    "min_scatter 0": (edit((("render",), {"min_scatter": 0})), ["render.min_scatter", ">= 1"]),
    "min_scatter 1.5": (edit((("render",), {"min_scatter": 1.5})),
                        ["render.min_scatter", "integer"]),
    "max_scatter below min": (edit((("render",), {"min_scatter": 3, "max_scatter": 2})),
                              ["render.max_scatter", ">= min_scatter"]),
    # -- not a scene at all
    "invalid TOML": (lambda tmp: "[camera\nposition = [0, 0]\n", ["invalid TOML"]),
    "not UTF-8": (lambda tmp: b"\xff\xfe[camera]\n", ["cannot read file", "utf-8"]),
}


def _write_scene(tmp: Path, build) -> Path:
    text = build(tmp)
    p = tmp / "scene.toml"
    if isinstance(text, bytes):
        p.write_bytes(text)
    else:
        p.write_text(text)
    return p


# --------------------------------------------------------------------------- command lines

def _ck_with(tmp: Path, content: bytes) -> str:
    (tmp / "ck").mkdir()
    (tmp / "ck" / "checkpoint.npz").write_bytes(content)
    return "ck"


def _file(tmp: Path, name: str) -> str:
    (tmp / name).write_text("x")
    return name


#: name -> (extra argv (list, or tmp -> list), needles). The scene is AREA unless the argv
#: names another; ``--out out.npz --png out.png`` are always added (unless given).
ARGS = {
    "unknown estimator": (["--estimator", "nosuch"], ["--estimator", "unknown estimator",
                                                      "nosuch"]),
    "empty estimator": (["--estimator", ""], ["--estimator", "unknown estimator"]),
    "-short on planes": (["--estimator", "planes-short"], ["--estimator", "'planes'",
                                                           "no short variant"]),
    "-short on sphere": (["--estimator", "sphere-short"], ["--estimator", "'sphere'",
                                                           "no short variant"]),
    "-short on a kernel baseline": (["--estimator", "points-short"],
                                    ["--estimator", "'points'", "no short variant"]),
    "-short on the reference": (["--estimator", "reference-short"],
                                ["--estimator", "reference-short"]),
    "-short on a preset": (["--estimator", "paper-full-short"],
                           ["--estimator", "paper-full", "no short variant"]),
    "MIS without members": (["--estimator", "mis:"], ["--estimator", "malformed MIS spec"]),
    "MIS trailing plus": (["--estimator", "mis:cone+"], ["--estimator", "malformed MIS spec"]),
    "MIS member twice": (["--estimator", "mis:cone+cone"], ["--estimator", "listed twice"]),
    "MIS of a kernel baseline": (["--estimator", "mis:points+cone"],
                                 ["--estimator", "'points'", "kernel baseline"]),
    "MIS of a preset": (["--estimator", "mis:paper-single+cone"], ["--estimator", "preset"]),
    "MIS unknown member": (["--estimator", "mis:cone+nosuch"], ["--estimator", "nosuch"]),
    "MIS bad -short member": (["--estimator", "mis:cone+sphere-short"],
                              ["--estimator", "'sphere'", "no short variant"]),
    "MIS unknown weighting": (["--estimator", "mis-pow:cone+disk"],
                              ["--estimator", "unknown estimator"]),
    "estimator for no light": (["--estimator", "ss-plane-uv", POINT],
                               ["point.toml", "ss-plane-uv", "applies to no light"]),
    "missing estimator": (["--out", "out.npz"], ["--estimator", "required"]),
    "missing out": (["--estimator", "planes", "--png", "out.png", "--out"], ["--out"]),
    "negative time": (["--estimator", "planes", "--time", "-1"], ["--time", "> 0", "-1"]),
    "zero time": (["--estimator", "planes", "--time", "0"], ["--time", "> 0"]),
    "NaN time": (["--estimator", "planes", "--time", "nan"], ["--time", "finite"]),
    "negative photons": (["--estimator", "planes", "--photons", "-5"], ["--photons", "> 0"]),
    "zero photons": (["--estimator", "planes", "--photons", "0"], ["--photons", "> 0"]),
    "photons not a number": (["--estimator", "planes", "--photons", "lots"],
                             ["--photons", "integer", "lots"]),
    "zero spp": (["--estimator", "planes", "--spp", "0"], ["--spp", "> 0"]),
    "zero passes": (["--estimator", "planes", "--passes", "0"], ["--passes", "> 0"]),
    "fractional passes": (["--estimator", "planes", "--passes", "2.5"], ["--passes", "integer"]),
    "negative seed": (["--estimator", "planes", "--seed", "-1"], ["--seed", ">= 0"]),
    "passes and time": (["--estimator", "planes", "--passes", "2", "--time", "1"],
                        ["--time", "not allowed with"]),
    "negative radius": (["--estimator", "points", "--radius", "-1"], ["--radius", "> 0"]),
    "radius shrink 0": (["--estimator", "points", "--radius-shrink", "0"],
                        ["--radius-shrink", "(0, 1]"]),
    "radius shrink 1.5": (["--estimator", "points", "--radius-shrink", "1.5"],
                          ["--radius-shrink", "(0, 1]"]),
    "zero memory budget": (["--estimator", "planes", "--memory-budget", "0"],
                           ["--memory-budget", "> 0"]),
    "min-scatter 0": (["--estimator", "planes", "--min-scatter", "0"], ["--min-scatter", ">= 1"]),
    "max-scatter -2": (["--estimator", "planes", "--max-scatter", "-2"], ["--max-scatter"]),
    "inverted scatter range": (["--estimator", "planes", "--min-scatter", "3", "--max-scatter",
                                "2"], ["--max-scatter", ">= min_scatter (3)"]),
    "unknown flag": (["--estimator", "planes", "--bogus"], ["--bogus", "unrecognized"]),
    "abbreviated flag": (["--estimator", "planes", "--phot", "10"], ["--phot"]),
    "out dir missing": (["--estimator", "planes", "--out", "nodir/x.npz"],
                        ["--out", "nodir", "does not exist"]),
    "out is a directory": (lambda t: ["--estimator", "planes", "--out", str(t)],
                           ["--out", "is a directory"]),
    "png dir missing": (["--estimator", "planes", "--png", "nodir/x.png"],
                        ["--png", "does not exist"]),
    "checkpoint-every negative": (["--estimator", "planes", "--checkpoint", "ck",
                                   "--checkpoint-every", "-5"], ["--checkpoint-every", ">= 0"]),
    "checkpoint-every alone": (["--estimator", "planes", "--checkpoint-every", "5"],
                               ["--checkpoint-every", "needs --checkpoint"]),
    "checkpoint is a file": (lambda t: ["--estimator", "planes", "--checkpoint",
                                        _file(t, "notadir")],
                             ["--checkpoint", "notadir", "not a directory"]),
    "checkpoint parent missing": (["--estimator", "planes", "--checkpoint", "a/b/ck"],
                                  ["--checkpoint", "a/b/ck", "parent directory does not exist"]),
    "checkpoint empty path": (["--estimator", "planes", "--checkpoint", ""], ["--checkpoint"]),
    "resume missing dir": (["--estimator", "planes", "--resume", "nock"],
                           ["--resume", "nock", "no such directory"]),
    "resume without checkpoint": (lambda t: ["--estimator", "planes", "--resume",
                                             (t / "ck").mkdir() or "ck"],
                                  ["--resume", "ck", "no checkpoint"]),
    "resume a corrupt checkpoint": (lambda t: ["--estimator", "planes", "--resume",
                                               _ck_with(t, b"PK\x03\x04 truncated")],
                                    ["--resume", "checkpoint.npz", "unreadable checkpoint"]),
}


def _argv(tmp: Path, spec) -> list[str]:
    extra = spec(tmp) if callable(spec) else list(spec)
    extra = [str(a) for a in extra]
    scene = [a for a in extra if a.endswith(".toml")]
    extra = [a for a in extra if not a.endswith(".toml")]
    outs = [] if "--out" in extra else ["--out", "out.npz"]
    outs += [] if "--png" in extra else ["--png", "out.png"]
    return ["render", *(scene or [str(AREA)]), *extra, *outs]


def _tree(tmp: Path) -> set:
    return {(str(p.relative_to(tmp)), p.stat().st_size if p.is_file() else -1)
            for p in tmp.rglob("*")}


def _one_error_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("psurf: error: "), err
    assert "Traceback" not in err
    return lines[0]


@pytest.fixture
def work(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    return tmp_path


# --------------------------------------------------------------------------- in-process corpus


def test_corpus_is_large_enough():
    assert len(SCENES) + len(ARGS) >= 30
    assert len(SCENES) >= 30  # SCENES.md rules, each at least once


@pytest.mark.parametrize("case", sorted(SCENES))
def test_bad_scene(case, work, capsys):
    build, needles = SCENES[case]
    scene = _write_scene(work, build)
    before = _tree(work)
    code = app.main(["render", str(scene), "--estimator", "planes", "--passes", "1",
                     "--out", "out.npz", "--png", "out.png", "--checkpoint", "ck"])
    out, err = capsys.readouterr()
    assert code == 2, (case, out, err)
    line = _one_error_line(err)
    for needle in [str(scene), *needles]:
        assert needle in line, (case, needle, line)
    assert _tree(work) == before  # no output, no temporary file, no checkpoint directory


@pytest.mark.parametrize("case", sorted(ARGS))
def test_bad_command_line(case, work, capsys):
    spec, needles = ARGS[case]
    argv = _argv(work, spec)
    before = _tree(work)
    code = app.main(argv)
    out, err = capsys.readouterr()
    assert code == 2, (case, argv, out, err)
    line = _one_error_line(err)
    for needle in needles:
        assert needle in line, (case, needle, line)
    assert _tree(work) == before


def test_scene_file_missing_or_a_directory(work, capsys):
    for target, needle in ((work / "nope.toml", "file not found"),
                           (work, "cannot read file")):
        code = app.main(["render", str(target), "--estimator", "planes", "--out", "o.npz"])
        line = _one_error_line(capsys.readouterr().err)
        assert code == 2 and str(target) in line and needle in line, line
    assert list(work.iterdir()) == []


# --------------------------------------------------------------------------- subprocesses

SUBPROCESS_CASES = {
    "scene rule": ("sigma_a negative", None),
    "mesh": ("mesh unreadable", None),
    "estimator": (None, "-short on sphere"),
    "MIS spec": (None, "MIS of a kernel baseline"),
    "budget": (None, "negative time"),
    "checkpoint": (None, "resume a corrupt checkpoint"),
}


@pytest.mark.parametrize("which", sorted(SUBPROCESS_CASES))
def test_subprocess_exit_code_2_without_traceback(which, tmp_path):
    scene_case, args_case = SUBPROCESS_CASES[which]
    if scene_case is not None:
        build, needles = SCENES[scene_case]
        scene = _write_scene(tmp_path, build)
        argv = ["render", str(scene), "--estimator", "planes", "--out", "out.npz"]
        needles = [str(scene), *needles]
    else:
        spec, needles = ARGS[args_case]
        argv = _argv(tmp_path, spec)
    before = _tree(tmp_path)
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    r = subprocess.run([sys.executable, str(ROOT / "app.py"), *argv], cwd=tmp_path, env=env,
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2, (r.stdout, r.stderr)
    assert r.stdout == ""
    line = _one_error_line(r.stderr)
    for needle in needles:
        assert needle in line, (needle, line)
    assert _tree(tmp_path) == before
