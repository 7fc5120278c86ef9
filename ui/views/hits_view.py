"""Intersect, Evaluate and Reconstruct in 3D: the query ray, its hits, the normals and the
reconstructed path (pyvista; the numbers come from :mod:`psurf_core.inspect`, the panel's text
from :mod:`ui.views.stage_text`).

Colours: techniques keep theirs (:mod:`ui.views.palette`); what is not a technique is drawn in
black, white and greys (the query ray, the hits, psi and the normals, the reconstructed path),
so no colour means two things.
"""

from __future__ import annotations

import numpy as np

from . import label_layout, scene_view
from ._vtk import pv
from .palette import OKABE_ITO, technique_colour
from .primitives_view import add_legend, add_primitives, primitive_mesh
from .scene_view import FONT, FONT_SMALL, TEXT_COLOUR, pt, px, scale_of
from .stage_text import NORMAL_ROWS, TABLE_ROWS, default_hit, hit_order  # noqa: F401

QUERY_COLOUR = "#1a1a1a"
NORMAL_COLOUR = "#000000"
PSI_COLOUR = "#707070"
HIT_COLOUR = "#ffffff"
PATH_COLOUR = "#000000"
LEADER_COLOUR = "#555555"


# --------------------------------------------------------------------------- selection
def hit_selection(inspection, rows=None) -> dict:
    """``(technique, batch) -> primitive rows`` of the primitives the given hits come from."""
    t = inspection.table
    rows = np.arange(len(t)) if rows is None else np.asarray(rows, dtype=np.int64)
    sel: dict = {}
    for r in rows:
        key = (str(t.technique[r]), int(t.batch[r]))
        sel.setdefault(key, set()).add(int(t.prim[r]))
    return {k: np.array(sorted(v), dtype=np.int64) for k, v in sel.items()}


# --------------------------------------------------------------------------- drawing
def add_query_ray(plotter: pv.Plotter, inspection, *, width: float = 8.0) -> None:
    """Each camera ray of the pixel: thin up to the medium, thick inside it (to its first
    occluder or the box exit)."""
    r = inspection.rays
    sc = scale_of(inspection.scene)
    for i in range(len(r)):
        o, d = r.o[i], r.d[i]
        a, b = float(r.s_min[i]), float(r.s_max[i])
        if b <= a:  # sees no medium: draw it up to the box's neighbourhood
            b = a = float(np.linalg.norm(inspection.scene.camera.position
                                         - 0.5 * (inspection.scene.medium.bounds_min
                                                  + inspection.scene.medium.bounds_max)))
        plotter.add_mesh(pv.Line(o, o + a * d), color="#777777", line_width=px(3),
                         name=f"ray{i}-out")
        if b > a:
            plotter.add_mesh(pv.Line(o + a * d, o + b * d), color=QUERY_COLOUR,
                             line_width=px(width), name=f"ray{i}-in")
            end = o + b * d
            plotter.add_mesh(pv.Cone(center=end + 0.9 * sc * d, direction=d, height=1.8 * sc,
                                     radius=0.7 * sc, resolution=24), color=QUERY_COLOUR,
                             name=f"ray{i}-tip")


def add_labels(plotter: pv.Plotter, scene, points: np.ndarray, labels: list, *, dist: float,
               name: str, size: float = FONT, colour: str = TEXT_COLOUR,
               camera=None) -> object:
    """Labels that are all drawn and never cover each other or a labelled point: each is
    placed on screen for the view's camera (``camera``, default the overview) at the first
    free spot around its point, about ``dist`` (world units) away
    (:func:`ui.views.label_layout.place`), and tied to it by a thin leader line."""
    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    if not len(pts):
        return None
    off, lead = _label_offsets(plotter, scene, pts, list(labels), dist, pt(size), camera)
    anchors = pts + off
    n = len(pts)
    lines = np.column_stack([np.full(n, 2), np.arange(n), np.arange(n) + n]).ravel()
    plotter.add_mesh(pv.PolyData(np.vstack([pts, pts + lead]), lines=lines),
                     color=LEADER_COLOUR, line_width=px(1.5), name=f"{name}-leaders")
    actor = plotter.add_point_labels(anchors, list(labels), font_size=pt(size),
                                     text_color=colour, shape_color="white",
                                     shape_opacity=0.85, show_points=False,
                                     always_visible=True, name=name)
    actor.GetMapper().PlaceAllLabelsOn()  # every label drawn (they are apart already)
    return actor


