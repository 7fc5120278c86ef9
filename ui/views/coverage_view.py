"""Coverage on the image panels: the pixels one primitive contributes to (the window's ``c``
and a right click on a primitive; computed by :func:`psurf_core.inspect.primitive_pixels`),
tinted and outlined on the render tile (pyvista)."""

from __future__ import annotations

import numpy as np

from ._vtk import pv
from .scene_view import px

COVERAGE_TINT = "#56B4E9"  # Okabe-Ito sky blue: visible on the grey render
COVERAGE_EDGE = "#0072B2"  # Okabe-Ito blue


def coverage_mesh(mask: np.ndarray):
    """The covered pixels of an ``(H, W)`` bool mask (row 0 at the top) as panel cells
    (pixel ``(X, Y)`` is the cell ``[X, X+1] x [H-Y-1, H-Y]``, as in ``ui.views.image_panels``), and
    the outline of the covered region (the cell edges between a covered and an uncovered
    pixel, or the image border).

    Returns
    -------
    cells : pv.UnstructuredGrid (possibly empty)
    outline : pv.PolyData (possibly empty), segments at ``z = 0.03``
    """
    m = np.asarray(mask, dtype=bool)
    h, w = m.shape
    if not m.any():
        return pv.UnstructuredGrid(), pv.PolyData()
    up = m[::-1]  # VTK rows go up: up[j, i] is the cell [i, i+1] x [j, j+1]
    grid = pv.ImageData(dimensions=(w + 1, h + 1, 1), origin=(0.0, 0.0, 0.02))
    cells = grid.extract_cells(np.flatnonzero(up.reshape(-1)))
    pad = np.pad(up, 1)
    j, i = np.nonzero(up)
    segs = []
    # (neighbour offset, edge start, edge end) for left, right, bottom, top edges
    for (dj, di), (a, b) in (((0, -1), ((0, 0), (0, 1))), ((0, 1), ((1, 0), (1, 1))),
                             ((-1, 0), ((0, 0), (1, 0))), ((1, 0), ((0, 1), (1, 1)))):
        edge = ~pad[j + 1 + dj, i + 1 + di]
        x, y = i[edge], j[edge]
        segs.append(np.stack([np.column_stack([x + a[0], y + a[1]]),
                              np.column_stack([x + b[0], y + b[1]])], axis=1))
    segs = np.concatenate(segs).astype(float)  # (S, 2, 2)
    n = segs.shape[0]
    pts = np.concatenate([segs.reshape(-1, 2), np.full((2 * n, 1), 0.03)], axis=1)
    lines = np.column_stack([np.full(n, 2), 2 * np.arange(n), 2 * np.arange(n) + 1]).ravel()
    return cells, pv.PolyData(pts, lines=lines)


def add_coverage(plotter: pv.Plotter, mask: np.ndarray, *, origin=(0.0, 0.0),
                 spacing: float = 1.0) -> int:
    """Tint the covered pixels on the current image panel and outline the region; returns
    the number of covered pixels. ``origin``/``spacing`` place the image (its lower-left
    corner and cell size) when it is a scaled tile."""
    cells, outline = coverage_mesh(mask)
    if origin != (0.0, 0.0) or spacing != 1.0:
        move = (float(origin[0]), float(origin[1]), 0.0)
        cells = cells.scale((spacing, spacing, 1.0)).translate(move) if cells.n_cells \
            else cells
        outline = outline.scale((spacing, spacing, 1.0)).translate(move) \
            if outline.n_points else outline
    if cells.n_cells:
        plotter.add_mesh(cells, color=COVERAGE_TINT, opacity=0.55, lighting=False,
                         name="coverage-cells", reset_camera=False)
    if outline.n_points:
        plotter.add_mesh(outline, color=COVERAGE_EDGE, line_width=px(2.5), lighting=False,
                         name="coverage-outline", reset_camera=False)
    return int(np.count_nonzero(mask))
