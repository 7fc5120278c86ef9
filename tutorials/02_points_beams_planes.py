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
# # 2 · Points → beams → planes
#
# **Learning goal.** See why density estimation needs a blur, how the blur's *dimension*
# trades bias for noise, and why photon planes (no blur, unbiased) are where the paper
# starts: they render the same scene without bias but have two weaknesses, a $1/|\mathbf
# n\cdot\boldsymbol\psi|$ singularity and no single scattering at all.
#
# The storyline is the talk's "previous work" section: volumetric photon mapping
# (Jensen & Christensen 98), the beam radiance estimate (Jarosz et al. 08), photon beams
# (Jarosz et al. 11), photon planes (Bitterli & Jarosz 17).
#
# `PSURF_TUTORIAL_BUDGET=test` switches to a small budget; figures go to `out/tutorials/02_*.png`.

# %% Setup: paths, budget switch, projector style
# ruff: noqa: E402, E501
import os
import sys
from dataclasses import replace
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.ticker import FormatStrFormatter, LogLocator

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

from psurf_core import RenderSettings, images, load_scene, parse_estimator, render_pass
from psurf_core.camera import clip_rays, pixel_directions
from psurf_core.inspect import inspect_pixel
from psurf_core.reference import single_scatter_quadrature
from ui.views import scene_view

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


B = dict(res=(32, 24), photons=2000, passes=4, ref_spp=16, ref_passes=8,
         sweep_photons=3000, sweep_passes=6, inspect_photons=8000) if TEST else \
    dict(res=(64, 48), photons=20000, passes=16, ref_spp=32, ref_passes=32,
         sweep_photons=20000, sweep_passes=16, inspect_photons=40000)

# %% [markdown]
# ## Why blur at all?
#
# A photon's vertex $\mathbf x_0$ is a point; a camera ray is a line. With probability one
# they never meet, so the delta $\delta^3(\mathbf x_0-\mathbf y(s))$ of tutorial 1 is never
# "hit". Classic estimators replace it by a kernel of radius $r$:
#
# | estimator | what is blurred | kernel | per-photon contribution |
# |---|---|---|---|
# | photon points (3D) | vertex vs. point on the ray | $K_3=3/(4\pi r^3)$ | $\Phi\frac{\sigma_s}{\sigma_t}\rho\int_0^S e^{-\sigma_t s}K_3\,ds$ |
# | beam radiance estimate (2D) | vertex vs. the whole ray | $K_2=1/(\pi r^2)$ | $\Phi\frac{\sigma_s}{\sigma_t}\rho\,e^{-\sigma_t s_p}K_2(d_\perp)$ |
# | photon beams (1D) | photon segment vs. ray | $K_1=1/(2r)$ | $\Phi\sigma_s\rho\,e^{-\sigma_t(t^*+s^*)}K_1(d)/|\omega\times\boldsymbol\psi|$ |
# | photon planes (0D) | a *surface* swept by two segments | none | $\frac{f}{|(\omega_1\times\omega_2)\cdot\boldsymbol\psi|}$ |
#
# Each step integrates one more photon dimension analytically, so one fewer dimension needs
# the blur; the plane integrates two (the distances $t_1, t_2$ of its last two segments) and
# needs none: it is **unbiased**. (ESTIMATORS.md, sections 3.1 and 3.4.)
#
# ## The same scene three ways
#
# Area light, light that scattered exactly twice ($K=2$, because planes need two segments),
# the same photon budget for points, beams and planes, and the reference path tracer.

# %%
area2 = at_resolution(load_scene(ROOT / "scenes" / "area.toml"), *B["res"]).with_scatter(2, 2)
settings = RenderSettings(photons=B["photons"])
three = {"photon points (3D blur)": "points", "photon beams (1D blur)": "beams",
         "photon planes (no blur)": "planes"}
runs = {label: render_passes(area2, spec, B["passes"], settings, seed=3)
        for label, spec in three.items()}
