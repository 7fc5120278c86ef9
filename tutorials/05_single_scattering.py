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
# # 5 · Single scattering: surfaces swept from the light
#
# **Learning goal.** Close the single-scattering gap of tutorial 2. A once-scattered path
# $\mathbf x_L\to\mathbf x_0=\mathbf y(s)$ has only the light's dimensions (position $u,v$ on
# an area light, direction $\cos\theta,\phi$, distance $t$): integrate two of them against the
# delta and the photon becomes a surface around the light. Point lights give spheres, cones
# and disks; area lights give the $[u,v]$ plane (the light itself, translated) and the
# $[u,t]$, $[v,t]$ strips; a mesh light's $[u,v]$ surfaces are translated copies of its
# triangles (the talk's "bunny light").
#
# `PSURF_TUTORIAL_BUDGET=test` switches to a small budget; figures go to `out/tutorials/05_*.png`.

# %% Setup: paths, budget switch, projector style
# ruff: noqa: E402, E501
import os
import sys
from dataclasses import replace
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

from psurf_core import RenderSettings, images, load_scene, parse_estimator, render_pass
from psurf_core.camera import clip_rays, pixel_directions
from psurf_core.inspect import inspect_pixel, reconstruct_hit
from psurf_core.reference import single_scatter_quadrature
from ui.views import primitives_view, scene_view

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


def at_resolution(scene, width, height):
    """The same scene with another image size (the camera is a frozen dataclass)."""
    return replace(scene, camera=replace(scene.camera, width=width, height=height))


def render_passes(scene, spec, n_passes, settings, seed=0):
    """(P, H, W, 3): every pass's image on its own (the mean and its error come from them)."""
    est = parse_estimator(spec, scene)
    return np.array([render_pass(scene, est, i, seed, settings) for i in range(n_passes)])


B = dict(res=(32, 24), photons=400, passes=3, ref_spp=8, ref_passes=6, inspect=1500,
         copies=120, size=(1920, 640)) if TEST else \
    dict(res=(64, 48), photons=1500, passes=8, ref_spp=64, ref_passes=32, inspect=6000,
         copies=400, size=(2400, 800))

# %% [markdown]
# ## The surfaces (ESTIMATORS.md, section 3.2)
#
# A $K=1$ path is $\mathbf x_0=\mathbf x_L(u,v)+t\,\omega(\cos\theta,\phi)$. Integrating two
# of $\{u,v,t,\cos\theta,\phi\}$ sweeps:
#
# | light | $[\xi_1,\xi_2]$ | surface | scaled normal $\mathbf n$ |
# |---|---|---|---|
# | point | $[\cos\theta,\phi]$ | **sphere** of radius $T$ about the light | $t^2\omega$ |
# | point | $[t,\phi]$ | **cone** about the light's axis $\mathbf a$ | $t(\mathbf a-c\,\omega)$ |
# | point | $[t,\cos\theta]$ | **disk**: the half-plane through $\mathbf a$ containing $\omega$ | $t(\omega\times\mathbf a)/\sin^2\theta$ |
# | area | $[u,v]$ | the **light translated** by $T\omega$ | $\mathbf e_u\times\mathbf e_v$ |
# | area | $[u,t]$ | **strip** swept by the edge $u\mapsto\mathbf x_L(u,v)$ along $\omega$ | $\mathbf e_u\times\omega$ |
# | area | $[v,t]$ | the same with $u\leftrightarrow v$ | $\mathbf e_v\times\omega$ |
#
# and the per-photon contribution is $f/(q\,|\mathbf n\cdot\boldsymbol\psi|)$ as always; e.g.
# the cone from an isotropic point light: $X=2I\sigma_s\rho_0e^{-\sigma_t(t^*+s^*)}/(t^*|(\mathbf
# a-c\,\omega^*)\cdot\boldsymbol\psi|)$.

# %%
point = load_scene(ROOT / "scenes" / "point.toml").with_scatter(1, 1)
area = load_scene(ROOT / "scenes" / "area.toml").with_scatter(1, 1)
view_pos, view_focal, view_up = (np.asarray(v) for v in scene_view.overview_camera(point))
VIEW = (view_pos - view_focal) / np.linalg.norm(view_pos - view_focal)

