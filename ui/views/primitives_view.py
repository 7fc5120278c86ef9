"""Trace and Create in 3D: photon subpaths and the primitives swept from them (pyvista).

Subpaths are polylines clipped to the medium box (``PhotonPaths.clip``), one colour per scatter
event. Primitives are drawn as geometry clipped to the box, each technique in its own colour
(:func:`ui.views.palette.technique_colour`, the same in every view), from what each family
declares in its own module (no family is known here by name): a surface technique's
``surface_grid`` (the points sweeping each primitive: planes and light copies, spheres, cones,
cylinders, disks and surfaces of revolution; :mod:`psurf_core.techniques.grids`) is meshed as
quads; a kernel estimator's ``kernel_extent`` is drawn as spheres of the kernel radius
(points) or tubes (beams). A family that declares neither (or whose data layout changed) falls
back to its primitives' bounding boxes, and the legend says so.
"""

from __future__ import annotations

import numpy as np

from . import baked_light
from ._vtk import pv
from .palette import technique_colour, text_on
from .scene_view import (
    FONT,
    FONT_SMALL,
    LINE,
    add_text,
    medium_bounds,
    pt,
    px,
    scale_of,
)

#: Cell arrays naming the primitive (row in its batch) and batch a drawn cell belongs to.
PRIM_ROW, PRIM_BATCH = "prim_row", "prim_batch"
#: Prefixes of the actor names primitives are drawn under (``<prefix>-<technique>:mesh`` and
#: ``...:edges``: pyvista's ``add_mesh(name=X)`` removes every actor named ``X-...``, so no
#: name may be another's prefix followed by ``-``, as ``plane-t1t2`` is ``plane-t1t2-short``'s).
PRIM_ACTORS = ("prims", "hitprims", "context", "coverage")
#: Default number of photon subpaths drawn (``+``/``-`` in the window change it).
DEFAULT_PATHS = 24
#: At most this many primitives per technique in the Create view.
MAX_PRIMS = 60
#: Colour map of scatter events (perceptually uniform, colour-blind safe).
PATH_CMAP = "viridis"
#: Scatter events get distinct colours up to this index; deeper ones share the last colour.
MAX_EVENT_COLOURS = 8


# --------------------------------------------------------------------------- photon paths
def drawn_photons(paths_list: list, n: int) -> list:
    """``(batch, photon)`` pairs of the first ``n`` photons of the pass."""
    out = []
    for b, paths in enumerate(paths_list):
        for p in range(len(paths)):
            if len(out) >= n:
                return out
            out.append((b, p))
    return out


def paths_mesh(paths_list: list, scene, n: int):
    """Clipped segments and in-box vertices of the first ``n`` photons.

    Returns
    -------
    lines : pv.PolyData
        One line cell per drawn segment, cell data ``event`` (the vertex it ends at, ``j``).
    verts : pv.PolyData
        Points: scattering vertices inside the box, point data ``event``; may be empty.
    """
    seg_pts, seg_ev, vtx, vtx_ev = [], [], [], []
    lo, hi = scene.medium.bounds_min, scene.medium.bounds_max
    for b, p in drawn_photons(paths_list, n):
        P = paths_list[b]
        for j in range(1, P.depth + 1):
            if not P.alive[p, j - 1]:
                break
            a, c = P.clip[p, j - 1]
            x, w = P.x[p, j - 1], P.w[p, j - 1]
            if c > a:
                seg_pts.append((x + a * w, x + c * w))
                seg_ev.append(j)
            y = P.x[p, j]
            if np.all(y >= lo) and np.all(y <= hi):
                vtx.append(y)
                vtx_ev.append(j)
    if seg_pts:
        pts = np.array(seg_pts).reshape(-1, 3)
        m = len(seg_pts)
        cells = np.column_stack([np.full(m, 2), 2 * np.arange(m), 2 * np.arange(m) + 1]).ravel()
        lines = pv.PolyData(pts, lines=cells)
        lines.cell_data["event"] = np.minimum(np.array(seg_ev), MAX_EVENT_COLOURS)
    else:
        lines = pv.PolyData()
    verts = pv.PolyData(np.array(vtx).reshape(-1, 3))
    if vtx:
        verts.point_data["event"] = np.minimum(np.array(vtx_ev), MAX_EVENT_COLOURS)
    return lines, verts


