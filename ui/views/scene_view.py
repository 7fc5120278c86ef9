"""The scene in 3D: medium box, lights, occluders, the camera and its frustum (pyvista).

Also the shared look of every view: the palette (:mod:`ui.views.palette`: Okabe-Ito, one
colour per technique), projector-sized fonts and lines, and text measured in pixels
(:func:`text_extent`, :func:`fit_font`) so that no text is cut. Everything here draws what
the core's :class:`~psurf_core.scene.Scene` holds; nothing is computed that the core does not
expose.
"""

from __future__ import annotations

import functools

import numpy as np

from psurf_core.camera import pixel_directions
from psurf_core.scene import AreaLight, BoxOccluder, MeshLight, PointLight, Scene, SphereOccluder

from ._vtk import pv, register_text_backends, vtkTextRenderer

# --------------------------------------------------------------------------- look
from .palette import FALLBACK_COLOUR, OKABE_ITO  # noqa: E402, F401 (the views' palette)

#: Lights: a pale warm white with black edges (yellow is the disk techniques' colour).
LIGHT_COLOUR = "#FFF1BA"
OCCLUDER_COLOUR = "#3a3a3a"
MEDIUM_COLOUR = OKABE_ITO["sky_blue"]
HIGHLIGHT = OKABE_ITO["black"]
TEXT_COLOUR = "#111111"
BACKGROUND = "white"

#: Projector legibility at the design size (1600 x 900): no text below 18 pt, thick lines.
#: Other window sizes scale fonts and lines with the window height (:func:`set_scale`), so a
#: screenshot at 800 x 450 has the same layout as the full-size window.
FONT = 22
FONT_SMALL = 18
FONT_TITLE = 30
LINE = 4
DESIGN_HEIGHT = 900

_SCALE = [1.0]


def set_scale(window_height: int) -> None:
    """Scale fonts and line widths for a window ``window_height`` pixels tall."""
    _SCALE[0] = float(window_height) / DESIGN_HEIGHT


def pt(size: float) -> int:
    """A font size (points at the design height) for the current window."""
    return max(6, int(round(size * _SCALE[0])))


def px(width: float) -> float:
    """A line width (pixels at the design height) for the current window."""
    return max(1.0, width * _SCALE[0])


def plain_text() -> None:
    """Render every string with FreeType as written: VTK would otherwise hand strings with
    ``|`` or ``$`` to its MathText backend (``|`` splits columns), and ``|n.psi|`` matters."""
    register_text_backends()  # the MathText override must be registered before the singleton
    renderer = vtkTextRenderer.GetInstance()
    if renderer is not None:
        renderer.SetDefaultBackend(1)  # vtkTextRenderer::FreeType


def _rgb(colour) -> tuple:
    return tuple(pv.Color(colour).float_rgb)


def add_text(plotter, text: str, x: float, y: float, size: float, *, mono: bool = False,
             name: str | None = None, bold: bool = False, box: bool = False,
             colour: str = TEXT_COLOUR, align: str = "left", background=None,
             size_px: int | None = None):
    """Text whose top-left / top-centre / top-right corner (``align``) is at the normalised
    viewport position ``(x, y)``, at ``size`` points (VTK points, i.e. pixels at 72 dpi, at
    the design height; pyvista's ``add_text`` would double the number it is given), or at
    ``size_px`` pixels exactly (a size already fitted to its box, :func:`fit_font`)."""
    actor = plotter.add_text(text, position=(x, y), viewport=True, font_size=size,
                             color=colour, font="courier" if mono else "arial", name=name)
    prop = actor.GetTextProperty()
    prop.SetFontSize(int(size_px) if size_px is not None else pt(size))
    prop.SetVerticalJustificationToTop()
    if align == "center":
        prop.SetJustificationToCentered()
    elif align == "right":
        prop.SetJustificationToRight()
    else:
        prop.SetJustificationToLeft()
    prop.SetBold(bold)
    if background is not None:
        prop.SetBackgroundColor(*_rgb(background))
        prop.SetBackgroundOpacity(1.0)
    if box:
        prop.SetBackgroundColor(1.0, 1.0, 1.0)
        prop.SetBackgroundOpacity(0.95)
        prop.SetFrame(True)
        prop.SetFrameColor(0.2, 0.2, 0.2)
        prop.SetFrameWidth(2)
    return actor


