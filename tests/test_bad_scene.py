"""Bad scene files given to ``python app.py render``: one clear line, exit code 2, nothing
written (the check: ``bad_input_support.py``).

One case or more per rule of SCENES.md "Required keys and defaults" (sections and keys,
camera, medium, lights, occluders, render), files that are not scenes at all, and a scene
path that is missing or a directory. Meshes have their own corpus (``test_bad_mesh.py``).
"""

from __future__ import annotations

import pytest
from bad_input_support import (
    AREA_LIGHT,
    DELETE,
    assert_rejected,
    assert_rejected_by_subprocess,
    bad_scene_argv,
    edit,
    light,
    one_error_line,
    write_scene,
)

import app

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


def test_corpus_is_large_enough():
    assert len(SCENES) >= 30  # SCENES.md rules, each at least once


@pytest.mark.parametrize("case", sorted(SCENES))
def test_bad_scene(case, tmp_path, capsys):
    build, needles = SCENES[case]
    scene = write_scene(tmp_path, build)
    assert_rejected(bad_scene_argv(scene), [str(scene), *needles], tmp_path, capsys)


def test_scene_file_missing_or_a_directory(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    for target, needle in ((tmp_path / "nope.toml", "file not found"),
                           (tmp_path, "cannot read file")):
        code = app.main(["render", str(target), "--estimator", "planes", "--out", "o.npz"])
        line = one_error_line(capsys.readouterr().err)
        assert code == 2 and str(target) in line and needle in line, line
    assert list(tmp_path.iterdir()) == []


def test_subprocess_exit_code_2_without_traceback(tmp_path):
    build, needles = SCENES["sigma_a negative"]
    scene = write_scene(tmp_path, build)
    assert_rejected_by_subprocess(["render", str(scene), "--estimator", "planes", "--out",
                                   "out.npz"], [str(scene), *needles], tmp_path)