def _label_offsets(plotter, scene, pts, labels, dist: float, font_px: int, camera):
    """World offsets ``(anchors, leader ends)`` of ``labels`` at ``pts`` for the plotter's
    current renderer (its size in pixels and view angle) seen from ``camera``."""
    cam = camera or scene_view.overview_camera(scene)
    x0, y0, x1, y1 = plotter.renderer.GetViewport()
    w, h = plotter.window_size
    view = ((x1 - x0) * w, (y1 - y0) * h, plotter.renderer.GetActiveCamera().GetViewAngle())
    # pyvista draws point labels bold
    sizes = [scene_view.text_extent(str(t), font_px, bold=True) for t in labels]
    _, depth = label_layout.project(pts, cam, view)
    dist_px = float(np.clip(dist * np.median(label_layout.pixels_per_unit(depth, view)),
                            10.0, 40.0))
    return label_layout.world_offsets(pts, sizes, cam, view, dist_px)


def add_hit_points(plotter: pv.Plotter, inspection, rows, *, labels: bool = True,
                   radius_scale: float = 0.7, camera=None) -> None:
    """Hit points: the table's top :data:`TABLE_ROWS` as white spheres, labelled ``#i``
    (display order) when asked, every other hit as a small point (an MIS set can have
    thousands: one sphere mesh each would take seconds to build and draw)."""
    t = inspection.table
    sc = scale_of(inspection.scene)
    rows = np.asarray(rows, dtype=np.int64)
    if not rows.size:
        return
    rank = np.empty(len(t), dtype=np.int64)
    rank[hit_order(inspection)] = np.arange(len(t))
    top = rows[rank[rows] < TABLE_ROWS]
    top = top[np.argsort(rank[top])]
    rest = rows[rank[rows] >= TABLE_ROWS]
    # (pyvista's add_mesh(name=X) removes the actors named "X-...": "hits" goes first)
    if top.size:
        g = pv.PolyData(t.point[top]).glyph(
            geom=pv.Sphere(radius=radius_scale * sc, theta_resolution=16, phi_resolution=12),
            scale=False, orient=False)
        plotter.add_mesh(g, color=HIT_COLOUR, smooth_shading=True, name="hits")
    if rest.size:
        plotter.add_mesh(pv.PolyData(t.point[rest]), color=HIT_COLOUR, point_size=px(7),
                         render_points_as_spheres=True, name="hits-rest")
    if top.size:
        if labels:
            add_ray_labels(plotter, inspection, top, [f"#{int(rank[r])}" for r in top],
                           camera=camera)


def add_ray_labels(plotter: pv.Plotter, inspection, rows, labels: list, *,
                   name: str = "hit-labels", camera=None) -> object:
    """Labels of hits on the query ray that never cover each other: lined up beside the ray
    on screen, in the order of the hits along it, one box apart
    (:func:`ui.views.label_layout.line_up`, for the view's camera and size), and tied to their
    hits by leader lines. Hits cluster along the ray, so labels next to their hits would
    pile up; every label is drawn (none is hidden where two would touch)."""
    t = inspection.table
    scene = inspection.scene
    sc = scale_of(scene)
    rows = np.asarray(rows, dtype=np.int64)
    if not rows.size:
        return None
    cam = camera or scene_view.overview_camera(scene)
    order = np.argsort(t.s[rows], kind="stable")
    pts = t.point[rows][order]
    names = [labels[i] for i in order]
    x0, y0, x1, y1 = plotter.renderer.GetViewport()
    w, h = plotter.window_size
    view = ((x1 - x0) * w, (y1 - y0) * h, plotter.renderer.GetActiveCamera().GetViewAngle())
    screen, _ = label_layout.project(pts, cam, view)
    ends, _ = label_layout.project(pts[:1] + t.psi[rows[order[0]]][None] * sc, cam, view)
    sizes = [scene_view.text_extent(str(x), pt(FONT), bold=True) for x in names]
    anchors_px, leaders_px = label_layout.line_up(screen, ends[0] - screen[0], sizes,
                                                  0.6 * pt(FONT))
    # back to the world, in the plane parallel to the image through the hits' middle
    _, _, right, up = label_layout.view_basis(cam)
    mid = pts.mean(axis=0)
    (mid_px,), (mid_depth,) = label_layout.project(mid[None], cam, view)
    per_px = 1.0 / float(label_layout.pixels_per_unit(mid_depth, view))

    def world(p):
        d = (p - mid_px[None]) * per_px
        return mid[None] + d[:, :1] * right[None] + d[:, 1:] * up[None]

    anchors, leader_ends = world(anchors_px), world(leaders_px)
    n = len(pts)
    cells = np.column_stack([np.full(n, 2), np.arange(n), np.arange(n) + n]).ravel()
    plotter.add_mesh(pv.PolyData(np.vstack([pts, leader_ends]), lines=cells),
                     color=LEADER_COLOUR, line_width=px(1.5), name=f"{name}-leaders")
    actor = plotter.add_point_labels(anchors, names, font_size=pt(FONT),
                                     text_color=TEXT_COLOUR, shape_color="white",
                                     shape_opacity=0.85, show_points=False,
                                     always_visible=True, name=name)
    actor.GetMapper().PlaceAllLabelsOn()
    return actor