@functools.lru_cache(maxsize=4096)
def _measure(text: str, size_px: int, mono: bool, bold: bool) -> tuple[int, int]:
    from ._vtk import vtkTextProperty

    prop = vtkTextProperty()
    prop.SetFontSize(int(size_px))
    prop.SetBold(bool(bold))
    if mono:
        prop.SetFontFamilyToCourier()
    else:
        prop.SetFontFamilyToArial()
    bb = [0, 0, 0, 0]
    renderer = vtkTextRenderer.GetInstance()
    if renderer is None or not text or not renderer.GetBoundingBox(prop, text, bb, 72):
        lines = text.split("\n") if text else [""]
        return (int(0.6 * size_px * max(len(s) for s in lines)),
                int(1.2 * size_px * len(lines)))
    return bb[1] - bb[0], bb[3] - bb[2]


def text_extent(text: str, size_px: int, *, mono: bool = False,
                bold: bool = False) -> tuple[int, int]:
    """``(width, height)`` in pixels of ``text`` (one or more lines) at ``size_px`` points,
    as VTK's FreeType renderer draws it (Arial, or Courier when ``mono``).

    Monospace text is measured from one line of its font (its advance and line height, once
    per size): the stage panel's text changes every frame, and measuring all of it with
    FreeType took tens of milliseconds each time.
    """
    size_px = int(size_px)
    if mono:
        lines = text.split("\n") if text else [""]
        one_w, one_h = _measure("M" * 40, size_px, True, bool(bold))
        two_h = _measure("M\nM", size_px, True, bool(bold))[1]
        step = two_h - one_h
        return (int(np.ceil(one_w / 40.0 * max(len(s) for s in lines))),
                one_h + step * (len(lines) - 1))
    return _measure(text, size_px, False, bool(bold))


def fit_font(text: str, size_px: int, box_px: tuple, *, mono: bool = False,
             bold: bool = False, minimum: int = 7) -> int:
    """The largest font size ``<= size_px`` at which ``text`` fits ``box_px = (width,
    height)`` (pixels; ``minimum`` at least)."""
    lo, hi = int(minimum), int(size_px)
    if hi <= lo:
        return max(hi, 1)

    def fits(size: int) -> bool:
        w, h = text_extent(text, size, mono=mono, bold=bold)
        return w <= box_px[0] and h <= box_px[1]

    if fits(hi):
        return hi
    while hi - lo > 1:  # fits(lo) assumed (the minimum), not fits(hi)
        mid = (lo + hi) // 2
        if fits(mid):
            lo = mid
        else:
            hi = mid
    return lo


def wrap_to(text: str, width_px: float, size_px: int, *, bold: bool = False) -> str:
    """``text`` wrapped (at spaces) so that every line is at most ``width_px`` wide."""
    words = text.split()
    lines, line = [], ""
    for word in words:
        trial = f"{line} {word}" if line else word
        if line and text_extent(trial, size_px, bold=bold)[0] > width_px:
            lines.append(line)
            line = word
        else:
            line = trial
    if line:
        lines.append(line)
    return "\n".join(lines)