def add_paths(plotter: pv.Plotter, paths_list: list, scene, n: int, *, opacity: float = 1.0,
              line_width: float = LINE, scalar_bar: bool = True, name: str = "paths") -> int:
    """Draw the first ``n`` photon subpaths; returns the number of segments drawn."""
    lines, verts = paths_mesh(paths_list, scene, n)
    if lines.n_cells == 0:
        return 0
    clim = [1, MAX_EVENT_COLOURS]
    bar = dict(title="scatter event j", n_labels=MAX_EVENT_COLOURS, fmt="%.0f",
               title_font_size=pt(FONT), label_font_size=pt(FONT_SMALL), color="black",
               vertical=False, position_x=0.05, position_y=0.03, width=0.4, height=0.07)
    plotter.add_mesh(lines, scalars="event", cmap=PATH_CMAP, clim=clim,
                     n_colors=MAX_EVENT_COLOURS, line_width=px(line_width), opacity=opacity,
                     render_lines_as_tubes=False, show_scalar_bar=scalar_bar,
                     scalar_bar_args=bar, name=name)
    if verts.n_points:
        r = 0.55 * scale_of(scene)
        glyphs = verts.glyph(geom=pv.Sphere(radius=r, theta_resolution=12, phi_resolution=12),
                             scale=False, orient=False)
        plotter.add_mesh(glyphs, scalars="event", cmap=PATH_CMAP, clim=clim,
                         n_colors=MAX_EVENT_COLOURS, opacity=opacity, show_scalar_bar=False,
                         name=f"{name}-vertices")
    return lines.n_cells


# --------------------------------------------------------------------------- surfaces
def grid_surface(P: np.ndarray) -> pv.PolyData:
    """Quads of ``M`` parametric patches sampled on ``(M, na, nb, 3)`` grids."""
    m, na, nb, _ = P.shape
    if m == 0:
        return pv.PolyData()
    i, j = np.meshgrid(np.arange(na - 1), np.arange(nb - 1), indexing="ij")
    i, j = i.ravel(), j.ravel()
    base = (i * nb + j)[None, :] + (np.arange(m) * na * nb)[:, None]
    q = np.stack([np.full_like(base, 4), base, base + nb, base + nb + 1, base + 1], axis=-1)
    return pv.PolyData(P.reshape(-1, 3).astype(float), faces=q.ravel())


def _family_mesh(tech, prims, idx: np.ndarray, scene, radius: float):
    """Geometry of primitives ``idx`` of one technique (unclipped), from what its family
    declares: the grid sweeping each surface (``tech.surface_grid``), or for a kernel
    estimator (``tech.surface`` False) its photon points (balls of the kernel radius) or beam
    segments (tubes). Returns ``(mesh, per_primitive)``: whether the mesh has the same
    number of cells for every primitive, in order. NotImplementedError where the family
    declares neither."""
    far = 3.0 * scene.medium.diagonal
    if tech.surface:
        return grid_surface(tech.surface_grid(prims, idx, far)), True
    ext = tech.kernel_extent(prims, idx, scene, far)
    if ext.shape[1] == 1:  # photon points
        r = radius if radius > 0 else scale_of(scene)
        return pv.PolyData(ext[:, 0]).glyph(geom=pv.Sphere(radius=r, theta_resolution=14,
                                                           phi_resolution=14),
                                            scale=False, orient=False), True
    if ext.shape[0] == 0:
        return pv.PolyData(), False
    k = ext.shape[0]
    cells = np.column_stack([np.full(k, 2), 2 * np.arange(k), 2 * np.arange(k) + 1])
    r = radius if radius > 0 else 0.3 * scale_of(scene)
    # Beams outside the box are left out: the tubes' cells are not one set per primitive.
    return pv.PolyData(ext.reshape(-1, 3), lines=cells.ravel()).tube(radius=r, n_sides=16), False