runs["reference"] = render_passes(area2, "reference", B["ref_passes"],
                                  RenderSettings(spp=B["ref_spp"]), seed=4)
stats = {}
ref_level = runs["reference"].mean()
for label, imgs in runs.items():
    per_pass = imgs.mean(axis=(1, 2, 3))
    stats[label] = (per_pass.mean(), per_pass.std(ddof=1) / np.sqrt(len(per_pass)))
    print(f"{label:26s} image mean {stats[label][0]:.5f} ± {stats[label][1]:.5f}"
          f"   ({100 * (stats[label][0] / ref_level - 1):+.1f}% vs reference)")

exposure = images.auto_exposure(runs["reference"].mean(axis=0))
var_lo, var_hi = images.log_range(np.concatenate(
    [images.luminance(runs[k].var(axis=0, ddof=1)).ravel() for k in three]))
fig, axes = plt.subplots(2, 4, figsize=(20, 8.4), layout="constrained")
for j, (label, imgs) in enumerate(runs.items()):
    axes[0, j].imshow(images.tone_map(imgs.mean(axis=0), exposure), interpolation="nearest")
    axes[0, j].set_title(label)
    if label in three:
        var = images.luminance(imgs.var(axis=0, ddof=1))
        im = axes[1, j].imshow(np.clip(var, var_lo, None), norm="log", vmin=var_lo, vmax=var_hi,
                               interpolation="nearest")
        axes[1, j].set_title("per-pass variance")
for ax in axes.flat:
    ax.set_axis_off()
fig.colorbar(im, cax=axes[1, 3].inset_axes([0.05, 0.05, 0.08, 0.9]), label="variance (log)")
fig.suptitle(f"Second bounce (K = 2), {B['photons']} photons per pass, {B['passes']} passes")
save(fig, "02_three_ways.png")

# %% [markdown]
# The three photon images look alike: the kernels are small here. The differences are in
# the numbers above and in what happens when we change the radius.
#
# ## Blur dimension vs bias
#
# Bias shows where the radiance changes fast. Single scattering from a point light has a
# sharp peak around the light, and an exact oracle: the 1D quadrature of tutorial 1,
# averaged over a 4×4 grid inside each pixel (the renderer's box filter). We sweep the kernel
# radius of points (3D), the beam radiance estimate (2D) and beams (1D) and watch the
# brightest pixel.

# %%
point1 = at_resolution(load_scene(ROOT / "scenes" / "point.toml"), *B["res"]).with_scatter(1, 1)
cam = point1.camera
grid = (np.arange(4) + 0.5) / 4
jx, jy = (g.ravel() for g in np.meshgrid(grid, grid))
row, col = np.divmod(np.arange(cam.n_pixels), cam.width)
d = pixel_directions(cam, (col[:, None] + jx).ravel(), (row[:, None] + jy).ravel())
o = np.broadcast_to(cam.position, d.shape)
s_min, s_max = clip_rays(point1, o, d)
oracle = single_scatter_quadrature(point1, o, d, s_min, s_max, n=512)
oracle = oracle.reshape(cam.n_pixels, 16, 3).mean(axis=1).reshape(cam.height, cam.width, 3)
peak = np.unravel_index(np.argmax(oracle[..., 0]), oracle.shape[:2])
print("brightest pixel (row, column):", peak, "oracle value", oracle[peak][0])

radii = [0.025, 0.05, 0.1, 0.2]
blurs = {"points (3D)": "points", "beam radiance est. (2D)": "bre", "beams (1D)": "beams"}
sweep = {}
for label, spec in blurs.items():
    for r in radii:
        imgs = render_passes(point1, spec, B["sweep_passes"],
                             RenderSettings(photons=B["sweep_photons"], radius=r), seed=5)
        v = imgs[:, peak[0], peak[1], 0]
        lit = oracle[..., 0] > 0.2 * oracle[..., 0].mean()  # noise: median over lit pixels
        noise = np.median(imgs[..., 0].std(axis=0, ddof=1)[lit] / oracle[..., 0][lit])
        sweep[label, r] = (v.mean() / oracle[peak][0] - 1,
                           v.std(ddof=1) / np.sqrt(len(v)) / oracle[peak][0], imgs.mean(axis=0),
                           noise)
        print(f"{label:24s} r = {r:5.3f}: peak pixel {100 * sweep[label, r][0]:+6.1f}% "
              f"± {100 * sweep[label, r][1]:.1f}%, noise of one pass {noise:.2f}")

