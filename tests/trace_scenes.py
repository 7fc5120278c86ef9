"""Scenes the Trace tests share: the bundled ones and three built here (mixed occluders, three
kinds of light in one scene, a nearly isotropic HG medium)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from psurf_core.scene import BoxOccluder, MeshOccluder, Phase, SphereOccluder
from psurf_core.scene_io import load_scene

ROOT = Path(__file__).resolve().parent.parent
BUNDLED = tuple(sorted(p.stem for p in (ROOT / "scenes").glob("*.toml")))
BUILT = ("mixed_occluders", "multi_light", "near_isotropic")


def mixed_occluders():
    """``point.toml`` with a sphere, a box and a triangle-mesh occluder (no bundled scene has a
    mesh occluder; the mesh is the mesh light's blob, shrunk and moved off the light)."""
    base = load_scene(ROOT / "scenes/point.toml")
    blob = load_scene(ROOT / "scenes/mesh_light.toml").lights[0].triangles
    tris = 0.5 * blob + np.array([0.35, -0.4, 0.2])
    occ = (SphereOccluder(center=np.array([-0.4, 0.3, 0.0]), radius=0.25),
           BoxOccluder(min=np.array([0.1, 0.2, -0.5]), max=np.array([0.5, 0.45, -0.2])),
           MeshOccluder(triangles=tris, source="blob, scaled"))
    return replace(base, occluders=occ)


def multi_light():
    """Point, area and mesh lights in one scene (photons split between them by power), the
    mixed occluders, a backward-scattering medium with a strong albedo."""
    base = mixed_occluders()
    point = replace(base.lights[0], intensity=base.lights[0].intensity / 12)  # power ~ the others
    lights = (point, load_scene(ROOT / "scenes/area.toml").lights[0],
              load_scene(ROOT / "scenes/mesh_light.toml").lights[0])
    med = replace(base.medium, sigma_s=1.6, sigma_a=0.1, phase=Phase("hg", -0.4))
    return replace(base, lights=lights, medium=med)


def scene(name: str):
    """A bundled scene by file stem, or one of :data:`BUILT`."""
    if name == "mixed_occluders":
        return mixed_occluders()
    if name == "multi_light":
        return multi_light()
    if name == "near_isotropic":  # |g| below HG_ISOTROPIC_G: sampled as isotropic
        s = load_scene(ROOT / "scenes/hg.toml")
        return replace(s, medium=replace(s.medium, phase=Phase("hg", 5e-4)))
    return load_scene(ROOT / f"scenes/{name}.toml")