def add_normals(plotter: pv.Plotter, inspection, rows, *, camera=None) -> None:
    """At each hit: the camera direction ``psi`` (grey) and the scaled normal ``n``
    (black, labelled with the hit's table number; length proportional to ``|n|``,
    clamped to stay readable)."""
    t = inspection.table
    sc = scale_of(inspection.scene)
    rows = np.asarray(rows, dtype=np.int64)
    if rows.size == 0:
        return
    n = t.normal[rows]
    ok = np.all(np.isfinite(n), axis=1) & (np.linalg.norm(n, axis=1) > 0)
    psi_len = 5.0 * sc
    psi = pv.PolyData(t.point[rows])
    psi["v"] = t.psi[rows]
    plotter.add_mesh(psi.glyph(orient="v", scale=False, factor=psi_len,
                               geom=pv.Arrow(tip_length=0.3, tip_radius=0.13, shaft_radius=0.05)),
                     color=PSI_COLOUR, name="psi-arrows")
    if ok.any():
        nn = n[ok]
        mag = np.linalg.norm(nn, axis=1)
        # sign: the side facing the camera, so the arrow is visible beside psi
        flip = np.where(np.einsum("ij,ij->i", nn, t.psi[rows][ok]) > 0, -1.0, 1.0)
        unit = nn / mag[:, None] * flip[:, None]
        ref = np.median(mag) if np.median(mag) > 0 else 1.0
        length = np.clip(mag / ref, 0.4, 2.0) * 5.0 * sc
        pts = pv.PolyData(t.point[rows][ok])
        pts["v"] = unit
        pts["len"] = length
        plotter.add_mesh(pts.glyph(orient="v", scale="len", factor=1.0,
                                   geom=pv.Arrow(tip_length=0.3, tip_radius=0.13,
                                                 shaft_radius=0.05)),
                         color=NORMAL_COLOUR, name="normal-arrows")
        tips = t.point[rows][ok] + unit * length[:, None]
        rank = {int(r): i for i, r in enumerate(hit_order(inspection))}
        names = [f"n #{rank[int(r)]}" for r in rows[ok]]
        tips = tips + _label_offsets(plotter, inspection.scene, tips, names, 1.5 * sc,
                                     pt(FONT_SMALL), camera)[0]
        actor = plotter.add_point_labels(
            tips, names,
            font_size=pt(FONT_SMALL), text_color=NORMAL_COLOUR, shape_color="white",
            shape_opacity=0.85, show_points=False, always_visible=True, name="normal-labels")
        actor.GetMapper().PlaceAllLabelsOn()


def add_hit_primitives(plotter: pv.Plotter, inspection, rows, *, legend: bool = True,
                       opacity: float = 0.45) -> dict:
    """The primitives the given hits belong to, with strong edges."""
    return add_primitives(plotter, inspection, hit_selection(inspection, rows), opacity=opacity,
                          name="hitprims", legend=legend, width=4.0, list_empty=False)


