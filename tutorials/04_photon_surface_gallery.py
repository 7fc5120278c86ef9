# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # 4 · The photon-surface gallery
#
# **Learning goal.** Recognise each photon surface of the paper (Fig. 2 and Table 1) as the
# set of points $\mathbf x_0$ one photon sweeps when two of its dimensions run free, and
# read its scaled normal $\mathbf n$ off the geometry: planes, generalized planes, sphere,
# cone, cylinder, disk, and the two surfaces of revolution (hyperboloid, torus).
#
# Every panel shows one photon from psurf's renderer: its sampled path (grey), the surface it
# sweeps (the short variant where one exists, so the surface is finite), the camera ray of one
# pixel (black), the hit, and at the hit the scaled normal $\mathbf n$ (vermillion) and the
# ray direction $\boldsymbol\psi$. The Jacobian of tutorial 3 is their dot product.
#
# `PSURF_TUTORIAL_BUDGET=test` switches to a small budget; figures go to `out/tutorials/04_*.png`.

# %% Setup: paths, budget switch, projector style
# ruff: noqa: E402, E501
import os
import sys
from pathlib import Path

import numpy as np

try:
    ROOT = Path(__file__).resolve().parents[1]
except NameError:  # in a notebook the working directory is tutorials/
    ROOT = Path.cwd().resolve().parent if (Path.cwd().parent / "scenes").is_dir() else Path.cwd()
sys.path.insert(0, str(ROOT))

BUDGET = os.environ.get("PSURF_TUTORIAL_BUDGET", "lecture")
if BUDGET not in ("test", "lecture"):
    raise SystemExit(f"PSURF_TUTORIAL_BUDGET must be 'test' or 'lecture', not {BUDGET!r}")
TEST = BUDGET == "test"
OUT = Path(os.environ.get("PSURF_TUTORIAL_OUT", ROOT / "out" / "tutorials"))
OUT.mkdir(parents=True, exist_ok=True)

import pyvista as pv

from psurf_core import RenderSettings, load_scene
from psurf_core.inspect import inspect_pixel, reconstruct_hit
from ui.views import palette, primitives_view, scene_view

pv.OFF_SCREEN = True
scene_view.plain_text()
OK = scene_view.OKABE_ITO  # colour-blind-safe palette (Okabe & Ito)

B = dict(photons=1500, size=(1920, 1080)) if TEST else dict(photons=6000, size=(2400, 1350))

# %% [markdown]
# ## The surfaces and their normals
#
# Notation of ESTIMATORS.md: the photon path ends $\mathbf x_3\to\mathbf x_2\to\mathbf
# x_1\to\mathbf x_0$ with directions $\omega_3,\omega_2,\omega_1$ and lengths $t_3,t_2,t_1$;
# $c_1=\omega_1\cdot\omega_2=\cos\theta_1$, $s_1=\sin\theta_1$; $A_3$ is $\omega_3$ (or the light
# axis when $\mathbf x_2$ is the light) and $\mathbf d_2=\mathbf x_0-\mathbf x_2$. Each entry
# below computes $\mathbf n$ from the full path of a hit, exactly as written in the paper's
# Table 1 (re-derived in ESTIMATORS.md 3.1 and 3.3).


# %%
def cross(a, b):
    return np.cross(a, b)


GALLERY = [
    # title, technique, scatter count K, normal formula (text), normal from the record
    ("plane [t1, t2]", "plane-t1t2-short", 2, "n = w1 x w2",
     lambda r, d2: cross(r.w1, r.w2)),
    ("generalized plane [t1, t3]", "plane-t1t3-short", 3, "n = w1 x w3",
     lambda r, d2: cross(r.w1, r.w3)),
    ("generalized plane [t2, t3]", "plane-t2t3-short", 3, "n = w2 x w3",
     lambda r, d2: cross(r.w2, r.w3)),
    ("sphere [cos th1, ph1]", "sphere", 2, "n = t1^2 w1",
     lambda r, d2: r.t1**2 * r.w1),
    ("cone [t1, ph1]", "cone-short", 2, "n = t1 (w2 - c1 w1)",
     lambda r, d2: r.t1 * (r.w2 - (r.w1 @ r.w2) * r.w1)),
    ("cylinder [t2, ph1]", "cylinder-short", 2, "n = t1 (c1 w2 - w1)",
     lambda r, d2: r.t1 * ((r.w1 @ r.w2) * r.w2 - r.w1)),
    ("disk [t1, cos th1]", "disk-short", 2, "n = t1 (w1 x w2) / s1^2",
     lambda r, d2: r.t1 * cross(r.w1, r.w2) / (1 - (r.w1 @ r.w2) ** 2)),
    ("hyperboloid [t1, ph2]", "hyperboloid-short", 2, "n = w1 x (A3 x d2)",
     lambda r, d2: cross(r.w1, cross(r.A3, d2))),
    ("torus [cos th1, ph2]", "torus", 2, "n = t1 (w2 - c1 w1)/s1^2 x (A3 x d2)",
     lambda r, d2: cross(r.t1 * (r.w2 - (r.w1 @ r.w2) * r.w1) / (1 - (r.w1 @ r.w2) ** 2),
                         cross(r.A3, d2))),
]