fig, (a1, a3, a2) = plt.subplots(1, 3, figsize=(24, 7), layout="constrained")
for i, label in enumerate(blurs):
    bias = np.array([sweep[label, r][0] for r in radii])
    err = np.array([sweep[label, r][1] for r in radii])
    a1.errorbar(np.array(radii) * (1 + 0.04 * (i - 1)), 100 * bias, yerr=200 * err, marker="o",
                ms=10, capsize=6, label=label)
a1.axhline(0, color="black", lw=2, ls="--")
a1.text(0.3, 0.92, "0 = unbiased: no radius at all\n(planes, surfaces)", fontsize=15,
        transform=a1.transAxes, va="top")
a1.set(xscale="log", xlabel="kernel radius $r$ (scene units)",
       ylabel="error of the brightest pixel (%)", title="Bias grows with the radius")
a1.legend(loc="lower left")
for label in blurs:
    a3.loglog(radii, [sweep[label, r][3] for r in radii], marker="o", ms=10, label=label)
a3.set(xlabel="kernel radius $r$ (scene units)", ylabel="relative noise of one pass (median)",
       title="Noise falls with the radius")
a3.legend(loc="lower left")
for ax in (a1, a3):
    ax.set_xticks(radii, [str(r) for r in radii])
    ax.minorticks_off()
a3.yaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
a3.yaxis.set_major_formatter(FormatStrFormatter("%g"))
xs = np.arange(cam.width)
a2.plot(xs, oracle[peak[0], :, 0], color="black", label="exact (quadrature)")
for label, r, ls in (("points (3D)", 0.2, "-"), ("beams (1D)", 0.2, "-"),
                     ("points (3D)", 0.025, ":")):
    a2.plot(xs, sweep[label, r][2][peak[0], :, 0], ls=ls, label=f"{label}, r = {r}")
a2.set(xlabel="pixel column", ylabel="radiance", xlim=(peak[1] - 12, peak[1] + 12),
       title=f"Row {peak[0]}: blur flattens the peak")
a2.legend()
save(fig, "02_blur_vs_bias.png")

# %% [markdown]
# A large radius gives a smooth but *wrong* image (the peak is flattened: bias); a small
# radius gives the right answer on average but a noisy one (error bars: ±2 standard errors).
# At the same radius the lower-dimensional blur is less noisy (middle panel: beams below
# points), so for the same noise it can use a smaller radius and pay less bias. Photon
# planes go all the way: zero blur dimensions, zero bias.
#
# ## The limitations of photon planes (why the paper exists)
#
# **1. Singularities.** A plane's contribution is $f/|(\omega_1\times\omega_2)\cdot
# \boldsymbol\psi|$: a camera ray grazing the plane divides by almost zero. Below, every hit
# of one pixel's ray with the photon planes of one pass: contribution against $|\mathbf
# n\cdot\boldsymbol\psi|$. Grazing hits are rare (the chance of hitting a plane shrinks like
# $|\mathbf n\cdot\boldsymbol\psi|$) but huge; the second moment $\int x\cdot x^{-2}\,dx$
# diverges logarithmically, so the variance is infinite and fireflies never quite go away.

