"""2D image panels (pyvista): the single render and per-pass variance panels of lecture mode
(:func:`add_render_panel`, :func:`add_variance_panel`), the off-screen figures of the panel
modes (:class:`FigureMaker`: recordings, ``breakdown``, the demo's comparison), and, re-exported,
the window's tiled panels (:class:`ui.views.panel_view.PanelView`) and the modes
(:mod:`ui.views.panel_modes`).

Images are ``(H, W, ...)`` arrays with row 0 at the top, as the core renders them; here they
are shown as VTK image cells (one cell per pixel, ``y`` up), so a pixel ``(X, Y)`` is the cell
spanning ``[X, X+1] x [H-Y-1, H-Y]`` (the tiles of ``PanelView`` keep that layout, scaled).
"""

from __future__ import annotations

import numpy as np

from psurf_core import images as im

from . import scene_view
from ._vtk import pv, rendered_image
from .panel_modes import (  # noqa: F401 - the modes' names are part of this module's API
    MEAN_VARIANCE_BAR,
    MODE_HELP,
    MODES,
    VARIANCE_CMAP,
    WEIGHT_BAR,
    WEIGHT_CMAP,
    Area,
    Entry,
    Tile,
    VarScale,
    entries_of,
    mode_areas,
    next_mode,
)
from .panel_view import PanelView, fit_title, pixel_outline, tile_rgb  # noqa: F401
from .scene_view import FONT_SMALL, HIGHLIGHT, OKABE_ITO, add_text, fit_font, pt, px

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


def add_variance_panel(plotter: pv.Plotter, var: np.ndarray, pixel_xy, title: str,
                       clim: tuple | None = None) -> None:
    """Per-pass variance in false colour (log scale) with a colour bar; ``clim`` pins the
    range (lecture states that compare estimators share one), default the map's own."""
    v = variance_values(var)
    h, w = v.shape
    lo, hi = im.log_range(v) if clim is None else (float(clim[0]), float(clim[1]))
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


def draw_image_panels(plotter: pv.Plotter, subplots, source, mode: str = "render",
                      pixel_xy=None, view: PanelView | None = None, **kw) -> PanelView:
    """Draw ``mode`` into ``subplots`` (see :meth:`PanelView.draw`); returns the view to
    pass back next time (in-place updates)."""
    view = PanelView() if view is None else view
    view.draw(plotter, subplots, source, mode, pixel_xy, **kw)
    return view


class FigureMaker:
    """Off-screen figures of the panels (recording, the ``breakdown`` command, the demo's
    comparison): one plotter with the two areas one above the other (and, with ``title``, a
    title line above them), reused frame after frame."""

    def __init__(self, size=(1200, 900), *, title: bool = False):
        scene_view.plain_text()
        self.size = (int(size[0]), int(size[1]))
        self.titled = bool(title)
        shape = dict(shape=(3, 1), row_weights=[0.07, 0.44, 0.49]) if title else \
            dict(shape=(2, 1))
        self.plotter = pv.Plotter(window_size=list(self.size), off_screen=True, border=False,
                                  **shape)
        self.plotter.set_background("white", all_renderers=True)
        # Pixel-aligned image tiles need no multisampling, and software OpenGL (llvmpipe, no
        # display) spends most of a frame on it: 4x MSAA costs ~0.25 s at 1200 x 900.
        self.plotter.ren_win.SetMultiSamples(0)
        self.view = PanelView()

    def frame(self, source, mode: str = "render", pixel_xy=None, *, title: str = "",
              **kw) -> np.ndarray:
        """(H, W, 3) uint8 picture of ``mode`` for ``source`` (``title``: the title line)."""
        # Fonts as in the window (18 pt at the design size) for a 960 x 720 figure.
        scene_view.set_scale(self.size[1] * scene_view.DESIGN_HEIGHT / 720.0)
        cells = [(1, 0), (2, 0)] if self.titled else [(0, 0), (1, 0)]
        if self.titled:
            self.plotter.subplot(0, 0)
            self.plotter.renderer.clear_actors()
            size = fit_font(title, pt(FONT_SMALL), (0.97 * self.size[0], 0.07 * self.size[1]))
            add_text(self.plotter, title, 0.5, 0.9, FONT_SMALL, size_px=size, align="center",
                     name="figure-title")
        self.view.draw(self.plotter, cells, source, mode, pixel_xy, **kw)
        return rendered_image(self.plotter)

    def close(self) -> None:
        self.plotter.close()


def panel_figure(source, mode: str = "render", out: str | None = None, size=(1200, 900),
                 pixel_xy=None, **kw) -> np.ndarray:
    """One off-screen picture of ``mode`` (written atomically to ``out`` as PNG if given)."""
    fm = FigureMaker(size)
    try:
        img = fm.frame(source, mode, pixel_xy, **kw)
    finally:
        fm.close()
    if out is not None:
        im.write_png(out, img)
    return img