NORMALS = {  # the table above, on a hit's reconstructed path (rec = PathRecord of one hit)
    "ss-sphere": lambda r: r.t1[0] ** 2 * r.w1[0],
    "ss-cone-short": lambda r: r.t1[0] * (r.axis[0] - (r.w1[0] @ r.axis[0]) * r.w1[0]),
    "ss-disk-short": lambda r: r.t1[0] * np.cross(r.w1[0], r.axis[0])
    / (1 - (r.w1[0] @ r.axis[0]) ** 2),
    "ss-plane-uv": lambda r: np.cross(r.eu[0], r.ev[0]),
    "ss-plane-ut-short": lambda r: np.cross(r.eu[0], r.w1[0]),
    "ss-plane-vt-short": lambda r: np.cross(r.ev[0], r.w1[0]),
}


def pick(ins, size_range):
    """(row, reconstruction, mesh) of the largest valid hit whose surface draws well."""
    t = ins.table
    first = None
    for r in t.by_contribution()[:400]:
        r = int(r)
        if not np.any(t.value[r]):
            continue
        name, b = str(t.technique[r]), int(t.batch[r])
        mesh, _ = primitives_view.primitive_mesh(ins.techniques[name], ins.prims[(name, b)],
                                                 [int(t.prim[r])], ins.scene, 0.0)
        first = first or (r, reconstruct_hit(ins, r), mesh)
        size = np.linalg.norm(np.ptp(np.asarray(mesh.points), axis=0)) if mesh.n_points else 0
        n_unit = t.normal[r] / np.linalg.norm(t.normal[r])
        if (size_range[0] < size < size_range[1] and 0.25 < abs(n_unit @ t.psi[r]) < 0.9
                and abs(n_unit @ VIEW) > 0.25):
            return r, reconstruct_hit(ins, r), mesh
    return first


def surface_panels(scene, panels, pixel, out, size_range):
    """One panel per (title, technique): the light, one photon's surface, the ray, the hit,
    the scaled normal. Returns the per-panel records for the checks."""
    p = pv.Plotter(off_screen=True, window_size=B["size"], shape=(1, len(panels)), border=True,
                   border_color="#bbbbbb")
    scene_view.set_scale(B["size"][1] * 1.35)
    box = scene_view.box_mesh(scene.medium.bounds_min, scene.medium.bounds_max)
    shots = []
    for i, (title, name) in enumerate(panels):
        ins = inspect_pixel(scene, name, 0, 0, pixel, RenderSettings(photons=B["inspect"]))
        assert len(ins.table), f"{name}: no hit at pixel {pixel}"
        r, recon, mesh = pick(ins, size_range)
        t = ins.table
        p.subplot(0, i)
        p.set_background("white")
        p.add_mesh(box.outline(), color="#777777", line_width=2)
        for lt in scene.lights:
            if lt.kind == "point":
                p.add_mesh(pv.Sphere(radius=0.05, center=lt.position), color=scene_view.LIGHT_COLOUR)
                p.add_mesh(pv.Arrow(start=lt.position, direction=lt.axis, scale=0.35),
                           color=OK["orange"])  # the fixed axis a of the cone and disk
            else:
                p.add_mesh(scene_view.quad(lt.corner, lt.edge_u, lt.edge_v),
                           color=scene_view.LIGHT_COLOUR, show_edges=True, edge_color="black")
        p.add_mesh(mesh, color=OK["blue"], opacity=0.5, culling=False)
        rec = recon["record"]
        photon = int(t.photon[r])
        paths = ins.paths[int(t.batch[r])]
        p.add_mesh(pv.Line(paths.x[photon, 0], paths.x[photon, 1]), color=OK["grey"],
                   line_width=6)  # the photon's own emission and flight T
        ray = int(t.ray[r])
        o, d = ins.rays.o[ray], ins.rays.d[ray]
        p.add_mesh(pv.Line(o + ins.rays.s_min[ray] * d, o + ins.rays.s_max[ray] * d),
                   color="black", line_width=5)
        hit, n = t.point[r], t.normal[r]
        unit = n / np.linalg.norm(n) * (-1.0 if n @ t.psi[r] > 0 else 1.0)
        p.add_mesh(pv.Sphere(radius=0.04, center=hit), color=OK["orange"])
        p.add_mesh(pv.Arrow(start=hit, direction=unit, scale=0.45, tip_length=0.25,
                            tip_radius=0.08, shaft_radius=0.03), color=OK["vermillion"])
        scene_view.add_text(p, title, 0.03, 0.97, 20, bold=True)
        scene_view.add_text(p, f"|n| = {np.linalg.norm(n):.3g}   |n.psi| = {t.n_dot_psi[r]:.3g}",
                            0.03, 0.87, 16)
        centre = 0.5 * (hit + np.asarray(mesh.center))
        extent = np.linalg.norm(np.ptp(np.asarray(mesh.points), axis=0))
        p.camera_position = [tuple(centre + (1.4 + 1.6 * extent) * VIEW), tuple(centre),
                             tuple(view_up)]
        shots.append(dict(name=name, n=n, n_formula=NORMALS[name](rec), psi=t.psi[r],
                          ndp=t.n_dot_psi[r]))
    p.screenshot(str(OUT / out))
    p.close()
    return shots


