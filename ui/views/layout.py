"""Where each part of the window goes, for any window size (plain Python, no VTK).

:func:`window_layout` cuts the window into rectangles that never overlap::

    +------------------------------+----------------------------------+
    | title, caption, stage hint   |  images: the renders             |
    +------------------------------+  (one tile per estimator)        |
    |                              |                                  |
    |  3D view                     +----------------------------------+
    |                              |  maps: variance / weight maps    |
    +------------------------------+  and their colour bar            |
    |  sliders (when shown)        |                                  |
    +------------------------------+                                  |
    |  stage panel (numbers)       |                                  |
    +------------------------------+----------------------------------+
    |  (narrow windows: the stage panel spans the width here instead)  |
    +-----------------------------------------------------------------+
    |  footer: estimator and member chips, buttons (the window only)  |
    +-----------------------------------------------------------------+

The left column holds what a stage shows (its title and caption are sized for the longest
caption, so the 3D view does not jump from stage to stage; the stage panel gets the lines
its text has, up to a cap, the 3D view the rest); the right column holds the image panels.
``focus`` shares the width differently: ``"split"`` (half and half), ``"images"`` (the
image panels get 70%) or ``"3d"`` (the 3D view gets 70%); the window's ``z`` key cycles them.

Rectangles are normalised VTK viewports ``(x0, y0, x1, y1)``, ``y`` up from the bottom of the
window. Fonts and lines scale with the window height (:func:`font_scale`: 1 at 900 px), the
texts that could overflow (the caption, the stage panel, the tile titles) are fitted to their
rectangle by the views (:func:`chars_per_line` is what this module assumes).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["FOCI", "Layout", "Rect", "font_scale", "next_focus", "window_layout"]

#: Layouts of the width, in the order the ``z`` key cycles them: the left column's share.
FOCI = {"split": 0.5, "images": 0.3, "3d": 0.7}
#: The design height: fonts are their nominal size here (:func:`font_scale`).
DESIGN_HEIGHT = 900
#: Nominal sizes (points = pixels at the design height) the layout reserves room for.
TITLE_PT, CAPTION_PT, TEXT_PT = 30, 18, 18
#: Height of one footer row (chips or buttons) at the design height, pixels.
FOOTER_ROW_PX = 38
#: Height of the slider block at the design height, pixels.
SLIDERS_PX = 96
#: Share of the left column the stage panel may take at most; the 3D view's least share of the
#: height (both above the footer).
PANEL_MAX, MIN_VIEW = 0.5, 0.28
#: The stage panel stays in the left column while its text needs no less than this share of
#: the nominal font there (else it spans the window's width).
PANEL_SHRINK = 0.8
#: The width of the stage panel's text the layout plans for (the evaluate table's lines;
#: fixed, so the layout does not jump from stage to stage).
PANEL_CHARS = 80
#: Average advance of a proportional (Arial) character, in font sizes; of a monospace one.
PROP_ADVANCE, MONO_ADVANCE = 0.5, 0.61


def font_scale(height: int) -> float:
    """Fonts and lines are ``nominal * font_scale(window height)``."""
    return float(height) / DESIGN_HEIGHT


def next_focus(focus: str) -> str:
    """The focus after ``focus`` (the window's ``z`` key)."""
    names = list(FOCI)
    return names[(names.index(focus) + 1) % len(names)] if focus in FOCI else names[0]


def chars_per_line(width_px: float, size_px: float, advance: float = PROP_ADVANCE) -> int:
    """How many characters of a font ``size_px`` tall fit on ``width_px`` (at least 10)."""
    return max(10, int(width_px / max(advance * size_px, 1e-6)))


@dataclass(frozen=True)
class Rect:
    """A normalised viewport ``(x0, y0, x1, y1)``, ``y`` up."""

    x0: float
    y0: float
    x1: float
    y1: float

    @property
    def viewport(self) -> tuple:
        return (self.x0, self.y0, self.x1, self.y1)

    def pixels(self, size) -> tuple:
        """``(width, height)`` in pixels of a window of ``size = (W, H)``."""
        return ((self.x1 - self.x0) * size[0], (self.y1 - self.y0) * size[1])

    @property
    def empty(self) -> bool:
        return self.x1 <= self.x0 or self.y1 <= self.y0

    def overlaps(self, other: Rect) -> bool:
        """Whether the two rectangles share an area (touching edges do not count)."""
        return (min(self.x1, other.x1) - max(self.x0, other.x0) > 1e-9
                and min(self.y1, other.y1) - max(self.y0, other.y0) > 1e-9)


@dataclass(frozen=True)
class Layout:
    """The rectangles of one window size (see the module docstring)."""

    size: tuple
    title: Rect
    view3d: Rect
    sliders: Rect | None
    panel: Rect
    images: Rect
    maps: Rect
    footer: Rect | None
    scale: float

    def parts(self) -> dict:
        """Name -> rectangle of every part that is shown."""
        out = {"title": self.title, "view3d": self.view3d, "panel": self.panel,
               "images": self.images, "maps": self.maps}
        if self.sliders is not None:
            out["sliders"] = self.sliders
        if self.footer is not None:
            out["footer"] = self.footer
        return out


def window_layout(size, *, focus: str = "split", footer_rows: int = 2,
                  sliders: bool = False, panel_lines: int = 12, panel_chars: int = PANEL_CHARS,
                  caption_chars: int = 300, map_share: float = 0.53) -> Layout:
    """The window's rectangles for a window of ``size = (W, H)`` pixels.

    Parameters
    ----------
    focus : {'split', 'images', '3d'}
        How the width is shared (:data:`FOCI`).
    footer_rows : int
        Rows of chips and buttons at the bottom (0: none, as in screenshots).
    sliders : bool
        Reserve the slider block under the 3D view.
    panel_lines, panel_chars : int
        Lines of the stage panel's text and the longest one: the panel gets their height (up
        to :data:`PANEL_MAX` of the column) and sits under the 3D view when the left column
        is wide enough for them at the nominal font, else across the whole width (narrow
        windows: 4:3, 5:4).
    caption_chars : int
        Length of the longest caption the title block must hold.
    map_share : float
        Share of the right column's height for the maps (they carry a colour bar).
    """
    w, h = (max(int(v), 1) for v in size)
    s = font_scale(h)
    if focus not in FOCI:
        raise ValueError(f"unknown focus {focus!r} (one of {', '.join(FOCI)})")
    left = FOCI[focus]
    foot = min(max(int(footer_rows), 0) * FOOTER_ROW_PX * s / h, 0.3)
    top = 1.0
    # Stage panel: its lines (mono, 1.2 line height) and a message line, capped; under the
    # 3D view when its lines fit the left column, else across the window.
    text_px = TEXT_PT * s
    wide = (focus != "images"  # images large: the stage panel stays in the narrow column
            and max(int(panel_chars), 1) * MONO_ADVANCE * text_px * PANEL_SHRINK
            > 0.96 * left * w)
    panel_px = (1.2 * text_px * (max(int(panel_lines), 1) + 1) + 16)
    avail = top - foot
    panel_h = min(panel_px / h, PANEL_MAX * avail * (0.75 if wide else 1.0))
    col_bottom = foot + panel_h if wide else foot
    # Title block: the title line, the caption wrapped to the column, a margin.
    col_px = left * w
    lines = math.ceil(caption_chars / chars_per_line(0.97 * col_px, CAPTION_PT * s))
    title_px = (1.35 * TITLE_PT + 1.22 * CAPTION_PT * lines + 14) * s
    title_h = min(title_px / h, 0.3)
    body = top - col_bottom - title_h
    slider_h = min(SLIDERS_PX * s / h, 0.25 * body) if sliders else 0.0
    # The 3D view keeps at least MIN_VIEW of the height: a long text shrinks to fit instead.
    view_h = body - slider_h - (0.0 if wide else panel_h)
    short = MIN_VIEW * avail - view_h
    if short > 0:
        cut = min(short, panel_h - 0.1 * avail)
        panel_h -= max(cut, 0.0)
        if wide:
            col_bottom = foot + panel_h
            body = top - col_bottom - title_h
    y_panel_top = foot + panel_h
    y_view_bottom = (col_bottom if wide else y_panel_top) + slider_h
    title = Rect(0.0, top - title_h, left, top)
    view3d = Rect(0.0, y_view_bottom, left, top - title_h)
    slider_rect = (Rect(0.0, y_view_bottom - slider_h, left, y_view_bottom) if sliders
                   else None)
    panel = Rect(0.0, foot, 1.0 if wide else left, y_panel_top)
    y_split = col_bottom + map_share * (top - col_bottom)
    images = Rect(left, y_split, 1.0, top)
    maps = Rect(left, col_bottom, 1.0, y_split)
    footer = Rect(0.0, 0.0, 1.0, foot) if foot > 0 else None
    return Layout((w, h), title, view3d, slider_rect, panel, images, maps, footer, s)
