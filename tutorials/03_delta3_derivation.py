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
# # 3 · The $\delta^3$ derivation: choose three dimensions, change variables
#
# **Learning goal.** Derive every photon surface from one recipe: keep the 3D delta of the
# measurement, integrate it analytically over **two photon dimensions and the camera
# distance $s$**, and the Jacobian of that change of variables is $|\mathbf n\cdot
# \boldsymbol\psi|$, with $\mathbf n=\partial\mathbf x_0/\partial\xi_1\times\partial\mathbf
# x_0/\partial\xi_2$ the *scaled normal* of the surface the photon sweeps. Then check it
# numerically: a finite-difference $3\times3$ Jacobian against psurf's $|\mathbf n\cdot
# \boldsymbol\psi|$ for every hit of every technique, and look at it.
#
# `PSURF_TUTORIAL_BUDGET=test` switches to a small budget; figures go to `out/tutorials/03_*.png`.

# %% Setup: paths, budget switch, projector style
# ruff: noqa: E402, E501
import os
import sys
from pathlib import Path

import matplotlib.pyplot as plt
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
from ui.views import hits_view, palette, primitives_view, scene_view

pv.OFF_SCREEN = True
scene_view.plain_text()
OK = scene_view.OKABE_ITO  # colour-blind-safe palette (Okabe & Ito)
plt.rcParams.update({
    "font.size": 18, "axes.titlesize": 20, "axes.labelsize": 18, "legend.fontsize": 15,
    "xtick.labelsize": 15, "ytick.labelsize": 15, "lines.linewidth": 3, "image.cmap": "viridis",
    "axes.prop_cycle": plt.cycler(color=[OK[c] for c in (
        "blue", "vermillion", "green", "orange", "purple", "sky_blue", "black")]),
})


def save(fig, name):
    """Write a figure to OUT (and keep it open only inside a notebook)."""
    fig.savefig(OUT / name, dpi=100, bbox_inches="tight")
    if "ipykernel" not in sys.modules:
        plt.close(fig)
    return OUT / name


B = dict(photons=1500, hits=12) if TEST else dict(photons=6000, hits=60)

# %% [markdown]
# ## The derivation (the talk's "Our approach")
#
# Tutorial 1 wrote a pixel's $K$-bounce value as
# $I=\int f(\bar{\mathbf y})\,\delta^3(\mathbf y-\mathbf x)\,f(\bar{\mathbf x})\,d\mu$:
# a camera subpath ending at $\mathbf y=\mathbf y(s)=\mathbf c+s\boldsymbol\psi$, a photon
# subpath ending at $\mathbf x=\mathbf x_0$, and a **3D delta kernel** joining them. Sampling
# both subpaths and evaluating the delta fails: the two endpoints coincide with
# probability zero. Blurring the delta (tutorial 2) gives bias.
#
# Instead, **split the integral** and **pre-integrate three dimensions** against the delta.
# With photon variables $\{t_1,t_2,\theta_1,\theta_2,\phi_1,\phi_2\}$ and the camera
# distance $s_1=s$, pick two photon dimensions $\xi_1,\xi_2$ and $s$:
#
# $$\int\delta^3\big(\mathbf x_0(\xi_1,\xi_2)-\mathbf y(s)\big)\,d\xi_1\,d\xi_2\,ds
#   =\sum_{\text{roots } r}\frac{1}{|\det J(r)|},\qquad
#   J=\Big[\tfrac{\partial\mathbf x_0}{\partial\xi_1},\;\tfrac{\partial\mathbf x_0}{\partial\xi_2},
#   \;-\boldsymbol\psi\Big].$$
#
# The triple product gives $|\det J|=|(\partial_{\xi_1}\mathbf x_0\times\partial_{\xi_2}
# \mathbf x_0)\cdot\boldsymbol\psi|=|\mathbf n\cdot\boldsymbol\psi|$ (paper, Eqs. 22-24),
# so every choice of $(\xi_1,\xi_2)$ is a **photon surface** (the set of all $\mathbf x_0$
# as $\xi_1,\xi_2$ vary) intersected with the camera ray, and
#
# $$X_p=\sum_r\frac{f(\text{path}_r)}{q(\text{sampled dims})\;|\mathbf n(\text{path}_r)\cdot
#   \boldsymbol\psi|}.$$
#
# $\mathbf n$ is not a unit normal: its length says how much surface area one unit of
# $d\xi_1\,d\xi_2$ covers. The choices psurf implements (ESTIMATORS.md, 3.1-3.3):
#
# | surface | $[\xi_1,\xi_2]$ | $\mathbf x_0(\xi_1,\xi_2)$ | scaled normal $\mathbf n$ |
# |---|---|---|---|
# | plane | $[t_1,t_2]$ | $\mathbf x_2+t_2\omega_2+t_1\omega_1$ | $\omega_1\times\omega_2$ |
# | generalized planes | $[t_1,t_3]$, $[t_2,t_3]$ | three segments, two lengths free | $\omega_1\times\omega_3$, $\omega_2\times\omega_3$ |
# | sphere | $[\cos\theta_1,\phi_1]$ | $\mathbf x_1+T_1\omega_1(\theta_1,\phi_1)$ | $t_1^2\,\omega_1$ |
# | cone | $[t_1,\phi_1]$ | $\mathbf x_1+t_1\omega_1(\phi_1)$ | $t_1(\omega_2-c_1\omega_1)$ |
# | cylinder | $[t_2,\phi_1]$ | $\mathbf x_2+t_2\omega_2+T_1\omega_1(\phi_1)$ | $t_1(c_1\omega_2-\omega_1)$ |
# | disk | $[t_1,\cos\theta_1]$ | $\mathbf x_1+t_1\omega_1(\theta_1)$ | $t_1(\omega_1\times\omega_2)/s_1^2$ |
# | hyperboloid | $[t_1,\phi_2]$ | ray $\mathbf x_1+t\,\omega_1$ revolved about $(\mathbf x_2,A_3)$ | $\omega_1\times(A_3\times\mathbf d_2)$ |
# | torus | $[\cos\theta_1,\phi_2]$ | meridian circle revolved about $(\mathbf x_2,A_3)$ | $\frac{t_1(\omega_2-c_1\omega_1)}{s_1^2}\times(A_3\times\mathbf d_2)$ |
#
# ($c_1=\cos\theta_1=\omega_1\cdot\omega_2$, $s_1=\sin\theta_1$, $\mathbf d_2=\mathbf x_0-\mathbf
# x_2$; the signs of $\mathbf n$ do not matter.)