# --------------------------------------------------------------------------- geometry
def box_mesh(lo, hi) -> pv.PolyData:
    """The axis-aligned box with corners ``lo`` and ``hi``."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    return pv.Box(bounds=(lo[0], hi[0], lo[1], hi[1], lo[2], hi[2]))


def medium_bounds(scene: Scene) -> tuple:
    """The medium box as ``(xmin, xmax, ymin, ymax, zmin, zmax)`` (pyvista's bounds)."""
    lo, hi = scene.medium.bounds_min, scene.medium.bounds_max
    return (lo[0], hi[0], lo[1], hi[1], lo[2], hi[2])


def quad(corner, eu, ev) -> pv.PolyData:
    """The parallelogram ``corner + u eu + v ev``, ``u, v`` in [0, 1]."""
    c, u, v = (np.asarray(a, float) for a in (corner, eu, ev))
    pts = np.array([c, c + u, c + u + v, c + v])
    return pv.PolyData(pts, faces=np.array([4, 0, 1, 2, 3]))


def triangles_mesh(tris: np.ndarray) -> pv.PolyData:
    """A PolyData from an ``(F, 3, 3)`` triangle soup."""
    f = tris.shape[0]
    faces = np.column_stack([np.full(f, 3), np.arange(3 * f).reshape(f, 3)]).ravel()
    return pv.PolyData(tris.reshape(-1, 3).astype(float), faces=faces)


def polyline(points: np.ndarray) -> pv.PolyData:
    """The polyline through ``points`` (N, 3); a single point when N < 2."""
    pts = np.asarray(points, float)
    return pv.lines_from_points(pts) if len(pts) > 1 else pv.PolyData(pts)


def scale_of(scene: Scene) -> float:
    """A length for glyphs: 1/40 of the medium diagonal."""
    return scene.medium.diagonal / 40.0


# --------------------------------------------------------------------------- views
#: Direction (in the scene camera's frame: right, up, forward) the overview looks from.
OVERVIEW_DIRECTION = (0.75, 0.5, -1.0)


def overview_camera(scene: Scene, zoom: float = 1.3, aspect: float | None = None):
    """A fixed oblique viewpoint, from behind and beside the scene camera, that frames the
    camera, its frustum and the medium box.

    With ``aspect`` (the view's width / height) the camera, the box's corners and the
    picked pixel's side of the frustum are fitted to that view (the window's 3D view, which
    has its own title cell); without it, the tutorials' framing (a bounding sphere, room left
    at the top for a title inside the view). Returns ``(position, focal_point, view_up)`` for
    ``plotter.camera_position``.
    """
    cam = scene.camera
    med = scene.medium
    a, b, c = OVERVIEW_DIRECTION
    side = cam.right * a + cam.image_up * b + cam.forward * c
    side = side / np.linalg.norm(side)
    centre = 0.5 * (med.bounds_min + med.bounds_max)
    view_up = cam.image_up - (cam.image_up @ side) * side
    view_up = view_up / np.linalg.norm(view_up)
    if aspect is not None:
        return _fitted_overview(scene, side, view_up, float(aspect))
    pts = np.vstack([cam.position, med.bounds_min, med.bounds_max])
    focal = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
    focal = 0.8 * focal + 0.2 * centre
    radius = 0.5 * np.linalg.norm(cam.position - centre) + 0.5 * med.diagonal
    # A 30 degree view angle: distance to fit the radius, then shift the focal point down
    # so the scene sits below the title and caption.
    dist = radius / np.tan(np.radians(15.0)) / zoom
    focal = focal + 0.1 * radius * view_up
    return [tuple(focal + dist * side), tuple(focal), tuple(view_up)]


#: Room around the fitted overview (fraction of the view's half width / height), and the
#: fraction of its height kept free at the bottom (the colour bar, the legend).
OVERVIEW_MARGIN, OVERVIEW_BOTTOM = 0.06, 0.14


def _fitted_overview(scene: Scene, side, up, aspect: float):
    """The overview along ``side`` whose 30 degree view just holds the scene camera and the
    box's eight corners in a view ``aspect`` wide per unit of height, above the bottom band
    that legends and colour bars use."""
    med = scene.medium
    lo, hi = med.bounds_min, med.bounds_max
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                        for z in (lo[2], hi[2])])
    pts = np.vstack([scene.camera.position, corners])
    right = np.cross(up, side)
    # centre the points across the view, then back off until every one is inside
    x, y = pts @ right, pts @ up
    mid = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
    focal = ((mid @ side) * side + 0.5 * (x.min() + x.max()) * right
             + 0.5 * (y.min() + y.max()) * up)
    q = pts - focal
    t = np.tan(np.radians(15.0))
    # normalized screen heights run from -1 to 1: the band [-1, -1 + 2 b] stays free
    b, m = OVERVIEW_BOTTOM, OVERVIEW_MARGIN
    tv = t * (1.0 - b - m)
    th = t * aspect * (1.0 - m)
    dist = float(np.max(q @ side + np.maximum(np.abs(q @ right) / th, np.abs(q @ up) / tv)))
    focal = focal - b * t * dist * up  # the scene sits b higher, above the band
    return [tuple(focal + dist * side), tuple(focal), tuple(up)]


def frustum_lines(scene: Scene, pixel_xy=None):
    """Frustum edges (to the far side of the box), the image-plane rectangle at a short
    distance and, when given, the picked pixel's quad on that plane.

    Returns ``(edges, image_rect, pixel_quad or None)`` meshes.
    """
    cam = scene.camera
    med = scene.medium
    corners_box = np.array([[x, y, z] for x in (med.bounds_min[0], med.bounds_max[0])
                            for y in (med.bounds_min[1], med.bounds_max[1])
                            for z in (med.bounds_min[2], med.bounds_max[2])])
    depth = (corners_box - cam.position) @ cam.forward
    far = float(np.min(depth))  # the box's nearest corner: rays continue as query rays
    near = max(0.3 * far, 0.05 * float(np.max(depth)))
    w, h = cam.width, cam.height
    px = np.array([0.0, w, w, 0.0])
    py = np.array([0.0, 0.0, h, h])
    d = pixel_directions(cam, px, py)
    cosf = d @ cam.forward
    far_pts = cam.position + d * (far / cosf)[:, None]
    near_pts = cam.position + d * (near / cosf)[:, None]
    pts = np.vstack([cam.position[None], far_pts])
    edges = pv.PolyData(pts, lines=np.array([2, 0, 1, 2, 0, 2, 2, 0, 3, 2, 0, 4]))
    rect_far = pv.PolyData(far_pts, lines=np.array([5, 0, 1, 2, 3, 0]))
    rect = pv.PolyData(near_pts, lines=np.array([5, 0, 1, 2, 3, 0]))
    edges = edges.merge(rect_far)
    pix = None
    if pixel_xy is not None:
        x, y = pixel_xy
        # Enlarged so the pixel stays visible on the small image plane.
        grow = max(1.0, 0.012 * w)
        qx = np.array([x, x + 1, x + 1, x], float) + np.array([-1, 1, 1, -1]) * (grow - 1) / 2
        qy = np.array([y, y, y + 1, y + 1], float) + np.array([-1, -1, 1, 1]) * (grow - 1) / 2
        dq = pixel_directions(cam, qx, qy)
        q = cam.position + dq * (near / (dq @ cam.forward))[:, None]
        pix = pv.PolyData(q, faces=np.array([4, 0, 1, 2, 3]))
    return edges, rect, pix