class One:
    """Row 0 of a PathRecord as plain vectors (so the formulas above read like the paper)."""

    def __init__(self, rec):
        for name in ("x2", "x1", "x0", "w3", "w2", "w1", "t1", "A3"):
            setattr(self, name, np.asarray(getattr(rec, name))[0])


# %% [markdown]
# ## One photon per surface
#
# For each technique we replay one pass for one pixel (`inspect_pixel`), and pick a hit
# whose surface is of a drawable size and is seen neither head-on nor edge-on.

# %%
point = load_scene(ROOT / "scenes" / "point.toml")
PIXEL = (30, 20)
settings = RenderSettings(photons=B["photons"])
view_pos, view_focal, view_up = (np.asarray(v) for v in scene_view.overview_camera(point))
VIEW = (view_pos - view_focal) / np.linalg.norm(view_pos - view_focal)


def pick(ins):
    """(row, reconstruction, mesh) of the largest hit that draws well (else the largest)."""
    t = ins.table
    first = None
    for r in t.by_contribution()[:300]:
        r = int(r)
        if not np.any(t.value[r]):
            continue  # an invalid path (occluded or outside the box) contributes nothing
        name, b = str(t.technique[r]), int(t.batch[r])
        mesh, how = primitives_view.primitive_mesh(ins.techniques[name], ins.prims[(name, b)],
                                                   [int(t.prim[r])], ins.scene, 0.0)
        rec = reconstruct_hit(ins, r)
        first = first or (r, rec, mesh)
        if how != "surface" or mesh.n_points < 3:
            continue
        pts = np.asarray(mesh.points)
        size = np.linalg.norm(np.ptp(pts, axis=0))
        spread = np.linalg.svd(pts - pts.mean(axis=0), compute_uv=False)
        n_unit = t.normal[r] / np.linalg.norm(t.normal[r])
        cos_ray = abs(n_unit @ t.psi[r])  # how the camera ray meets the surface
        cos_eye = abs(n_unit @ VIEW)  # how the figure's viewpoint sees it
        if (1.0 < size < 2.4 and spread[1] > 0.3 * spread[0] and 0.3 < cos_ray < 0.9
                and cos_eye > 0.3):
            return r, rec, mesh
    return first


shots = []
for title, name, K, formula, normal_of in GALLERY:
    scene = point.with_scatter(K, K)
    ins = inspect_pixel(scene, name, 0, 0, PIXEL, settings)
    assert len(ins.table), f"{name}: no hit at pixel {PIXEL}"
    r, recon, mesh = pick(ins)
    one = One(recon["record"])
    n_formula = normal_of(one, one.x0 - one.x2)
    shots.append(dict(title=title, name=name, formula=formula, row=r, ins=ins, recon=recon,
                      mesh=mesh, n_psurf=ins.table.normal[r], n_formula=n_formula,
                      psi=ins.table.psi[r], hit=ins.table.point[r],
                      ndp=ins.table.n_dot_psi[r]))
    print(f"{title:28s} hit #{r:<4d} |n| = {np.linalg.norm(n_formula):7.4f}   "
          f"|n.psi| = {ins.table.n_dot_psi[r]:.4f}")

# %% [markdown]
# ## The gallery

# %%
p = pv.Plotter(off_screen=True, window_size=B["size"], shape=(3, 3), border=True,
               border_color="#bbbbbb")