def _bounds_boxes(prims, idx) -> pv.PolyData:
    out = pv.PolyData()
    for i in idx:
        lo, hi = prims.lo[i], prims.hi[i]
        if np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(hi >= lo):
            out = out.merge(pv.Box(bounds=(lo[0], hi[0], lo[1], hi[1], lo[2], hi[2])).outline())
    return out


#: Meshes of recently drawn primitives (stepping through the stages draws the same ones again;
#: building and clipping them is most of a stage's drawing time). Keyed by the primitives'
#: identity, which each entry keeps alive so the key stays valid.
_MESHES: dict = {}
MESH_CACHE = 48


def primitive_mesh(tech, prims, idx, scene, radius: float):
    """Geometry of primitives ``idx`` of ``tech``, clipped to the medium box (a copy the caller
    may add arrays to; recently built ones are reused).

    Returns
    -------
    mesh : pv.PolyData (possibly empty)
    how : str
        ``"surface"`` (drawn by family) or ``"bounds"`` (fallback: bounding boxes).
    """
    idx = np.asarray(idx, dtype=np.int64)
    if idx.size == 0:
        return pv.PolyData(), "surface"
    key = (id(prims), id(scene), tech.name, float(radius), idx.tobytes())
    hit = _MESHES.get(key)
    if hit is None:
        mesh, how = _primitive_mesh(tech, prims, idx, scene, radius)
        if len(_MESHES) >= MESH_CACHE:
            _MESHES.pop(next(iter(_MESHES)))
        _MESHES[key] = hit = (mesh, how, prims, scene)
    mesh, how = hit[0], hit[1]
    return mesh.copy(deep=False), how