point_shots = surface_panels(point, [("sphere [cos th, ph]", "ss-sphere"),
                                     ("cone [t, ph] about a", "ss-cone-short"),
                                     ("disk [t, cos th]", "ss-disk-short")],
                             (30, 20), "05_point_light_surfaces.png", (0.5, 2.4))
area_shots = surface_panels(area, [("plane [u, v]: the light, moved by T w", "ss-plane-uv"),
                                   ("strip [u, t]", "ss-plane-ut-short"),
                                   ("strip [v, t]", "ss-plane-vt-short")],
                            (32, 10), "05_area_light_surfaces.png", (0.3, 2.4))

# %% [markdown]
# ## Rendering with them
#
# Each surface alone is an unbiased estimator of single scattering; their balance-heuristic
# MIS is the paper's "single scattering" preset. Oracles: for the point light the exact 1D
# quadrature of tutorial 1 averaged over a 4×4 grid in each pixel, for the area light the
# reference path tracer restricted to $K=1$.


# %%
def pixel_oracle(scene):
    """Single scattering from point lights, averaged over a 4x4 grid inside each pixel."""
    cam = scene.camera
    grid = (np.arange(4) + 0.5) / 4
    jx, jy = (g.ravel() for g in np.meshgrid(grid, grid))
    row, col = np.divmod(np.arange(cam.n_pixels), cam.width)
    d = pixel_directions(cam, (col[:, None] + jx).ravel(), (row[:, None] + jy).ravel())
    o = np.broadcast_to(cam.position, d.shape)
    s_min, s_max = clip_rays(scene, o, d)
    q = single_scatter_quadrature(scene, o, d, s_min, s_max, n=512)
    return q.reshape(cam.n_pixels, 16, 3).mean(axis=1).reshape(cam.height, cam.width, 3)


def compare(scene, specs, truth_imgs, truth_label, out, title):
    """Render every spec; figure: images (one exposure) over per-pass variance maps."""
    settings = RenderSettings(photons=B["photons"])
    runs = {label: render_passes(scene, spec, B["passes"], settings, seed=21)
            for label, spec in specs.items()}
    truth = truth_imgs.mean(axis=0)
    t_level = truth.mean()
    t_err = truth_imgs.mean(axis=(1, 2, 3)).std(ddof=1) / np.sqrt(len(truth_imgs)) \
        if len(truth_imgs) > 1 else 0.0
    exposure = images.auto_exposure(truth)
    var = {k: images.luminance(v.var(axis=0, ddof=1)) for k, v in runs.items()}
    lo, hi = images.log_range(np.concatenate([v.ravel() for v in var.values()]))
    fig, axes = plt.subplots(2, len(runs) + 1, figsize=(4.6 * (len(runs) + 1), 7.6),
                             layout="constrained")
    axes[0, 0].imshow(images.tone_map(truth, exposure), interpolation="nearest")
    axes[0, 0].set_title(truth_label)
    result = {}
    for j, (label, imgs) in enumerate(runs.items(), start=1):
        per_pass = imgs.mean(axis=(1, 2, 3))
        m, e = per_pass.mean(), per_pass.std(ddof=1) / np.sqrt(len(per_pass))
        # Noise summary: the median over lit pixels of one pass's variance / value^2.
        lit = truth[..., 0] > 0.2 * truth[..., 0].mean()
        rel_var = float(np.median(imgs[..., 0].var(axis=0, ddof=1)[lit] / truth[..., 0][lit] ** 2))
        result[label] = (m, e, rel_var)
        print(f"{label:22s} mean {m:.5f} ± {e:.5f}  ({truth_label} {t_level:.5f} ± {t_err:.5f})"
              f"  relative variance (median) {rel_var:.3g}")
        axes[0, j].imshow(images.tone_map(imgs.mean(axis=0), exposure), interpolation="nearest")
        axes[0, j].set_title(label)
        im = axes[1, j].imshow(np.clip(var[label], lo, None), norm="log", vmin=lo, vmax=hi,
                               interpolation="nearest")
        axes[1, j].set_title(f"variance, rel. {rel_var:.2g}")
    for ax in axes.flat:
        ax.set_axis_off()
    fig.colorbar(im, cax=axes[1, 0].inset_axes([0.85, 0.05, 0.08, 0.9]), label="variance (log)")
    fig.suptitle(title)
    save(fig, out)
    return result, t_level, t_err


