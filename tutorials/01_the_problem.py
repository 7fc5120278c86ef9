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
# # 1 · The problem: a medium, a light, a camera
#
# **Learning goal.** Say exactly what one pixel of a participating-medium image measures:
# an integral of scattered light along the camera ray, which splits into the light that
# scattered once, twice, ... (the *k-th bounce*). Every estimator in psurf, from photon
# points to photon surfaces, estimates one of these bounce integrals.
#
# Run it as a script (`.venv/bin/python tutorials/01_the_problem.py`) or open it as a notebook
# (`jupytext --to notebook tutorials/01_the_problem.py`). `PSURF_TUTORIAL_BUDGET=test` switches
# to a small budget; figures go to `out/tutorials/01_*.png`.

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

from psurf_core import RenderSettings, camera_rays, images, load_scene, parse_estimator, render_pass
from psurf_core.reference import single_scatter_quadrature
from psurf_core.sampling import phase_value
from psurf_core.trace import trace
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


# Budgets: `test` is for `make test` (seconds), `lecture` for figures worth projecting.
B = dict(res=(32, 24), ref_spp=4, ref_passes=8, paths=16) if TEST else \
    dict(res=(128, 96), ref_spp=16, ref_passes=32, paths=40)

# %% [markdown]
# ## The scene
#
# A box of homogeneous medium (extinction $\sigma_t=\sigma_s+\sigma_a$, transmittance
# $T_r(t)=e^{-\sigma_t t}$, phase function $\rho(\mu)$), a light inside it, and a pinhole
# camera outside. Surfaces are black: they only block light. A pixel's camera ray is
# $\mathbf y(s)=\mathbf c+s\,\boldsymbol\psi$, and only its part inside the box,
# $s\in[s_{\min},s_{\max}]$, sees medium.
#
# The coloured polylines are *photon subpaths* traced from the light exactly as in an
# infinite medium (free flights $t\sim\sigma_t e^{-\sigma_t t}$, phase-sampled turns); the
# box only clips what is drawn. Their colour is the scatter event a segment ends at.

# %%
point = load_scene(ROOT / "scenes" / "point.toml")
cam = point.camera
PIXEL = (37, 17)  # (column, row): a ray that passes just beside the light
pix = PIXEL[1] * cam.width + PIXEL[0]
ray = camera_rays(point, 1, jitter=False, pixels=np.array([pix]))
photons = trace(point, B["paths"], np.random.default_rng(1))

p = pv.Plotter(off_screen=True, window_size=(1600, 900))
scene_view.set_scale(900)
scene_view.add_scene(p, point, pixel_xy=PIXEL)
primitives_view.add_paths(p, [photons], point, B["paths"])
o, d = ray.o[0], ray.d[0]
p.add_mesh(pv.Line(o, o + ray.s_min[0] * d), color="#555555", line_width=3)
p.add_mesh(pv.Line(o + ray.s_min[0] * d, o + ray.s_max[0] * d), color="black", line_width=8)
scene_view.add_text(p, "The problem: a light, a medium, a camera", 0.015, 0.985,
                    scene_view.FONT_TITLE, bold=True)
scene_view.add_text(p, f"photon subpaths from the point light; the camera ray of pixel {PIXEL} "
                       "(thick inside the medium)", 0.015, 0.93, scene_view.FONT_SMALL)
p.camera_position = scene_view.overview_camera(point, zoom=1.6)
p.screenshot(str(OUT / "01_scene.png"))
p.close()

# %% [markdown]
# ## Radiance along a ray
#
# Without surfaces, the radiance reaching the camera is the volume rendering equation,
# light in-scattered at every point of the ray and attenuated on its way out:
#
# $$L(\mathbf c,-\boldsymbol\psi)=\int_0^{S} T_r(s)\,\sigma_s
#   \int_{S^2}\rho\,L_i(\mathbf y(s),\omega)\,d\omega\,ds .$$
#
# Light that scattered **once** (a point light of intensity $I$ at $\mathbf x_L$,
# $r(s)=|\mathbf y(s)-\mathbf x_L|$) is a 1D integral we can evaluate to any precision:
#
# $$L_1=\int_{s_{\min}}^{s_{\max}} e^{-\sigma_t (s-s_{\min})}\,\sigma_s\,\rho(\mu(s))\;
#   \frac{I\,e^{-\sigma_t r(s)}}{r(s)^2}\;ds,\qquad
#   \mu(s)=\frac{\mathbf y(s)-\mathbf x_L}{r(s)}\cdot(-\boldsymbol\psi).$$
#
# Below: the integrand along our pixel's ray, integrated by us with the trapezoid rule and by
# psurf's own quadrature oracle. It peaks a little before the point closest to the light:
# the light scattered there has less medium to cross on its way back to the camera.

# %%
med, light = point.medium, point.lights[0]
s = np.linspace(ray.s_min[0], ray.s_max[0], 20001)
y = o + s[:, None] * d
v = y - light.position
r = np.linalg.norm(v, axis=1)
mu = -(v / r[:, None]) @ d
integrand = (np.exp(-med.sigma_t * (s - s[0])) * med.sigma_s * phase_value(mu, med.phase.g)
             * light.intensity[0] * np.exp(-med.sigma_t * r) / r**2)
ours = float(np.sum(0.5 * (integrand[1:] + integrand[:-1]) * np.diff(s)))
oracle = float(single_scatter_quadrature(point, ray.o, ray.d, ray.s_min, ray.s_max, n=4096)[0, 0])
print(f"L_1 along pixel {PIXEL}: trapezoid {ours:.6f}, psurf quadrature {oracle:.6f}")