def path_frame(recon: dict, scene) -> tuple:
    """``(centre, radius)`` of the reconstructed path (light .. x0, its hit on the ray); the
    photon's own sampled vertices are left out (traced as in an infinite medium, they may lie
    far outside the box)."""
    pts = np.asarray(recon["polyline"], dtype=float)[:-1]
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    centre = 0.5 * (lo + hi)
    radius = max(float(np.linalg.norm(pts - centre, axis=1).max()), 6.0 * scale_of(scene))
    return centre, radius


def reconstruct_camera(recon: dict, scene, margin: float = 1.35):
    """A camera ``(position, focal_point, view_up)`` that frames the reconstructed path (the
    Reconstruct stage's auto-zoom), looking from the overview's direction."""
    pos, focal, up = (np.asarray(v, float) for v in scene_view.overview_camera(scene))
    back = (pos - focal) / np.linalg.norm(pos - focal)
    centre, radius = path_frame(recon, scene)
    dist = margin * radius / np.tan(np.radians(15.0))  # pyvista's 30 degree view angle
    return [tuple(centre + dist * back), tuple(centre), tuple(up)]


def add_reconstruction(plotter: pv.Plotter, inspection, recon: dict, *, camera=None) -> None:
    """The full path a hit implies (thick, every vertex labelled: no two labels share one)
    and, thin and grey, the photon's own sampled vertices it replaced."""
    scene = inspection.scene
    sc = scale_of(scene)
    own = np.asarray(recon["photon_polyline"])
    if len(own) > 1:
        plotter.add_mesh(pv.lines_from_points(own), color=OKABE_ITO["grey"], line_width=px(4),
                         name="photon-own")
    poly = np.asarray(recon["polyline"])
    plotter.add_mesh(pv.lines_from_points(poly[:-1]), color=PATH_COLOUR, line_width=px(9),
                     name="recon-path")
    plotter.add_mesh(pv.Line(poly[-2], poly[-1]), color=QUERY_COLOUR, line_width=px(3),
                     name="recon-camera")
    _, radius = path_frame(recon, scene)
    g = pv.PolyData(poly[:-1]).glyph(geom=pv.Sphere(radius=min(0.9 * sc, 0.04 * radius)),
                                     scale=False, orient=False)
    plotter.add_mesh(g, color="black", name="recon-vertices")
    add_labels(plotter, scene, poly[:-1], list(recon["labels"][:-1]),
               dist=max(0.16 * radius, 1.5 * sc), name="recon-labels", camera=camera)


def add_member_surfaces(plotter: pv.Plotter, inspection, recon: dict, members: dict, *,
                        opacity: float = 0.22) -> list:
    """Every MIS member's surface through the reconstructed path (the talk's Reconstruct:
    one path, each technique's primitive through it, their ``Q`` and weights), each in its
    technique's colour; the hit's own technique is drawn stronger. Returns the legend
    entries.

    ``members`` is :func:`psurf_core.inspect.member_primitives` of ``recon``.
    """
    q_w = {name: (q, w) for name, q, w in recon["members"]}
    entries = []
    for name, (tech, prims, rows) in members.items():
        col = technique_colour(name)
        q, w = q_w.get(name, (float("nan"), float("nan")))
        own = name == recon["technique"]
        label = f"{'> ' if own else ''}{name}  w {w:.2f}"
        if prims is None or rows.size == 0:
            entries.append([f"{name}: cannot make K={recon['K']}", OKABE_ITO["grey"]])
            continue
        mesh, how = primitive_mesh(tech, prims, rows, inspection.scene,
                                   inspection.radii.get(name, 0.0))
        if mesh.n_points:
            if how == "bounds":
                plotter.add_mesh(mesh, color=col, line_width=px(3), name=f"member-{name}:mesh")
            else:
                plotter.add_mesh(mesh, color=col, opacity=0.55 if own else opacity,
                                 show_edges=False, culling=False, name=f"member-{name}:mesh")
                edges = mesh.extract_feature_edges(boundary_edges=True, feature_edges=False,
                                                   manifold_edges=False,
                                                   non_manifold_edges=False)
                if edges.n_points:
                    plotter.add_mesh(edges, color=col, line_width=px(4 if own else 2),
                                     name=f"member-{name}:edges")
        entries.append([label, col])
    if entries:
        add_legend(plotter, entries, loc="lower right")
    return entries
