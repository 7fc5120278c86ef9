"""Translucent surfaces shaded once, on the CPU, for the renderer's lights as they are: the
window's cheap way to draw the primitives in software OpenGL.

Rendering the Create and Intersect stages' 3D view (dozens of translucent primitives, a few
thousand cells, lit by pyvista's light kit of five lights) took 80-130 ms of Mesa llvmpipe at
1600x900 (``benchmarks/ui_frames.py``), ~30-40 ms of it lighting every translucent fragment
five times. Flat shading (what the primitives use: one normal per cell) is a colour per cell,
so it can be computed here once per view, exactly as VTK's shader does it (diffuse only:
pyvista's surfaces have no ambient or specular term; two-sided: a cell facing away is lit on
its other side), and drawn unlit. The picture is the same for the camera the colours were
made for (:func:`shaded_cells`); when the user turns the view the colours stay as they were
made (the next stage, or any redraw, makes them again).

The window switches it on (:func:`enable`) only when it finds software OpenGL; screenshots
and GPU windows light the surfaces in the shader.
"""

from __future__ import annotations

import numpy as np

from ._vtk import pv

__all__ = ["enable", "enabled", "shaded_cells"]

#: The attribute of a plotter that switches the baked shading on.
_FLAG = "_psurf_baked_light"


def enable(plotter: pv.Plotter, on: bool = True) -> None:
    """Draw ``plotter``'s translucent primitives with baked shading (or not)."""
    setattr(plotter, _FLAG, bool(on))


def enabled(plotter: pv.Plotter) -> bool:
    return bool(getattr(plotter, _FLAG, False))


def _light_directions(renderer) -> list:
    """``(unit vector towards the light (3,), RGB intensity (3,))`` of each light that is on,
    in world coordinates for the renderer's camera as it is now."""
    cam = renderer.GetActiveCamera()
    pos, focal = np.array(cam.GetPosition()), np.array(cam.GetFocalPoint())
    fwd = focal - pos
    fwd /= max(np.linalg.norm(fwd), 1e-300)
    right = np.cross(fwd, np.array(cam.GetViewUp()))
    right /= max(np.linalg.norm(right), 1e-300)
    up = np.cross(right, fwd)
    out = []
    for light in renderer.GetLights():
        if not light.GetSwitch() or light.GetIntensity() <= 0:
            continue
        if light.LightTypeIsHeadlight():
            to_light = -fwd
        else:
            d = np.array(light.GetPosition()) - np.array(light.GetFocalPoint())
            if light.LightTypeIsCameraLight():  # camera at (0, 0, 1) looking at the origin
                d = d[0] * right + d[1] * up - d[2] * fwd
            to_light = d
        n = np.linalg.norm(to_light)
        if n > 0:
            colour = np.array(light.GetDiffuseColor()) * light.GetIntensity()
            out.append((to_light / n, colour))
    return out


def shaded_cells(mesh: pv.PolyData, colour, renderer) -> np.ndarray:
    """``(n_cells, 3)`` uint8: ``colour`` lit by ``renderer``'s lights for its camera, per
    cell (flat, two-sided, diffuse), as VTK's shader would light the cell."""
    n_cells = mesh.n_cells
    base = np.array(pv.Color(colour).float_rgb)
    if n_cells == 0:
        return np.zeros((0, 3), np.uint8)
    normals = mesh.compute_normals(cell_normals=True, point_normals=False,
                                   split_vertices=False, consistent_normals=False,
                                   auto_orient_normals=False).cell_data["Normals"]
    centres = mesh.cell_centers().points
    pos = np.array(renderer.GetActiveCamera().GetPosition())
    facing = np.einsum("ij,ij->i", normals, pos[None] - centres)
    normals = np.where((facing < 0)[:, None], -normals, normals)  # two-sided lighting
    light = np.zeros((n_cells, 3))
    for to_light, rgb in _light_directions(renderer):
        light += np.maximum(normals @ to_light, 0.0)[:, None] * rgb[None]
    return np.clip(np.rint(255.0 * base[None] * light), 0, 255).astype(np.uint8)