fig, ax = plt.subplots(figsize=(12, 5.5))
ax.fill_between(s, integrand, color=OK["sky_blue"], alpha=0.45, label=f"area = $L_1$ = {oracle:.3f}")
ax.plot(s, integrand, color=OK["blue"])
closest = s[np.argmin(r)]
ax.axvline(closest, color="black", ls="--", lw=2)
ax.text(closest + 0.03, 0.04 * integrand.max(), "closest\nto the light")
ax.set(xlabel="distance $s$ along the camera ray", ylabel="in-scattered radiance per unit $s$",
       title=f"Single scattering along the ray of pixel {PIXEL}")
ax.legend(loc="upper right")
save(fig, "01_ray_integrand.png")

# %% [markdown]
# ## Full transport and the k-th bounce
#
# Expanding $L_i$ again and again turns the pixel into a sum over the number $K$ of
# scattering events, each term an integral over whole light paths
# $\mathbf x_K\to\dots\to\mathbf x_1\to\mathbf x_0=\mathbf y(s)$ (ESTIMATORS.md, section 1):
#
# $$L=\sum_{K\ge1}L_K,\qquad
#   L_K=\int f(\bar{\mathbf x})\;\delta^3\!\big(\mathbf x_0(\bar{\mathbf x})-\mathbf y(s)\big)
#   \;d\bar{\mathbf x}\,ds,$$
#
# $$f=\text{Le-term}\prod_{k=1}^{K}e^{-\sigma_t t_k}
#    \prod_{k=1}^{K-1}\sigma_s\rho(\omega_{k+1}\!\cdot\omega_k)\;
#    \sigma_s\rho(-\omega_1\!\cdot\boldsymbol\psi)\,e^{-\sigma_t s}.$$
#
# The delta says the photon path must *end on the camera ray*; tutorial 3 is about what to do
# with it. Here we let psurf's reference path tracer (next-event estimation with MIS, the
# ground truth) render the area-light scene restricted to one bounce count at a time, via the
# scene's `[render]` scatter window (`scene.with_scatter(min, max)`).

# %%
area = at_resolution(load_scene(ROOT / "scenes" / "area.toml"), *B["res"])
ref_settings = RenderSettings(spp=B["ref_spp"])
windows = {"K = 1": (1, 1), "K = 2": (2, 2), "K = 3": (3, 3), "K ≥ 4": (4, -1),
           "all K ≥ 1": (1, -1)}
bounce = {}
for label, (lo, hi) in windows.items():
    bounce[label] = render_passes(area.with_scatter(lo, hi), "reference", B["ref_passes"],
                                  ref_settings, seed=11)
mean_img = {k: v.mean(axis=0) for k, v in bounce.items()}
pass_means = {k: v.mean(axis=(1, 2, 3)) for k, v in bounce.items()}  # image mean, per pass
err = {k: m.std(ddof=1) / np.sqrt(len(m)) for k, m in pass_means.items()}
level = {k: m.mean() for k, m in pass_means.items()}
for k in windows:
    print(f"{k:10s} image mean {level[k]:.5f} ± {err[k]:.5f}")

exposure = images.auto_exposure(mean_img["all K ≥ 1"])
fig, axes = plt.subplots(1, 5, figsize=(20, 4.4), layout="constrained")
for ax, (label, img) in zip(axes, mean_img.items(), strict=True):
    ax.imshow(images.tone_map(img, exposure), interpolation="nearest")
    ax.set_title(f"{label}: {level[label] / level['all K ≥ 1']:.0%}")
    ax.set_axis_off()
fig.suptitle("Area light, reference path tracer: one image per bounce count (one exposure)")
save(fig, "01_bounces.png")

parts = ["K = 1", "K = 2", "K = 3", "K ≥ 4"]
fig, ax = plt.subplots(figsize=(10, 5.5))
frac = np.array([level[k] for k in parts]) / level["all K ≥ 1"]
ax.bar(parts, frac, yerr=np.array([err[k] for k in parts]) / level["all K ≥ 1"],
       color=OK["blue"], capsize=8)
for i, f in enumerate(frac):
    ax.text(i, f + 0.02, f"{100 * f:.0f}%", ha="center")
ax.set(ylabel="share of the full image", ylim=(0, 1.0),
       title="Full transport = sum of the k-th bounces")
save(fig, "01_bounce_shares.png")

# %% [markdown]
# Most of the light in this scene (albedo 0.8, a box two mean free paths wide) scatters once
# or twice, but higher orders are far from negligible. Photon planes (tutorial 2) only
# handle $K\ge2$; the paper's single-scattering surfaces (tutorial 5) fill in $K=1$.
#
# ## What this tutorial claims, checked

# %%
# 1. The ray integral: our trapezoid rule and psurf's Gauss-Legendre oracle agree.
assert abs(ours - oracle) < 1e-3 * oracle, (ours, oracle)
# 2. Full transport is the sum of the bounces (independent renders, within 4 standard errors).
total = sum(level[k] for k in parts)
sigma = np.sqrt(sum(err[k] ** 2 for k in parts) + err["all K ≥ 1"] ** 2)
assert abs(total - level["all K ≥ 1"]) < 4 * sigma, (total, level["all K ≥ 1"], sigma)
# 3. Every bounce contributes, and here fewer bounces carry more light.
assert all(level[k] > 0 for k in parts)
assert level["K = 1"] > level["K = 2"] > level["K = 3"]
for name in ("01_scene.png", "01_ray_integrand.png", "01_bounces.png", "01_bounce_shares.png"):
    assert (OUT / name).stat().st_size > 10_000, name
print("01: all checks passed")
