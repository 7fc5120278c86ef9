"""Read and validate scene files (TOML, format v1; the contract is ``SCENES.md``).

Every problem raises :class:`~psurf_core.scene.SceneError` with one line
``"<file>: <key path>: <problem>"``, e.g. ``scenes/x.toml: medium.phase.g: |g| must be < 1,
got 1.2``. Key paths index arrays of tables from 0 (``lights[0]`` is the first light).
"""

from __future__ import annotations

import math
import os
import tomllib
import warnings
from typing import Any, NoReturn

import numpy as np

from .scene import (
    AreaLight,
    BoxOccluder,
    Camera,
    Medium,
    MeshLight,
    MeshOccluder,
    Phase,
    PointLight,
    Scene,
    SceneError,
    SphereOccluder,
)

__all__ = ["load_scene", "parse_scene"]

_TOP = {"camera": True, "medium": True, "lights": True, "occluders": False, "render": False}
_PHASE_KEYS = {"isotropic": (set(), set()), "hg": ({"g"}, set())}
_LIGHT_KEYS = {
    "point": ({"position", "intensity"}, {"axis"}),
    "area": ({"corner", "edge_u", "edge_v", "radiance"}, set()),
    "mesh": ({"mesh", "radiance"}, {"transform"}),
}
_OCCLUDER_KEYS = {
    "sphere": ({"center", "radius"}, set()),
    "box": ({"min", "max"}, set()),
    "mesh": ({"mesh"}, {"transform"}),
}


def load_scene(path: str | os.PathLike) -> Scene:
    """Read a scene file and validate it against ``SCENES.md``.

    Parameters
    ----------
    path : str or path-like
        The TOML scene file. Mesh paths inside it are relative to its folder.

    Returns
    -------
    Scene
        The validated scene; every vector is a float64 numpy array.

    Raises
    ------
    SceneError
        One line ``"<file>: <key path>: <problem>"`` when the file is missing, is not valid
        TOML or breaks any rule of the contract.
    """
    name = os.fspath(path)
    try:
        with open(name, "rb") as f:
            data = tomllib.load(f)
    except FileNotFoundError:
        raise SceneError(f"{name}: file not found") from None
    except tomllib.TOMLDecodeError as e:
        raise SceneError(" ".join(f"{name}: invalid TOML: {e}".split())) from None
    except (OSError, UnicodeDecodeError) as e:
        raise SceneError(" ".join(f"{name}: cannot read file: {e}".split())) from None
    return parse_scene(data, name)


def parse_scene(data: dict, path: str) -> Scene:
    """Validate an already parsed TOML document and build the :class:`Scene`.

    Parameters
    ----------
    data : dict
        The document as returned by ``tomllib``.
    path : str
        The file it came from: named in error messages, and the base of relative mesh paths.

    Returns
    -------
    Scene

    Raises
    ------
    SceneError
        On any violation of the contract (see the module docstring for the message format).

    Notes
    -----
    Mesh lights and mesh occluders drop their zero-area triangles; a mesh is an error only
    when none remain. The scale of a mesh ``transform`` must be > 0 (no mirroring, which
    would turn the emitting side of every triangle inwards).
    """
    ctx = _Ctx(str(path))
    if not isinstance(data, dict):
        ctx.fail("<document>", "must be a TOML table")
    _keys(ctx, data, "", {k for k, req in _TOP.items() if req}, set(_TOP), what="section")
    camera = _camera(ctx, _table(ctx, data["camera"], "camera"))
    medium = _medium(ctx, _table(ctx, data["medium"], "medium"))
    lights_raw = _table(ctx, data["lights"], "lights", array=True)
    if not lights_raw:
        ctx.fail("lights", "at least one [[lights]] entry is required")
    lights = tuple(_light(ctx, t, f"lights[{i}]") for i, t in enumerate(lights_raw))
    occ_raw = _table(ctx, data.get("occluders", []), "occluders", True)
    occluders = tuple(_occluder(ctx, t, f"occluders[{i}]") for i, t in enumerate(occ_raw))
    min_s, max_s = _render(ctx, _table(ctx, data.get("render", {}), "render"))

    tol = 1e-9 * medium.diagonal
    lo, hi = medium.bounds_min - tol, medium.bounds_max + tol
    box = f"{_fmt(medium.bounds_min.tolist())}..{_fmt(medium.bounds_max.tolist())}"
    for i, light in enumerate(lights):
        key, pts = _light_points(light, f"lights[{i}]")
        bad = ~np.all((pts >= lo) & (pts <= hi), axis=1)
        if bad.any():
            ctx.fail(key, f"light point {_fmt(pts[bad][0].tolist())} is outside the medium box "
                          f"{box} (lights must be inside the medium or on its boundary)")
    probes = [("camera.position", camera.position[None, :])]
    probes += [_light_points(lt, f"lights[{i}]") for i, lt in enumerate(lights)]
    for j, occ in enumerate(occluders):
        for key, pts in probes:
            inside = _inside(occ, pts, tol)
            if inside.any():
                who = "camera" if key.startswith("camera") else "light point"
                ctx.fail(key, f"{who} {_fmt(pts[inside][0].tolist())} is inside "
                              f"occluders[{j}] ({occ.kind})")
    return Scene(camera=camera, medium=medium, lights=lights, occluders=occluders,
                 min_scatter=min_s, max_scatter=max_s, path=ctx.file)


