"""What the multiple-scattering photon-surface tests (``test_photon_surfaces_multi_*.py``)
share: the techniques under test and their two scenes at 12x9 pixels."""

from __future__ import annotations

import numpy as np
from small_scenes import TOP_AREA, make_scene

from psurf_core.scene import PointLight, Scene, SphereOccluder

MINE_K2 = ["sphere", "cone", "cone-short", "cylinder", "cylinder-short", "disk", "disk-short",
           "hyperboloid", "hyperboloid-short", "torus"]
MINE_K3 = ["plane-t1t3", "plane-t1t3-short", "plane-t2t3", "plane-t2t3-short"]
#: The light strips (K = 2, 3; area and mesh lights only).
MINE_LIGHT = ["plane-ut", "plane-ut-short", "plane-vt", "plane-vt-short"]
SIZE = (12, 9)


def area_scene(k: int, g: float = 0.0) -> Scene:
    """SCENES.md's default: a downward area light below the top of the box (K = k)."""
    return make_scene((TOP_AREA,), g=g, kmin=k, kmax=k, size=SIZE)


def point_scene(k: int) -> Scene:
    """Point light, HG g = 0.5, and a sphere occluder the camera sees (K = k)."""
    light = PointLight(np.array([0.3, 0.4, 0.1]), np.full(3, 4.0), np.array([0.0, 1.0, 0.0]))
    occ = SphereOccluder(np.array([-0.2, -0.1, 0.0]), 0.3)
    return make_scene((light,), (occ,), g=0.5, kmin=k, kmax=k, size=SIZE)


#: The scenes by key: K = 2 with either light, K = 3 with the area light (HG g = 0.3).
SCENES = {"area2": lambda: area_scene(2), "point2": lambda: point_scene(2),
          "area3": lambda: area_scene(3, g=0.3)}


def unit(v):
    """Rows of ``v`` (N, 3) normalized."""
    return v / np.linalg.norm(v, axis=1, keepdims=True)
