"""Scene files: the bundled scenes load, defaults and derived values, and bad input (SCENES.md)."""

from __future__ import annotations

import copy
import shutil
from pathlib import Path

import numpy as np
import pytest
import trimesh
from toml_writer import dumps

from psurf_core.scene import (
    AreaLight,
    BoxOccluder,
    MeshLight,
    Phase,
    PointLight,
    SceneError,
    SphereOccluder,
)
from psurf_core.scene_io import load_scene, parse_scene

ROOT = Path(__file__).resolve().parent.parent
SCENES = ROOT / "scenes"
BLOB = SCENES / "meshes" / "blob.obj"
BUNDLED = sorted(SCENES.glob("*.toml"))


BASE = {
    "camera": {
        "position": [0.0, 0.0, -4.0],
        "look_at": [0.0, 0.0, 0.0],
        "up": [0.0, 1.0, 0.0],
        "fov_y": 40.0,
        "resolution": [64, 48],
    },
    "medium": {
        "bounds_min": [-1.0, -1.0, -1.0],
        "bounds_max": [1.0, 1.0, 1.0],
        "sigma_s": 0.8,
        "sigma_a": 0.2,
        "phase": {"type": "hg", "g": 0.3},
    },
    "lights": [
        {"type": "point", "position": [0.3, 0.4, 0.1], "intensity": [4.0, 4.0, 4.0]},
        {
            "type": "area",
            "corner": [-0.3, 0.95, -0.3],
            "edge_u": [0.6, 0.0, 0.0],
            "edge_v": [0.0, 0.0, 0.6],
            "radiance": [3.0, 3.0, 3.0],
        },
        {
            "type": "mesh",
            "mesh": "meshes/blob.obj",
            "radiance": [2.0, 2.0, 2.0],
            "transform": {"scale": 1.0, "rotate_deg": [0.0, 0.0, 0.0],
                          "translate": [0.0, -0.5, 0.0]},
        },
    ],
    "render": {"min_scatter": 1, "max_scatter": -1},
}


@pytest.fixture
def write(tmp_path):
    """``write(doc, name="bad.toml") -> Path``; blob.obj is available as meshes/blob.obj."""
    (tmp_path / "meshes").mkdir()
    shutil.copy(BLOB, tmp_path / "meshes" / "blob.obj")

    def _write(doc: dict, name: str = "bad.toml") -> Path:
        p = tmp_path / name
        p.write_text(dumps(doc))
        return p

    return _write


def base() -> dict:
    return copy.deepcopy(BASE)


# --------------------------------------------------------------------------- valid scenes


def test_bundled_scenes_exist():
    names = {p.name for p in BUNDLED}
    assert {"point.toml", "area.toml", "area_occluder.toml", "mesh_light.toml",
            "hg.toml"} <= names


@pytest.mark.parametrize("path", BUNDLED, ids=lambda p: p.name)
def test_bundled_scene_loads(path):
    s = load_scene(path)
    assert s.path == str(path)
    # 64x48 (fast tests and studies), but the lecture showcase: >= 160x120 (issue 13)
    if path.name == "showcase.toml":
        assert s.camera.width >= 160 and s.camera.height >= 120
    else:
        assert (s.camera.width, s.camera.height) == (64, 48)
    for arr in (s.camera.position, s.camera.look_at, s.camera.up,
                s.medium.bounds_min, s.medium.bounds_max):
        assert arr.dtype == np.float64 and arr.shape == (3,)
    assert s.medium.sigma_t > 0 and len(s.lights) >= 1
    assert np.all(s.light_pmf > 0) and np.isclose(s.light_pmf.sum(), 1.0)
    lo, hi = s.medium.bounds_min, s.medium.bounds_max
    for lt in s.lights:
        if isinstance(lt, MeshLight):
            pts = lt.triangles.reshape(-1, 3)
            assert lt.triangles.dtype == np.float64 and lt.triangles.shape[1:] == (3, 3)
        elif isinstance(lt, AreaLight):
            pts = np.stack([lt.corner, lt.corner + lt.edge_u + lt.edge_v])
        else:
            pts = lt.position[None]
        assert np.all((pts >= lo) & (pts <= hi))


