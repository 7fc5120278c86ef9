"""Intersect, Evaluate and Reconstruct in 3D: the query ray, its hits, the normals, the
evaluate table and the reconstructed path (pyvista; the numbers come from
:mod:`psurf_core.inspect`)."""

from __future__ import annotations

import textwrap

import numpy as np

from . import scene_view
from ._vtk import pv
from .primitives_view import add_legend, add_primitives, primitive_mesh
from .scene_view import (
    FONT,
    FONT_SMALL,
    HIGHLIGHT,
    OKABE_ITO,
    TEXT_COLOUR,
    pt,
    px,
    scale_of,
)

#: Rows of the evaluate table shown (largest contributions first).
TABLE_ROWS = 9
NORMAL_COLOUR = OKABE_ITO["vermillion"]
PSI_COLOUR = OKABE_ITO["black"]
HIT_COLOUR = OKABE_ITO["orange"]
PATH_COLOUR = OKABE_ITO["vermillion"]
#: Normals and psi are drawn at this many hits (largest contributions).
NORMAL_ROWS = 3
#: Colours of the MIS members' surfaces in Reconstruct (one per member, in group order;
#: Okabe-Ito, colour-blind safe; several members share a family, so families won't do).
MEMBER_COLOURS = [OKABE_ITO[c] for c in ("blue", "orange", "green", "purple", "sky_blue",
                                          "vermillion", "yellow", "grey")]


# --------------------------------------------------------------------------- selection
def hit_order(inspection) -> np.ndarray:
    """Table rows by decreasing contribution: row ``i`` of the display is ``hit_order[i]``."""
    return inspection.table.by_contribution()


def default_hit(inspection) -> int | None:
    """The hit the Reconstruct stage shows when none is asked: the largest contribution."""
    t = inspection.table
    return None if len(t) == 0 else int(t.by_contribution()[0])


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
        plotter.add_mesh(pv.Line(o, o + a * d), color="#555555", line_width=px(3),
                         name=f"ray{i}-out")
        if b > a:
            plotter.add_mesh(pv.Line(o + a * d, o + b * d), color=HIGHLIGHT, line_width=px(width),
                             name=f"ray{i}-in")
            end = o + b * d
            plotter.add_mesh(pv.Cone(center=end + 0.9 * sc * d, direction=d, height=1.8 * sc,
                                     radius=0.7 * sc, resolution=24), color=HIGHLIGHT,
                             name=f"ray{i}-tip")


def add_hit_points(plotter: pv.Plotter, inspection, rows, *, labels: bool = True,
                   radius_scale: float = 0.7) -> None:
    """Hit points as orange spheres, labelled ``#i`` (display order) when asked."""
    t = inspection.table
    sc = scale_of(inspection.scene)
    rows = np.asarray(rows, dtype=np.int64)
    if rows.size:
        g = pv.PolyData(t.point[rows]).glyph(geom=pv.Sphere(radius=radius_scale * sc),
                                             scale=False, orient=False)
        plotter.add_mesh(g, color=HIT_COLOUR, smooth_shading=True, name="hits")
    if labels and rows.size:
        order = hit_order(inspection)
        rank = {int(r): i for i, r in enumerate(order)}
        shown = [r for r in rows if rank[int(r)] < TABLE_ROWS]
        if shown:
            up = inspection.scene.camera.image_up
            pts = t.point[shown] + 1.8 * sc * up
            plotter.add_point_labels(pts, [f"#{rank[int(r)]}" for r in shown],
                                     font_size=pt(FONT), text_color=TEXT_COLOUR,
                                     shape_color="white", shape_opacity=0.85,
                                     show_points=False, always_visible=True, name="hit-labels")


