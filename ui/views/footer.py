"""The window's footer and sliders: estimator chips (which estimator the stages inspect),
member chips (switch an MIS member on or off), the buttons, and the medium / photon sliders,
drawn in an overlay renderer that no ``compose()`` clears (VTK, through
:mod:`ui.views._vtk`). What they change is :mod:`ui.views.controls`'s; the window binds them
(:mod:`ui.views.interactive`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

from .controls import RANGES, MediumParams

# --------------------------------------------------------------------------- buttons
#: The buttons of the footer's bottom row: ``(action, label)``.
BUTTONS = (("previous", "< prev"), ("next", "next >"), ("play", "play"), ("reset", "reset"),
           ("inspect", "inspect next"), ("mode", "mode"), ("scale", "scale"),
           ("focus", "layout"), ("coverage", "coverage"), ("pass-", "pass -"),
           ("pass+", "pass +"), ("sliders", "sliders"), ("record", "rec"), ("save", "save"),
           ("help", "help"))
#: Gap between chips and the left margin (normalised window width).
GAP, MARGIN = 0.004, 0.006
BUTTON_COLOUR = "#333333"


def rect_contains(rect, xy) -> bool:
    """Whether display point ``xy`` is inside ``rect = (x0, y0, x1, y1)`` (display pixels)."""
    x0, y0, x1, y1 = rect
    return x0 <= xy[0] <= x1 and y0 <= xy[1] <= y1


def member_chip_label(i: int, name: str, on: bool) -> str:
    """A member chip's text: its key, on/off in words (never by colour alone), its name."""
    key = f"{i + 1}" if i < 9 else " "
    return f" {key} {'on ' if on else 'off'} {name} "