scene_view.set_scale(B["size"][1])
light = point.lights[0]
box = scene_view.box_mesh(point.medium.bounds_min, point.medium.bounds_max)
for i, sh in enumerate(shots):
    p.subplot(i // 3, i % 3)
    p.set_background("white")
    p.add_mesh(box.outline(), color="#777777", line_width=2)
    p.add_mesh(pv.Sphere(radius=0.06, center=light.position), color=scene_view.LIGHT_COLOUR)
    tech = sh["ins"].techniques[str(sh["ins"].table.technique[sh["row"]])]
    p.add_mesh(sh["mesh"], color=palette.technique_colour(tech.name), opacity=0.55,
               show_edges=False, culling=False)
    own = np.vstack([light.position, sh["recon"]["photon_polyline"][1:]])
    p.add_mesh(pv.lines_from_points(own), color=OK["grey"], line_width=6)
    rays = sh["ins"].rays
    ray = int(sh["ins"].table.ray[sh["row"]])
    o, d = rays.o[ray], rays.d[ray]
    p.add_mesh(pv.Line(o + rays.s_min[ray] * d, o + rays.s_max[ray] * d), color="black",
               line_width=5)
    hit, n = sh["hit"], sh["n_psurf"]
    unit = n / np.linalg.norm(n) * (-1.0 if n @ sh["psi"] > 0 else 1.0)  # face the camera
    p.add_mesh(pv.Sphere(radius=0.045, center=hit), color=OK["orange"])
    p.add_mesh(pv.Arrow(start=hit, direction=unit, scale=0.55, tip_length=0.25, tip_radius=0.08,
                        shaft_radius=0.03), color=OK["vermillion"])
    p.add_mesh(pv.Arrow(start=hit, direction=sh["psi"], scale=0.4, tip_length=0.25,
                        tip_radius=0.08, shaft_radius=0.03), color="black")
    p.add_point_labels(np.array([hit + 0.62 * unit]), ["n"], font_size=scene_view.pt(22),
                       text_color=OK["vermillion"], shape_opacity=0.0, show_points=False,
                       always_visible=True)
    scene_view.add_text(p, sh["title"], 0.03, 0.97, 20, bold=True)
    scene_view.add_text(p, f"{sh['formula']}\n|n| = {np.linalg.norm(n):.3g}   "
                           f"|n.psi| = {sh['ndp']:.3g}", 0.03, 0.84, 16)
    size = np.linalg.norm(np.ptp(np.asarray(sh["mesh"].points), axis=0))
    centre = 0.5 * (hit + np.asarray(sh["mesh"].center))
    p.camera_position = [tuple(centre + (1.0 + 1.7 * size) * VIEW), tuple(centre),
                         tuple(view_up)]
p.screenshot(str(OUT / "04_gallery.png"))
p.close()

# %% [markdown]
# Things to notice on the slide:
#
# * **Planes** are flat, so $\mathbf n$ is the same everywhere on them; a *generalized* plane
#   does not pass through any photon vertex on the camera side: it is swept from $\mathbf x_3$.
# * The **sphere**'s normal is radial and grows like $t_1^2$ (solid angle to area). The
#   **cone** and **cylinder** normals are perpendicular to their generators; the **disk**'s is
#   perpendicular to the half-plane, and $1/s_1^2$ makes it long near the axis.
# * The surfaces of **revolution** spin part of the path about the axis $(\mathbf x_2,A_3)$:
#   their normals involve $A_3\times\mathbf d_2$, the velocity of that spin.
#
# ## What this tutorial claims, checked

# %%
for sh in shots:
    n_p, n_f = sh["n_psurf"], sh["n_formula"]
    # 1. The normal psurf uses is the paper's scaled normal (up to its irrelevant sign) ...
    assert np.allclose(np.abs(n_p @ n_f), np.linalg.norm(n_p) * np.linalg.norm(n_f), rtol=1e-6)
    assert np.isclose(np.linalg.norm(n_p), np.linalg.norm(n_f), rtol=1e-6), sh["name"]
    # 2. ... and the Jacobian of the hit is its dot product with the ray direction.
    assert np.isclose(abs(n_f @ sh["psi"]), sh["ndp"], rtol=1e-6), sh["name"]
    # 3. The drawn surface is the one the ray hit: the hit lies on the (tessellated) mesh.
    _, closest = sh["mesh"].find_closest_cell(sh["hit"], return_closest_point=True)
    assert np.linalg.norm(closest - sh["hit"]) < 0.03, (sh["name"], closest, sh["hit"])
assert (OUT / "04_gallery.png").stat().st_size > 50_000
print("04: all checks passed")