def _primitive_mesh(tech, prims, idx: np.ndarray, scene, radius: float):
    try:
        mesh, per_primitive = _family_mesh(tech, prims, idx, scene, radius)
    except (KeyError, IndexError, ValueError, NotImplementedError):
        return _bounds_boxes(prims, idx), "bounds"
    if mesh.n_points == 0:
        return mesh, "surface"
    # Which primitive each cell belongs to (right click picks it).
    if per_primitive and mesh.n_cells % idx.size == 0:
        mesh.cell_data[PRIM_ROW] = np.repeat(idx, mesh.n_cells // idx.size)
    clipped = mesh.clip_box(medium_bounds(scene), invert=False)
    if not isinstance(clipped, pv.PolyData):
        clipped = clipped.extract_surface()
    return clipped, "surface"


def create_selection(inspection, n_paths: int, max_prims: int = MAX_PRIMS) -> dict:
    """``(technique, batch) -> primitive rows`` made from the first ``n_paths`` photons."""
    drawn = {}
    for b, p in drawn_photons(inspection.paths, n_paths):
        drawn.setdefault(b, []).append(p)
    sel = {}
    for (name, b), prims in inspection.prims.items():
        ph = np.asarray(drawn.get(b, []), dtype=np.int64)
        rows = np.flatnonzero(np.isin(prims.photon, ph))
        sel[(name, b)] = rows[:max_prims]
    return sel


def add_primitives(plotter: pv.Plotter, inspection, selection: dict, **kw) -> dict:
    """Draw the selected primitives of every technique; returns ``technique -> status``.

    ``status`` is ``"N drawn"``, ``"N bounds only"`` or ``"none"``; techniques with nothing
    selected appear in the legend as "none here" when ``list_empty``. Keywords as
    :func:`primitive_steps`.
    """
    steps = primitive_steps(plotter, inspection, selection, **kw)
    while True:
        try:
            next(steps)
        except StopIteration as stop:
            return stop.value


def primitive_steps(plotter: pv.Plotter, inspection, selection: dict, *, opacity: float = 0.45,
                    edges: bool = True, name: str = "prims", legend: bool = True,
                    legend_loc: str = "lower right", width: float = 3.0,
                    list_empty: bool = True):
    """:func:`add_primitives` one technique per step (a generator; it returns the status):
    meshing and clipping a technique's primitives the first time is the dearest part of a
    stage's 3D view (the window spreads the steps over its timer ticks,
    :mod:`ui.views.view3d`). Each step draws into the plotter's current renderer."""
    status = {}
    entries = []
    drew = False  # a step ends after a technique that had primitives to mesh and draw
    for tname, tech in inspection.techniques.items():
        if drew:
            yield
        drew = False
        meshes, how, count = [], "surface", 0
        for (n2, b), rows in selection.items():
            if n2 != tname or len(rows) == 0:
                continue
            mesh, how = primitive_mesh(tech, inspection.prims[(n2, b)], rows, inspection.scene,
                                       inspection.radii.get(tname, 0.0))
            if PRIM_ROW in mesh.cell_data:
                mesh.cell_data[PRIM_BATCH] = np.full(mesh.n_cells, b, dtype=np.int64)
            count += len(rows)
            if mesh.n_points:
                meshes.append(mesh)
        col = technique_colour(tname)
        drew = count > 0
        if count == 0:
            status[tname] = "none"
            if list_empty:
                entries.append([f"{tname}: none here", col])
            continue
        merged = meshes[0] if len(meshes) == 1 else (meshes[0].merge(meshes[1:])
                                                     if meshes else pv.PolyData())
        if merged.n_points:
            if how == "bounds":
                plotter.add_mesh(merged, color=col, line_width=px(width),
                                 name=f"{name}-{tname}:mesh")
            else:
                fe = (merged.extract_feature_edges(boundary_edges=True, feature_edges=False,
                                                   manifold_edges=False,
                                                   non_manifold_edges=False)
                      if edges else None)
                if baked_light.enabled(plotter):  # the window in software OpenGL
                    baked_light.shade(merged, col, plotter.renderer)
                    plotter.add_mesh(merged, scalars=baked_light.SHADE, rgb=True,
                                     lighting=False, opacity=opacity, show_edges=False,
                                     show_scalar_bar=False, name=f"{name}-{tname}:mesh",
                                     culling=False)
                else:
                    plotter.add_mesh(merged, color=col, opacity=opacity, show_edges=False,
                                     smooth_shading=False, name=f"{name}-{tname}:mesh",
                                     culling=False)
                if fe is not None and fe.n_points:
                    plotter.add_mesh(fe, color=col, line_width=px(width),
                                     name=f"{name}-{tname}:edges")
        tag = "bounds only (no drawer)" if how == "bounds" else "drawn"
        status[tname] = f"{count} {tag}"
        entries.append([f"{tech.family}: {tname} ({count}{', bounds' if how == 'bounds' else ''})",
                         col])
    if legend and entries:
        add_legend(plotter, entries, loc=legend_loc)
    return status


def add_legend(plotter: pv.Plotter, entries: list, loc: str = "lower right") -> None:
    """A legend of colour chips (label on its technique's colour), stacked in a corner of the
    current renderer, one text line apart whatever the renderer's height.

    ``entries`` is a list of ``[label, colour]``; ``loc`` is ``"lower right"`` or
    ``"upper right"``.
    """
    ren = plotter.renderer
    vx0, vy0, vx1, vy1 = ren.GetViewport()
    vh = max((vy1 - vy0) * plotter.window_size[1], 1.0)
    step = 1.55 * pt(FONT_SMALL) / vh
    n = len(entries)
    y0 = (0.02 + step * n) if loc == "lower right" else 0.98
    for i, (label, col) in enumerate(entries):
        add_text(plotter, f" {label} ", 0.985, y0 - i * step, FONT_SMALL, align="right",
                 colour=text_on(col), background=col, name=f"legend-{i}")


def picked_primitive(renderer, actor, cell_id: int):
    """``(technique, batch, prim)`` of the primitive cell ``cell_id`` of ``actor`` (a mesh
    :func:`add_primitives` drew in ``renderer``), or None for anything else."""
    if actor is None or cell_id < 0:
        return None
    name = next((n for n, a in renderer.actors.items() if a is actor), None)
    if name is None or not name.endswith(":mesh"):
        return None
    prefix, _, technique = name[: -len(":mesh")].partition("-")
    if prefix not in PRIM_ACTORS or not technique:
        return None
    mesh = actor.GetMapper().GetInput()
    data = pv.wrap(mesh).cell_data
    if PRIM_ROW not in data or PRIM_BATCH not in data or cell_id >= mesh.GetNumberOfCells():
        return None
    return technique, int(data[PRIM_BATCH][cell_id]), int(data[PRIM_ROW][cell_id])