def test_area_scene_defaults_and_derived_values():
    s = load_scene(SCENES / "area.toml")
    (light,) = s.lights
    assert isinstance(light, AreaLight)
    np.testing.assert_allclose(light.normal, [0.0, -1.0, 0.0])
    assert light.area == pytest.approx(0.36)
    assert s.occluders == () and (s.min_scatter, s.max_scatter) == (1, -1)
    assert s.medium.phase == Phase("isotropic", 0.0)
    assert s.medium.sigma_s == 0.8 and s.medium.sigma_a == 0.2


def test_point_light_axis_default_and_normalized(write):
    doc = base()
    del doc["render"]
    doc["lights"] = [doc["lights"][0], dict(doc["lights"][0], axis=[2.0, 2.0, 0.0])]
    s = load_scene(write(doc, "ok.toml"))
    a, b = s.lights
    assert isinstance(a, PointLight)
    np.testing.assert_allclose(a.axis, [0.0, 1.0, 0.0])
    np.testing.assert_allclose(b.axis, [np.sqrt(0.5), np.sqrt(0.5), 0.0])
    assert (s.min_scatter, s.max_scatter) == (1, -1)
    assert s.medium.phase == Phase("hg", 0.3)


def test_occluders_parse(write):
    doc = base()
    doc["occluders"] = [
        {"type": "sphere", "center": [0.5, -0.5, 0.5], "radius": 0.2},
        {"type": "box", "min": [-0.9, -0.9, -0.9], "max": [-0.7, -0.7, -0.7]},
        {"type": "mesh", "mesh": "meshes/blob.obj", "transform": {"translate": [0.6, 0.6, 0.6]}},
    ]
    s = load_scene(write(doc, "ok.toml"))
    sph, box, mesh = s.occluders
    assert isinstance(sph, SphereOccluder) and sph.radius == 0.2
    assert isinstance(box, BoxOccluder)
    assert mesh.triangles.shape == (320, 3, 3)


def test_light_on_box_boundary_is_allowed(write):
    doc = base()
    doc["lights"][0]["position"] = [1.0, -1.0, 0.0]
    load_scene(write(doc, "ok.toml"))


def _write_obj(path: Path, verts, faces) -> None:
    text = "".join(f"v {x} {y} {z}\n" for x, y, z in verts)
    text += "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in faces)
    path.write_text(text)


def test_mesh_transform_winding_and_degenerate_triangles(write, tmp_path):
    verts = [(0, 0, 0), (0.2, 0, 0), (0, 0.1, 0), (0.4, 0, 0)]
    # the second triangle is collinear (zero area) and must be dropped
    _write_obj(tmp_path / "meshes" / "tri.obj", verts, [(0, 1, 2), (0, 1, 3)])
    doc = base()
    doc["lights"][2] = {
        "type": "mesh", "mesh": "meshes/tri.obj", "radiance": [1.0, 1.0, 1.0],
        "transform": {"scale": [2.0, 1.0, 1.0], "rotate_deg": [0.0, 0.0, 90.0],
                      "translate": [0.1, 0.2, 0.3]},
    }
    light = load_scene(write(doc, "ok.toml")).lights[2]
    assert light.triangles.shape == (1, 3, 3) and light.triangles.dtype == np.float64
    # scale x by 2 -> (0.4, 0, 0); rotate 90 deg about z -> (0, 0.4, 0); then translate
    expected = np.array([[0, 0, 0], [0, 0.4, 0], [-0.1, 0, 0]]) + [0.1, 0.2, 0.3]
    np.testing.assert_allclose(light.triangles[0], expected, atol=1e-12)
    np.testing.assert_allclose(light.normals[0], [0, 0, 1], atol=1e-12)  # CCW kept
    assert light.source.endswith("tri.obj")