# %% [markdown]
# ## The photon dimensions as functions
#
# To check psurf we need $\mathbf x_0$ as a function of the two integrated dimensions, starting
# from the full path a hit implies (`reconstruct_hit`, the paper's Reconstruct stage).
# Azimuths rotate about the previous direction, polar cosines tilt towards or away from it;
# a step in $\cos\theta$ is scaled by $\sin^2\theta$ so the finite difference stays well
# conditioned near the axis.


# %%
def rotate(v, axis, angle):
    """Rodrigues: ``v`` rotated by ``angle`` about unit ``axis`` (a change of azimuth)."""
    axis = axis / np.linalg.norm(axis)
    return (v * np.cos(angle) + np.cross(axis, v) * np.sin(angle)
            + axis * (axis @ v) * (1.0 - np.cos(angle)))


def tilt(w, axis, dc):
    """``w`` with its cosine about ``axis`` changed by ``dc`` (same azimuth)."""
    c = w @ axis
    e_r = (w - c * axis) / np.linalg.norm(w - c * axis)
    return (c + dc) * axis + np.sqrt(1.0 - (c + dc) ** 2) * e_r


def sin2(w, axis):
    return 1.0 - (w @ axis) ** 2


def sweep(name, rec):
    """``x0(xi1, xi2)`` about the hit (``xi = 0`` is the hit) and the FD step of each dim."""
    x3, x2, x1 = rec.x3[0], rec.x2[0], rec.x1[0]
    w3, w2, w1 = rec.w3[0], rec.w2[0], rec.w1[0]
    t3, t2, t1 = rec.t3[0], rec.t2[0], rec.t1[0]
    A3, a = rec.A3[0], rec.axis[0]  # revolution axis (3.3); light axis / normal (3.2)
    h = 1e-6
    table = {
        "plane-t1t2": (lambda u, v: x2 + (t2 + v) * w2 + (t1 + u) * w1, (h, h)),
        "plane-t1t3": (lambda u, v: x3 + (t3 + v) * w3 + t2 * w2 + (t1 + u) * w1, (h, h)),
        "plane-t2t3": (lambda u, v: x3 + (t3 + v) * w3 + (t2 + u) * w2 + t1 * w1, (h, h)),
        "sphere": (lambda u, v: x1 + t1 * rotate(tilt(w1, w2, u), w2, v), (h * sin2(w1, w2), h)),
        "cone": (lambda u, v: x1 + (t1 + u) * rotate(w1, w2, v), (h, h)),
        "cylinder": (lambda u, v: x2 + (t2 + u) * w2 + t1 * rotate(w1, w2, v), (h, h)),
        "disk": (lambda u, v: x1 + (t1 + u) * tilt(w1, w2, v), (h, h * sin2(w1, w2))),
        "hyperboloid": (lambda u, v: x2 + rotate(t2 * w2 + (t1 + u) * w1, A3, v), (h, h)),
        "torus": (lambda u, v: x2 + rotate(t2 * w2 + t1 * tilt(w1, w2, u), A3, v),
                  (h * sin2(w1, w2), h)),
        "ss-sphere": (lambda u, v: x1 + t1 * rotate(tilt(w1, a, u), a, v), (h * sin2(w1, a), h)),
        "ss-cone": (lambda u, v: x1 + (t1 + u) * rotate(w1, a, v), (h, h)),
        "ss-disk": (lambda u, v: x1 + (t1 + u) * tilt(w1, a, v), (h, h * sin2(w1, a))),
        "ss-plane-uv": (lambda u, v: x1 + u * rec.eu[0] + v * rec.ev[0] + t1 * w1, (h, h)),
        "ss-plane-ut": (lambda u, v: x1 + u * rec.eu[0] + (t1 + v) * w1, (h, h)),
        "ss-plane-vt": (lambda u, v: x1 + u * rec.ev[0] + (t1 + v) * w1, (h, h)),
    }
    return table[name]


