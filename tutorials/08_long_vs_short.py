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
# # 8 · Long vs short surfaces: two ways to pay for transmittance
#
# **Learning goal.** Every photon surface integrates at least one distance $t^*$, and the
# light along that distance is attenuated by $T_r(t^*)=e^{-\sigma_tt^*}$. A **long** surface
# lets $t^*$ run to infinity and multiplies by $T_r(t^*)$ (an *expected-value* estimator); a
# **short** surface stops at the photon's own sampled flight $T$ and drops the exponential
# (a *track-length* estimator). Both are unbiased; they differ in variance, in cost and in
# what they look like.
#
# `PSURF_TUTORIAL_BUDGET=test` switches to a small budget; figures go to `out/tutorials/08_*.png`.

# %% Setup: paths, budget switch, projector style
# ruff: noqa: E402, E501
import os
import sys
import time
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
from psurf_core.inspect import inspect_pixel
from psurf_core.render import PassRecord
from psurf_core.sampling import sample_free_flight
from ui.views import palette, primitives_view, scene_view

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


B = dict(res=(32, 24), photons=500, passes=4, ref_spp=16, ref_passes=8, flights=2000) \
    if TEST else dict(res=(64, 48), photons=3000, passes=12, ref_spp=64, ref_passes=32,
                      flights=20000)

# %% [markdown]
# ## Transmittance, two estimators (the talk's "long beam and short beam")
#
# The photon samples its flight $T\sim\sigma_te^{-\sigma_tT}$, so
#
# $$P(T>t^*)=e^{-\sigma_tt^*}=T_r(t^*)\qquad\Longrightarrow\qquad
#   \mathbb E\big[\mathbf 1(T>t^*)\big]=T_r(t^*).$$
#
# * **Expected value** (long): use $T_r(t^*)$ itself. Zero variance for this factor; the
#   surface is infinite (in a box: clipped at the boundary).
# * **Track length** (short): use $\mathbf 1(T>t^*)$, i.e. only hits with $t^*<T$ count and
#   $T_r$ is dropped. Variance $T_r(1-T_r)$ for this factor, but the surface is finite
#   (fewer, cheaper hits) and $f$ carries no exponential.
#
# For MIS the short technique's density is $Q_{\text{short}}=Q_{\text{long}}\,T_r(t^*)$
# (ESTIMATORS.md, section 2). Check the key identity with psurf's own free-flight sampler:

# %%
medium = load_scene(ROOT / "scenes" / "area.toml").medium
st = medium.sigma_t
flights = sample_free_flight(st, np.random.default_rng(8), B["flights"])
ts = np.linspace(0.0, 3.0, 31)
indicator = flights[None, :] > ts[:, None]  # track-length estimates, one row per t*
track_mean = indicator.mean(axis=1)
track_err = indicator.std(axis=1, ddof=1) / np.sqrt(B["flights"])
exact = np.exp(-st * ts)

fig, (a1, a2) = plt.subplots(1, 2, figsize=(20, 6.8), layout="constrained")
a1.plot(ts, exact, color="black", label="expected value: $e^{-\\sigma_t t^*}$ (exact)")
a1.errorbar(ts, track_mean, yerr=2 * track_err, fmt="o", ms=8, capsize=5, color=OK["vermillion"],
            label=f"track length: mean of $\\mathbf{{1}}(T>t^*)$, {B['flights']} flights")
a1.set(xlabel="integrated distance $t^*$", ylabel="transmittance",
       title=f"Both estimate $T_r$ ($\\sigma_t$ = {st:g})")
a1.legend()
a2.plot(ts, exact * (1 - exact), color=OK["vermillion"], label="track length: $T_r(1-T_r)$")
a2.plot(ts, indicator.var(axis=1, ddof=1), "o", ms=8, color=OK["vermillion"], alpha=0.6,
        label="measured")
a2.plot(ts, 0 * ts, color="black", label="expected value: 0")
a2.set(xlabel="integrated distance $t^*$", ylabel="variance of one estimate",
       title="The price of the shortcut")
a2.legend()
save(fig, "08_transmittance.png")

# %% [markdown]
# ## What they look like
#
# The same photon, long and short: a long photon plane is a quadrant of a plane through the
# light (clipped to the box), the short one the parallelogram of the photon's own two
# flights; a long cone reaches the box wall, a short one stops at $t_1=T_1$.

# %%
area2 = at_resolution(load_scene(ROOT / "scenes" / "area.toml"), *B["res"]).with_scatter(2, 2)
PAIRS = {"plane [t1,t2]": ("plane-t1t2", "planes"), "cone [t1,ph1]": ("cone", "cone-short"),
         "cylinder [t2,ph1]": ("cylinder", "cylinder-short")}
