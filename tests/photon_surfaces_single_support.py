"""What the single-scattering photon-surface tests (``test_photon_surfaces_single_*.py``) share:
the technique names, the lights (a point, a parallelogram and two mesh lights, so that the
light-selection weight ``1/P_L`` and the per-triangle pdfs are exercised) and one pass of one
technique against every camera ray."""

from __future__ import annotations

import numpy as np
import trimesh
from small_scenes import POINT, TOP_AREA, make_scene

from psurf_core.camera import camera_rays
from psurf_core.geometry import blockers_of
from psurf_core.scene import MeshLight
from psurf_core.techniques import get_technique
from psurf_core.techniques.base import PassContext
from psurf_core.trace import trace

SINGLE = ("ss-sphere", "ss-cone", "ss-cone-short", "ss-disk", "ss-disk-short")
PLANES = ("ss-plane-uv", "ss-plane-ut", "ss-plane-ut-short", "ss-plane-vt", "ss-plane-vt-short")
ALL = (*SINGLE, *PLANES)

#: The icosphere the mesh light is made of (80 outward faces about its centre MESH_CENTER).
ICO = trimesh.creation.icosphere(subdivisions=1, radius=0.2)
MESH_CENTER = np.array([0.2, -0.1, 0.2])
MESH = MeshLight(ICO.vertices[ICO.faces] + MESH_CENTER, np.array([2.0, 2.0, 2.0]))
# The parallelogram as two triangles (counter-clockwise about its downward normal).
_C, _U, _V = TOP_AREA.corner, TOP_AREA.edge_u, TOP_AREA.edge_v
QUAD = MeshLight(np.array([[_C, _C + _U, _C + _U + _V], [_C, _C + _U + _V, _C + _V]]),
                 np.array([3.0, 3.0, 3.0]))
LIGHTS = {"area": (TOP_AREA,), "mesh": (MESH,), "quad": (QUAD,),
          "mixed": (POINT, TOP_AREA, MESH)}
#: The three light kinds in one scene (HG g = 0.5).
MIXED = make_scene(LIGHTS["mixed"], g=0.5)


def unit(v):
    """``v`` normalized along its last axis."""
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def hits_of(scene, name, n=1500, seed=8, paths=None, rays=None):
    """One pass of one technique (a name or an instance), every ray against every primitive.

    Returns ``(tech, prims, hits, values, rec, paths, rays, ctx)``.
    """
    bl = blockers_of(scene)
    ctx = PassContext(scene, bl)
    rays = camera_rays(scene, 1, jitter=False, blockers=bl) if rays is None else rays
    paths = trace(scene, n, np.random.default_rng(seed), blockers=bl) if paths is None else paths
    tech = get_technique(name) if isinstance(name, str) else name
    prims = tech.create(paths, ctx)
    ray = np.repeat(np.arange(len(rays)), len(prims))
    prim = np.tile(np.arange(len(prims)), len(rays))
    hits = tech.intersect(prims, rays, ray, prim, ctx)
    val = tech.evaluate(hits, prims, paths, rays, ctx)
    rec = tech.reconstruct(hits, prims, paths, rays, ctx)
    return tech, prims, hits, val, rec, paths, rays, ctx