def fd_jacobian(x0, steps, psi):
    """Central-difference ``J = [dx0/dxi1, dx0/dxi2, -psi]`` (3 x 3)."""
    h1, h2 = steps
    d1 = (x0(h1, 0.0) - x0(-h1, 0.0)) / (2 * h1)
    d2 = (x0(0.0, h2) - x0(0.0, -h2)) / (2 * h2)
    return np.column_stack([d1, d2, -psi])


# %% [markdown]
# ## One hit, by hand
#
# A photon plane: replay one pixel of one pass (`inspect_pixel`), take its largest hit,
# rebuild $\mathbf x_0(t_1,t_2)$, differentiate numerically and compare with the $|\mathbf
# n\cdot\boldsymbol\psi|$ the plane's Intersect stage computed.

# %%
point2 = load_scene(ROOT / "scenes" / "point.toml").with_scatter(2, 2)
PIXEL = (30, 20)
settings = RenderSettings(photons=B["photons"])
ins = inspect_pixel(point2, "plane-t1t2", 0, 0, PIXEL, settings)
k = int(ins.table.by_contribution()[0])
rec = reconstruct_hit(ins, k)["record"]
x0, steps = sweep("plane-t1t2", rec)
J = fd_jacobian(x0, steps, ins.table.psi[k])
print("x0 at the hit:", x0(0, 0), "(the table says", ins.table.point[k], ")")
print("finite-difference J =\n", np.round(J, 6))
print(f"|det J| = {abs(np.linalg.det(J)):.9f}   psurf |n.psi| = {ins.table.n_dot_psi[k]:.9f}")

# %% [markdown]
# ## Every technique, many hits
#
# The same check for all fifteen surfaces: multiple scattering at $K=2$ (generalized planes
# need three segments: $K=3$), single scattering from the point light and the area light.

# %%
cases = [("point.toml", 2, ["plane-t1t2", "sphere", "cone", "cylinder", "disk", "hyperboloid",
                            "torus"]),
         ("point.toml", 3, ["plane-t1t3", "plane-t2t3"]),
         ("point.toml", 1, ["ss-sphere", "ss-cone", "ss-disk"]),
         ("area.toml", 1, ["ss-plane-uv", "ss-plane-ut", "ss-plane-vt"])]
checks = {}
for scene_file, K, names in cases:
    scene = load_scene(ROOT / "scenes" / scene_file).with_scatter(K, K)
    for name in names:
        ins_t = inspect_pixel(scene, name, 0, 0, PIXEL, settings)
        t = ins_t.table
        rows = t.by_contribution()[: B["hits"]]
        fd, ours = [], []
        for r in rows:
            rec_r = reconstruct_hit(ins_t, int(r))["record"]
            f, st = sweep(name, rec_r)
            assert np.allclose(f(0.0, 0.0), t.point[r], atol=1e-9), name  # the right path
            fd.append(abs(np.linalg.det(fd_jacobian(f, st, t.psi[r]))))
            ours.append(t.n_dot_psi[r])
        checks[name] = (np.array(fd), np.array(ours))
        rel = np.abs(checks[name][0] / checks[name][1] - 1)
        print(f"{name:12s} K={K}: {len(rows):3d} hits, max relative difference {rel.max():.1e}")