def test_rotation_order_is_x_then_y_then_z(write, tmp_path):
    _write_obj(tmp_path / "meshes" / "tri.obj", [(0.1, 0, 0), (0, 0.1, 0), (0, 0, 0.1)],
               [(0, 1, 2)])
    doc = base()
    doc["lights"][2] = {"type": "mesh", "mesh": "meshes/tri.obj", "radiance": [1.0, 1.0, 1.0],
                        "transform": {"rotate_deg": [90.0, 90.0, 0.0]}}
    tri = load_scene(write(doc, "ok.toml")).lights[2].triangles[0]
    # x-axis: Rx keeps it, Ry(90) sends x -> -z;  y-axis: Rx(90) -> z, Ry(90) -> x
    np.testing.assert_allclose(tri[0], [0, 0, -0.1], atol=1e-12)
    np.testing.assert_allclose(tri[1], [0.1, 0, 0], atol=1e-12)


def test_multi_object_mesh_file_is_concatenated(write, tmp_path):
    a = trimesh.creation.box(extents=[0.2, 0.2, 0.2])
    b = trimesh.creation.box(extents=[0.2, 0.2, 0.2])
    b.apply_translation([0.5, 0.0, 0.0])
    trimesh.Scene([a, b]).export(tmp_path / "meshes" / "two.glb")
    doc = base()
    doc["lights"][2]["mesh"] = "meshes/two.glb"
    assert load_scene(write(doc, "ok.toml")).lights[2].triangles.shape == (24, 3, 3)


def test_mesh_path_relative_to_scene_file(monkeypatch, tmp_path):
    monkeypatch.chdir(tmp_path)
    assert load_scene(SCENES / "mesh_light.toml").lights[0].triangles.shape == (320, 3, 3)


def test_parse_scene_from_dict(tmp_path):
    doc = base()
    del doc["lights"][2]
    s = parse_scene(doc, str(tmp_path / "mem.toml"))
    assert len(s.lights) == 2 and s.path.endswith("mem.toml")


def test_open_mesh_occluder_has_no_inside(write, tmp_path):
    _write_obj(tmp_path / "meshes" / "tri.obj", [(-1, -1, 0), (1, -1, 0), (0, 1, 0)], [(0, 1, 2)])
    doc = base()
    doc["occluders"] = [{"type": "mesh", "mesh": "meshes/tri.obj"}]
    load_scene(write(doc, "ok.toml"))


# --------------------------------------------------------------------------- bad scenes


def _set(path: str, value):
    """Mutator setting ``a.b[0].c``-style path to ``value`` (``...`` deletes it)."""

    def mutate(doc):
        parts = path.replace("]", "").replace("[", ".").split(".")
        node = doc
        for p in parts[:-1]:
            node = node[int(p)] if p.isdigit() else node[p]
        last = int(parts[-1]) if parts[-1].isdigit() else parts[-1]
        if value is ...:
            del node[last]
        else:
            node[last] = value

    return mutate


def _add_occluder(occ):
    def mutate(doc):
        doc.setdefault("occluders", []).append(occ)

    return mutate


def _mesh_file(content: bytes | None, name: str):
    """Mutator pointing lights[2] at meshes/<name> (written with ``content`` unless None)."""

    def mutate(doc, tmp_path):
        if content is not None:
            (tmp_path / "meshes" / name).write_bytes(content)
        doc["lights"][2]["mesh"] = f"meshes/{name}"

    return mutate


GARBAGE = bytes(range(256)) * 3