view_pos, view_focal, view_up = (np.asarray(v) for v in scene_view.overview_camera(area2))
VIEW = (view_pos - view_focal) / np.linalg.norm(view_pos - view_focal)
geo = load_scene(ROOT / "scenes" / "area.toml").with_scatter(2, 2)
p = pv.Plotter(off_screen=True, window_size=(2000, 1100), shape=(2, 2), border=True,
               border_color="#bbbbbb")
scene_view.set_scale(1100)
box = scene_view.box_mesh(geo.medium.bounds_min, geo.medium.bounds_max)
light = geo.lights[0]
for i, (label, (long_name, short_name)) in enumerate(list(PAIRS.items())[:2]):
    for j, (name, kind) in enumerate(((long_name, "long"), (short_name, "short"))):
        ins = inspect_pixel(geo, name, 0, 0, (32, 16), RenderSettings(photons=200))
        prims = ins.prims[(ins.estimator.techniques[0].name, 0)]
        T1 = prims.data["T1"]
        # (a cone keeps no T2: any value in the window below will do)
        T2 = prims.data["T2"] if "T2" in prims.data.dtype.names else np.full_like(T1, 0.6)
        # Long and short make primitives from the same photons in the same order, so the
        # first photon with two visible flights is the same photon in both panels.
        k = int(np.argmax((T1 > 0.4) & (T1 < 0.8) & (T2 > 0.4) & (T2 < 0.9)))
        mesh, _ = primitives_view.primitive_mesh(ins.estimator.techniques[0], prims, [k], geo, 0.0)
        photon = int(prims.photon[k])
        path = ins.paths[0].x[photon, :3]
        p.subplot(i, j)
        p.set_background("white")
        p.add_mesh(box.outline(), color="#777777", line_width=3)
        p.add_mesh(scene_view.quad(light.corner, light.edge_u, light.edge_v),
                   color=scene_view.LIGHT_COLOUR, show_edges=True, edge_color="black")
        tname = ins.estimator.techniques[0].name  # one colour per technique, as in the app
        p.add_mesh(mesh, color=palette.technique_colour(tname), opacity=0.55, culling=False)
        p.add_mesh(pv.lines_from_points(path), color="black", line_width=7)
        p.add_mesh(pv.PolyData(path[1:]).glyph(geom=pv.Sphere(radius=0.04), scale=False,
                                               orient=False), color="black")
        scene_view.add_text(p, f"{label}, {kind} ({name})", 0.03, 0.96, 22, bold=True)
        if j == 0:  # frame the long surface and the path; the short one gets the same view
            pts = np.vstack([np.asarray(mesh.points), path])
            centre = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
            dist = 1.2 + 1.6 * np.linalg.norm(np.ptp(pts, axis=0))
        p.camera_position = [tuple(centre + dist * VIEW), tuple(centre), tuple(view_up)]
p.screenshot(str(OUT / "08_long_short_geometry.png"))
p.close()

# %% [markdown]
# ## Rendering: same answer, different noise and cost
#
# The second bounce of the area-light scene with each pair, the same photons for both, and
# the reference. We also count the hits: a short surface is a part of the long one, so its
# hits are a subset.

# %%
settings = RenderSettings(photons=B["photons"])
ref = np.array([render_pass(area2, parse_estimator("reference", area2), i, 81,
                            RenderSettings(spp=B["ref_spp"])) for i in range(B["ref_passes"])])
ref_mean = ref.mean(axis=0)
lit = ref_mean[..., 0] > 0.2 * ref_mean[..., 0].mean()
runs = {}
for names in PAIRS.values():
    for name in names:
        est = parse_estimator(name, area2)
        imgs, secs, n_hits = [], [], 0
        for i in range(B["passes"]):
            rec = PassRecord()
            t0 = time.perf_counter()
            imgs.append(render_pass(area2, est, i, 82, settings, record=rec))
            secs.append(time.perf_counter() - t0)
            n_hits += sum(len(h) for chunks in rec.hits.values() for h, _ in chunks)
        imgs = np.array(imgs)
        per_pass = imgs.mean(axis=(1, 2, 3))
        runs[name] = dict(
            imgs=imgs, mean=per_pass.mean(), err=per_pass.std(ddof=1) / np.sqrt(len(per_pass)),
            rel_var=float(np.median(imgs[..., 0].var(axis=0, ddof=1)[lit]
                                    / ref_mean[..., 0][lit] ** 2)),
            tau=float(np.median(secs)), hits=n_hits)
        r = runs[name]
        r["var_time"] = r["rel_var"] * r["tau"]  # variance at equal time, up to a constant
        print(f"{name:16s} mean {r['mean']:.5f} ± {r['err']:.5f}  relative variance "
              f"{r['rel_var']:.3g}  {r['tau']:.2f} s/pass  {r['hits']} hits")