def add_normals(plotter: pv.Plotter, inspection, rows) -> None:
    """At each hit: the camera direction ``psi`` (black) and the scaled normal ``n``
    (vermillion, labelled with the hit's table number; length proportional to ``|n|``,
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
        tips = tips + label_offsets(inspection.scene, tips, 1.5 * sc)
        rank = {int(r): i for i, r in enumerate(hit_order(inspection))}
        actor = plotter.add_point_labels(
            tips, [f"n #{rank[int(r)]}" for r in rows[ok]],
            font_size=pt(FONT_SMALL), text_color=NORMAL_COLOUR, shape_color="white",
            shape_opacity=0.85, show_points=False, always_visible=True, name="normal-labels")
        actor.GetMapper().PlaceAllLabelsOn()


def add_hit_primitives(plotter: pv.Plotter, inspection, rows, *, legend: bool = True,
                       opacity: float = 0.45) -> dict:
    """The primitives the given hits belong to, with strong edges."""
    return add_primitives(plotter, inspection, hit_selection(inspection, rows), opacity=opacity,
                          name="hitprims", legend=legend, width=4.0, list_empty=False)


def add_reconstruction(plotter: pv.Plotter, inspection, recon: dict) -> None:
    """The full path a hit implies (thick, labelled vertices) and, thin and dashed-grey,
    the photon's own sampled vertices it replaced."""
    sc = scale_of(inspection.scene)
    own = np.asarray(recon["photon_polyline"])
    if len(own) > 1:
        plotter.add_mesh(pv.lines_from_points(own), color=OKABE_ITO["grey"], line_width=px(4),
                         name="photon-own")
    poly = np.asarray(recon["polyline"])
    plotter.add_mesh(pv.lines_from_points(poly[:-1]), color=PATH_COLOUR, line_width=px(9),
                     name="recon-path")
    plotter.add_mesh(pv.Line(poly[-2], poly[-1]), color=HIGHLIGHT, line_width=px(3),
                     name="recon-camera")
    g = pv.PolyData(poly[:-1]).glyph(geom=pv.Sphere(radius=0.9 * sc), scale=False, orient=False)
    plotter.add_mesh(g, color="black", name="recon-vertices")
    # Vertices closer than a glyph share one label (x2 right next to the light, ...).
    pts, labs = [], []
    for v, lab in zip(poly[:-1], recon["labels"][:-1], strict=True):
        if pts and np.linalg.norm(v - pts[-1]) < 1.2 * sc:
            labs[-1] = f"{labs[-1]}, {lab}"
        else:
            pts.append(v)
            labs.append(lab)
    pts = np.array(pts)
    offset = label_offsets(inspection.scene, pts, 2.4 * sc)
    actor = plotter.add_point_labels(pts + offset, labs, font_size=pt(FONT),
                                     text_color=TEXT_COLOUR, shape_color="white",
                                     shape_opacity=0.85, show_points=False,
                                     always_visible=True, name="recon-labels")
    actor.GetMapper().PlaceAllLabelsOn()  # every vertex named, even where labels touch


def add_member_surfaces(plotter: pv.Plotter, inspection, recon: dict, members: dict, *,
                        opacity: float = 0.22) -> list:
    """Every MIS member's surface through the reconstructed path (the talk's Reconstruct:
    one path, each technique's primitive through it, their ``Q`` and weights), one colour per
    member; the hit's own technique is drawn stronger. Returns the legend entries.

    ``members`` is :func:`psurf_core.inspect.member_primitives` of ``recon``.
    """
    q_w = {name: (q, w) for name, q, w in recon["members"]}
    entries = []
    for i, (name, (tech, prims, rows)) in enumerate(members.items()):
        col = MEMBER_COLOURS[i % len(MEMBER_COLOURS)]
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
                plotter.add_mesh(mesh, color=col, line_width=px(3), name=f"member-{name}")
            else:
                plotter.add_mesh(mesh, color=col, opacity=0.55 if own else opacity,
                                 show_edges=False, culling=False, name=f"member-{name}")
                edges = mesh.extract_feature_edges(boundary_edges=True, feature_edges=False,
                                                   manifold_edges=False,
                                                   non_manifold_edges=False)
                if edges.n_points:
                    plotter.add_mesh(edges, color=col, line_width=px(4 if own else 2),
                                     name=f"member-{name}-edges")
        entries.append([label, col])
    if entries:
        add_legend(plotter, entries, loc="lower right")
    return entries


def label_offsets(scene, pts: np.ndarray, dist: float) -> np.ndarray:
    """(N, 3) world offsets for labels of ``pts`` that keep them apart on screen.

    Greedy, in the plane of the overview view: each label takes, of eight directions, the
    one whose label position is farthest from every vertex and every label placed so far.
    """
    pos, focal, up = (np.asarray(v, float) for v in scene_view.overview_camera(scene))
    back = (pos - focal) / np.linalg.norm(pos - focal)
    up = up / np.linalg.norm(up)
    right = np.cross(up, back)
    ang = np.radians([90, 45, 135, 0, 180, 270, 315, 225])
    cands = np.cos(ang)[:, None] * right[None] + np.sin(ang)[:, None] * up[None]

    def screen(x):
        return np.stack([x @ right, x @ up], axis=-1)

    taken = list(screen(pts))
    out = np.zeros_like(pts)
    for i, p in enumerate(pts):
        spots = screen(p[None] + dist * cands)
        gap = np.min(np.linalg.norm(spots[:, None] - np.array(taken)[None], axis=-1), axis=1)
        best = int(np.argmax(np.round(gap / dist, 1)))  # ties keep the earlier (upper) spot
        out[i] = dist * cands[best]
        taken.append(spots[best])
    return out


