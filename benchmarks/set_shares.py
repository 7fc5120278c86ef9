"""What share of the photons each summed set of an estimator should sweep, measured.

Usage::

    python benchmarks/set_shares.py SCENE [--estimator fast-full] [--reference REF.npz]
        [--photons 2000] [--passes 8] [--split-passes 40] [--min-scatter K] [--max-scatter K]
        [--resolution W,H] [--out out/set_shares.json]

A preset such as ``fast-full`` sums independent sets (single scattering, multiple
scattering). Set ``g`` sweeping a share ``s_g`` of each pass's photons costs ``s_g c_g`` a
photon and has the per-photon variance ``v_g / s_g``; the sum's variance at equal time,
``(sum_g v_g / s_g) (sum_g s_g c_g)``, is smallest at ``s_g`` proportional to
``sqrt(v_g / c_g)`` (Cauchy-Schwarz). This script measures ``c_g`` and ``v_g`` for each set
with its members' shares scaled so that the largest is 1 (the set's own allocation kept):

* ``c_g``, seconds a photon: the slope of the median wall time of ``--passes`` passes at
  ``--photons`` and at a quarter of it (``pass_size.timed_cost``: the pass's fixed part, the
  camera rays, is left out; it is paid once for the sum);
* ``v_g``, the per-photon relative variance: ``--split-passes`` split passes
  (``pass_size.split_variances``: two photon sets on one set of camera rays, so the
  pixel jitter cancels), each pixel weighted by one over its squared reference value as a
  relMSE weighs it (``metrics.relative_weight``).

It prints both, the best shares (largest 1), and the model's variance at equal time of the
estimator's present shares and of the best ones, relative to every set on every photon.
The reference is ``--reference`` (an image ``.npz`` with ``mean``), else the sum of the
sets' means over four passes. One thread (``render_pass``), warm (a pass of each set
first compiles its walkers). Heavy tails make ``v_g`` of a few passes low more often than
high: the shares are a guide for the presets' constants, not a per-render choice.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from psurf_core.estimators import parse_estimator  # noqa: E402
from psurf_core.metrics import relative_weight  # noqa: E402
from psurf_core.render import RenderSettings, render_pass, warm_up  # noqa: E402
from psurf_core.scene_io import load_scene  # noqa: E402
from psurf_core.share_pilot import measure_set, model, set_alone  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scene")
    ap.add_argument("--estimator", default="fast-full")
    ap.add_argument("--reference", default=None)
    ap.add_argument("--photons", type=int, default=2000)
    ap.add_argument("--passes", type=int, default=8)
    ap.add_argument("--split-passes", type=int, default=40)
    ap.add_argument("--min-scatter", type=int, default=None)
    ap.add_argument("--max-scatter", type=int, default=None)
    ap.add_argument("--resolution", default=None, help="W,H instead of the scene's")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)

    scene = load_scene(args.scene)
    scene = replace(scene, min_scatter=scene.min_scatter if args.min_scatter is None
                    else args.min_scatter,
                    max_scatter=scene.max_scatter if args.max_scatter is None
                    else args.max_scatter)
    if args.resolution:
        w, h = (int(x) for x in args.resolution.split(","))
        scene = replace(scene, camera=replace(scene.camera, width=w, height=h))
    n_sets = len(parse_estimator(args.estimator, scene).sets)
    sets = [set_alone(args.estimator, scene, g) for g in range(n_sets)]
    settings = RenderSettings(photons=args.photons)
    sizes = (max(args.photons // 4, 1), args.photons)

    if args.reference:
        ref = np.load(args.reference)["mean"]
    else:  # the sets' sum over a few passes (their means are what the weights need)
        ref = sum(sum(render_pass(scene, est, 500 + i, 98, settings) for i in range(4)) / 4
                  for est, _ in sets)
    weight = relative_weight(ref)
    rows = []
    for est, share in sets:
        warm_up(scene, est, settings)
        c0, c1, vp = measure_set(scene, est, settings, weight, sizes, args.passes, 100,
                                 args.split_passes, 7, max(args.photons // 2, 1))
        rows.append({"members": [t.label for t in est.techniques], "present_share": share,
                     "c0_s": c0, "c1_s_per_photon": c1, "v_rel_per_photon": vp})
    v = [r["v_rel_per_photon"] for r in rows]
    c = [r["c1_s_per_photon"] for r in rows]
    best = [math.sqrt(vi / ci) for vi, ci in zip(v, c, strict=True)]
    best = [b / max(best) for b in best]
    present = [r["present_share"] for r in rows]
    ones = [1.0] * len(rows)
    for r, b in zip(rows, best, strict=True):
        r["best_share"] = b
    result = {"command": " ".join(sys.argv), "utc": time.strftime("%Y-%m-%dT%H:%M:%SZ",
                                                                   time.gmtime()),
              "scene": args.scene, "estimator": args.estimator, "sets": rows,
              "model_present_vs_all_on": model(v, c, present) / model(v, c, ones),
              "model_best_vs_all_on": model(v, c, best) / model(v, c, ones)}
    for r in rows:
        print(f"{'+'.join(r['members'])}: {r['c1_s_per_photon'] * 1e6:.2f} us a photon "
              f"(fixed {r['c0_s'] * 1e3:.1f} ms a pass), relVar {r['v_rel_per_photon']:.3g} "
              f"a photon; present share {r['present_share']:g}, best {r['best_share']:.3g}")
    print(f"variance at equal time, against every set on every photon: present shares "
          f"{result['model_present_vs_all_on']:.3f}x, best {result['model_best_vs_all_on']:.3f}x")
    if args.out:
        Path(args.out).write_text(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
