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
# # 6 · Photon surfaces as sampling strategies: MIS
#
# **Learning goal.** Treat each photon surface as a *sampling technique* for the same
# integral, and combine them with multiple importance sampling (Veach & Guibas 95). See the
# talk's "unweighted vs weighted" picture of the second bounce: every surface alone is a
# complete (noisy) estimate; after weighting, each keeps the part of the image it is good
# at, and the weighted parts add up to the MIS image. Then follow one hit through the
# paper's **Reconstruct & Evaluate** stage.
#
# `PSURF_TUTORIAL_BUDGET=test` switches to a small budget; figures go to `out/tutorials/06_*.png`.

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
from psurf_core.inspect import inspect_pixel, reconstruct_hit
from psurf_core.render import PassRecord
from ui.views import hits_view, scene_view

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


B = dict(res=(32, 24), photons=400, passes=3, ref_spp=16, ref_passes=8, inspect=1500) \
    if TEST else dict(res=(64, 48), photons=2000, passes=10, ref_spp=64, ref_passes=32,
                      inspect=4000)

# %% [markdown]
# ## Why the balance heuristic is unbiased here
#
# Each technique $i$ turns a photon into hits; a hit fixes a whole light path (the photon's
# sampled dimensions plus the roots of the integrated ones). On that path technique $i$ has
# an *effective density* with respect to one shared measure (ESTIMATORS.md, section 2):
#
# $$Q_i(\text{path})=q_i(\text{sampled dims of } i)\;|\mathbf n_i(\text{path})\cdot\boldsymbol\psi|,
#   \qquad X_i=\frac{f}{Q_i}.$$
#
# Every photon feeds every technique once, so the balance heuristic weights each hit by
#
# $$w_i=\frac{Q_i}{\sum_j Q_j}\quad\Longrightarrow\quad w_iX_i=\frac{f}{\sum_jQ_j}.$$
#
# All $Q_j$ are evaluated on the **same reconstructed path** (Reconstruct), and since the
# weights sum to one on every path, the combination is unbiased whatever the $Q$'s are.
# Where one technique is singular ($Q_i\to0$: a grazing plane, a tiny sphere), its weight
# goes to zero and the others take over: the singularities of tutorial 2 disappear.
#
# The paper's second-bounce set: plane $[t_1,t_2]$, sphere, cone and cylinder.

# %%
scene = at_resolution(load_scene(ROOT / "scenes" / "area.toml"), *B["res"]).with_scatter(2, 2)
MEMBERS = {"plane [t1,t2]": "plane-t1t2", "sphere": "sphere", "cone": "cone",
           "cylinder": "cylinder"}
MIS = "mis:" + "+".join(MEMBERS.values())
settings = RenderSettings(photons=B["photons"])

# Unweighted: each technique alone, a complete estimator of K = 2.
unweighted = {label: render_passes(scene, spec, B["passes"], settings, seed=31)
              for label, spec in MEMBERS.items()}

# Weighted: one MIS render; the pass record keeps every hit's weighted value, per technique.
est = parse_estimator(MIS, scene)
cam = scene.camera
mis_passes, weighted_passes = [], {label: [] for label in MEMBERS}
for i in range(B["passes"]):
    rec = PassRecord()
    mis_passes.append(render_pass(scene, est, i, 31, settings, record=rec))
    norm = settings.photons * settings.spp
    for label, spec in MEMBERS.items():
        part = np.zeros((cam.n_pixels, 3))
        for (name, _b), chunks in rec.hits.items():
            if name != spec:
                continue
            for hits, val in chunks:  # val: w_i X_i of every hit (after the MIS weight)
                for c in range(3):
                    part[:, c] += np.bincount(rec.rays.pixel[hits.ray], weights=val[:, c],
                                              minlength=cam.n_pixels)
        weighted_passes[label].append(part.reshape(cam.height, cam.width, 3) / norm)
mis_passes = np.array(mis_passes)
weighted = {k: np.array(v) for k, v in weighted_passes.items()}
reference = render_passes(scene, "reference", B["ref_passes"], RenderSettings(spp=B["ref_spp"]),
                          seed=32)


