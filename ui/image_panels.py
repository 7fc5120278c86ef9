"""2D panels: the progressive render and its per-pixel variance (false colour, log scale,
with a colour bar), the picked pixel outlined on both (pyvista).

Images are ``(H, W, ...)`` arrays with row 0 at the top, as the core renders them; they are
shown as VTK image cells (one cell per pixel, ``y`` up), so a pixel ``(X, Y)`` is the cell
spanning ``[X, X+1] x [H-Y-1, H-Y]``.
"""

from __future__ import annotations

import numpy as np
import pyvista as pv

from psurf_core import images as im

from .scene_view import FONT_SMALL, HIGHLIGHT, OKABE_ITO, add_text, pt, px

VARIANCE_CMAP = "viridis"
VARIANCE_BAR = "variance (log)"


def image_grid(values: np.ndarray, name: str = "values") -> pv.ImageData:
    """An ImageData with one cell per pixel (``values`` (H, W) or (H, W, C))."""
    v = np.asarray(values)
    h, w = v.shape[:2]
    grid = pv.ImageData(dimensions=(w + 1, h + 1, 1), spacing=(1.0, 1.0, 1.0),
                        origin=(0.0, 0.0, 0.0))
    flipped = v[::-1]  # VTK rows go up
    grid.cell_data[name] = flipped.reshape(h * w, *v.shape[2:])
    return grid


def pixel_outline(pixel_xy, height: int, grow: float = 0.0) -> pv.PolyData:
    """The outline of pixel ``(X, Y)`` in panel coordinates (slightly above the image)."""
    x, y = pixel_xy
    y0 = height - y - 1
    g = grow
    pts = np.array([[x - g, y0 - g, 0.05], [x + 1 + g, y0 - g, 0.05],
                    [x + 1 + g, y0 + 1 + g, 0.05], [x - g, y0 + 1 + g, 0.05]])
    return pv.PolyData(pts, lines=np.array([5, 0, 1, 2, 3, 0]))


def fit_view(plotter: pv.Plotter, width: int, height: int, *, top: float = 0.16,
             bottom: float = 0.08) -> None:
    """2D camera that fits a ``width x height`` image in the current viewport, leaving
    ``top`` and ``bottom`` fractions of the viewport free (title, colour bar)."""
    ren = plotter.renderer
    vx0, vy0, vx1, vy1 = ren.GetViewport()
    ww, wh = plotter.window_size
    aspect = ((vx1 - vx0) * ww) / max((vy1 - vy0) * wh, 1.0)
    usable = 1.0 - top - bottom
    half_h = max(0.5 * height / usable, 0.5 * width * 1.06 / aspect / usable)
    cx = 0.5 * width
    # centre of the usable band: shift the focal point so the image sits in that band
    cy = 0.5 * height + (top - bottom) * half_h
    cam = plotter.camera
    cam.parallel_projection = True
    cam.focal_point = (cx, cy, 0.0)
    cam.position = (cx, cy, 10.0 * max(width, height))
    cam.up = (0.0, 1.0, 0.0)
    cam.parallel_scale = half_h
    ren.ResetCameraClippingRange()


def add_render_panel(plotter: pv.Plotter, mean: np.ndarray, pixel_xy, title: str) -> None:
    """The tone-mapped mean image of the progressive render."""
    h, w = mean.shape[:2]
    rgb = im.tone_map(mean)
    plotter.add_mesh(image_grid(rgb, "rgb"), scalars="rgb", rgb=True, lighting=False,
                     show_scalar_bar=False, name="render-image")
    if pixel_xy is not None:
        plotter.add_mesh(pixel_outline(pixel_xy, h, 0.6), color=OKABE_ITO["vermillion"],
                         line_width=px(4), name="render-pixel")
    add_text(plotter, title, 0.5, 0.97, FONT_SMALL, name="render-title", align="center")
    fit_view(plotter, w, h, bottom=0.24)


def variance_values(var: np.ndarray) -> np.ndarray:
    """(H, W) per-pixel variance of one pass's estimate (mean over RGB)."""
    v = np.asarray(var, dtype=float)
    return v.mean(axis=-1) if v.ndim == 3 else v


def add_variance_panel(plotter: pv.Plotter, var: np.ndarray, pixel_xy, title: str) -> None:
    """Per-pass variance in false colour (log scale) with a colour bar."""
    v = variance_values(var)
    h, w = v.shape
    lo, hi = im.log_range(v)
    shown = np.clip(np.where(np.isfinite(v), v, lo), lo, hi)
    bar = dict(title=VARIANCE_BAR, title_font_size=1, label_font_size=pt(FONT_SMALL),
               n_labels=3, fmt="%.0e", color="black", vertical=False,
               position_x=0.08, position_y=0.04, width=0.84, height=0.12)
    plotter.add_mesh(image_grid(shown, "variance"), scalars="variance", cmap=VARIANCE_CMAP,
                     log_scale=True, clim=(lo, hi), lighting=False, scalar_bar_args=bar,
                     name="variance-image")
    if pixel_xy is not None:
        plotter.add_mesh(pixel_outline(pixel_xy, h, 0.6), color=HIGHLIGHT, line_width=px(4),
                         name="variance-pixel")
        plotter.add_mesh(pixel_outline(pixel_xy, h, 1.4), color="white", line_width=px(2),
                         name="variance-pixel-halo")
    add_text(plotter, title, 0.5, 0.97, FONT_SMALL, name="variance-title", align="center")
    fit_view(plotter, w, h, bottom=0.24)