ref_pp = ref.mean(axis=(1, 2, 3))
ref_level, ref_err = ref_pp.mean(), ref_pp.std(ddof=1) / np.sqrt(len(ref_pp))
print(f"{'reference':16s} mean {ref_level:.5f} ± {ref_err:.5f}")

fig, axes = plt.subplots(1, 4, figsize=(26, 6.5), layout="constrained")
labels = list(PAIRS)
x = np.arange(len(labels))
for ax, (key, ylabel, title) in zip(axes, (
        ("mean", "image mean", "Same answer (±2 s.e.; line: reference)"),
        ("rel_var", "relative variance of one pass", "Noise"),
        ("hits", "camera-ray hits", "Work: hits to evaluate"),
        ("var_time", "variance x seconds per pass", "Equal time (lower is better)")),
        strict=True):
    for k, (kind, colour) in enumerate((("long", OK["blue"]), ("short", OK["orange"]))):
        vals = [runs[PAIRS[lb][k]][key] for lb in labels]
        err = [2 * runs[PAIRS[lb][k]]["err"] for lb in labels] if key == "mean" else None
        ax.bar(x + (k - 0.5) * 0.38, vals, width=0.36, yerr=err, capsize=6, color=colour,
               label=kind)
    if key == "mean":
        ax.axhline(ref_level, color="black", lw=2, ls="--")
        tops = [runs[n]["mean"] + 3 * runs[n]["err"] for pair in PAIRS.values() for n in pair]
        ax.set_ylim(0.7 * ref_level, max(1.15 * ref_level, *tops))
    ax.set_xticks(x, [lb.split(" ")[0] for lb in labels])
    ax.set(ylabel=ylabel, title=title)
    ax.legend(loc="lower right" if key == "mean" else "upper right")
save(fig, "08_long_short_numbers.png")

exposure = images.auto_exposure(ref_mean)
fig, axes = plt.subplots(2, 3, figsize=(16, 8.4), layout="constrained")
for j, label in enumerate(labels):
    for i, name in enumerate(PAIRS[label]):
        axes[i, j].imshow(images.tone_map(runs[name]["imgs"].mean(axis=0), exposure),
                          interpolation="nearest")
        axes[i, j].set_title(f"{name}", fontsize=17)
        axes[i, j].set_axis_off()
fig.suptitle(f"Long (top) vs short (bottom), K = 2: {B['photons']} photons x {B['passes']} passes")
save(fig, "08_long_short_renders.png")

# %% [markdown]
# Long surfaces evaluate more (and longer-reaching) hits but each carries the exact
# transmittance; short ones evaluate fewer hits and pay with the track-length factor's
# noise. The last panel weighs the two: variance times the time per pass. Which one wins depends on the medium's optical thickness: in a thin medium the long
# surface's extra reach is cheap light; in a thick one most of it is attenuated away and the
# short surface's economy wins. In an MIS combination both are unbiased, whichever density
# weights them (tutorial 6).
#
# ## What this tutorial claims, checked

# %%
# 1. Track length estimates transmittance without bias, with variance T_r (1 - T_r).
assert np.all(np.abs(track_mean - exact) <= 4 * np.maximum(track_err, 1e-12) + 1e-12)
assert np.allclose(indicator.var(axis=1, ddof=1), exact * (1 - exact), atol=0.03)
for label, (long_name, short_name) in PAIRS.items():
    lo, sh = runs[long_name], runs[short_name]
    # 2. Long and short render the same image on average, and agree with the reference.
    assert abs(lo["mean"] - sh["mean"]) < 4 * np.hypot(lo["err"], sh["err"]), label
    for r in (lo, sh):
        assert abs(r["mean"] - ref_level) < 4 * np.hypot(r["err"], ref_err), label
    # 3. A short surface is part of the long one: never more hits for the same photons.
    assert sh["hits"] <= lo["hits"], (label, sh["hits"], lo["hits"])
for name in ("08_transmittance.png", "08_long_short_geometry.png", "08_long_short_numbers.png",
             "08_long_short_renders.png"):
    assert (OUT / name).stat().st_size > 10_000, name
print("08: all checks passed")
