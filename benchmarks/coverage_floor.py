"""How far an estimator is from the lowest equal-time variance any photon-surface estimator can
reach on a scene, and whether an equal-time target is reachable at all (docs/study.md).

Every estimator here adds one value per *hit* (a camera ray crossing a photon's surface) and
pays for each hit. For pixel ``p`` with value ``I_p``, let ``pi_p`` be the probability that a
photon's surfaces cross the pixel's ray. Its per-photon contribution ``X_p`` is nonzero with
probability ``pi_p``, so by Cauchy-Schwarz ``E[X_p^2] >= I_p^2 / pi_p`` and its variance is at
least ``I_p^2 (1 / pi_p - 1)``. A photon makes ``H >= sum_p pi_p`` hits; the smallest
``sum_p I_p^2 / pi_p`` for a given ``H`` (``pi_p`` proportional to ``I_p``) gives, for the mean
over the ``P`` pixels of the per-photon variance ``Vp``::

    Vp * H  >=  E*(H)  =  H min mean_p I_p^2 (1 / pi_p - 1)  over  sum_p pi_p <= H
                    (pi_p = min(1, lam I_p); ~ P mean(I)^2 when H << P, 0 when H >= P)

``Vp * H`` is an estimator's variance per photon times its hits per photon: with the cost of a
photon ``~ H`` times the cost of a hit, it is its variance x time up to that cost. MIS can take
``Vp * H`` down to ``E*`` (no spikes, hits where the light is) and no further; only cheaper
hits, fewer fixed costs per pass or a smaller pixel-jitter variance go beyond.

For each estimator this prints, from passes through the pixel centres (``Vp`` alone, as
``benchmarks/pass_model.py``): hits per photon ``H``, ``Vp``, ``E = Vp H``, ``E / E*`` and ``E``
relative to the first estimator's. With ``--target R --cost C``, it also says how low
``E_m / E_first`` must go for the second estimator to reach an equal-time variance ratio ``R``
against the first when a photon of it costs ``C`` times as much per hit, with the pass model's
pixel-jitter term (``Vj``, ``c0``, ``c1`` of both, measured here as pass_model does), and
compares that with ``E* / E_first``.

Usage::

    python benchmarks/coverage_floor.py SCENE.toml KMIN KMAX PASSES PHOTONS SPEC [SPEC ...]
        [--target R]
    python benchmarks/coverage_floor.py scenes/study_medium.toml 2 3 100 1000 planes fast-multi
"""

from __future__ import annotations

import argparse
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from benchmarks.pass_model import model  # noqa: E402
from benchmarks.scene_args import add_scene_args, scene_of  # noqa: E402
from psurf_core import render as render_mod  # noqa: E402
from psurf_core.camera import camera_rays  # noqa: E402
from psurf_core.estimators import parse_estimator  # noqa: E402
from psurf_core.render import RenderSettings, render_pass  # noqa: E402


def efficiency(scene, spec: str, photons: int, passes: int, seed: int = 5) -> dict:
    """Hits per photon, ``Vp`` (unjittered passes) and the passes' images of ``spec``."""
    est = parse_estimator(spec, scene)
    hits = [0]

    def tally(tech, h, prims, rays, raw, val):
        hits[0] += len(h)

    real = render_mod.camera_rays
    render_mod.camera_rays = lambda *a, **k: camera_rays(*a, jitter=False, **k)
    try:
        imgs = np.array([render_pass(scene, est, i, seed, RenderSettings(photons=photons),
                                     tally=tally) for i in range(passes)])
    finally:
        render_mod.camera_rays = real
    vp = float(imgs.var(axis=0, ddof=1).mean()) * photons
    return {"spec": spec, "H": hits[0] / (photons * passes), "Vp": vp, "images": imgs}


