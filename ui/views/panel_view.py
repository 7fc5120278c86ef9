"""The image panels' tiles, drawn and updated in place: :class:`PanelView` lays out the
:class:`~ui.views.panel_modes.Area` s of a mode (``ui.views.panel_modes.mode_areas``) in a set of
subplots: one textured quad per image (nearest-neighbour, so pixels stay crisp; a tenth of the
cost of one quad per pixel in software OpenGL), its title fitted to the tile (shrunk, then
wrapped at an estimator spec's joints: never cut), the inspected estimator's tiles framed, the
picked pixel outlined, one colour bar per area. Actors are built once per layout and then
updated in place (new texture values, ranges, texts), so a progressive frame costs a few
milliseconds, not a rebuild.
"""

from __future__ import annotations

import functools

import numpy as np

from . import scene_view
from ._vtk import pv, vtkTextActor
from .palette import text_on
from .panel_modes import Area, Tile, mode_areas
from .scene_view import FONT_SMALL, HIGHLIGHT, OKABE_ITO, fit_font, pt, px

__all__ = ["PanelView", "fit_title", "tile_rgb"]


def pixel_outline(pixel_xy, height: int, grow: float = 0.0) -> pv.PolyData:
    """The outline of pixel ``(X, Y)`` in panel coordinates (slightly above the image)."""
    x, y = pixel_xy
    y0 = height - y - 1
    g = grow
    pts = np.array([[x - g, y0 - g, 0.05], [x + 1 + g, y0 - g, 0.05],
                    [x + 1 + g, y0 + 1 + g, 0.05], [x - g, y0 + 1 + g, 0.05]])
    return pv.PolyData(pts, lines=np.array([5, 0, 1, 2, 3, 0]))


def _label(plotter, text: str, x: float, y: float, size_px: int, *, name: str,
           align: str = "center", bold: bool = False, background: str | None = None):
    """A text whose top ``align`` point is at the normalised viewport position ``(x, y)``,
    ``size_px`` pixels (already scaled).

    A plain ``vtkTextActor`` (not ``plotter.add_text``): after a panel was rebuilt with
    another layout, pyvista's text actors sometimes came back at twice their font size.
    """
    actor = vtkTextActor()
    actor.SetInput(text)
    actor.SetTextScaleModeToNone()
    coord = actor.GetPositionCoordinate()
    coord.SetCoordinateSystemToNormalizedViewport()
    coord.SetValue(x, y)
    prop = actor.GetTextProperty()
    prop.SetFontSize(int(size_px))
    prop.SetFontFamilyToArial()
    prop.SetColor(*pv.Color(scene_view.TEXT_COLOUR if background is None
                            else text_on(background)).float_rgb)
    if background is not None:  # a technique's tile: its title on the technique's colour
        prop.SetBackgroundColor(*pv.Color(background).float_rgb)
        prop.SetBackgroundOpacity(1.0)
    prop.SetBold(bold)
    prop.SetVerticalJustificationToTop()
    {"center": prop.SetJustificationToCentered, "right": prop.SetJustificationToRight,
     "left": prop.SetJustificationToLeft}[align]()
    plotter.add_actor(actor, name=name, reset_camera=False, pickable=False)
    return actor


def _outline_points(pixel_xy, height: int, s: float, x0: float, y0: float) -> np.ndarray:
    """(4, 3) corners of the outline of pixel ``pixel_xy`` on a tile at ``(x0, y0)`` drawn
    ``s`` viewport pixels per image pixel."""
    # at least a few screen pixels around it: a 160x120 render's pixel is ~2 pixels wide
    # (the corners of ``pixel_outline``, without building a mesh: this runs every frame)
    g = max(0.6, px(4) / max(s, 1e-6))
    x, y = pixel_xy
    yb = height - y - 1
    pts = np.array([[x - g, yb - g, 0.05], [x + 1 + g, yb - g, 0.05],
                    [x + 1 + g, yb + 1 + g, 0.05], [x - g, yb + 1 + g, 0.05]])
    return pts * [s, s, 1.0] + [x0, y0, 0.0]