fig, ax = plt.subplots(figsize=(11, 10), layout="constrained")
markers = "osD^v<>ph*XPd8H"
for (name, (fd, ours)), m in zip(checks.items(), markers, strict=False):
    ax.loglog(ours, fd, m, ms=9, alpha=0.75, label=name)
lim = [min(v[1].min() for v in checks.values()) / 2, max(v[1].max() for v in checks.values()) * 2]
ax.loglog(lim, lim, color="black", lw=2, ls="--", zorder=0)
ax.set(xlabel="psurf's $|\\mathbf{n}\\cdot\\psi|$ (closed form)",
       ylabel="$|\\det J|$ by finite differences",
       title="The Jacobian is $|\\mathbf{n}\\cdot\\psi|$, for every surface")
ax.legend(ncol=2, fontsize=13, loc="upper left")
save(fig, "03_fd_check.png")

# %% [markdown]
# ### How small a step?
#
# Central differences have two errors: truncation ($\propto h^2$) and round-off
# ($\propto\varepsilon/h$). Plotting the error against $h$ for one hit of each family shows
# the classic V; the checks above use $h=10^{-6}$, near its bottom.

# %%
fig, ax = plt.subplots(figsize=(11, 7), layout="constrained")
hs = np.logspace(-9, -1, 33)
for name in ("cone", "sphere", "disk", "torus"):
    ins_t = inspect_pixel(point2, name, 0, 0, PIXEL, settings)
    r = int(ins_t.table.by_contribution()[0])
    f, st = sweep(name, reconstruct_hit(ins_t, r)["record"])
    scale = np.array(st) / 1e-6
    err = [abs(abs(np.linalg.det(fd_jacobian(f, scale * h, ins_t.table.psi[r])))
               / ins_t.table.n_dot_psi[r] - 1) for h in hs]
    ax.loglog(hs, np.maximum(err, 1e-17), marker="o", ms=6, label=name)
ax.axvline(1e-6, color="black", ls="--", lw=2)
ax.set(xlabel="finite-difference step $h$", ylabel="relative error of $|\\det J|$",
       title="Truncation vs round-off: the V")
ax.legend()
save(fig, "03_fd_step.png")

# %% [markdown]
# ## The Jacobian made visible
#
# One photon cone $[t_1,\phi_1]$: the photon's path light $\to\mathbf x_2\to\mathbf x_1$
# (grey), the cone it sweeps, the camera ray, and at the hit the three columns of $J$:
# $\partial\mathbf x_0/\partial t_1$ (along the generator), $\partial\mathbf
# x_0/\partial\phi_1$ (around the cone) and $\boldsymbol\psi$. The box they span has volume
# $|\det J|=|\mathbf n\cdot\boldsymbol\psi|$: a ray that grazes the cone squashes the box
# flat, and the contribution $f/|\mathbf n\cdot\boldsymbol\psi|$ blows up.

# %%
ins_c = inspect_pixel(point2, "cone-short", 0, 0, PIXEL, settings)
tc = ins_c.table


def showable(r):
    """A hit that draws well: a wide cone of moderate size and a box that is not flat."""
    rec_r = reconstruct_hit(ins_c, int(r))["record"]
    f_r, st_r = sweep("cone", rec_r)
    J_r = fd_jacobian(f_r, st_r, tc.psi[r])
    unit_cols = J_r / np.linalg.norm(J_r, axis=0)
    return (0.3 < rec_r.t1[0] < 1.0 and abs(rec_r.w1[0] @ rec_r.w2[0]) < 0.8
            and abs(np.linalg.det(unit_cols)) > 0.4)


order = tc.by_contribution()
rc = int(next((r for r in order[:200] if showable(r)), order[0]))
recon = reconstruct_hit(ins_c, rc)
f, st = sweep("cone", recon["record"])
Jc = fd_jacobian(f, st, tc.psi[rc])
hit = tc.point[rc]
edge = 0.3  # drawn length of each column of J (scene units)
cols = [Jc[:, 0] / np.linalg.norm(Jc[:, 0]), Jc[:, 1] / np.linalg.norm(Jc[:, 1]), tc.psi[rc]]