class Controls:
    """The footer (estimator chips, member chips, buttons) and sliders of the window.

    Chips and buttons are text actors in an overlay renderer (layer 1, whole window, no
    background) hit-tested by their on-screen bounding boxes, so they work the same with or
    without an interactor (tests click them through :meth:`hit`). They flow left to right
    and wrap onto more rows when the window is narrow; :attr:`rows` is how many rows the
    layout must leave at the bottom (``ui.views.layout``), so nothing covers a view. Sliders
    are VTK slider widgets placed in the layout's slider block; they need an interactor and
    their callbacks only *push* a value (the window applies it when the slider has been still,
    see :class:`Debouncer`).
    """

    def __init__(self, plotter, actions: dict, *, on_slider: Callable | None = None):
        from ._vtk import vtkRenderer

        self.p = plotter
        self.actions = actions  # action name -> callable(*args)
        self.on_slider = on_slider
        self.overlay = vtkRenderer()
        self.overlay.SetViewport(0.0, 0.0, 1.0, 1.0)
        self.overlay.SetLayer(1)
        self.overlay.InteractiveOff()
        rw = plotter.ren_win
        rw.SetNumberOfLayers(max(rw.GetNumberOfLayers(), 2))
        rw.AddRenderer(self.overlay)
        self.hot: list = []  # (action, text actor)
        self.props: list = []  # everything draw() added (labels, backdrops)
        self._key = None  # what the footer was last drawn from
        self.sliders: dict = {}
        self.sliders_on = False
        self.rows = 1

    # ---------------------------------------------------------------- drawing
    def _row_h(self) -> float:
        from .layout import FOOTER_ROW_PX, font_scale

        h = self.p.window_size[1]
        return FOOTER_ROW_PX * font_scale(h) / h

    def draw(self, state, member_names: Sequence, disabled, recording: bool = False) -> int:
        """(Re)draw the footer for ``state``; returns (and keeps in :attr:`rows`) its rows."""
        from .palette import chip_colours
        from .scene_view import FONT_SMALL, pt

        size = pt(0.9 * FONT_SMALL)
        row_h = self._row_h()
        chips = []  # (action or None, text, background, colour, frame)
        specs = list(getattr(state, "specs", ()) or ())
        if len(specs) > 1:
            chips.append((None, "inspect:", None, "#111111", None))
            for i, spec in enumerate(specs):
                me = i == getattr(state, "inspected", 0)
                chips.append((f"inspect:{i}", f" {spec} ", "#111111" if me else "#e6e6e6",
                              "#ffffff" if me else "#111111", "#111111"))
        if len(member_names) > 1:
            chips.append((None, "members:", None, "#111111", None))
            for i, name in enumerate(member_names):
                on = name not in disabled
                bg, fg, fr = chip_colours(name, on)
                chips.append((f"member:{name}", member_chip_label(i, name, on), bg, fg, fr))
        buttons = []
        for action, label in BUTTONS:
            if action == "play":
                label = "pause" if state.playing else "play"
            elif action == "coverage" and state.coverage:
                label = "coverage: on"
            elif action == "record" and recording:
                label = "stop rec"
            elif action == "sliders" and self.sliders_on:
                label = "hide sliders"
            elif action == "inspect" and len(specs) < 2:
                continue
            buttons.append((action, f" {label} ", BUTTON_COLOUR, "#ffffff", "#ffffff"))
        # Laying out some thirty text actors (each measured) is tens of milliseconds: the same
        # footer in the same window is left as it is.
        key = (tuple(chips), tuple(buttons), tuple(self.p.window_size), size, row_h)
        if key == getattr(self, "_key", None) and self.props:
            return self.rows
        self._key = key
        for a in self.props:
            self.overlay.RemoveViewProp(a)
        self.hot, self.props = [], []
        # The backdrop first (drawn under the chips), as tall as the rows once they are known.
        backdrop = self._backdrop(self.rows * row_h)
        self.props.append(backdrop)
        rows = self._flow(buttons, 0, size, row_h)
        if chips:
            rows += self._flow(chips, rows, size, row_h)
        self.rows = rows
        self._set_rect(backdrop, 0.0, 0.0, 1.0, rows * row_h)
        return rows

    def _flow(self, items, first_row: int, size: int, row_h: float) -> int:
        """Lay ``items`` out from row ``first_row`` (0 = bottom), wrapping; rows used."""
        x, row = MARGIN, first_row
        for action, text, bg, fg, frame in items:
            y = row * row_h + 0.12 * row_h
            a = self._chip(text, x, y, size, background=bg, colour=fg, frame=frame)
            wdt = self._width(a)
            if x > MARGIN and x + wdt > 1.0 - MARGIN:  # wrap onto the next row
                row += 1
                x = MARGIN
                a.GetPositionCoordinate().SetValue(x, row * row_h + 0.12 * row_h)
            if action is not None:
                self.hot.append((action, a))
            self.props.append(a)
            x += wdt + GAP
        return row - first_row + 1

    def _chip(self, text, x, y, size, *, background, colour, frame):
        from ._vtk import pv, vtkTextActor

        a = vtkTextActor()
        a.SetInput(text)
        a.GetPositionCoordinate().SetCoordinateSystemToNormalizedViewport()
        a.GetPositionCoordinate().SetValue(x, y)
        prop = a.GetTextProperty()
        prop.SetFontSize(size)
        prop.SetFontFamilyToArial()
        prop.SetColor(*pv.Color(colour).float_rgb)
        if background is not None:
            prop.SetBackgroundColor(*pv.Color(background).float_rgb)
            prop.SetBackgroundOpacity(1.0)
        if frame is not None:
            prop.SetFrame(True)
            prop.SetFrameColor(*pv.Color(frame).float_rgb)
            prop.SetFrameWidth(2)
        prop.SetVerticalJustificationToBottom()
        self.overlay.AddViewProp(a)
        return a

    def _width(self, actor) -> float:
        """Width of a text actor in normalised window units."""
        bb = [0.0] * 4
        actor.GetBoundingBox(self.overlay, bb)
        return (bb[1] - bb[0]) / float(self.p.window_size[0])

    def _backdrop(self, height: float, y0: float = 0.0, x0: float = 0.0, x1: float = 1.0):
        """A white rectangle (normalised window coordinates) under the footer or sliders:
        no renderer covers those parts of the window."""
        from ._vtk import (
            vtkActor2D,
            vtkCellArray,
            vtkCoordinate,
            vtkPoints,
            vtkPolyData,
            vtkPolyDataMapper2D,
        )

        y1 = y0 + height
        pts = vtkPoints()
        for x, y in ((x0, y0), (x1, y0), (x1, y1), (x0, y1)):
            pts.InsertNextPoint(x, y, 0.0)
        cells = vtkCellArray()
        cells.InsertNextCell(4, [0, 1, 2, 3])
        poly = vtkPolyData()
        poly.SetPoints(pts)
        poly.SetPolys(cells)
        coord = vtkCoordinate()
        coord.SetCoordinateSystemToNormalizedViewport()
        mapper = vtkPolyDataMapper2D()
        mapper.SetInputData(poly)
        mapper.SetTransformCoordinate(coord)
        actor = vtkActor2D()
        actor.SetMapper(mapper)
        actor.GetProperty().SetColor(1.0, 1.0, 1.0)
        self.overlay.AddViewProp(actor)
        return actor

    def show_help(self, text: str, on: bool) -> None:
        """The key list over the middle of the window (``h``), as large as fits."""
        from ._vtk import pv, vtkTextActor
        from .scene_view import FONT, fit_font, pt

        if getattr(self, "_help", None) is not None:
            self.overlay.RemoveViewProp(self._help)
            self._help = None
        if not on:
            return
        from .scene_view import text_extent

        w, h = self.p.window_size
        size = fit_font(text, pt(FONT), (0.9 * w, 0.85 * h), mono=True)
        tw, th = text_extent(text, size, mono=True)
        a = vtkTextActor()
        a.SetInput(text)
        a.GetPositionCoordinate().SetCoordinateSystemToNormalizedViewport()
        # left-justified lines (the key column stays a column), the block centred
        a.GetPositionCoordinate().SetValue(0.5 - 0.5 * tw / w, 0.5 + 0.5 * th / h)
        prop = a.GetTextProperty()
        prop.SetFontFamilyToCourier()
        prop.SetFontSize(size)
        prop.SetColor(*pv.Color("#111111").float_rgb)
        prop.SetBackgroundColor(1.0, 1.0, 1.0)
        prop.SetBackgroundOpacity(0.96)
        prop.SetFrame(True)
        prop.SetFrameColor(0.2, 0.2, 0.2)
        prop.SetFrameWidth(2)
        prop.SetJustificationToLeft()
        prop.SetVerticalJustificationToTop()
        self.overlay.AddViewProp(a)
        self._help = a

    @staticmethod
    def _set_rect(actor, x0: float, y0: float, x1: float, y1: float) -> None:
        """Move a backdrop to ``(x0, y0)-(x1, y1)`` (normalised window coordinates)."""
        poly = actor.GetMapper().GetInput()
        pts = poly.GetPoints()
        for i, (x, y) in enumerate(((x0, y0), (x1, y0), (x1, y1), (x0, y1))):
            pts.SetPoint(i, x, y, 0.0)
        pts.Modified()
        poly.Modified()

    def rects(self) -> list:
        """``(action, (x0, y0, x1, y1))`` display rectangles of every button and chip."""
        out = []
        for action, a in self.hot:
            bb = [0.0] * 4
            a.GetBoundingBox(self.overlay, bb)  # relative to the actor's anchor
            x, y = a.GetPositionCoordinate().GetComputedDisplayValue(self.overlay)
            out.append((action, (x + bb[0], y + bb[2], x + bb[1], y + bb[3])))
        return out

    def hit(self, display_xy) -> str | None:
        """The action of the button or chip at a display position (None: none there)."""
        for action, rect in self.rects():
            if rect_contains(rect, display_xy):
                return action
        return None

    def click(self, display_xy) -> bool:
        """Run the action under a display position; True when there was one."""
        action = self.hit(display_xy)
        if action is None:
            return False
        self.actions[action.split(":", 1)[0]](*action.split(":", 1)[1:])
        return True

    # ---------------------------------------------------------------- sliders
    def add_sliders(self, params: MediumParams) -> None:
        """Slider widgets (need an interactor): sigma_s, sigma_a, g, log2 photons."""
        if self.p.iren is None:
            return
        specs = [("sigma_s", "sigma_s", RANGES["sigma_s"], params.sigma_s, "%.2f"),
                 ("sigma_a", "sigma_a", RANGES["sigma_a"], params.sigma_a, "%.2f"),
                 ("g", "HG g", RANGES["g"], params.g, "%.2f"),
                 ("photons", "log2 N", tuple(math.log2(v) for v in RANGES["photons"]),
                  math.log2(params.photons), "%.1f")]
        # The block's backdrop before the sliders: the overlay draws its props in order.
        self._slider_backdrop = self._backdrop(0.0)
        for key, title, rng, value, fmt in specs:
            self.sliders[key] = self._slider(key, title, rng, value, fmt)
        self.show_sliders(self.sliders_on)

    def place_sliders(self, rect) -> None:
        """Put the sliders in ``rect`` (the layout's slider block, a ``ui.views.layout.Rect``):
        two columns, two rows, on a white backdrop."""
        if rect is None or not self.sliders:
            return
        self._set_rect(self._slider_backdrop, rect.x0, rect.y0, rect.x1, rect.y1)
        self._slider_backdrop.SetVisibility(self.sliders_on)
        w, h = rect.x1 - rect.x0, rect.y1 - rect.y0
        for i, key in enumerate(("sigma_s", "sigma_a", "g", "photons")):
            col, row = i % 2, i // 2
            x = rect.x0 + (0.06 + 0.5 * col) * w
            y = rect.y1 - (0.38 + 0.5 * row) * h
            rep = self.sliders[key].GetRepresentation()
            rep.GetPoint1Coordinate().SetValue(x, y)
            rep.GetPoint2Coordinate().SetValue(x + 0.38 * w, y)
            rep.Modified()
            rep.BuildRepresentation()

    def show_sliders(self, on: bool) -> None:
        """Show or hide the slider block (hidden, it takes no clicks)."""
        self.sliders_on = bool(on)
        for w in self.sliders.values():
            # Disabling forgets the widget's renderer; enabling would then pick the renderer
            # under the last event (drawn below the overlay).
            w.SetCurrentRenderer(self.overlay)
            w.SetEnabled(int(self.sliders_on))
        if getattr(self, "_slider_backdrop", None) is not None:
            self._slider_backdrop.SetVisibility(self.sliders_on)

    def _slider(self, key, title, rng, value, fmt):
        from ._vtk import vtkSliderRepresentation2D, vtkSliderWidget
        from .palette import OKABE_ITO

        rep = vtkSliderRepresentation2D()
        rep.SetMinimumValue(rng[0])
        rep.SetMaximumValue(rng[1])
        rep.SetValue(value)
        rep.SetTitleText("")
        rep.SetLabelFormat(f"{title} {fmt}")  # one line above the tube: name and value
        rep.GetPoint1Coordinate().SetCoordinateSystemToNormalizedDisplay()
        rep.GetPoint1Coordinate().SetValue(0.05, 0.1)
        rep.GetPoint2Coordinate().SetCoordinateSystemToNormalizedDisplay()
        rep.GetPoint2Coordinate().SetValue(0.2, 0.1)
        # Sizes are fractions of the window (the overlay): text about FONT_SMALL at 900 px.
        rep.SetSliderLength(0.03)
        rep.SetSliderWidth(0.02)
        rep.SetTubeWidth(0.006)
        rep.SetEndCapLength(0.006)
        rep.SetEndCapWidth(0.02)
        rep.SetTitleHeight(0.022)
        rep.SetLabelHeight(0.022)
        for prop in (rep.GetTitleProperty(), rep.GetLabelProperty()):
            prop.SetColor(0.07, 0.07, 0.07)
            prop.SetShadow(False)
            prop.SetBold(False)
        rep.GetTubeProperty().SetColor(0.55, 0.55, 0.55)
        rep.GetCapProperty().SetColor(0.3, 0.3, 0.3)
        rep.GetSliderProperty().SetColor(0.2, 0.2, 0.2)
        rep.GetSelectedProperty().SetColor(*pv_rgb(OKABE_ITO["orange"]))
        w = vtkSliderWidget()
        w.SetInteractor(self.p.iren.interactor)
        # Drawn in the overlay (whole window, normalised display coordinates), which no
        # compose() clears.
        w.SetCurrentRenderer(self.overlay)
        w.SetRepresentation(rep)
        w.SetAnimationModeToJump()
        w.On()

        def moved(widget, _event, key=key):
            if self.on_slider is not None:
                self.on_slider(key, float(widget.GetRepresentation().GetValue()))

        # Every drag step pushes the value; the window's debouncer applies the last one.
        w.AddObserver("InteractionEvent", moved)
        w.AddObserver("EndInteractionEvent", moved)
        return w

    def set_slider(self, key: str, value: float) -> None:
        """Move a slider to ``value`` without calling back (keys changed the parameter)."""
        w = self.sliders.get(key)
        if w is not None:
            w.GetRepresentation().SetValue(float(value))

    def close(self) -> None:
        for w in self.sliders.values():
            w.Off()
        self.sliders = {}


def pv_rgb(colour: str) -> tuple:
    """``(r, g, b)`` in 0..1 of a ``#RRGGBB`` colour."""
    c = colour.lstrip("#")
    return tuple(int(c[i:i + 2], 16) / 255.0 for i in (0, 2, 4))