BAD = [
    # id, mutator, key path expected in the message, problem word
    ("missing-section", _set("camera", ...), "camera", "missing"),
    ("missing-medium-key", _set("medium.sigma_a", ...), "medium.sigma_a", "missing"),
    ("missing-camera-key", _set("camera.fov_y", ...), "camera.fov_y", "missing"),
    ("missing-light-key", _set("lights[1].edge_v", ...), "lights[1].edge_v", "missing"),
    ("no-lights", _set("lights", []), "lights", "at least one"),
    ("lights-not-array", _set("lights", 3), "lights", "array"),
    ("unknown-top", _set("version", 1), "version", "unknown"),
    ("unknown-camera", _set("camera.fvo_y", 40.0), "camera.fvo_y", "unknown"),
    ("unknown-light", _set("lights[0].colour", [1, 1, 1]), "lights[0].colour", "unknown"),
    ("unknown-phase", _set("medium.phase.k", 1.0), "medium.phase.k", "unknown"),
    ("g-with-isotropic", _set("medium.phase", {"type": "isotropic", "g": 0.2}),
     "medium.phase.g", "unknown"),
    ("unknown-transform", _set("lights[2].transform.scal", 2.0), "lights[2].transform.scal",
     "unknown"),
    ("unknown-render", _set("render.max_depth", 3), "render.max_depth", "unknown"),
    ("wrong-type-string", _set("medium.sigma_s", "0.8"), "medium.sigma_s", "number"),
    ("wrong-type-bool", _set("camera.fov_y", True), "camera.fov_y", "number"),
    ("wrong-type-vector", _set("camera.position", "origin"), "camera.position", "3 finite"),
    ("section-not-table", _set("medium", 5), "medium", "table"),
    ("vector-length", _set("lights[1].radiance", [1, 2]), "lights[1].radiance",
     "3 finite numbers >= 0"),
    ("vector-bool", _set("camera.up", [0, True, 0]), "camera.up", "3 finite"),
    ("nan-sigma", _set("medium.sigma_a", float("nan")), "medium.sigma_a", "finite"),
    ("inf-position", _set("lights[0].position", [0.0, float("inf"), 0.0]),
     "lights[0].position", "finite"),
    ("negative-sigma", _set("medium.sigma_s", -0.1), "medium.sigma_s", ">= 0"),
    ("sigma-t-zero", lambda d: d["medium"].update(sigma_s=0.0, sigma_a=0), "medium", "sigma_t"),
    ("g-one", _set("medium.phase.g", 1.0), "medium.phase.g", "|g| must be < 1"),
    ("g-minus", _set("medium.phase.g", -1.2), "medium.phase.g", "|g|"),
    ("hg-missing-g", _set("medium.phase", {"type": "hg"}), "medium.phase.g", "missing"),
    ("phase-type", _set("medium.phase", {"type": "rayleigh"}), "medium.phase.type", "unknown"),
    ("fov-0", _set("camera.fov_y", 0.0), "camera.fov_y", "(0, 180)"),
    ("fov-180", _set("camera.fov_y", 180), "camera.fov_y", "(0, 180)"),
    ("resolution-0", _set("camera.resolution", [0, 48]), "camera.resolution", "integers"),
    ("resolution-float", _set("camera.resolution", [64.0, 48]), "camera.resolution", "integer"),
    ("resolution-len", _set("camera.resolution", [64]), "camera.resolution", "2 integers"),
    ("up-parallel", _set("camera.up", [0.0, 0.0, 2.0]), "camera.up", "parallel"),
    ("camera-at-look-at", _set("camera.look_at", [0.0, 0.0, -4.0]), "camera.look_at", "differ"),
    ("bounds-inverted", _set("medium.bounds_max", [1.0, -1.0, 1.0]), "medium.bounds_max",
     "bounds_min"),
    ("zero-intensity", _set("lights[0].intensity", [0, 0.0, 0]), "lights[0].intensity", "zero"),
    ("negative-radiance", _set("lights[1].radiance", [1.0, -1.0, 1.0]), "lights[1].radiance",
     ">= 0"),
    ("zero-area", _set("lights[1].edge_v", [1.2, 0.0, 0.0]), "lights[1]", "zero-area"),
    ("zero-axis", _set("lights[0].axis", [0, 0, 0]), "lights[0].axis", "zero"),
    ("point-outside", _set("lights[0].position", [0.0, 1.5, 0.0]), "lights[0].position",
     "outside"),
    ("area-outside", _set("lights[1].corner", [0.6, 0.95, -0.3]), "lights[1]", "outside"),
    ("mesh-outside", _set("lights[2].transform.translate", [0.0, 0.0, 0.9]), "lights[2].mesh",
     "outside"),
    ("mesh-scale", _set("lights[2].transform.scale", -1.0), "lights[2].transform.scale", "> 0"),
    ("min-scatter-0", _set("render.min_scatter", 0), "render.min_scatter", ">= 1"),
    ("min-scatter-float", _set("render.min_scatter", 1.0), "render.min_scatter", "integer"),
    ("max-lt-min", lambda d: d["render"].update(min_scatter=3, max_scatter=2),
     "render.max_scatter", "min_scatter"),
    ("camera-in-sphere", _add_occluder({"type": "sphere", "center": [0, 0, -4.1], "radius": 0.5}),
     "camera.position", "inside"),
    ("light-in-box", _add_occluder({"type": "box", "min": [0.2, 0.3, 0.0],
                                     "max": [0.4, 0.5, 0.2]}), "lights[0].position", "inside"),
    ("light-in-closed-mesh", _add_occluder({"type": "mesh", "mesh": "meshes/blob.obj",
                                            "transform": {"translate": [0.3, 0.4, 0.1]}}),
     "lights[0].position", "inside"),
    ("sphere-radius", _add_occluder({"type": "sphere", "center": [0, 0, 0], "radius": 0}),
     "occluders[0].radius", "> 0"),
    ("unknown-light-type", _set("lights[0].type", "spot"), "lights[0].type", "unknown"),
    ("missing-light-type", _set("lights[0].type", ...), "lights[0].type", "missing"),
    ("unknown-occluder-type", _add_occluder({"type": "cone"}), "occluders[0].type", "unknown"),
]