def floor_vp(i_pix: np.ndarray, hits: float) -> float:
    """The lowest mean per-photon variance of an estimator making ``hits`` hits per photon:
    ``min mean_p I_p^2 (1 / pi_p - 1)`` over coverages ``0 < pi_p <= 1`` with
    ``sum_p pi_p <= hits`` (water-filling: ``pi_p = min(1, lam I_p)``)."""
    i = np.abs(i_pix[i_pix != 0])
    if hits >= i.size:
        return 0.0
    lo, hi = 0.0, 1.0 / i.min()
    for _ in range(200):  # bisection on lam: sum min(1, lam I) = hits
        lam = 0.5 * (lo + hi)
        lo, hi = (lam, hi) if np.minimum(1.0, lam * i).sum() < hits else (lo, lam)
    pi = np.minimum(1.0, lo * i)
    return float((i**2 * (1.0 / pi - 1.0)).sum() / i_pix.size)


def required_ratio(target: float, first: dict, second: dict) -> float:
    """The ``Vp c1`` ratio (second over first) at which the second estimator's equal-time
    variance is ``target`` times the first's, each at its best photons per pass: the pass
    model's ``(sqrt(Vj c0) + sqrt(Vp c1))^2``, the second with the first's ``Vj`` (every
    unbiased estimator has the same pixel-jitter variance) and its own ``c0``."""
    vj = first["Vj"]
    a1, b1 = math.sqrt(vj * first["c0"]), math.sqrt(first["Vp"] * first["c1"])
    a2 = math.sqrt(vj * second["c0"])
    b2 = math.sqrt(target) * (a1 + b1) - a2
    return max(b2, 0.0) ** 2 / b1**2


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_scene_args(ap)
    ap.add_argument("passes", type=int)
    ap.add_argument("photons", type=int)
    ap.add_argument("specs", nargs="+")
    ap.add_argument("--target", type=float, default=None,
                    help="equal-time variance ratio to test (second spec vs first)")
    ap.add_argument("--model-passes", type=int, default=12,
                    help="passes per size of the pass model (with --target)")
    a = ap.parse_args(argv)
    scene = scene_of(a)
    args = sys.argv[1:] if argv is None else argv
    print(f"# python benchmarks/coverage_floor.py {' '.join(args)}")
    runs = [efficiency(scene, s, a.photons, a.passes) for s in a.specs]
    mean = np.mean([r["images"].mean(axis=0) for r in runs], axis=0)  # pooled: every run is
    i_pix = mean.mean(axis=2).ravel()                                    # unbiased
    e_first = runs[0]["Vp"] * runs[0]["H"]
    for r in runs:
        e = r["Vp"] * r["H"]
        floor = floor_vp(i_pix, r["H"]) * r["H"]
        r.update(E=e, floor=floor)
        print(f"{r['spec']:44s} H {r['H']:7.1f} hits/photon  Vp {r['Vp']:.4g}  E = Vp H "
              f"{e:.4g}  E/E* {e / floor:5.2f}  E/E_first {e / e_first:.3f}  "
              f"(E*/E_first {floor / e_first:.3f})", flush=True)
    if a.target is not None and len(runs) >= 2:
        m1 = model(scene, a.specs[0], a.model_passes)
        m2 = model(scene, a.specs[1], a.model_passes)
        need = required_ratio(a.target, m1, m2)
        need_c0 = required_ratio(a.target, m1, dict(m2, c0=m1["c0"]))
        have = (m2["Vp"] * m2["c1"]) / (m1["Vp"] * m1["c1"])
        cost = (m2["c1"] / runs[1]["H"]) / (m1["c1"] / runs[0]["H"])
        best = runs[1]["floor"] / e_first * cost
        print(f"target Var {a.target:g}x: needs Vp c1 of {a.specs[1]} <= {need:.3f}x "
              f"{a.specs[0]}'s (pass model: Vj {m1['Vj']:.3g}, c0 {m1['c0'] * 1e3:.1f} / "
              f"{m2['c0'] * 1e3:.1f} ms); measured {have:.3f}x; a photon of it costs "
              f"{cost:.2f}x per hit, so the floor E* allows {best:.3f}x")
        print(f"  pass model: {a.specs[0]} c1 {m1['c1'] * 1e6:.1f} us, Vp {m1['Vp']:.3g}; "
              f"{a.specs[1]} c1 {m2['c1'] * 1e6:.1f} us, Vp {m2['Vp']:.3g}; with "
              f"{a.specs[1]}'s c0 equal to {a.specs[0]}'s the target needs <= {need_c0:.3f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