def parallelepiped(origin, a, b, c):
    """The box ``origin + [0,1]^3 . (a, b, c)`` as a surface mesh."""
    corners = np.array([origin + i * a + j * b + k * c for k in (0, 1) for j in (0, 1)
                        for i in (0, 1)])
    quads = [[0, 1, 3, 2], [4, 5, 7, 6], [0, 1, 5, 4], [2, 3, 7, 6], [0, 2, 6, 4], [1, 3, 7, 5]]
    return pv.PolyData(corners, faces=np.hstack([[4, *q] for q in quads]))


p = pv.Plotter(off_screen=True, window_size=(1600, 900))
scene_view.set_scale(900)
scene_view.add_scene(p, point2, box_opacity=0.03, labels=False)
tname, b = str(tc.technique[rc]), int(tc.batch[rc])
mesh, _ = primitives_view.primitive_mesh(ins_c.techniques[tname], ins_c.prims[(tname, b)],
                                         [int(tc.prim[rc])], point2, 0.0)
p.add_mesh(mesh, color=palette.technique_colour(tname), opacity=0.3)
p.add_mesh(pv.lines_from_points(recon["photon_polyline"]), color=OK["grey"], line_width=6)
hits_view.add_query_ray(p, ins_c)
p.add_mesh(parallelepiped(hit, *(edge * c for c in cols)), color=OK["sky_blue"], opacity=0.6,
           show_edges=True, edge_color="black", line_width=3)
labels = ["dx0/dt1", "dx0/dphi1", "psi"]
for vec, col in zip(cols, (OK["blue"], OK["green"], "black"), strict=True):
    p.add_mesh(pv.Arrow(start=hit, direction=vec, scale=edge * 1.25, tip_length=0.2,
                        tip_radius=0.06, shaft_radius=0.02), color=col)
tips = np.array([hit + 1.35 * edge * v for v in cols])
p.add_point_labels(tips, labels, font_size=scene_view.pt(scene_view.FONT), shape_opacity=0.8,
                   shape_color="white", show_points=False, always_visible=True)
scene_view.add_text(p, "The Jacobian made visible: photon cone [t1, phi1]", 0.015, 0.985,
                    scene_view.FONT_TITLE, bold=True)
scene_view.add_text(p, f"box spanned by dx0/dt1, dx0/dphi1 (unit length) and psi;  "
                       f"|det J| = |n.psi| = {tc.n_dot_psi[rc]:.3f}", 0.015, 0.93,
                    scene_view.FONT_SMALL)
pos, focal, up = (np.asarray(v) for v in scene_view.overview_camera(point2))
view = (pos - focal) / np.linalg.norm(pos - focal)
# Look at the box along its diagonal (all three edges visible), from the overview's side.
diag = sum(cols) / np.linalg.norm(sum(cols))
if diag @ view < 0:
    diag = -diag
eye = diag + 0.6 * view
centre = hit + 0.5 * edge * sum(cols)
p.camera_position = [tuple(centre + 2.2 * eye / np.linalg.norm(eye)), tuple(centre), tuple(up)]
p.screenshot(str(OUT / "03_jacobian_box.png"))
p.close()

# %% [markdown]
# ## What this tutorial claims, checked

# %%
# 1. For every surface and every hit, |det J| by finite differences equals psurf's |n.psi|.
for name, (fd, ours) in checks.items():
    assert len(ours) > 0, f"{name}: no hit to check"
    assert np.allclose(fd, ours, rtol=1e-6, atol=0), (name, np.abs(fd / ours - 1).max())
# 2. The hand-worked plane: the triple product is the determinant.
n_plane = np.cross(rec.w1[0], rec.w2[0])
assert np.isclose(abs(np.linalg.det(J)), abs(n_plane @ ins.table.psi[k]), rtol=1e-6)
# 3. The drawn box: its (unit-edge) volume times |dx0/dt1| |dx0/dphi1| is |det J|.
vol = abs(np.linalg.det(np.column_stack(cols))) * np.prod(np.linalg.norm(Jc[:, :2], axis=0))
assert np.isclose(vol, tc.n_dot_psi[rc], rtol=1e-6), (vol, tc.n_dot_psi[rc])
for name in ("03_fd_check.png", "03_fd_step.png", "03_jacobian_box.png"):
    assert (OUT / name).stat().st_size > 10_000, name
print("03: all checks passed")