BAD_MESH = [
    ("mesh-missing", _mesh_file(None, "nope.obj"), "not found"),
    ("mesh-garbage-ply", _mesh_file(GARBAGE, "junk.ply"), "cannot load"),
    ("mesh-garbage-obj", _mesh_file(GARBAGE, "junk.obj"), "no triangles"),
    ("mesh-empty", _mesh_file(b"", "empty.obj"), "no triangles"),
    ("mesh-points-only", _mesh_file(b"v 0 0 0\nv 0.1 0 0\n", "pts.obj"), "no triangles"),
    ("mesh-all-degenerate", _mesh_file(b"v 0 0 0\nv 0.1 0 0\nv 0.2 0 0\nf 1 2 3\n", "flat.obj"),
     "non-zero area"),
    ("mesh-unknown-format", _mesh_file(b"hello", "blob.xyz"), "cannot load"),
]


def _check(err: SceneError, key: str, word: str, fname: str = "bad.toml") -> None:
    msg = str(err)
    assert "\n" not in msg
    assert fname in msg, msg
    assert f": {key}: " in msg, msg
    assert word in msg, msg


@pytest.mark.parametrize(("mutate", "key", "word"), [b[1:] for b in BAD], ids=[b[0] for b in BAD])
def test_bad_scene(write, mutate, key, word):
    doc = base()
    mutate(doc)
    with pytest.raises(SceneError) as ei:
        load_scene(write(doc))
    _check(ei.value, key, word)


@pytest.mark.parametrize(("mutate", "word"), [b[1:] for b in BAD_MESH],
                         ids=[b[0] for b in BAD_MESH])
def test_bad_mesh(write, tmp_path, mutate, word):
    doc = base()
    mutate(doc, tmp_path)
    with pytest.raises(SceneError) as ei:
        load_scene(write(doc))
    _check(ei.value, "lights[2].mesh", word)
    assert Path(doc["lights"][2]["mesh"]).name in str(ei.value)


def test_invalid_toml(tmp_path):
    p = tmp_path / "broken.toml"
    p.write_text("[camera]\nposition = = [0, 0, 0]\n")
    with pytest.raises(SceneError) as ei:
        load_scene(p)
    msg = str(ei.value)
    assert "broken.toml" in msg and "invalid TOML" in msg and "line" in msg and "\n" not in msg


def test_missing_file(tmp_path):
    with pytest.raises(SceneError, match=r"nothing\.toml: file not found"):
        load_scene(tmp_path / "nothing.toml")


def test_directory_is_not_a_scene(tmp_path):
    with pytest.raises(SceneError, match="cannot read"):
        load_scene(tmp_path)