def level(imgs):
    """Image mean and its standard error, from the per-pass image means."""
    m = imgs.mean(axis=(1, 2, 3))
    return m.mean(), m.std(ddof=1) / np.sqrt(len(m))


ref_mean = reference.mean(axis=0)
lit = ref_mean[..., 0] > 0.2 * ref_mean[..., 0].mean()


def rel_var(imgs):
    """Median over lit pixels of one pass's variance / (reference value)^2."""
    return float(np.median(imgs[..., 0].var(axis=0, ddof=1)[lit] / ref_mean[..., 0][lit] ** 2))


for label in MEMBERS:
    m, e = level(unweighted[label])
    print(f"{label:14s} alone: mean {m:.5f} ± {e:.5f}, relative variance {rel_var(unweighted[label]):.3g}")
m, e = level(mis_passes)
print(f"{'MIS':14s}      : mean {m:.5f} ± {e:.5f}, relative variance {rel_var(mis_passes):.3g}")
print(f"{'reference':14s}      : mean {level(reference)[0]:.5f} ± {level(reference)[1]:.5f}")

# %% [markdown]
# ## Unweighted vs weighted (the talk's second-bounce slide)

# %%
mis_mean = mis_passes.mean(axis=0)
exposure = images.auto_exposure(mis_mean)
fig, axes = plt.subplots(3, 5, figsize=(23, 13), layout="constrained")
for j, label in enumerate(MEMBERS):
    axes[0, j].imshow(images.tone_map(unweighted[label].mean(axis=0), exposure),
                      interpolation="nearest")
    axes[0, j].set_title(f"{label}, alone")
    w_img = weighted[label].mean(axis=0)
    axes[1, j].imshow(images.tone_map(w_img, exposure), interpolation="nearest")
    axes[1, j].set_title(f"{label}, weighted")
    share = np.divide(w_img[..., 0], mis_mean[..., 0], out=np.zeros(w_img.shape[:2]),
                      where=mis_mean[..., 0] > 0)
    im = axes[2, j].imshow(share, cmap="cividis", vmin=0, vmax=1, interpolation="nearest")
    axes[2, j].set_title(f"share: {100 * w_img.sum() / mis_mean.sum():.0f}% overall")
axes[0, 4].imshow(images.tone_map(ref_mean, exposure), interpolation="nearest")
axes[0, 4].set_title("reference")
axes[1, 4].imshow(images.tone_map(mis_mean, exposure), interpolation="nearest")
axes[1, 4].set_title("MIS = sum of the weighted")
for ax in axes.flat:
    ax.set_axis_off()
fig.colorbar(im, cax=axes[2, 4].inset_axes([0.1, 0.05, 0.1, 0.9]),
             label="share of the MIS image")
fig.suptitle(f"Second bounce, area light: {B['photons']} photons x {B['passes']} passes, "
             "one exposure")
save(fig, "06_unweighted_weighted.png")

# %% [markdown]
# Top: each surface alone is an unbiased but noisy image (the sphere is the worst: its
# normal $t_1^2\omega_1$ makes it singular for short last segments). Middle: after weighting,
# each technique contributes where it is strong, and their sum is the MIS image. Bottom: the
# share of each technique, pixel by pixel.
#
# ## Reconstruct & Evaluate, for one hit
#
# Replay one pixel of pass 0 (`inspect_pixel`), take one of its largest hits and rebuild
# its full path (`reconstruct_hit`): every member evaluates its $Q_j$ on that path, and the
# weight is $Q_i/\sum_jQ_j$.