# --------------------------------------------------------------------------- helpers


class _Ctx:
    """Error context: the file name and a ``fail`` that raises the one-line message."""

    def __init__(self, file: str):
        self.file = file
        self.base = os.path.dirname(os.path.abspath(file))

    def fail(self, key: str, problem: str) -> NoReturn:
        raise SceneError(" ".join(f"{self.file}: {key}: {problem}".split()))


def _fmt(v: Any) -> str:
    """Short TOML-like rendering of a value for messages."""
    if isinstance(v, bool):
        s = str(v).lower()
    elif isinstance(v, (list, tuple)):
        s = "[" + ", ".join(_fmt(x) for x in v) + "]"
    elif isinstance(v, dict):
        s = "{" + ", ".join(f"{k} = {_fmt(x)}" for k, x in v.items()) + "}"
    else:
        s = repr(v) if isinstance(v, (str, float)) else str(v)
    return s if len(s) <= 80 else s[:77] + "..."


def _is_num(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _finite(x: Any) -> bool:
    try:
        return _is_num(x) and math.isfinite(x)
    except OverflowError:
        return False


def _table(ctx: _Ctx, v: Any, key: str, array: bool = False) -> Any:
    if not isinstance(v, list if array else dict):
        what = f"an array of tables ([[{key}]])" if array else "a table"
        ctx.fail(key, f"must be {what}, got {_fmt(v)}")
    return v


def _keys(ctx: _Ctx, t: dict, prefix: str, required: set, allowed: set, what="key") -> None:
    """Unknown keys first (a typo is then reported as such), then missing ones."""
    dot = f"{prefix}." if prefix else ""
    for k in t:
        if k not in allowed:
            ctx.fail(dot + k, f"unknown key (allowed: {', '.join(sorted(allowed))})")
    for k in sorted(required):
        if k not in t:
            ctx.fail(dot + k, f"missing required {what}")


def _num(ctx: _Ctx, v: Any, key: str) -> float:
    if not _finite(v):
        ctx.fail(key, f"must be a finite number, got {_fmt(v)}")
    return float(v)


def _int(ctx: _Ctx, v: Any, key: str) -> int:
    if not isinstance(v, int) or isinstance(v, bool):
        ctx.fail(key, f"must be an integer, got {_fmt(v)}")
    return v


def _vec(ctx: _Ctx, v: Any, key: str, n: int = 3, nonneg: bool = False) -> np.ndarray:
    if not (isinstance(v, list) and len(v) == n
            and all(_finite(x) and (x >= 0 or not nonneg) for x in v)):
        ctx.fail(key, f"must be {n} finite numbers{' >= 0' if nonneg else ''}, got {_fmt(v)}")
    return np.array(v, dtype=np.float64)


def _emission(ctx: _Ctx, v: Any, key: str) -> np.ndarray:
    e = _vec(ctx, v, key, nonneg=True)
    if not e.any():
        ctx.fail(key, f"must not be all zero, got {_fmt(v)}")
    return e


# --------------------------------------------------------------------------- sections


def _camera(ctx: _Ctx, t: dict) -> Camera:
    keys = {"position", "look_at", "up", "fov_y", "resolution"}
    _keys(ctx, t, "camera", keys, keys)
    pos = _vec(ctx, t["position"], "camera.position")
    at = _vec(ctx, t["look_at"], "camera.look_at")
    up = _vec(ctx, t["up"], "camera.up")
    fov = _num(ctx, t["fov_y"], "camera.fov_y")
    if not 0.0 < fov < 180.0:
        ctx.fail("camera.fov_y", f"must be in (0, 180) degrees, got {_fmt(t['fov_y'])}")
    res = t["resolution"]
    if not (isinstance(res, list) and len(res) == 2
            and all(isinstance(x, int) and not isinstance(x, bool) and x >= 1 for x in res)):
        ctx.fail("camera.resolution", f"must be 2 integers >= 1 (width, height), got {_fmt(res)}")
    view = at - pos
    if np.linalg.norm(view) == 0.0:
        ctx.fail("camera.look_at",
                 f"must differ from camera.position, both are {_fmt(t['look_at'])}")
    f = view / np.linalg.norm(view)
    nu = np.linalg.norm(up)
    if nu == 0.0 or np.linalg.norm(np.cross(f, up / nu)) < 1e-9:
        ctx.fail("camera.up", f"must not be zero or parallel to the view direction "
                              f"(look_at - position = {_fmt(view.tolist())}), got {_fmt(t['up'])}")
    return Camera(position=pos, look_at=at, up=up, fov_y=fov, width=res[0], height=res[1])


def _medium(ctx: _Ctx, t: dict) -> Medium:
    keys = {"bounds_min", "bounds_max", "sigma_s", "sigma_a", "phase"}
    _keys(ctx, t, "medium", keys, keys)
    bmin = _vec(ctx, t["bounds_min"], "medium.bounds_min")
    bmax = _vec(ctx, t["bounds_max"], "medium.bounds_max")
    if not np.all(bmax > bmin):
        ctx.fail("medium.bounds_max", f"must be > bounds_min in every component, got "
                                      f"{_fmt(t['bounds_max'])} vs {_fmt(t['bounds_min'])}")
    sig = {}
    for k in ("sigma_s", "sigma_a"):
        sig[k] = _num(ctx, t[k], f"medium.{k}")
        if sig[k] < 0:
            ctx.fail(f"medium.{k}", f"must be >= 0, got {_fmt(t[k])}")
    if sig["sigma_s"] + sig["sigma_a"] <= 0:
        ctx.fail("medium", "sigma_t = sigma_s + sigma_a must be > 0, got 0")
    phase = Phase("isotropic", 0.0)
    if _typed(ctx, t["phase"], "medium.phase", _PHASE_KEYS, "phase") == "hg":
        g = _num(ctx, t["phase"]["g"], "medium.phase.g")
        if not abs(g) < 1.0:
            ctx.fail("medium.phase.g", f"|g| must be < 1, got {_fmt(t['phase']['g'])}")
        phase = Phase("hg", g)
    return Medium(bmin, bmax, sig["sigma_s"], sig["sigma_a"], phase)


def _typed(ctx: _Ctx, t: Any, key: str, table: dict, what: str) -> str:
    t = _table(ctx, t, key)
    if "type" not in t:
        ctx.fail(f"{key}.type", "missing required key")
    kind = t["type"]
    if not isinstance(kind, str) or kind not in table:
        ctx.fail(f"{key}.type", f"unknown {what} type {_fmt(kind)} "
                                f"(expected one of: {', '.join(table)})")
    req, opt = table[kind]
    _keys(ctx, t, key, req | {"type"}, req | opt | {"type"})
    return kind


def _light(ctx: _Ctx, t: Any, key: str):
    kind = _typed(ctx, t, key, _LIGHT_KEYS, "light")
    if kind == "point":
        axis = _vec(ctx, t.get("axis", [0.0, 1.0, 0.0]), f"{key}.axis")
        if np.linalg.norm(axis) == 0.0:
            ctx.fail(f"{key}.axis", "must not be the zero vector")
        return PointLight(position=_vec(ctx, t["position"], f"{key}.position"),
                          intensity=_emission(ctx, t["intensity"], f"{key}.intensity"),
                          axis=axis / np.linalg.norm(axis))
    if kind == "area":
        c = _vec(ctx, t["corner"], f"{key}.corner")
        u = _vec(ctx, t["edge_u"], f"{key}.edge_u")
        v = _vec(ctx, t["edge_v"], f"{key}.edge_v")
        rad = _emission(ctx, t["radiance"], f"{key}.radiance")
        n = np.cross(u, v)
        if np.linalg.norm(n) <= 1e-12 * (u @ u + v @ v):
            ctx.fail(key, f"zero-area parallelogram: cross(edge_u, edge_v) = {_fmt(n.tolist())}")
        return AreaLight(corner=c, edge_u=u, edge_v=v, radiance=rad)
    rad = _emission(ctx, t["radiance"], f"{key}.radiance")
    tris, src = _mesh(ctx, t, key)
    return MeshLight(triangles=tris, radiance=rad, source=src)


def _occluder(ctx: _Ctx, t: Any, key: str):
    kind = _typed(ctx, t, key, _OCCLUDER_KEYS, "occluder")
    if kind == "sphere":
        r = _num(ctx, t["radius"], f"{key}.radius")
        if r <= 0:
            ctx.fail(f"{key}.radius", f"must be > 0, got {_fmt(t['radius'])}")
        return SphereOccluder(center=_vec(ctx, t["center"], f"{key}.center"), radius=r)
    if kind == "box":
        lo = _vec(ctx, t["min"], f"{key}.min")
        hi = _vec(ctx, t["max"], f"{key}.max")
        if not np.all(hi > lo):
            ctx.fail(f"{key}.max", f"must be > min in every component, got "
                                   f"{_fmt(t['max'])} vs {_fmt(t['min'])}")
        return BoxOccluder(min=lo, max=hi)
    tris, src = _mesh(ctx, t, key)
    return MeshOccluder(triangles=tris, source=src)


def _render(ctx: _Ctx, t: dict) -> tuple[int, int]:
    _keys(ctx, t, "render", set(), {"min_scatter", "max_scatter"})
    lo = _int(ctx, t.get("min_scatter", 1), "render.min_scatter")
    if lo < 1:
        ctx.fail("render.min_scatter", f"must be >= 1, got {lo}")
    hi = _int(ctx, t.get("max_scatter", -1), "render.max_scatter")
    if hi != -1 and hi < lo:
        ctx.fail("render.max_scatter", f"must be >= min_scatter ({lo}) or -1, got {hi}")
    return lo, hi


# --------------------------------------------------------------------------- meshes


def _transform(ctx: _Ctx, t: Any, key: str):
    """``(scale (3,), R (3, 3), translate (3,))``; ``x' = R (s * x) + t``, ``R = Rz Ry Rx``."""
    t = _table(ctx, t, key)
    _keys(ctx, t, key, set(), {"scale", "rotate_deg", "translate"})
    s = t.get("scale", 1.0)
    if _is_num(s):
        s = [s, s, s]
    if not (isinstance(s, list) and len(s) == 3 and all(_finite(x) and x > 0 for x in s)):
        ctx.fail(f"{key}.scale", f"must be a number > 0 or 3 numbers > 0, got {_fmt(t['scale'])}")
    ax, ay, az = np.radians(_vec(ctx, t.get("rotate_deg", [0.0, 0.0, 0.0]), f"{key}.rotate_deg"))
    tr = _vec(ctx, t.get("translate", [0.0, 0.0, 0.0]), f"{key}.translate")
    cx, sx, cy, sy, cz, sz = np.cos(ax), np.sin(ax), np.cos(ay), np.sin(ay), np.cos(az), np.sin(az)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return np.array(s, dtype=np.float64), rz @ ry @ rx, tr


def _mesh(ctx: _Ctx, t: dict, key: str) -> tuple[np.ndarray, str]:
    """Load ``t['mesh']`` (relative to the scene file), transform it, drop zero-area triangles.

    Returns the ``(F, 3, 3)`` float64 triangles (file winding kept) and the resolved path.
    """
    import trimesh  # heavy; only scenes with meshes pay for it

    mkey = f"{key}.mesh"
    rel = t["mesh"]
    if not isinstance(rel, str) or not rel:
        ctx.fail(mkey, f"must be a file path string, got {_fmt(rel)}")
    s, rot, tr = _transform(ctx, t.get("transform", {}), f"{key}.transform")
    path = os.path.normpath(os.path.join(ctx.base, rel))
    if not os.path.isfile(path):
        ctx.fail(mkey, f"mesh file not found: {path}")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            m = trimesh.load(path, force="mesh", process=False)
        if not isinstance(m, trimesh.Trimesh):
            ctx.fail(mkey, f"{path} is not a triangle mesh (loaded a {type(m).__name__})")
        faces = np.asarray(m.faces, dtype=np.int64)
        verts = np.asarray(m.vertices, dtype=np.float64)
        if faces.size == 0:
            ctx.fail(mkey, f"{path} contains no triangles")
        tris = verts[faces.reshape(-1, 3)]
    except SceneError:
        raise
    except Exception as e:  # any loader failure becomes a one-line scene error
        ctx.fail(mkey, f"cannot load mesh file {path}: {type(e).__name__}: {e}")
    if not np.isfinite(tris).all():
        ctx.fail(mkey, f"{path} has non-finite vertex coordinates")
    tris = (tris * s) @ rot.T + tr
    e1, e2 = tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
    scale2 = np.maximum((e1 * e1).sum(1), (e2 * e2).sum(1))
    keep = np.linalg.norm(np.cross(e1, e2), axis=1) > 1e-12 * scale2
    if not keep.any():
        ctx.fail(mkey, f"{path} has no triangle of non-zero area")
    return np.ascontiguousarray(tris[keep], dtype=np.float64), path


# --------------------------------------------------------------------------- placement


def _light_points(light, key: str) -> tuple[str, np.ndarray]:
    """Key path and ``(N, 3)`` points that must lie in the box and outside every occluder."""
    if light.kind == "point":
        return f"{key}.position", light.position[None, :]
    if light.kind == "area":
        c, u, v = light.corner, light.edge_u, light.edge_v
        return key, np.stack([c, c + u, c + u + v, c + v])
    return f"{key}.mesh", np.unique(light.triangles.reshape(-1, 3), axis=0)


def _inside(occ, pts: np.ndarray, tol: float) -> np.ndarray:
    """``(N,)`` bool: points strictly inside an occluder (mesh occluders: only closed ones)."""
    if occ.kind == "sphere":
        return np.linalg.norm(pts - occ.center, axis=1) < occ.radius - tol
    if occ.kind == "box":
        return np.all((pts > occ.min + tol) & (pts < occ.max - tol), axis=1)
    if not _is_closed(occ.triangles):
        return np.zeros(len(pts), dtype=bool)
    return np.abs(_winding_number(occ.triangles, pts)) > 0.5


def _is_closed(tris: np.ndarray) -> bool:
    """Watertight with consistent winding (after merging coincident vertices)."""
    import trimesh

    m = trimesh.Trimesh(vertices=tris.reshape(-1, 3),
                        faces=np.arange(3 * len(tris)).reshape(-1, 3), process=True)
    return bool(m.is_watertight and m.is_winding_consistent)


def _winding_number(tris: np.ndarray, pts: np.ndarray, chunk: int = 1 << 18) -> np.ndarray:
    """Generalized winding number of a triangle soup at ``pts`` (Van Oosterom-Strackee).

    For a closed, consistently wound mesh it is +-1 inside and 0 outside.
    """
    out = np.zeros(len(pts))
    step = max(1, chunk // max(1, len(tris)))
    for i in range(0, len(pts), step):
        d = tris[None, :, :, :] - pts[i:i + step, None, None, :]  # (n, F, 3, 3)
        a, b, c = d[:, :, 0], d[:, :, 1], d[:, :, 2]
        la, lb, lc = (np.linalg.norm(x, axis=-1) for x in (a, b, c))
        num = np.einsum("nfk,nfk->nf", a, np.cross(b, c))
        den = (la * lb * lc + np.einsum("nfk,nfk->nf", a, b) * lc
               + np.einsum("nfk,nfk->nf", a, c) * lb + np.einsum("nfk,nfk->nf", b, c) * la)
        out[i:i + step] = 2.0 * np.arctan2(num, den).sum(axis=1) / (4.0 * np.pi)
    return out
