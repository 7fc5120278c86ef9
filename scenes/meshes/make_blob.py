"""Generate ``blob.obj``: a small closed, outward-wound (CCW) triangle mesh for the mesh light.

A subdivided icosphere (2 subdivisions, 320 faces) of radius 0.25, deformed smoothly and
deterministically (no randomness) into a lumpy blob. Run from anywhere::

    python scenes/meshes/make_blob.py
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh

RADIUS = 0.25


def make_blob() -> trimesh.Trimesh:
    """Return the blob mesh (vertices scaled radially, so winding and closure are kept)."""
    sphere = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    v = np.asarray(sphere.vertices, dtype=np.float64)
    x, y, z = v.T
    # smooth radial bumps: r(dir) in roughly [0.8, 1.2] * RADIUS, star-shaped so never folds
    r = 1.0 + 0.12 * np.sin(3.0 * x) * np.cos(2.0 * y) + 0.08 * np.cos(4.0 * z + 1.0 * x)
    blob = trimesh.Trimesh(vertices=v * (RADIUS * r)[:, None], faces=sphere.faces, process=False)
    assert blob.is_watertight and blob.is_winding_consistent and blob.volume > 0
    return blob


def main() -> None:
    out = Path(__file__).with_name("blob.obj")
    make_blob().export(out, file_type="obj", include_normals=False, include_texture=False)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