#: Titles are never cut: they shrink down to this share of the tile font, then wrap.
MIN_TITLE_SHARE = 0.72


def _wrap_spec(line: str) -> list[str]:
    """``line`` in two at the joint nearest its middle: before a spec's ``~`` or ``+``, or
    at a space (a line without joints stays whole)."""
    cuts = [i for i, ch in enumerate(line) if ch in "~+" and i > 0]
    cuts += [i + 1 for i, ch in enumerate(line) if ch == " " and 0 < i < len(line) - 1]
    if not cuts:
        return [line]
    i = min(cuts, key=lambda c: abs(c - len(line) / 2))
    return [line[:i].rstrip(), line[i:].lstrip()]


def fit_title(text: str, width_px: float, size_px: int, *, bold: bool = False) -> tuple:
    """``(text, size)``: ``text`` at the largest size ``<= size_px`` that fits ``width_px``
    per line; lines that would need less than :data:`MIN_TITLE_SHARE` of the size are
    wrapped (at spec joints, then spaces) instead. Nothing is ever cut."""
    lines = text.split("\n")
    floor = max(7, int(MIN_TITLE_SHARE * size_px))
    out = []
    for line in lines:
        todo = [line]
        while todo:
            cur = todo.pop(0)
            size = fit_font(cur, size_px, (width_px, 10 * size_px), bold=bold)
            if size < floor:
                parts = _wrap_spec(cur)
                if len(parts) > 1 and all(parts):
                    todo[:0] = parts
                    continue
            out.append(cur)
    joined = "\n".join(out)
    return joined, fit_font(joined, size_px, (width_px, 100 * size_px), bold=bold,
                            minimum=min(floor, 7))


def _grid_shape(n: int, w: int, h: int, vw: float, vh: float, label_px: float,
                rows: int | None) -> tuple:
    """(rows, cols, scale) that makes ``n`` tiles of ``w x h`` pixels largest in the viewport
    ``vw x vh`` (pixels) with ``label_px`` above every row and a 4% gap between tiles."""
    best = None
    for r in ([rows] if rows else range(1, n + 1)):
        c = -(-n // r)
        s = min(vw / (c * w * 1.06), (vh - r * label_px) / (r * h * 1.04))
        if best is None or s > best[2]:
            best = (r, c, s)
    return best


@functools.lru_cache(maxsize=8)
def _lut(cmap: str) -> np.ndarray:
    """(256, 3) uint8 colours of a matplotlib colour map."""
    from matplotlib import colormaps

    return np.round(colormaps[cmap](np.linspace(0.0, 1.0, 256))[:, :3] * 255).astype(np.uint8)


def tile_rgb(tile: Tile) -> np.ndarray:
    """(H, W, 3) uint8 picture of a tile: its ``rgb``, or its ``values`` in false colour
    (clipped to ``clim``, log scale when ``log``, as its colour bar shows them)."""
    if tile.rgb is not None:
        return tile.rgb
    lo, hi = (float(v) for v in tile.clim)
    v = np.where(np.isfinite(tile.values), tile.values, lo)
    v = np.clip(v, lo, hi)
    if tile.log:
        lo, hi = np.log10(max(lo, 1e-300)), np.log10(max(hi, 1e-300))
        v = np.log10(np.maximum(v, 1e-300))
    t = (v - lo) / (hi - lo) if hi > lo else np.zeros_like(v)
    return _lut(tile.cmap)[np.clip(np.round(t * 255), 0, 255).astype(np.int64)]


def _tile_actor(plotter, tile: Tile, name: str, origin, s: float, hw):
    """A tile as one textured quad at ``origin`` (viewport pixels), ``s`` pixels per image
    pixel, nearest-neighbour sampled: a tenth of the drawing cost of one quad per pixel in
    software OpenGL. Its field data say where it is (``controls.image_tiles``: picking).

    Returns ``(image, actor)``; the image's ``rgb`` is updated in place frame after frame.
    """
    from .controls import TILE_FIELD

    h, w = hw
    x0, y0 = origin
    img = pv.ImageData(dimensions=(w, h, 1))
    img.point_data["rgb"] = tile_rgb(tile)[::-1].reshape(h * w, 3)
    tex = pv.Texture(img)
    tex.interpolate = False
    x1, y1 = x0 + w * s, y0 + h * s
    quad = pv.PolyData(np.array([[x0, y0, 0.0], [x1, y0, 0.0], [x1, y1, 0.0], [x0, y1, 0.0]]),
                       faces=np.array([4, 0, 1, 2, 3]))
    quad.active_texture_coordinates = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0],
                                                [0.0, 1.0]])
    quad.field_data[TILE_FIELD] = np.array([x0, y0, s, w, h], dtype=float)
    actor = plotter.add_mesh(quad, texture=tex, lighting=False, show_scalar_bar=False,
                             name=name, reset_camera=False)
    return tex.GetInput() if tex.GetInput() is not None else img, actor