# --------------------------------------------------------------------------- text
def _g(x: float) -> str:
    if not np.isfinite(x):
        return "   -   "
    return f"{x:7.1e}" if (x != 0 and (abs(x) < 1e-2 or abs(x) >= 1e3)) else f"{x:7.3f}"


def _short(name: str, n: int = 13) -> str:
    name = name.replace("-short", "-s")
    return name if len(name) <= n else name[: n - 1] + "~"


def evaluate_table_text(inspection, max_rows: int = TABLE_ROWS) -> str:
    """The evaluate table as monospace text (largest contributions first).

    Columns: display index, technique and primitive id (its row in that technique's
    primitives of the hit's photon batch), K, distance ``s``, ``|n.psi|``, the Jacobian factor
    ``1/|n.psi|``, ``f = value |n.psi|``, MIS weight ``w`` and the contribution (mean over
    RGB); ``!`` marks a near-singular hit, ``x`` one whose path is invalid (Evaluate returned
    0: occluded, or a vertex outside). A first line names each technique's family.
    """
    t = inspection.table
    px, py = inspection.pixel_xy
    fam: dict = {}
    for n, f in zip(t.technique, t.family, strict=True):
        fam.setdefault(str(f), {})[_short(str(n), 12)] = None
    lines = [f"pixel ({px}, {py})  pass {inspection.pass_index}  "
             f"{len(t)} hits  {inspection.n_photons} photons"]
    lines += textwrap.wrap("; ".join(f"{f}: {' '.join(ns)}" for f, ns in fam.items()) or "-",
                           width=74, initial_indent="families: ", subsequent_indent="  ")
    lines.append(" # technique   prim  K     s    |n.psi| 1/|n.psi|    f     w   contrib")
    order = hit_order(inspection)
    with np.errstate(divide="ignore", invalid="ignore"):
        jac = 1.0 / t.n_dot_psi
    for i, r in enumerate(order[:max_rows]):
        mark = "x" if not np.any(t.value[r]) else ("!" if t.near_singular[r] else " ")
        lines.append(f"{i:2d}{mark}{_short(str(t.technique[r]), 12):<12s}{int(t.prim[r]):4d} "
                     f"{int(t.K[r]):2d} {t.s[r]:6.3f} {_g(t.n_dot_psi[r])} {_g(jac[r])} "
                     f"{_g(float(np.mean(t.f[r])))} "
                     f"{t.mis_weight[r]:4.2f} {_g(float(np.mean(t.contribution[r])))}")
    if len(t) > max_rows:
        rest = order[max_rows:]
        lines.append(f"   ... {len(rest)} more hits, together "
                     f"{_g(float(np.mean(t.contribution[rest].sum(axis=0)))).strip()}")
    total = float(np.mean(t.total))
    pv_ = float(np.mean(inspection.pixel_value))
    ok = "= pixel value (check ok)" if inspection.sum_matches else "!= pixel value (MISMATCH)"
    lines.append(f"sum {_g(total).strip()} {ok} {_g(pv_).strip()}")
    shown = order[:max_rows]
    if any(not np.any(t.value[r]) for r in shown):
        lines.append("x invalid path (occluded or outside the box): adds 0")
    if t.near_singular[shown].any():
        lines.append("! near-singular: |n.psi| < 1e-3, huge 1/|n.psi|")
    return "\n".join(lines)


def reconstruct_text(inspection, recon: dict, display_index: int | None = None) -> str:
    """The Reconstruct stage's panel: the hit, its path and every MIS member's ``Q`` and
    weight on that same path."""
    t = inspection.table
    k = recon["row"]
    idx = f"#{display_index}" if display_index is not None else f"row {k}"
    lines = [f"hit {idx}: {recon['technique']}  K={recon['K']}  s={t.s[k]:.3f}",
             "path: " + " -> ".join(lb.split(" ")[0] for lb in recon["labels"])]
    if not recon["available"]:
        lines.append(recon["note"])
        return "\n".join(lines)
    wt = recon["weighting"] or "none (single technique)"
    lines.append(f"MIS weighting: {wt}")
    lines.append("  member            Q = q|n.psi|   weight")
    for name, q, w in recon["members"]:
        me = "<" if name == recon["technique"] else " "
        lines.append(f" {me}{_short(name, 17):<17s} {_g(q):>12s}   {w:5.3f}")
    wsum = sum(w for _, _, w in recon["members"])
    lines.append(f"weights sum to {wsum:.3f}; contribution "
                 f"{_g(float(np.mean(t.contribution[k]))).strip()}")
    return "\n".join(lines)
