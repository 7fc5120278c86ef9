"""2D panels: the progressive render and its per-pixel variance (false colour, log scale,
with a colour bar), the picked pixel outlined on both (pyvista).

Images are ``(H, W, ...)`` arrays with row 0 at the top, as the core renders them; they are
shown as VTK image cells (one cell per pixel, ``y`` up), so a pixel ``(X, Y)`` is the cell
spanning ``[X, X+1] x [H-Y-1, H-Y]``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from psurf_core import images as im
from psurf_core.accumulate import Welford

from . import scene_view
from ._vtk import pv, vtkTextActor
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


# =========================================================================== panel modes
# The window hands a list of subplots (e.g. its render and variance cells) to
# :class:`PanelView`, which tiles a mode's images into them. Actors are built once per layout
# and then updated in place (new cell values, ranges, texts), so a progressive frame costs a
# few milliseconds, not a rebuild.

#: Panel modes, in the order the window's ``m`` key cycles them.
MODES = ("render", "techniques", "bounces")
MODE_HELP = {
    "render": "each estimator's render and variance, side by side at equal time",
    "techniques": "MIS: each technique's weighted contribution and its weight map",
    "bounces": "per scatter count K; each technique unweighted vs weighted at one K",
}
#: Colour-blind-safe maps: viridis for variance, cividis for weights (linear, [0, 1]).
WEIGHT_CMAP = "cividis"
MEAN_VARIANCE_BAR = "variance of the mean (log)"
WEIGHT_BAR = "share of the pixel (mean MIS weight)"


def next_mode(mode: str) -> str:
    """The mode after ``mode`` (the window's ``m`` key)."""
    return MODES[(MODES.index(mode) + 1) % len(MODES)] if mode in MODES else MODES[0]


@dataclass
class Entry:
    """One estimator as the panels see it (``label``, ``acc``, ``seconds``, ``breakdown``)."""

    label: str
    acc: Welford
    seconds: float = 0.0
    breakdown: object = None


def entries_of(source) -> list:
    """Normalise a panel source: a ``Progressive``, a list of its runs, a ``{label: Welford}``
    dict or one ``Welford``."""
    if isinstance(source, Welford):
        return [Entry("render", source)]
    if isinstance(source, dict):
        return [Entry(str(k), v) for k, v in source.items()]
    runs = getattr(source, "runs", source)
    return [r if isinstance(r, Entry) else
            Entry(getattr(r, "label", getattr(r, "spec", "?")), r.acc,
                  float(getattr(r, "seconds", 0.0)), getattr(r, "breakdown", None))
            for r in runs]


@dataclass
class Tile:
    """One image of a panel: ``rgb`` (H, W, 3) uint8, or ``values`` (H, W) float drawn in
    false colour with range ``clim`` (log scale when ``log``)."""

    title: str
    rgb: np.ndarray | None = None
    values: np.ndarray | None = None
    clim: tuple = (1e-3, 1.0)
    log: bool = True
    cmap: str = VARIANCE_CMAP
    pixel: bool = False  # outline the picked pixel


@dataclass
class Area:
    """What one subplot shows: a header line, tiles on a grid, an optional colour bar."""

    header: str
    tiles: list
    rows: int | None = None  # None: the grid that makes tiles largest
    bar: str | None = None  # colour-bar title (for the false-colour tiles)


def _fmt_ratio(r) -> str:
    return "Var: n/a" if r is None else f"Var: {r:.2g}\u00d7"


def _k_of(layout, k) -> int:
    return layout.k_min + 1 if k is None and layout.n_k > 1 and layout.k_min < 2 else (
        layout.k_min if k is None else int(k))


def mode_areas(source, mode: str, *, reference: np.ndarray | None = None,
               estimator: int | None = None, technique=None, k: int | None = None) -> list:
    """The two areas (images, then maps) of ``mode`` for ``source``.

    Parameters
    ----------
    mode : {'render', 'techniques', 'bounces'}
    reference : (H, W, 3) ndarray, optional
        Ground truth: relMSE is shown per estimator in ``render`` mode.
    estimator : int, optional
        Which estimator the ``techniques``/``bounces`` modes break down (default: the first
        with a breakdown).
    technique : str or int, optional
        ``bounces``: show this technique's images per K (unweighted vs weighted) instead of
        every technique at one K.
    k : int, optional
        ``bounces``: the scatter count compared across techniques (default 2 when the
        breakdown has it, else its first K).

    Returns
    -------
    list of Area
        Two areas; a mode without data (no breakdown) gives areas with one message tile.
    """
    from ui.cli.progressive import compare_rows

    ents = entries_of(source)
    if mode not in MODES:
        raise ValueError(f"unknown panel mode {mode!r} (one of {', '.join(MODES)})")
    if mode == "render":
        rows = compare_rows(ents, reference)
        means = [e.acc.mean for e in ents]
        exposure = min(im.auto_exposure(m) for m in means)
        var_means = [variance_values(e.acc.variance) / max(e.acc.n, 1) for e in ents]
        lo, hi = im.log_range(np.concatenate([v.ravel() for v in var_means]))
        tiles_a, tiles_b = [], []
        for e, row, v in zip(ents, rows, var_means, strict=True):
            took = f", {e.seconds:.1f} s" if e.seconds > 0 else ""
            tiles_a.append(Tile(f"{e.label}\n{e.acc.n} passes{took}",
                                rgb=im.tone_map(e.acc.mean, exposure), pixel=True))
            title = _fmt_ratio(row["ratio"]) if len(ents) > 1 else e.label
            if row["relmse"] is not None:
                title += f"  relMSE {row['relmse']:.2g}"
            tiles_b.append(Tile(title, values=v, clim=(lo, hi), pixel=True))
        head = "renders, one exposure" if len(ents) > 1 else "progressive render"
        return [Area(head, tiles_a, rows=1 if len(ents) <= 3 else None),
                Area(f"Var at equal {rows[0]['equal']}" if len(ents) > 1
                     else "variance of the mean",
                     tiles_b, rows=1 if len(ents) <= 3 else None, bar=MEAN_VARIANCE_BAR)]
    pick = [i for i, e in enumerate(ents) if e.breakdown is not None]
    # By default the first MIS set (the pictures are about MIS), or the first estimator that
    # has ``technique``.
    pick.sort(key=lambda i: len(ents[i].breakdown.layout.techniques) < 2)
    if technique is not None and isinstance(technique, str):
        pick = [i for i in pick if technique in ents[i].breakdown.layout.techniques] or pick
    if estimator is not None:
        pick = [int(estimator)] if ents[int(estimator)].breakdown is not None else []
    if not pick or ents[pick[0]].breakdown.n == 0:
        msg = ("no breakdown: start the render with breakdown=True" if not pick
               else "waiting for the first pass")
        blank = Tile(msg, rgb=np.full((*ents[0].acc.mean.shape[:2], 3), 255, np.uint8))
        return [Area(MODE_HELP[mode], [blank]), Area("", [])]
    e = ents[pick[0]]
    b = e.breakdown
    lay = b.layout
    names = lay.techniques
    total = b.image
    exposure = im.auto_exposure(total)
    if mode == "techniques":
        imgs = b.technique_images()
        w = b.technique_weights()
        tiles_a = [Tile("sum (the image)", rgb=im.tone_map(total, exposure))]
        tiles_a += [Tile(f"{n}", rgb=im.tone_map(x, exposure)) for n, x in zip(names, imgs,
                                                                                strict=True)]
        tiles_b = [Tile(n, values=x, clim=(0.0, 1.0), log=False, cmap=WEIGHT_CMAP)
                   for n, x in zip(names, w, strict=True)]
        return [Area(f"weighted contributions, {b.n} passes",
                     tiles_a),
                Area("weight maps: share of each pixel", tiles_b,
                     bar=WEIGHT_BAR)]
    # bounces
    kimg = b.k_images()
    tiles_a = [Tile(lbl, rgb=im.tone_map(x, exposure)) for lbl, x in zip(lay.labels, kimg,
                                                                         strict=True)]
    area_a = Area(f"per scatter count K, {b.n} passes", tiles_a)
    if technique is not None:
        t = b.index(technique)
        un = b.unweighted.mean[t]
        we = b.weighted.mean[t]
        ex = im.auto_exposure(un)
        tiles_b = ([Tile(f"{lbl} unweighted", rgb=im.tone_map(x, ex))
                    for lbl, x in zip(lay.labels, un, strict=True)]
                   + [Tile(f"{lbl} weighted", rgb=im.tone_map(x, ex))
                      for lbl, x in zip(lay.labels, we, strict=True)])
        return [area_a, Area(f"{names[t]}: unweighted / weighted", tiles_b,
                             rows=2)]
    kk = _k_of(lay, k)
    kb = lay.k_bin(kk)
    ex = im.auto_exposure(kimg[kb])  # every unweighted image estimates this bin
    # Techniques that cannot produce this K (plane-t1t3 at K = 2) would be black tiles.
    ts = [t for t in range(len(names)) if b.unweighted.mean[t, kb].any()] or \
        list(range(len(names)))
    tiles_b = ([Tile(f"{names[t]} unweighted", rgb=im.tone_map(b.unweighted.mean[t, kb], ex))
                for t in ts]
               + [Tile(f"{names[t]} weighted", rgb=im.tone_map(b.weighted.mean[t, kb], ex))
                  for t in ts])
    return [area_a, Area(f"{lay.labels[kb]}: unweighted / weighted", tiles_b,
                         rows=2)]


def _label(plotter, text: str, x: float, y: float, size: float, *, name: str,
           align: str = "center", bold: bool = False):
    """A text whose top ``align`` point is at the normalised viewport position ``(x, y)``.

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
    prop.SetFontSize(pt(size))
    prop.SetFontFamilyToArial()
    prop.SetColor(*pv.Color(scene_view.TEXT_COLOUR).float_rgb)
    prop.SetBold(bold)
    prop.SetVerticalJustificationToTop()
    {"center": prop.SetJustificationToCentered, "right": prop.SetJustificationToRight,
     "left": prop.SetJustificationToLeft}[align]()
    plotter.add_actor(actor, name=name, reset_camera=False, pickable=False)
    return actor


def _outline_points(pixel_xy, height: int, s: float, x0: float, y0: float) -> np.ndarray:
    """(4, 3) corners of the outline of pixel ``pixel_xy`` on a tile at ``(x0, y0)`` drawn
    ``s`` viewport pixels per image pixel."""
    pts = np.array(pixel_outline(pixel_xy, height, 0.6).points, dtype=float)
    return pts * [s, s, 1.0] + [x0, y0, 0.0]


def _fit(text: str, width_px: float) -> str:
    """Shorten every line of ``text`` to about ``width_px`` pixels at the tile font."""
    n = max(4, int(width_px / (0.55 * pt(FONT_SMALL))))
    return "\n".join(line if len(line) <= n else line[: n - 1] + "\u2026"
                     for line in text.split("\n"))


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
             k=None) -> None:
        """Draw ``mode`` (see :func:`mode_areas`) of ``source`` into ``subplots``.

        Parameters
        ----------
        subplots : list of (int, int)
            Subplot indices of ``plotter``; area ``i`` goes to ``subplots[i]`` (extra areas
            are dropped, so one subplot shows the images only).
        source : Progressive, list of runs, dict of Welford, or Welford
        pixel_xy : (int, int), optional
            Picked pixel, outlined on the render and variance tiles.
        """
        areas = mode_areas(source, mode, reference=reference, estimator=estimator,
                           technique=technique, k=k)
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
    def _draw_area(self, plotter, tag, area: Area, pixel_xy) -> None:
        ren = plotter.renderer
        vx0, vy0, vx1, vy1 = ren.GetViewport()
        ww, wh = plotter.window_size
        vw, vh = (vx1 - vx0) * ww, (vy1 - vy0) * wh
        lines = max((t.title.count("\n") + 1 for t in area.tiles), default=1)
        line_px = 1.35 * pt(FONT_SMALL)
        label_px = lines * line_px + 4
        top_px = line_px + 10  # the header
        bottom_px = (0.16 * vh) if area.bar else 6.0
        h, w = area.tiles[0].values.shape if area.tiles and area.tiles[0].values is not None \
            else (area.tiles[0].rgb.shape[:2] if area.tiles else (1, 1))
        key = (tag, id(ren), tuple((t.rgb is None, t.cmap, t.log, t.pixel) for t in area.tiles),
               area.rows, area.bar, round(vw), round(vh), (h, w), lines, pixel_xy is None)
        parts = self._parts.get(tag)
        if self._key.get(tag) != key or parts is None or not self._alive(plotter, ren, parts):
            parts = self._build(plotter, tag, area, vw, vh, top_px, bottom_px, label_px,
                                (h, w), pixel_xy)
            self._key[tag], self._parts[tag] = key, parts
        # in-place update: values, ranges, texts
        parts["header"].SetInput(_fit(area.header, 0.98 * vw))
        for tile, (grid, actor, text), room in zip(area.tiles, parts["tiles"], parts["fits"],
                                                   strict=True):
            text.SetInput(_fit(tile.title, room))
            arr = grid.cell_data["rgb" if tile.rgb is not None else "values"]
            if tile.rgb is not None:
                arr[:] = tile.rgb[::-1].reshape(h * w, 3)
            else:
                lo, hi = tile.clim
                v = np.where(np.isfinite(tile.values), tile.values, lo)
                arr[:] = np.clip(v, lo, hi)[::-1].ravel()
                actor.mapper.SetScalarRange(lo, hi)
                actor.mapper.lookup_table.SetRange(lo, hi)
            grid.Modified()
        if pixel_xy is not None:  # a moved pixel moves the outlines (no rebuild)
            for mesh, (x0, y0, sc) in parts["outlines"]:
                mesh.points = _outline_points(pixel_xy, h, sc, x0, y0)

    @staticmethod
    def _alive(plotter, ren, parts) -> bool:
        # The window may have cleared the subplot or every scalar bar since the last frame.
        bar_ok = parts["bar"] is None or parts["bar"] in plotter.scalar_bars
        return bar_ok and all(name in ren.actors for name in parts["names"])

    def _build(self, plotter, tag, area: Area, vw, vh, top_px, bottom_px, label_px, hw,
               pixel_xy) -> dict:
        ren = plotter.renderer
        old = self._parts.get(tag)
        # Only this area's own bar: bars are keyed by title across the whole plotter.
        if old is not None and old["bar"] is not None and old["bar"] in plotter.scalar_bars:
            plotter.remove_scalar_bar(old["bar"])
        ren.clear_actors()
        ren.set_background("white")
        h, w = hw
        n = len(area.tiles)
        usable_h = vh - top_px - bottom_px
        rows, cols, s = _grid_shape(max(n, 1), w, h, vw, usable_h, label_px, area.rows)
        s = max(s, 1e-3)
        names, fits, outlines = [], [], []
        header = _label(plotter, _fit(area.header, 0.98 * vw), 0.5, 1.0 - 4 / vh, FONT_SMALL,
                          name=f"{tag}-header", align="center", bold=True)
        names.append(f"{tag}-header")
        tiles = []
        gap_x = 0.06 * w * s
        row_h = h * s * 1.04 + label_px
        x_start = (vw - cols * w * s - (cols - 1) * gap_x) / 2
        bar_done = False
        for i, tile in enumerate(area.tiles):
            r, c = divmod(i, cols)
            px0 = x_start + c * (w * s + gap_x)
            py_top = vh - top_px - r * row_h  # top of this row's label (pixels from bottom)
            py0 = py_top - label_px - h * s
            grid = pv.ImageData(dimensions=(w + 1, h + 1, 1), spacing=(s, s, 1.0),
                                origin=(px0, py0, 0.0))
            name = f"{tag}-tile{i}"
            if tile.rgb is not None:
                grid.cell_data["rgb"] = tile.rgb[::-1].reshape(h * w, 3)
                actor = plotter.add_mesh(grid, scalars="rgb", rgb=True, lighting=False,
                                         show_scalar_bar=False, name=name, reset_camera=False)
            else:
                lo, hi = tile.clim
                grid.cell_data["values"] = np.clip(
                    np.where(np.isfinite(tile.values), tile.values, lo), lo, hi)[::-1].ravel()
                show_bar = area.bar is not None and not bar_done
                bar = dict(title=area.bar, title_font_size=pt(FONT_SMALL),
                           label_font_size=pt(FONT_SMALL), n_labels=3,
                           fmt="%.0e" if tile.log else "%.1f", color="black", vertical=False,
                           position_x=0.1, position_y=0.02,
                           width=0.8, height=min(0.13, 0.9 * bottom_px / vh))
                actor = plotter.add_mesh(grid, scalars="values", cmap=tile.cmap,
                                         log_scale=tile.log, clim=(lo, hi), lighting=False,
                                         show_scalar_bar=show_bar, scalar_bar_args=bar,
                                         name=name, reset_camera=False)
                bar_done = bar_done or show_bar
            names.append(name)
            text = _label(plotter, _fit(tile.title, w * s * 1.05), (px0 + w * s / 2) / vw,
                            py_top / vh,
                            FONT_SMALL, name=f"{name}-title", align="center")
            fits.append(w * s * 1.05)
            names.append(f"{name}-title")
            if tile.pixel and pixel_xy is not None:
                outline = pixel_outline(pixel_xy, h, 0.6)
                outline.points = _outline_points(pixel_xy, h, s, px0, py0)
                outlines.append((outline, (px0, py0, s)))
                plotter.add_mesh(outline, color=OKABE_ITO["vermillion"], line_width=px(3),
                                 name=f"{name}-pixel", reset_camera=False)
                names.append(f"{name}-pixel")
            tiles.append((grid, actor, text))
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
        return {"header": header, "tiles": tiles, "names": names, "fits": fits,
                "outlines": outlines,
                "bar": area.bar if bar_done else None}


def draw_image_panels(plotter: pv.Plotter, subplots, source, mode: str = "render",
                      pixel_xy=None, view: PanelView | None = None, **kw) -> PanelView:
    """Draw ``mode`` into ``subplots`` (see :meth:`PanelView.draw`); returns the view to
    pass back next time (in-place updates)."""
    view = PanelView() if view is None else view
    view.draw(plotter, subplots, source, mode, pixel_xy, **kw)
    return view


class FigureMaker:
    """Off-screen figures of the panels (recording, the ``breakdown`` command): one plotter
    with the two areas one above the other, reused frame after frame."""

    def __init__(self, size=(1200, 900)):
        scene_view.plain_text()
        self.size = (int(size[0]), int(size[1]))
        self.plotter = pv.Plotter(window_size=list(self.size), off_screen=True, shape=(2, 1),
                                  border=False)
        self.plotter.set_background("white", all_renderers=True)
        # Pixel-aligned image tiles need no multisampling, and software OpenGL (llvmpipe, no
        # display) spends most of a frame on it: 4x MSAA costs ~0.25 s at 1200 x 900.
        self.plotter.ren_win.SetMultiSamples(0)
        self.view = PanelView()

    def frame(self, source, mode: str = "render", pixel_xy=None, **kw) -> np.ndarray:
        """(H, W, 3) uint8 picture of ``mode`` for ``source``."""
        # Fonts as in the window (18 pt at the design size) for a 960 x 720 figure.
        scene_view.set_scale(self.size[1] * scene_view.DESIGN_HEIGHT / 720.0)
        self.view.draw(self.plotter, [(0, 0), (1, 0)], source, mode, pixel_xy, **kw)
        self.plotter.render()  # screenshot() alone may return the last rendered image
        # a copy: the screenshot buffer may be reused by the next frame
        return np.array(self.plotter.screenshot(None, return_img=True)[..., :3])

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
