"""Bad meshes in scene files given to ``python app.py render`` (a mesh light's or a mesh
occluder's file: missing, not a path, unreadable, garbage, empty, of zero-area triangles, a
bad transform): one clear line naming the file, exit code 2, nothing written (the check:
``bad_input_support.py``)."""

from __future__ import annotations

from pathlib import Path

import pytest
from bad_input_support import (
    assert_rejected,
    assert_rejected_by_subprocess,
    bad_scene_argv,
    edit,
    light,
    write_scene,
)

#: The emission of every mesh light here.
TRI = {"radiance": [1.0, 1.0, 1.0]}


def _mesh_file(name: str, text: bytes):
    """A value for :func:`edit` that writes ``meshes/<name>`` and names it."""
    def make(tmp: Path) -> str:
        (tmp / "meshes").mkdir(exist_ok=True)
        (tmp / "meshes" / name).write_bytes(text)
        return f"meshes/{name}"

    return make


#: name -> (scene builder (tmp -> TOML text), needles that must all be in the message).
MESHES = {
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
}


@pytest.mark.parametrize("case", sorted(MESHES))
def test_bad_mesh(case, tmp_path, capsys):
    build, needles = MESHES[case]
    scene = write_scene(tmp_path, build)
    assert_rejected(bad_scene_argv(scene), [str(scene), *needles], tmp_path, capsys)


def test_subprocess_exit_code_2_without_traceback(tmp_path):
    build, needles = MESHES["mesh unreadable"]
    scene = write_scene(tmp_path, build)
    assert_rejected_by_subprocess(["render", str(scene), "--estimator", "planes", "--out",
                                   "out.npz"], [str(scene), *needles], tmp_path)