# %%
PIXEL = (cam.width // 2, cam.height // 3)
ins = inspect_pixel(scene, MIS, 31, 0, PIXEL, RenderSettings(photons=B["inspect"]))
t = ins.table


def drawable(r):
    """A hit whose path has well separated vertices (so the 3D figure reads well)."""
    poly = reconstruct_hit(ins, int(r))["polyline"][:-1]  # light ... x0 (no camera)
    return len(poly) >= 3 and np.linalg.norm(np.diff(poly, axis=0), axis=1).min() > 0.3


order = t.by_contribution()
row = int(next((r for r in order[:300] if drawable(r)), order[0]))
recon = reconstruct_hit(ins, row)
print(f"pixel {PIXEL}, pass 0: {len(t)} hits; we follow a {recon['technique']} hit "
      f"(rank {int(np.flatnonzero(order == row)[0])} by contribution), K = {recon['K']}, "
      f"s = {t.s[row]:.3f}")
print("path:", " -> ".join(recon["labels"]))
print(f"{'member':12s} {'Q_j':>12s} {'w_j':>8s}")
for name, q, w in recon["members"]:
    mark = "  <- this hit's technique" if name == recon["technique"] else ""
    print(f"{name:12s} {q:12.4e} {w:8.4f}{mark}")
print(f"value X = {t.value[row, 0]:.4e}, weight {t.mis_weight[row]:.4f}, "
      f"contribution w X / (N spp) = {t.contribution[row, 0]:.4e}")

names = [m[0] for m in recon["members"]]
qs = np.array([m[1] for m in recon["members"]])
ws = np.array([m[2] for m in recon["members"]])
fig, (a1, a2) = plt.subplots(1, 2, figsize=(18, 6.5), layout="constrained")
colours = [OK["vermillion"] if n == recon["technique"] else OK["blue"] for n in names]
a1.bar(names, qs, color=colours)
a1.set(yscale="log", ylabel="$Q_j$ on the reconstructed path",
       title="Every member's density on the same path")
a2.bar(names, ws, color=colours)
for i, w in enumerate(ws):
    a2.text(i, w + 0.02, f"{w:.2f}", ha="center")
a2.set(ylim=(0, 1.1), ylabel="balance weight $Q_j/\\sum Q$",
       title=f"Weights (sum {ws.sum():.3f}); red: the hit's technique")
save(fig, "06_reconstruct_weights.png")

p = pv.Plotter(off_screen=True, window_size=(1600, 900))
scene_view.set_scale(900)
scene_view.add_scene(p, scene, pixel_xy=PIXEL, labels=False)
hits_view.add_query_ray(p, ins)
hits_view.add_hit_primitives(p, ins, [row], opacity=0.5)
hits_view.add_reconstruction(p, ins, recon)
scene_view.add_text(p, "Reconstruct & Evaluate: the full path of one hit", 0.015, 0.985,
                    scene_view.FONT_TITLE, bold=True)
scene_view.add_text(p, "thick: the path the hit implies; grey: the photon's own vertices it "
                       "replaced.\n" + ",  ".join(f"{n}: w = {w:.2f}" for n, w in zip(names, ws,
                                                                                   strict=True)),
                    0.015, 0.93, scene_view.FONT_SMALL)
p.camera_position = scene_view.overview_camera(scene, zoom=1.8)
p.screenshot(str(OUT / "06_reconstruct_3d.png"))
p.close()

# %% [markdown]
# ## What this tutorial claims, checked

# %%
# 1. The weighted images add up to the MIS image, pass by pass, to rounding.
assert np.allclose(sum(weighted.values()), mis_passes, rtol=1e-9, atol=1e-15)
# 2. The MIS image's mean agrees with the reference (and so does every technique alone).
ref_m, ref_e = level(reference)
for label, imgs in [*unweighted.items(), ("MIS", mis_passes)]:
    m, e = level(imgs)
    assert abs(m - ref_m) < 4 * np.hypot(e, ref_e), (label, m, e, ref_m, ref_e)
# 3. MIS is less noisy than every technique alone.
assert all(rel_var(mis_passes) < rel_var(v) for v in unweighted.values())
# 4. Reconstruct & Evaluate: the weights are Q_i / sum Q_j and sum to one, and the hit's
#    share of the pixel is its weight times its value; the hit table sums to the pixel value.
assert np.isclose(ws.sum(), 1.0) and np.allclose(ws, qs / qs.sum())
me = names.index(recon["technique"])
assert np.isclose(t.mis_weight[row], ws[me])
assert np.allclose(t.contribution[row], ws[me] * t.value[row] / B["inspect"], rtol=1e-9)
assert ins.sum_matches
for name in ("06_unweighted_weighted.png", "06_reconstruct_weights.png", "06_reconstruct_3d.png"):
    assert (OUT / name).stat().st_size > 10_000, name
print("06: all checks passed")
