"""Print the numbers behind ``tests/test_vs_mitsuba.py``'s convention checks.

Usage: ``python benchmarks/mitsuba_conventions.py [--variant V] [--mutations]``. Runs each
check of the test with the test's scenes, sample counts and seeds (its helpers, imported) and
prints, per check, the largest per-pixel ``|z|`` (on the pixels where the test bounds it), the
aggregate (image-sum) z per channel, Mitsuba's image sum over the oracle's and that sum's
relative standard error: how closely the converted scene agrees, not only that it passes. The
test asserts; this only reports. ``--mutations`` instead breaks one convention at a time in the
converted scene (monkeypatched, no file changes) and reports whether the same check rejects
it: that the checks can fail.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

import test_vs_mitsuba as T  # noqa: E402

from psurf_core.camera import project  # noqa: E402


def _row(label, m, se, ref, ref_se, mask=None, pixels=None):
    """One table row; the per-pixel |z| on ``pixels`` (as the test bounds it) if given."""
    z, agg = T._z(m, se, ref, ref_se, mask)
    if pixels is not None:
        z, _ = T._z(m, se, ref, ref_se, pixels)
    mask = np.ones(m.shape[:2], bool) if mask is None else mask
    ref_se = np.broadcast_to(ref_se, se.shape)
    ratio = m[mask].sum(axis=0) / ref[mask].sum(axis=0)
    rel_se = np.sqrt((se[mask] ** 2 + ref_se[mask] ** 2).sum(axis=0)) / ref[mask].sum(axis=0)
    fmt = ", ".join
    print(f"| {label} | {z.max():.2f} | {fmt(f'{a:+.2f}' for a in agg)} "
          f"| {fmt(f'{r:.4f}' for r in ratio)} | {fmt(f'{s:.4f}' for s in rel_se)} |")


def main(argv=None) -> int:
    """Command line (module docstring)."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--variant", default=None)
    ap.add_argument("--mutations", action="store_true", help="break conventions one by one")
    args = ap.parse_args(argv)
    variant = T.ms.pick_variant(args.variant)
    print(f"Mitsuba variant {variant}\n")
    if args.mutations:
        mutations()
        return 0
    print("| check | max per-pixel abs z | aggregate z (R, G, B) | Mitsuba sum / oracle sum "
          "| rel. s.e. of the sum |\n|---|---:|---:|---:|---:|")
    for label in T.POINT_CASES:
        scene = T.point_scene(label)
        fine, coarse = T._pixel_quadrature(scene, 8), T._pixel_quadrature(scene, 4)
        px, py, _ = project(scene.camera, T.POINT.position[None])
        mask = np.ones((T.H, T.W), bool)
        mask[max(int(py[0]) - 1, 0): int(py[0]) + 2, max(int(px[0]) - 1, 0): int(px[0]) + 2] = 0
        m, se = T._mitsuba(scene, passes=32, spp=T.POINT_SPP[label], seed=3)
        _row(f"point K=1 {label} vs pixel quadrature", m, se, fine, np.abs(fine - coarse), mask)
        for flip in (np.fliplr, np.flipud):
            z, _ = T._z(flip(m), flip(se), fine, np.abs(fine - coarse), mask)
            print(f"| (the same, image {flip.__name__}: rejected) | {z.max():.0f} | | | |")
    for window, seeds in (((1, 1), (11, 12)), ((1, -1), (11, 12)), ((2, 3), (21, 22))):
        scene = T._scene([T.AREA, T.TETRA], T.OCCLUDERS, g=0.4, sigma_s=1.2, sigma_a=0.2,
                         kmin=window[0], kmax=window[1])
        ref, ref_se = T._psurf_reference(scene, passes=32, spp=32, seed=seeds[0])
        m, se = T._mitsuba(scene, passes=32, spp=128, seed=seeds[1])
        k = f"{window[0]}..{'inf' if window[1] < 0 else window[1]}"
        inside = T.inside_silhouette(scene)
        _row(f"area + mesh lights, occluders, K={k} vs psurf reference", m, se, ref, ref_se,
             pixels=inside)
        if window == (1, 1):
            z, _ = T._z(np.fliplr(m), np.fliplr(se), ref, ref_se, inside)
            print(f"| (the same, image fliplr: rejected) | {z.max():.0f} | | | |")
        if window == (2, 3):
            two, two_se = T._psurf_reference(scene.with_scatter(2, 2), passes=32, spp=32,
                                             seed=23)
            _, agg = T._z(m, se, two, two_se)
            print(f"| (K=2..3 against K=2..2: rejected) | | "
                  f"{', '.join(f'{a:+.1f}' for a in agg)} | | |")
    window_seeds()
    return 0