point_r = at_resolution(point, *B["res"])
oracle = pixel_oracle(point_r)
point_result, point_truth, point_truth_err = compare(
    point_r, {"sphere [cos th, ph]": "ss-sphere", "cone [t, ph]": "ss-cone",
              "disk [t, cos th]": "ss-disk", "MIS of the three": "paper-single"},
    oracle[None], "exact (quadrature)", "05_point_renders.png",
    f"Point light, single scattering: {B['photons']} photons x {B['passes']} passes")

area_r = at_resolution(area, *B["res"])
area_ref = render_passes(area_r, "reference", B["ref_passes"], RenderSettings(spp=B["ref_spp"]),
                         seed=22)
area_result, area_truth, area_truth_err = compare(
    area_r, {"[u, v]": "ss-plane-uv", "[u, t]": "ss-plane-ut", "[v, t]": "ss-plane-vt",
             "MIS (paper preset)": "paper-single"},
    area_ref, "reference", "05_area_renders.png",
    f"Area light, single scattering: {B['photons']} photons x {B['passes']} passes")

# %% [markdown]
# The numbers under the variance maps are the median over lit pixels of one pass's
# variance divided by the squared value. For the point light they follow ESTIMATORS.md
# section 5 (per photon, infinite medium: sphere 14.8, cone 2.9, disk 2.0, MIS 0.63): disk
# and cone beat the sphere, and MIS beats all three. For the area light the best single
# surface depends on how the light's edges sit relative to the camera ray (section 5's
# configuration favoured $[v,t]$; read this scene's winner off the printout), and the moved
# light $[u,v]$ is the noisiest. MIS is close to the best member everywhere, without our
# having to know which one that is.
#
# A warning about single surfaces: their variance is (logarithmically) infinite, because a
# ray grazing a surface divides by $|\mathbf n\cdot\boldsymbol\psi|\approx0$. Their mean is
# still right, but a short render is usually a little *low* (the rare huge hits that pay for
# the grazing part have not happened yet) and its estimated standard error is too small.
# MIS tames the tails, which is why the checks below are strict only for MIS.
#
# ## The mesh light: photon surfaces are translated copies of the emitter
#
# A mesh light emits from each triangle $k$ with barycentric $(u,v)$; the $[u,v]$ surface of
# a photon that left triangle $k$ in direction $\omega$ after flying $T$ is triangle $k$
# translated by $T\omega$ (normal $(\mathbf v_1-\mathbf v_0)\times(\mathbf v_2-\mathbf
# v_0)=2A_k\mathbf n_k$). The talk shows a bunny; psurf bundles a lumpy blob
# (`scenes/meshes/blob.obj`, 320 triangles). Left: one photon, its triangle and the copy.
# Right: the copies of many photons: a cloud of emitter pieces, each shifted by its
# photon's flight.

# %%
mesh_scene = load_scene(ROOT / "scenes" / "mesh_light.toml").with_scatter(1, 1)
light = mesh_scene.lights[0]
ins_m = inspect_pixel(mesh_scene, "ss-plane-uv", 0, 0, (32, 14),
                      RenderSettings(photons=B["copies"]))
(tname, b), prims = next(iter(ins_m.prims.items()))
paths = ins_m.paths[b]
d = prims.data
tri = light.triangles[paths.tri[prims.photon]]  # (M, 3, 3) each photon's emitting triangle
shift = d["T1"][:, None] * d["w"]  # T w (the photon's flight: T1)
copies = np.stack([d["org"], d["org"] + d["A"], d["org"] + d["B"]], axis=1)  # drawn corners

p = pv.Plotter(off_screen=True, window_size=(2000, 900), shape=(1, 2), border=True,
               border_color="#bbbbbb")
scene_view.set_scale(900)
blob = scene_view.triangles_mesh(light.triangles)
centre = light.triangles.reshape(-1, 3).mean(axis=0)
# A photon worth drawing: it left a triangle facing us and flew a visible distance sideways.
facing = light.normals[paths.tri[prims.photon]] @ VIEW
one = int(np.argmax((d["T1"] > 0.3) * (d["T1"] < 0.7) * facing * (1.0 - np.abs(d["w"] @ VIEW))))
for col in (0, 1):
    p.subplot(0, col)
    p.set_background("white")
    p.add_mesh(blob, color=scene_view.LIGHT_COLOUR, opacity=1.0 if col else 0.3,
               show_edges=col == 0, edge_color="#999999")
