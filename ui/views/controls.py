"""The window's controls: picking a pixel by clicking, on-screen buttons and sliders, and what
they change (estimator members, medium parameters, photon count).

Pure parts (no rendering; unit-tested in ``tests/test_window_controls.py``):

* :func:`viewport_at`, :func:`display_to_panel`, :func:`panel_to_pixel`: a click at a display
  position (VTK's: pixels, ``x`` from the left, ``y`` from the *bottom* of the window) becomes
  the image pixel ``(X, Y)`` (column from the left, row from the top) it falls on, through the
  image panel's parallel camera (cell layout: ``ui.views.image_panels``, pixel ``(X, Y)`` is the
  cell ``[X, X+1] x [H-Y-1, H-Y]``);
* :func:`members` / :func:`estimator_with`: an estimator with some of its techniques disabled
  (an MIS set re-parsed as ``mis:A+B``; at least one member stays);
* :class:`MediumParams` and :func:`scene_with`: sigma_s, sigma_a, g and the photon count, with
  the ranges the sliders and keys allow;
* :class:`Debouncer`: a change is applied once nothing has changed for ``delay`` seconds (a
  dragged slider or a held key rebuilds the scene once, not on every tick).

The pure parts import no VTK (the drawing parts import it from :mod:`ui.views._vtk` when they
run). Drawing parts: :class:`Controls` puts a strip of buttons and the member chips in an overlay
renderer spanning the window (so composing a stage never erases them) and, when the plotter
has an interactor, VTK slider widgets for the medium and the photon count.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

# --------------------------------------------------------------------------- picking


def viewport_at(display_xy, window_size, viewports: Sequence) -> int | None:
    """Index of the viewport containing a display position, or None.

    Parameters
    ----------
    display_xy : (float, float)
        VTK display position in pixels, ``y`` from the bottom of the window.
    window_size : (int, int)
        ``(W, H)`` in pixels.
    viewports : sequence of (x0, y0, x1, y1)
        Normalised viewports (VTK's ``GetViewport()``), in the order to search.
    """
    w, h = window_size
    u, v = display_xy[0] / float(w), display_xy[1] / float(h)
    for i, (x0, y0, x1, y1) in enumerate(viewports):
        if x0 <= u < x1 and y0 <= v < y1:
            return i
    return None


def display_to_panel(display_xy, window_size, viewport, focal_xy, parallel_scale: float):
    """World ``(x, y)`` under a display position in a viewport with a parallel camera looking
    down ``-z`` with ``+y`` up (what ``image_panels.fit_view`` sets).

    VTK maps the viewport's height to ``2 * parallel_scale`` world units centred on the focal
    point, and keeps the aspect ratio, so one display pixel is
    ``2 * parallel_scale / viewport_height_px`` world units in both directions.

    Returns
    -------
    (float, float)
        Panel coordinates (image cells are unit squares, the image spans ``[0, W] x [0, H]``).
    """
    ww, wh = window_size
    x0, y0, x1, y1 = viewport
    cx = 0.5 * (x0 + x1) * ww
    cy = 0.5 * (y0 + y1) * wh
    half_h = 0.5 * (y1 - y0) * wh
    k = float(parallel_scale) / half_h
    return (float(focal_xy[0]) + (display_xy[0] - cx) * k,
            float(focal_xy[1]) + (display_xy[1] - cy) * k)


def panel_to_display(panel_xy, window_size, viewport, focal_xy, parallel_scale: float):
    """Inverse of :func:`display_to_panel`: the display position of a panel point."""
    ww, wh = window_size
    x0, y0, x1, y1 = viewport
    cx = 0.5 * (x0 + x1) * ww
    cy = 0.5 * (y0 + y1) * wh
    k = float(parallel_scale) / (0.5 * (y1 - y0) * wh)
    return (cx + (panel_xy[0] - float(focal_xy[0])) / k,
            cy + (panel_xy[1] - float(focal_xy[1])) / k)


def panel_to_pixel(panel_xy, width: int, height: int, origin=(0.0, 0.0), spacing: float = 1.0):
    """The image pixel ``(X, Y)`` (column from the left, row from the top) whose cell contains
    the panel point, or None outside the ``width x height`` image.

    The image's cells are squares of side ``spacing`` from ``origin`` (lower-left corner):
    ``ui.views.image_panels.add_render_panel`` draws unit cells from ``(0, 0)``, the tiles of
    ``image_panels.PanelView`` are scaled and placed side by side.
    """
    fx = math.floor((panel_xy[0] - origin[0]) / spacing)
    fy = math.floor((panel_xy[1] - origin[1]) / spacing)
    x, y = int(fx), int(height - 1 - fy)
    if 0 <= x < width and 0 <= y < height:
        return x, y
    return None


def pixel_centre(pixel_xy, height: int, origin=(0.0, 0.0), spacing: float = 1.0):
    """Panel coordinates of the centre of pixel ``(X, Y)`` (inverse of
    :func:`panel_to_pixel`)."""
    return (origin[0] + (pixel_xy[0] + 0.5) * spacing,
            origin[1] + (height - pixel_xy[1] - 0.5) * spacing)


def image_tiles(renderer, width: int, height: int) -> list:
    """``(name, origin (x, y), spacing)`` of every ``width x height`` image (one cell per
    pixel) drawn in ``renderer``, by actor name."""
    from ._vtk import vtkImageData

    out = []
    for name, actor in sorted(renderer.actors.items()):
        mapper = actor.GetMapper() if hasattr(actor, "GetMapper") else None
        data = mapper.GetInput() if mapper is not None else None
        if isinstance(data, vtkImageData) and tuple(data.GetDimensions()) == (
                width + 1, height + 1, 1):
            ox, oy, _ = data.GetOrigin()
            out.append((name, (ox, oy), float(data.GetSpacing()[0])))
    return out


def pick_pixel(renderer, display_xy, window_size, width: int, height: int):
    """The pixel under a display position on any image tile of ``renderer`` (an image panel
    with a parallel camera), or None."""
    cam = renderer.GetActiveCamera()
    fx, fy, _ = cam.GetFocalPoint()
    panel = display_to_panel(display_xy, window_size, renderer.GetViewport(), (fx, fy),
                             cam.GetParallelScale())
    for _, origin, spacing in image_tiles(renderer, width, height):
        xy = panel_to_pixel(panel, width, height, origin, spacing)
        if xy is not None:
            return xy
    return None


# --------------------------------------------------------------------------- estimator members
def members(est) -> tuple:
    """Technique names of an estimator, in spec order (what the member toggles list)."""
    return tuple(t.name for t in est.techniques)


def estimator_with(base_spec: str, scene, disabled):
    """``base_spec`` parsed for ``scene`` with the techniques named in ``disabled`` left out:
    ``base_spec~A~B`` (the estimator grammar's "without"), a spec that works on the command
    line and in a progressive worker. The other members keep what ``base_spec`` gave them (a
    preset's per-light choice, its MIS sets: ``paper-full`` keeps two).

    Raises
    ------
    ValueError
        When every member would be disabled.
    """
    from psurf_core.estimators import parse_estimator

    base = parse_estimator(base_spec, scene)
    names = members(base)
    dropped = [n for n in names if n in set(disabled)]
    if len(dropped) == len(names):
        raise ValueError("at least one estimator member must stay enabled")
    if not dropped:
        return base
    return parse_estimator("~".join([base_spec, *dropped]), scene)


# --------------------------------------------------------------------------- medium
@dataclass(frozen=True)
class MediumParams:
    """What the sliders change: ``sigma_s``, ``sigma_a`` (1/scene unit), HG ``g`` and photons
    per pass."""

    sigma_s: float
    sigma_a: float
    g: float
    photons: int

    @classmethod
    def of(cls, scene, photons: int) -> MediumParams:
        m = scene.medium
        return cls(float(m.sigma_s), float(m.sigma_a), float(m.phase.g), int(photons))

    def clamped(self) -> MediumParams:
        """Within the slider ranges (:data:`RANGES`); sigma_t stays > 0."""
        lo, hi = RANGES["sigma_s"]
        ss = min(max(self.sigma_s, lo), hi)
        lo, hi = RANGES["sigma_a"]
        sa = min(max(self.sigma_a, lo), hi)
        if ss + sa <= 0.0:
            ss = RANGES["sigma_s"][1] * 1e-3
        lo, hi = RANGES["g"]
        g = min(max(self.g, lo), hi)
        lo, hi = RANGES["photons"]
        n = int(min(max(int(round(self.photons)), lo), hi))
        return MediumParams(ss, sa, g, n)


#: Slider ranges (a teaching scene is a few units across: optical depths of 0..10).
RANGES = {"sigma_s": (0.01, 5.0), "sigma_a": (0.0, 5.0), "g": (-0.9, 0.9),
          "photons": (100, 64000)}


def scene_with(scene, params: MediumParams):
    """``scene`` with the medium's sigma_s, sigma_a and phase from ``params`` (a new frozen
    Scene; HG when ``g != 0``, isotropic otherwise)."""
    from psurf_core.scene import Phase

    phase = Phase("hg", float(params.g)) if params.g != 0.0 else Phase("isotropic", 0.0)
    return scene.with_medium(sigma_s=float(params.sigma_s), sigma_a=float(params.sigma_a),
                             phase=phase)


class Debouncer:
    """Holds the latest value of a change until it has been quiet for ``delay`` seconds.

    ``push(value, now)`` records a change; ``due(now)`` returns the value (once) when
    ``delay`` has passed since the last push, else None. Time is passed in, so tests need no
    clock.
    """

    def __init__(self, delay: float = 0.35):
        self.delay = float(delay)
        self.value = None
        self.since = None

    def push(self, value, now: float) -> None:
        self.value, self.since = value, float(now)

    @property
    def pending(self) -> bool:
        return self.since is not None

    def due(self, now: float):
        if self.since is None or now - self.since < self.delay:
            return None
        v, self.value, self.since = self.value, None, None
        return v


# --------------------------------------------------------------------------- buttons
#: Buttons along the bottom of the stage panel, two rows (bottom row first):
#: ``(action, label)``.
BUTTONS = ((("previous", "< prev"), ("next", "next >"), ("play", "play"), ("reset", "reset"),
            ("mode", "mode"), ("record", "rec"), ("save", "save"), ("help", "help")),
           (("coverage", "coverage"), ("pass-", "pass -"), ("pass+", "pass +"),
            ("sliders", "sliders")))
#: Left edge, bottom of each row and gap of the strip (normalised window coordinates).
STRIP_X0, STRIP_Y, STRIP_GAP = 0.505, (0.012, 0.052), 0.006


#: Left ends of the four sliders (normalised window coordinates) and their length: a 2 x 2
#: block over the lower left of the 3D view, shown on demand (``sliders`` button, ``w``),
#: on a white backdrop.
SLIDER_SPOTS = ((0.03, 0.165), (0.26, 0.165), (0.03, 0.085), (0.26, 0.085))
SLIDER_LENGTH = 0.19
BACKDROP = (0.008, 0.03, 0.475, 0.225)


def rect_contains(rect, xy) -> bool:
    """Whether display point ``xy`` is inside ``rect = (x0, y0, x1, y1)`` (display pixels)."""
    x0, y0, x1, y1 = rect
    return x0 <= xy[0] <= x1 and y0 <= xy[1] <= y1


class Controls:
    """Buttons, member chips and sliders of the interactive window.

    Buttons and chips are text actors in an overlay renderer (layer 1, whole window, no
    background) hit-tested by their on-screen bounding boxes, so they work the same with or
    without an interactor (tests click them through :meth:`hit`). Sliders are VTK slider
    widgets and need an interactor; their callbacks only *push* a value (the window applies it
    when the slider has been still, see :class:`Debouncer`).
    """

    def __init__(self, plotter, actions: dict, *, on_slider: Callable | None = None):
        from ._vtk import vtkRenderer

        self.p = plotter
        self.actions = actions  # action name -> callable()
        self.on_slider = on_slider
        self.overlay = vtkRenderer()
        self.overlay.SetViewport(0.0, 0.0, 1.0, 1.0)
        self.overlay.SetLayer(1)
        self.overlay.InteractiveOff()
        rw = plotter.ren_win
        rw.SetNumberOfLayers(max(rw.GetNumberOfLayers(), 2))
        rw.AddRenderer(self.overlay)
        self.hot: list = []  # (action, text actor)
        self.sliders: dict = {}
        self.sliders_on = False
        self.backdrop = None

    # ---------------------------------------------------------------- drawing
    def draw(self, state, member_names: Sequence, disabled, recording: bool = False) -> None:
        """(Re)draw the button strip and the member chips for ``state``."""
        from .scene_view import FONT_SMALL, OKABE_ITO, pt

        for _, a in self.hot:  # only our chips: the sliders' representations live here too
            self.overlay.RemoveViewProp(a)
        self.hot = []
        for row, y in zip(BUTTONS, STRIP_Y, strict=True):
            x = STRIP_X0
            for action, label in row:
                if action == "play":
                    label = "pause" if state.playing else "play"
                elif action == "coverage" and state.coverage:
                    label = "coverage: on"
                elif action == "record" and recording:
                    label = "stop rec"
                elif action == "sliders" and self.sliders_on:
                    label = "hide sliders"
                a = self._chip(f" {label} ", x, y, pt(FONT_SMALL),
                               background=OKABE_ITO["blue"], colour="white")
                self.hot.append((action, a))
                x += self._width(a) + STRIP_GAP
        # Member chips (MIS sets and presets): upper right of the 3D view, one per technique.
        if len(member_names) > 1:
            y = 0.80
            for i, name in enumerate(member_names):
                on = name not in disabled
                key = f"{i + 1}" if i < 9 else " "
                a = self._chip(f" {key} [{'x' if on else ' '}] {name} ", 0.495, y,
                               pt(FONT_SMALL), background=OKABE_ITO["green"] if on else
                               "#bbbbbb", colour="white" if on else "black", right=True)
                self.hot.append((f"member:{name}", a))
                y -= 0.045

    def _chip(self, text, x, y, size, *, background, colour, right=False):
        from ._vtk import pv, vtkTextActor

        a = vtkTextActor()
        a.SetInput(text)
        a.GetPositionCoordinate().SetCoordinateSystemToNormalizedViewport()
        a.GetPositionCoordinate().SetValue(x, y)
        prop = a.GetTextProperty()
        prop.SetFontSize(size)
        prop.SetFontFamilyToArial()
        prop.SetColor(*pv.Color(colour).float_rgb)
        prop.SetBackgroundColor(*pv.Color(background).float_rgb)
        prop.SetBackgroundOpacity(1.0)
        prop.SetFrame(True)
        prop.SetFrameColor(1.0, 1.0, 1.0)
        prop.SetFrameWidth(2)
        if right:
            prop.SetJustificationToRight()
        prop.SetVerticalJustificationToBottom()
        self.overlay.AddViewProp(a)
        return a

    def _width(self, actor) -> float:
        """Width of a text actor in normalised window units."""
        bb = [0.0] * 4
        actor.GetBoundingBox(self.overlay, bb)
        return (bb[1] - bb[0]) / float(self.p.window_size[0])

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
        self.backdrop = self._backdrop(BACKDROP)
        for (key, title, rng, value, fmt), (x, y) in zip(specs, SLIDER_SPOTS, strict=True):
            self.sliders[key] = self._slider(key, title, rng, value, fmt, (x, y),
                                             (x + SLIDER_LENGTH, y))
        self.show_sliders(self.sliders_on)

    def show_sliders(self, on: bool) -> None:
        """Show or hide the slider block (hidden, it takes no clicks)."""
        self.sliders_on = bool(on)
        for w in self.sliders.values():
            # Disabling forgets the widget's renderer; enabling would then pick the renderer
            # under the last event (drawn below the overlay's backdrop).
            w.SetCurrentRenderer(self.overlay)
            w.SetEnabled(int(self.sliders_on))
        if self.backdrop is not None:
            self.backdrop.SetVisibility(self.sliders_on)

    def _backdrop(self, rect):
        """A white rectangle (normalised window coordinates) behind the sliders."""
        from ._vtk import (
            vtkActor2D,
            vtkCellArray,
            vtkCoordinate,
            vtkPoints,
            vtkPolyData,
            vtkPolyDataMapper2D,
        )

        x0, y0, x1, y1 = rect
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
        actor.GetProperty().SetOpacity(0.92)
        self.overlay.AddViewProp(actor)
        return actor

    def _slider(self, key, title, rng, value, fmt, a, b):
        from ._vtk import vtkSliderRepresentation2D, vtkSliderWidget
        from .scene_view import OKABE_ITO, _rgb

        rep = vtkSliderRepresentation2D()
        rep.SetMinimumValue(rng[0])
        rep.SetMaximumValue(rng[1])
        rep.SetValue(value)
        rep.SetTitleText("")
        rep.SetLabelFormat(f"{title} {fmt}")  # one line above the tube: name and value
        rep.GetPoint1Coordinate().SetCoordinateSystemToNormalizedDisplay()
        rep.GetPoint1Coordinate().SetValue(*a)
        rep.GetPoint2Coordinate().SetCoordinateSystemToNormalizedDisplay()
        rep.GetPoint2Coordinate().SetValue(*b)
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
        rep.GetSliderProperty().SetColor(*_rgb(OKABE_ITO["blue"]))
        rep.GetSelectedProperty().SetColor(*_rgb(OKABE_ITO["vermillion"]))
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

