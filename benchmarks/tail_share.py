"""Which member of an MIS set makes its heavy tail: each member's largest per-hit
contributions, how grazing those hits are and what MIS weight they got.

Renders ``PASSES`` passes of ``SPEC`` with a tally (every hit's value before and after its MIS
weight; the walkers emit their hits) and prints per member: hits a pass, the share of the
second moment ``sum c^2`` (``c``: a hit's contribution to its pass image) held by the largest
0.01 % and 0.1 % of its hits, and its twelve largest hits: ``c`` over the member's mean ``c``,
``|n . psi|`` (the surface's scaled normal against the camera ray: small is grazing) and the
weight the hit was given (with sample counts a helper sweeping a share ``a`` of the photons
weighs up to ``1 / a``).

Usage::

    python benchmarks/tail_share.py SCENE.toml KMIN KMAX SPEC [--resolution W,H]
        [--photons 1000] [--passes 30] [--seed 5]
    python benchmarks/tail_share.py scenes/study_occluder.toml 2 3 fast-multi --resolution 256,192

Not a test; the largest hits change with the seed (that is what a heavy tail is).
"""

from __future__ import annotations

import argparse
import os
import sys
from collections import defaultdict

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from benchmarks.scene_args import add_scene_args, scene_of  # noqa: E402
from psurf_core.estimators import parse_estimator  # noqa: E402
from psurf_core.render import RenderSettings, render_pass, warm_up  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_scene_args(ap)
    ap.add_argument("spec")
    ap.add_argument("--photons", type=int, default=1000)
    ap.add_argument("--passes", type=int, default=30)
    ap.add_argument("--seed", type=int, default=5)
    args = ap.parse_args(argv)
    scene = scene_of(args)
    st = RenderSettings(photons=args.photons)
    est = parse_estimator(args.spec, scene)
    warm_up(scene, est, st)
    per = defaultdict(list)  # member -> [(values, unweighted values, |n . psi|)]

    def tally(tech, hits, prims, rays, raw, val):
        v, r = val.sum(1), raw.sum(1)
        keep = v > 0
        dt = getattr(hits.data, "dtype", None)  # a record array, or a dict (numpy stages)
        names = (dt.names or ()) if dt is not None else tuple(hits.data)
        ndp = (hits.data["n_dot_psi"][keep] if "n_dot_psi" in names
               else np.full(int(keep.sum()), np.nan))
        per[tech.name].append((v[keep], r[keep], ndp))

    for i in range(args.passes):
        render_pass(scene, est, i, args.seed, st, tally=tally)
    print(f"# python benchmarks/tail_share.py {' '.join(sys.argv[1:] if argv is None else argv)}")
    for name, rows in per.items():
        v, r, ndp = (np.concatenate(x) for x in zip(*rows, strict=True))
        c = v / args.photons  # render_pass divides the sums by the photons
        c2 = np.sort(c * c)[::-1]
        k = max(1, len(c2) // 10000)
        top = np.argsort(c)[::-1][:12]
        print(f"{name}: {len(c) / args.passes:.0f} hits a pass; the largest 0.01 % hold "
              f"{c2[:k].sum() / c2.sum():.3f} of sum c^2, the largest 0.1 % "
              f"{c2[:10 * k].sum() / c2.sum():.3f}")
        print(f"  largest c / mean c: {np.array2string((c[top] / c.mean()).round(0))}")
        print(f"  their |n . psi|:    {np.array2string(ndp[top], precision=4)}")
        print(f"  their MIS weight:   {np.array2string((v / r)[top], precision=3)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