def _point_z(case):
    scene = T.point_scene(case)
    fine, coarse = T._pixel_quadrature(scene, 8), T._pixel_quadrature(scene, 4)
    px, py, _ = project(scene.camera, T.POINT.position[None])
    mask = np.ones((T.H, T.W), bool)
    mask[max(int(py[0]) - 1, 0): int(py[0]) + 2, max(int(px[0]) - 1, 0): int(px[0]) + 2] = 0
    m, se = T._mitsuba(scene, passes=32, spp=T.POINT_SPP[case], seed=3)
    return T._z(m, se, fine, np.abs(fine - coarse), mask)


def _emitter_z(window):
    scene = T._scene([T.AREA, T.TETRA], T.OCCLUDERS, g=0.4, sigma_s=1.2, sigma_a=0.2,
                     kmin=window[0], kmax=window[1])
    ref, ref_se = T._psurf_reference(scene, passes=32, spp=32, seed=11)
    m, se = T._mitsuba(scene, passes=32, spp=128, seed=12)
    z, _ = T._z(m, se, ref, ref_se, T.inside_silhouette(scene))
    return z, T._z(m, se, ref, ref_se)[1]


def mutations() -> None:
    """Each mutation of the converted scene against the check that should reject it."""
    ms = T.ms.convert  # the conversion's module: the renders read these from it
    scene_dict, integrator_dict, near_clip = ms.scene_dict, ms.integrator_dict, ms.NEAR_CLIP

    def fov_x(d):
        d["sensor"]["fov_axis"] = "x"

    def g_flipped(d):
        d["medium"]["phase"]["g"] *= -1

    def gaussian(d):
        d["sensor"]["film"]["rfilter"] = {"type": "gaussian"}

    def no_occluders(d):
        for k in [k for k in d if k.startswith("occluder")]:
            del d[k]

    def emitters_shown(d):
        d["hide_emitters"] = False

    cases = (  # (name, scene mutation, integrator mutation, near clip, check)
        ("fov_axis x", fov_x, None, None, lambda: _point_z("iso")),
        ("HG g sign flipped", g_flipped, None, None, lambda: _point_z("hg-sphere")),
        ("gaussian pixel filter", gaussian, None, None, lambda: _point_z("iso")),
        ("near_clip 0.01 (Mitsuba's default)", None, None, 1e-2,
         lambda: _point_z("camera-inside")),
        ("occluders dropped", no_occluders, None, None, lambda: _emitter_z((1, 1))),
        ("emitters seen directly (no hide_emitters)", None, emitters_shown, None,
         lambda: _emitter_z((1, 1))),
    )
    print("| mutation | max per-pixel abs z | max abs aggregate z | rejected |")
    print("|---|---:|---:|---|")
    for name, f_scene, f_int, clip, check in cases:
        def sd(scene, spp=16, f=f_scene):
            d = scene_dict(scene, spp)
            if f is not None:
                f(d)
            return d

        def idict(depth, f=f_int):
            d = integrator_dict(depth)
            if f is not None:
                f(d)
            return d

        ms.scene_dict, ms.integrator_dict = sd, idict
        ms.NEAR_CLIP = near_clip if clip is None else clip
        try:
            z, agg = check()
        finally:
            ms.scene_dict, ms.integrator_dict, ms.NEAR_CLIP = scene_dict, integrator_dict, near_clip
        bad = z.max() > T.Z_PIXEL or np.abs(agg).max() > T.Z_MAX
        print(f"| {name} | {z.max():.1f} | {np.abs(agg).max():.1f} | {'yes' if bad else 'NO'} |",
              flush=True)


def window_seeds(passes: int = 24, spp: int = 16) -> None:
    """Per-pass variance of a K = 2..3 window on ``scenes/study_occluder.toml`` rendered as
    ``I(max_depth 4) - I(max_depth 2)`` with the same seed in both renders, with independent
    seeds, and of ``I(max_depth 4)`` alone (mitsuba_scene's module docstring)."""
    from psurf_core.scene_io import load_scene

    scene = load_scene(ROOT / "scenes/study_occluder.toml").with_scatter(2, 3)
    r = T.ms.MitsubaRenderer(scene, spp=spp)

    def img(integrator, seed):
        return np.array(r.mi.render(r.mi_scene, integrator=integrator, seed=seed, spp=spp),
                        dtype=np.float64)

    runs = {"same seed": [], "independent seeds": [], "K = 1..3 alone": []}
    for i in range(passes):
        hi = img(r.hi, T.ms.pass_seed(7, i))
        runs["same seed"].append(hi - img(r.lo, T.ms.pass_seed(7, i)))
        runs["independent seeds"].append(hi - img(r.lo, T.ms.pass_seed(8, i)))
        runs["K = 1..3 alone"].append(hi)
    print(f"\nstudy_occluder K=2..3, {passes} passes x {spp} spp:")
    for name, a in runs.items():
        a = np.array(a)
        var = a.var(axis=0, ddof=1).mean()
        print(f"  {name}: mean {a.mean():.4g}, per-pass variance {var:.3g}")


if __name__ == "__main__":
    sys.exit(main())