class PanelView:
    """The image panels of one mode in a set of subplots, updated in place between frames.

    Call :meth:`draw` every time there is something new (a merged pass, another mode, a moved
    pixel); it rebuilds its actors only when the layout changed or the subplot was cleared.
    """

    def __init__(self):
        self._key = {}
        self._parts = {}

    def draw(self, plotter: pv.Plotter, subplots, source, mode: str = "render",
             pixel_xy=None, *, reference=None, estimator=None, technique=None,
             k=None, clim=None, scale=None, inspected=None) -> None:
        """Draw ``mode`` (see :func:`ui.views.panel_modes.mode_areas`) of ``source`` into
        ``subplots``.

        Parameters
        ----------
        subplots : list of (int, int)
            Subplot indices of ``plotter``; area ``i`` goes to ``subplots[i]`` (extra areas
            are dropped, so one subplot shows the images only).
        source : Progressive, list of runs, dict of Welford, or Welford
        pixel_xy : (int, int), optional
            Picked pixel, outlined on the render and variance tiles.
        clim, scale, inspected
            The variance maps' range or shared :class:`VarScale`, and the inspected
            estimator (framed); see ``mode_areas``.
        """
        areas = mode_areas(source, mode, reference=reference, estimator=estimator,
                           technique=technique, k=k, clim=clim, scale=scale,
                           inspected=inspected)
        # Once a window has been shown pyvista renders after every added actor; a rebuild adds
        # dozens (seconds in software OpenGL), so rendering is held: the caller renders once.
        held = plotter.suppress_rendering
        plotter.suppress_rendering = True
        try:
            for idx, (sub, area) in enumerate(zip(subplots, areas, strict=False)):
                plotter.subplot(*sub)
                self._draw_area(plotter, f"ip{idx}", area, pixel_xy)
        finally:
            plotter.suppress_rendering = held

    # ------------------------------------------------------------------ one area
    def _fitted(self, area: Area, vw: float, vh: float, top_px: float, bottom_px: float,
                hw) -> tuple:
        """Grid, scale and fitted tile titles of ``area`` in a ``vw x vh`` viewport."""
        h, w = hw
        size = pt(FONT_SMALL)
        line_px = 1.3 * size
        n = max(len(area.tiles), 1)
        titles = [t.title for t in area.tiles]
        lines = max((t.count("\n") + 1 for t in titles), default=1)
        for _ in range(2):  # fitting may wrap titles onto more lines: lay out again once
            label_px = lines * line_px + 6
            rows, cols, s = _grid_shape(n, w, h, vw, vh - top_px - bottom_px, label_px,
                                        area.rows)
            s = max(s, 1e-3)
            room = max(w * s * 1.04, 40.0)
            fitted = [fit_title(t, room, size, bold=tile.frame)
                      for t, tile in zip(titles, area.tiles, strict=True)]
            need = max((t.count("\n") + 1 for t, _ in fitted), default=1)
            if need <= lines:
                break
            lines = need
        return rows, cols, s, label_px, fitted

    def _draw_area(self, plotter, tag, area: Area, pixel_xy) -> None:
        ren = plotter.renderer
        vx0, vy0, vx1, vy1 = ren.GetViewport()
        ww, wh = plotter.window_size
        vw, vh = (vx1 - vx0) * ww, (vy1 - vy0) * wh
        size = pt(FONT_SMALL)
        header, header_size = fit_title(area.header, 0.98 * vw, size, bold=True)
        top_px = (header.count("\n") + 1) * 1.3 * header_size + 10
        bottom_px = max(0.14 * vh, 3.2 * size) if area.bar else 6.0
        h, w = area.tiles[0].values.shape if area.tiles and area.tiles[0].values is not None \
            else (area.tiles[0].rgb.shape[:2] if area.tiles else (1, 1))
        rows, cols, s, label_px, fitted = self._fitted(area, vw, vh, top_px, bottom_px, (h, w))
        key = (tag, id(ren), tuple((t.rgb is None, t.cmap, t.log, t.pixel, t.frame, t.colour)
                                   for t in area.tiles),
               area.rows, area.bar, round(vw), round(vh), (h, w), round(label_px),
               round(top_px), pixel_xy is None)
        parts = self._parts.get(tag)
        if self._key.get(tag) != key or parts is None or not self._alive(plotter, ren, parts):
            parts = self._build(plotter, tag, area, vw, vh, top_px, bottom_px, label_px,
                                (rows, cols, s), (h, w), pixel_xy)
            self._key[tag], self._parts[tag] = key, parts
        # in-place update: values, ranges, texts
        parts["header"].SetInput(header)
        parts["header"].GetTextProperty().SetFontSize(header_size)
        drawn = parts.setdefault("keys", [None] * len(area.tiles))
        for i, (tile, (img, _actor, text), (title, tsize)) in enumerate(
                zip(area.tiles, parts["tiles"], fitted, strict=True)):
            if text.GetInput() != title:  # a changed text is rasterized again: only then
                text.SetInput(title)
            text.GetTextProperty().SetFontSize(tsize)
            if tile.key is not None and drawn[i] == tile.key:
                continue  # the same picture: no new texture
            img.point_data["rgb"][:] = tile_rgb(tile)[::-1].reshape(h * w, 3)
            img.Modified()
            drawn[i] = tile.key
        if parts["bar"] is not None and area.bar is not None:
            lo, hi = next(t.clim for t in area.tiles if t.values is not None)
            keyed = parts["bar_actor"]
            keyed.mapper.SetScalarRange(lo, hi)
            keyed.mapper.lookup_table.SetRange(lo, hi)
            plotter.scalar_bars[parts["bar"]].SetTitle(area.bar)
        if pixel_xy is not None:  # a moved pixel moves the outlines (no rebuild)
            for mesh, (x0, y0, sc) in parts["outlines"]:
                mesh.points = _outline_points(pixel_xy, h, sc, x0, y0)

    @staticmethod
    def _alive(plotter, ren, parts) -> bool:
        # The window may have cleared the subplot or every scalar bar since the last frame.
        bar_ok = parts["bar"] is None or parts["bar"] in plotter.scalar_bars
        # ``ren.actors`` builds a dict of every actor on each access: once, not per name.
        names = set(ren.actors)
        return bar_ok and all(name in names for name in parts["names"])

    def _build(self, plotter, tag, area: Area, vw, vh, top_px, bottom_px, label_px, grid_rcs,
               hw, pixel_xy) -> dict:
        ren = plotter.renderer
        old = self._parts.get(tag)
        # Only this area's own bar: bars are keyed by title across the whole plotter.
        if old is not None and old["bar"] is not None and old["bar"] in plotter.scalar_bars:
            plotter.remove_scalar_bar(old["bar"])
        ren.clear_actors()
        ren.set_background("white")
        h, w = hw
        rows, cols, s = grid_rcs
        names, outlines = [], []
        header = _label(plotter, area.header, 0.5, 1.0 - 4 / vh, pt(FONT_SMALL),
                        name=f"{tag}-header", align="center", bold=True)
        names.append(f"{tag}-header")
        tiles = []
        gap_x = 0.06 * w * s
        row_h = h * s * 1.04 + label_px
        x_start = (vw - cols * w * s - (cols - 1) * gap_x) / 2
        # the grid centred between the header and the colour bar
        spare = max(vh - top_px - bottom_px - rows * row_h, 0.0)
        top_px = top_px + 0.5 * spare
        bar_done, bar_actor = False, None
        bar_key = f"{area.bar}#{tag}" if area.bar else None  # bars are keyed by title
        for i, tile in enumerate(area.tiles):
            r, c = divmod(i, cols)
            px0 = x_start + c * (w * s + gap_x)
            py_top = vh - top_px - r * row_h  # top of this row's label (pixels from bottom)
            py0 = py_top - label_px - h * s
            name = f"{tag}-tile{i}"
            img, actor = _tile_actor(plotter, tile, name, (px0, py0), s, (h, w))
            if tile.values is not None and area.bar is not None and not bar_done:
                # The colour bar of the area's maps: a hidden mesh carries its lookup table.
                lo, hi = tile.clim
                bar = dict(title=bar_key, title_font_size=pt(FONT_SMALL),
                           label_font_size=pt(FONT_SMALL), n_labels=3,
                           fmt="%.0e" if tile.log else "%.1f", color="black", vertical=False,
                           position_x=0.1, position_y=0.02,
                           width=0.8, height=min(0.13, 0.9 * bottom_px / vh))
                carrier = pv.PolyData(np.zeros((2, 3)))
                carrier.point_data["values"] = np.array([lo, hi])
                bar_actor = plotter.add_mesh(carrier, scalars="values", cmap=tile.cmap,
                                             log_scale=tile.log, clim=(lo, hi),
                                             show_scalar_bar=True, scalar_bar_args=bar,
                                             name=f"{tag}-barmesh", reset_camera=False)
                bar_actor.SetVisibility(False)
                names.append(f"{tag}-barmesh")
                plotter.scalar_bars[bar_key].SetTitle(area.bar)
                bar_done = True
            names.append(name)
            text = _label(plotter, tile.title, (px0 + w * s / 2) / vw, py_top / vh,
                          pt(FONT_SMALL), name=f"{name}-title", align="center",
                          bold=tile.frame, background=tile.colour)
            names.append(f"{name}-title")
            if tile.frame:  # the inspected estimator: a frame around its tile
                g = max(px(3), 3.0)
                corners = np.array([[px0 - g, py0 - g, 0.04], [px0 + w * s + g, py0 - g, 0.04],
                                    [px0 + w * s + g, py0 + h * s + g, 0.04],
                                    [px0 - g, py0 + h * s + g, 0.04]])
                plotter.add_mesh(pv.PolyData(corners, lines=np.array([5, 0, 1, 2, 3, 0])),
                                 color=HIGHLIGHT, line_width=px(4), name=f"{name}-frame",
                                 reset_camera=False)
                names.append(f"{name}-frame")
            if tile.pixel and pixel_xy is not None:
                outline = pixel_outline(pixel_xy, h, 0.6)
                outline.points = _outline_points(pixel_xy, h, s, px0, py0)
                outlines.append((outline, (px0, py0, s)))
                plotter.add_mesh(outline, color=OKABE_ITO["vermillion"], line_width=px(3),
                                 name=f"{name}-pixel", reset_camera=False)
                names.append(f"{name}-pixel")
            tiles.append((img, actor, text))
        # World units are the viewport's pixels, so the camera depends on the viewport size
        # only. Moving the camera of a lower subplot while its actors were being replaced
        # left it blank (pyvista 0.49 / VTK, EGL): set it after the actors, and only when
        # it changes.
        cam = plotter.camera
        view = ((vw / 2, vh / 2, 0.0), (vw / 2, vh / 2, 1000.0), vh / 2)
        if (not cam.parallel_projection or cam.GetParallelScale() != view[2]
                or tuple(cam.GetFocalPoint()) != view[0]
                or tuple(cam.GetPosition()) != view[1]):
            cam.parallel_projection = True
            cam.focal_point = view[0]
            cam.position = view[1]
            cam.up = (0.0, 1.0, 0.0)
            cam.parallel_scale = view[2]
        ren.ResetCameraClippingRange()
        return {"header": header, "tiles": tiles, "names": names, "outlines": outlines,
                "bar": bar_key if bar_done else None,
                "bar_actor": bar_actor if bar_done else None}