def add_picked_pixel(plotter: pv.Plotter, scene: Scene, pixel_xy) -> None:
    """The picked pixel's quad on the camera's image plane (the actor ``picked-pixel``;
    drawn apart from :func:`add_scene` so that a moved pixel keeps the scene's actors)."""
    if pixel_xy is None:
        return
    pix = frustum_lines(scene, pixel_xy)[2]
    plotter.add_mesh(pix, color=HIGHLIGHT, lighting=False, name="picked-pixel",
                     reset_camera=False)


def add_scene(plotter: pv.Plotter, scene: Scene, *, pixel_xy=None, box_opacity=0.07,
              labels=True) -> None:
    """Draw the medium box (translucent, with edges), lights, occluders and the camera."""
    box = box_mesh(scene.medium.bounds_min, scene.medium.bounds_max)
    plotter.add_mesh(box, color=MEDIUM_COLOUR, opacity=box_opacity, lighting=False,
                     name="medium")
    plotter.add_mesh(box.outline(), color="#444444", line_width=px(3), name="medium-edges")
    sc = scale_of(scene)
    label_pts, label_txt = [], []
    for i, lt in enumerate(scene.lights):
        if isinstance(lt, PointLight):
            plotter.add_mesh(pv.Sphere(radius=1.3 * sc, center=lt.position), color=LIGHT_COLOUR,
                             smooth_shading=True, name=f"light{i}")
            label_pts.append(lt.position + 4.0 * sc * scene.camera.image_up)
        elif isinstance(lt, AreaLight):
            q = quad(lt.corner, lt.edge_u, lt.edge_v)
            plotter.add_mesh(q, color=LIGHT_COLOUR, show_edges=True, edge_color="black",
                             line_width=px(3), lighting=False, name=f"light{i}")
            c = lt.corner + 0.5 * (lt.edge_u + lt.edge_v)
            arrow = pv.Arrow(start=c, direction=lt.normal, scale=6 * sc, tip_length=0.3,
                             tip_radius=0.12, shaft_radius=0.04)
            plotter.add_mesh(arrow, color="#333333", name=f"light{i}-normal")
            label_pts.append(c - lt.normal * 2.5 * sc)
        elif isinstance(lt, MeshLight):
            plotter.add_mesh(triangles_mesh(lt.triangles), color=LIGHT_COLOUR,
                             smooth_shading=False, name=f"light{i}")
            label_pts.append(lt.triangles.reshape(-1, 3).max(axis=0))
        label_txt.append(f"{lt.kind} light")
    for j, oc in enumerate(scene.occluders):
        if isinstance(oc, SphereOccluder):
            m = pv.Sphere(radius=oc.radius, center=oc.center, theta_resolution=48,
                          phi_resolution=48)
        elif isinstance(oc, BoxOccluder):
            m = box_mesh(oc.min, oc.max)
        else:
            m = triangles_mesh(oc.triangles)
        plotter.add_mesh(m, color=OCCLUDER_COLOUR, smooth_shading=True, name=f"occluder{j}")
    edges, rect, pix = frustum_lines(scene, pixel_xy)
    plotter.add_mesh(edges, color="#555555", line_width=px(2), name="frustum")
    plotter.add_mesh(rect, color="black", line_width=px(3), name="image-plane")
    if pix is not None:
        plotter.add_mesh(pix, color=HIGHLIGHT, lighting=False, name="picked-pixel")
    plotter.add_mesh(pv.Sphere(radius=0.8 * sc, center=scene.camera.position), color="black",
                     name="camera")
    label_pts.append(scene.camera.position + scene.camera.image_up * 3 * sc)
    label_txt.append("camera")
    if labels:
        plotter.add_point_labels(np.array(label_pts), label_txt, font_size=pt(FONT),
                                 text_color=TEXT_COLOUR, shape_color="white",
                                 shape_opacity=0.8, show_points=False, always_visible=True,
                                 name="scene-labels")
