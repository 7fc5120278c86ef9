"""The window's controls, their pure parts: picking a pixel by clicking, and what the chips,
buttons and sliders change (estimator members, medium parameters, photon count).

No rendering here (unit-tested in ``tests/test_window_controls.py``):

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

This module imports no VTK. The drawing part, :class:`ui.views.footer.Controls` (chips,
buttons and sliders in an overlay renderer), is in :mod:`ui.views.footer`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
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


#: Field-data array of a textured image tile (``ui.views.image_panels.PanelView``): origin x,
#: origin y, spacing (viewport pixels per image pixel), width, height.
TILE_FIELD = "psurf_tile"


def image_tiles(renderer, width: int, height: int) -> list:
    """``(name, origin (x, y), spacing)`` of every ``width x height`` image drawn in
    ``renderer`` (one cell per pixel, or a textured tile that says where it is), by actor
    name."""
    from ._vtk import vtkImageData

    out = []
    for name, actor in sorted(renderer.actors.items()):
        mapper = actor.GetMapper() if hasattr(actor, "GetMapper") else None
        data = mapper.GetInput() if mapper is not None else None
        if data is None:
            continue
        if isinstance(data, vtkImageData) and tuple(data.GetDimensions()) == (
                width + 1, height + 1, 1):
            ox, oy, _ = data.GetOrigin()
            out.append((name, (ox, oy), float(data.GetSpacing()[0])))
            continue
        field = data.GetFieldData().GetArray(TILE_FIELD) if hasattr(data, "GetFieldData") \
            else None
        if field is not None and field.GetNumberOfTuples() * field.GetNumberOfComponents() == 5:
            ox, oy, sp, w, h = (field.GetValue(i) for i in range(5))
            if (int(w), int(h)) == (width, height):
                out.append((name, (ox, oy), float(sp)))
    return out


def pick_tile(renderer, display_xy, window_size, width: int, height: int):
    """``(tile name, (X, Y))``: the image tile of ``renderer`` (an image panel with a
    parallel camera) under a display position and the pixel there, or None."""
    cam = renderer.GetActiveCamera()
    fx, fy, _ = cam.GetFocalPoint()
    panel = display_to_panel(display_xy, window_size, renderer.GetViewport(), (fx, fy),
                             cam.GetParallelScale())
    for name, origin, spacing in image_tiles(renderer, width, height):
        xy = panel_to_pixel(panel, width, height, origin, spacing)
        if xy is not None:
            return name, xy
    return None


def pick_pixel(renderer, display_xy, window_size, width: int, height: int):
    """The pixel under a display position on any image tile of ``renderer``, or None."""
    hit = pick_tile(renderer, display_xy, window_size, width, height)
    return None if hit is None else hit[1]


def tile_index(name: str) -> int | None:
    """The tile number in a ``PanelView`` actor name (``ip0-tile3`` -> 3), or None."""
    head, _, num = str(name).rpartition("-tile")
    return int(num) if head and num.isdigit() else None


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