# %%
ins = inspect_pixel(area2, "planes", 0, 0, (area2.camera.width // 2, area2.camera.height // 3),
                    RenderSettings(photons=B["inspect_photons"]))
tab = ins.table
good = tab.value[:, 0] > 0  # hits whose reconstructed path is valid (in the box, unoccluded)
ndp, value, f_only = tab.n_dot_psi[good], tab.value[good, 0], tab.f[good, 0]
slope = np.polyfit(np.log10(ndp), np.log10(value), 1)[0]
print(f"{good.sum()} hits; log-log slope of contribution vs |n.psi|: {slope:.2f}; "
      f"smallest |n.psi| {ndp.min():.1e}")

fig, (a1, a2) = plt.subplots(1, 2, figsize=(20, 7), layout="constrained")
a1.loglog(ndp, value, "o", ms=6, alpha=0.5, color=OK["blue"], label="contribution $f/|n\\cdot\\psi|$")
a1.loglog(ndp, f_only, "o", ms=4, alpha=0.4, color=OK["orange"], label="$f$ alone")
xx = np.array([ndp.min(), 1.0])
a1.loglog(xx, np.median(f_only) / xx, color="black", ls="--", label="slope $-1$")
a1.set(xlabel="$|\\mathbf{n}\\cdot\\psi|$ of the hit", ylabel="per-photon value",
       title="Every hit of one pixel: the Jacobian drives the spread")
a1.legend()
a2.hist(ndp, bins=25, range=(0, 1), color=OK["sky_blue"], edgecolor="black")
a2.set(xlabel="$|\\mathbf{n}\\cdot\\psi|$ of the hit", ylabel="hits",
       title="Grazing hits are rare, not impossible")
save(fig, "02_plane_singularity.png")

# %% [markdown]
# **2. The single-scattering gap.** A plane needs two photon segments, so it cannot
# estimate light that scattered once, which in tutorial 1 was half of the image. Render
# $K=1$ with planes:

# %%
planes_k1 = render_passes(point1, "planes", 1, RenderSettings(photons=B["photons"]))[0]
print("planes at K = 1: largest pixel", planes_k1.max())
fig, axes = plt.subplots(1, 2, figsize=(14, 5.4), layout="constrained")
exp1 = images.auto_exposure(oracle)
for ax, (label, img) in zip(axes, (("single scattering (exact)", oracle),
                                   ("photon planes, K = 1", planes_k1)), strict=True):
    ax.imshow(images.tone_map(img, exp1), interpolation="nearest")
    ax.set_title(label)
    ax.set_axis_off()
fig.suptitle("Photon planes see nothing of single scattering")
save(fig, "02_single_gap.png")

# %% [markdown]
# **3. Surface-to-medium transport** (light reflected by surfaces into the medium) is the
# third limitation in the talk; psurf's surfaces are black, so it does not arise here.
#
# The paper answers the first two: more photon *surfaces* (tutorials 3-4), combined by MIS so
# each covers the others' singularities (tutorial 6), and single-scattering surfaces
# (tutorial 5).
#
# ## What this tutorial claims, checked

# %%
ref_mean, ref_err = stats["reference"]
pl_mean, pl_err = stats["photon planes (no blur)"]
# 1. Photon planes are unbiased: their image mean agrees with the reference.
assert abs(pl_mean - ref_mean) < 4 * np.hypot(pl_err, ref_err), (pl_mean, ref_mean)
# 2. Blur is bias: with the largest radius every kernel estimator darkens the peak, by far
#    more than its noise.
for label in blurs:
    bias, err = sweep[label, radii[-1]][:2]
    assert bias < 0 and abs(bias) > 4 * err, (label, bias, err)
#    Lower blur dimension, less noise at the same radius: beams below points.
for r in radii:
    assert sweep["beams (1D)", r][3] < sweep["points (3D)", r][3], r
# 3. A plane's contribution scales like 1/|n.psi| (the singularity), and grazing hits occur.
assert -1.2 < slope < -0.8, slope
assert (ndp < 0.1).any()
# 4. The single-scattering gap: planes give exactly nothing for K = 1.
assert np.all(planes_k1 == 0.0) and oracle.max() > 0
for name in ("02_three_ways.png", "02_blur_vs_bias.png", "02_plane_singularity.png",
             "02_single_gap.png"):
    assert (OUT / name).stat().st_size > 10_000, name
print("02: all checks passed")
