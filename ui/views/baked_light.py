"""Translucent surfaces shaded once, on the CPU, for the renderer's lights as they are: the
window's cheap way to draw the primitives in software OpenGL.

Rendering the Create and Intersect stages' 3D view (dozens of translucent primitives, a few
thousand cells, lit by pyvista's light kit of five lights) took 80-130 ms of Mesa llvmpipe at
1600x900 (``benchmarks/ui_frames.py``), ~30-40 ms of it lighting every translucent fragment
five times. Flat shading (what the primitives use: one normal per cell) is a colour per cell,
so it can be computed here once per view, exactly as VTK's shader does it (diffuse only:
pyvista's surfaces have no ambient or specular term; two-sided: a cell facing away is lit on
its other side), and drawn unlit. The picture is the same for the camera the colours were
made for (:func:`shaded_cells`); while the user turns the view they stay as they were made,
and when the turn ends the window makes them again for the new view (:func:`relight`).

The window switches it on (:func:`enable`) only when it finds software OpenGL; screenshots
and GPU windows light the surfaces in the shader.
"""

from __future__ import annotations

import numpy as np

from ._vtk import pv

__all__ = ["enable", "enabled", "relight", "shade", "shaded_cells"]

#: Cell array of the shaded colours; field arrays of the colour and the view they were made
#: from.
SHADE, BASE, VIEW = "shade", "shade_base", "shade_view"


def _view(renderer) -> np.ndarray:
    """What the shading depends on: the camera's direction and view up (the lights are
    camera lights, directional)."""
    cam = renderer.GetActiveCamera()
    d = np.array(cam.GetFocalPoint()) - np.array(cam.GetPosition())
    return np.concatenate([d / max(np.linalg.norm(d), 1e-300), np.array(cam.GetViewUp())])

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


def shade(mesh: pv.PolyData, colour, renderer) -> pv.PolyData:
    """``mesh`` with its cells shaded for ``renderer`` (the cell array :data:`SHADE`, drawn
    with ``scalars=SHADE, rgb=True, lighting=False``); ``colour`` is kept with it."""
    mesh.cell_data[SHADE] = shaded_cells(mesh, colour, renderer)
    mesh.field_data[BASE] = np.array(pv.Color(colour).float_rgb)
    mesh.field_data[VIEW] = _view(renderer)
    return mesh


def relight(renderer) -> int:
    """Shade every baked mesh of ``renderer`` again for its camera as it is now (after the
    user turned the view) if it was made for another view; returns how many were changed
    (render to show them). The colours are written into the arrays the mappers draw."""
    n, view = 0, _view(renderer)
    for actor in list(renderer.actors.values()):
        mapper = actor.GetMapper() if hasattr(actor, "GetMapper") else None
        data = mapper.GetInput() if hasattr(mapper, "GetInput") else None
        if data is None or not data.GetNumberOfPolys():
            continue
        shade_arr = data.GetCellData().GetArray(SHADE)
        base_arr = data.GetFieldData().GetArray(BASE)
        view_arr = data.GetFieldData().GetArray(VIEW)
        if shade_arr is None or base_arr is None or view_arr is None:
            continue
        made_for = pv.convert_array(view_arr)  # views of VTK's buffers: written in place
        if np.allclose(made_for, view, atol=1e-6):
            continue
        colours = pv.convert_array(shade_arr)
        colours[...] = shaded_cells(pv.wrap(data), tuple(pv.convert_array(base_arr)),
                                    renderer).reshape(colours.shape)
        made_for[...] = view
        shade_arr.Modified()
        data.Modified()
        n += 1
    return n