p.subplot(0, 0)
p.add_mesh(scene_view.triangles_mesh(tri[one:one + 1]), color=OK["orange"],
           show_edges=True, edge_color="black", line_width=4)
p.add_mesh(scene_view.triangles_mesh(copies[one:one + 1]), color=OK["blue"],
           show_edges=True, edge_color="black", line_width=4)
for k in range(3):
    p.add_mesh(pv.Line(tri[one, k], copies[one, k]), color=OK["grey"], line_width=4)
c0 = tri[one].mean(axis=0)
p.add_mesh(pv.Arrow(start=c0, direction=shift[one], scale=float(np.linalg.norm(shift[one])),
                    tip_length=0.15, tip_radius=0.05, shaft_radius=0.015), color="black")
p.add_point_labels(np.array([c0 + 0.5 * shift[one] + 0.05 * view_up]), ["T w"],
                   font_size=scene_view.pt(26), shape_opacity=0.8, show_points=False,
                   always_visible=True)
scene_view.add_text(p, "One photon: its triangle (orange) and the [u,v] surface (blue)",
                    0.02, 0.97, 24, bold=True)
mid = 0.5 * (centre + c0 + shift[one])
p.camera_position = [tuple(mid + 2.6 * VIEW), tuple(mid), tuple(view_up)]
p.subplot(0, 1)
p.add_mesh(scene_view.triangles_mesh(copies), color=OK["blue"], opacity=0.9, show_edges=True,
           edge_color="black")
scene_view.add_text(p, f"{len(copies)} photons: translated copies of emitter triangles",
                    0.02, 0.97, 24, bold=True)
p.camera_position = [tuple(centre + 4.0 * VIEW), tuple(centre), tuple(view_up)]
p.screenshot(str(OUT / "05_mesh_light.png"))
p.close()

mesh_r = at_resolution(mesh_scene, *B["res"])
mesh_ref = render_passes(mesh_r, "reference", B["ref_passes"], RenderSettings(spp=B["ref_spp"]),
                         seed=23)
mesh_result, mesh_truth, mesh_truth_err = compare(
    mesh_r, {"[u, v] (translated copies)": "ss-plane-uv",
             "MIS [u,v] + [u,t] + [v,t]": "mis:ss-plane-uv+ss-plane-ut+ss-plane-vt"},
    mesh_ref, "reference", "05_mesh_renders.png", "Mesh light, single scattering")

# %% [markdown]
# ## What this tutorial claims, checked

# %%
# 1. The normals psurf uses are those of the table (up to sign) and give the Jacobian.
for sh in point_shots + area_shots:
    assert np.isclose(np.linalg.norm(sh["n"]), np.linalg.norm(sh["n_formula"]), rtol=1e-6)
    assert np.isclose(abs(sh["n"] @ sh["n_formula"]),
                      np.linalg.norm(sh["n"]) * np.linalg.norm(sh["n_formula"]), rtol=1e-6)
    assert np.isclose(abs(sh["n_formula"] @ sh["psi"]), sh["ndp"], rtol=1e-6), sh["name"]
# 2. The MIS combinations are unbiased and well behaved: image means agree with the oracle
#    within 4 standard errors. Single surfaces are unbiased too, but heavy-tailed (their
#    variance diverges logarithmically at grazing hits, ESTIMATORS.md section 5), so a short
#    render can sit several of its *estimated* standard errors away; they get a 15% band.
for result, truth, truth_err in ((point_result, point_truth, point_truth_err),
                                 (area_result, area_truth, area_truth_err),
                                 (mesh_result, mesh_truth, mesh_truth_err)):
    for label, (m, e, _) in result.items():
        if label.startswith("MIS"):
            assert abs(m - truth) < 4 * np.hypot(e, truth_err), (label, m, e, truth, truth_err)
        else:
            assert abs(m / truth - 1) < 0.15, (label, m, truth)
# 3. MIS beats the worst single surface it combines, by a wide margin.
for result in (point_result, area_result):
    worst = max(v[2] for k, v in result.items() if not k.startswith("MIS"))
    mis = [v[2] for k, v in result.items() if k.startswith("MIS")][0]
    assert mis < 0.5 * worst, (mis, worst)
# 4. A mesh light's [u,v] surface is its photon's triangle translated by T w: all three
#    corners move by the same vector.
assert np.allclose(copies - tri, shift[:, None, :], atol=1e-12)
for name in ("05_point_light_surfaces.png", "05_area_light_surfaces.png", "05_point_renders.png",
             "05_area_renders.png", "05_mesh_light.png", "05_mesh_renders.png"):
    assert (OUT / name).stat().st_size > 10_000, name
print("05: all checks passed")
