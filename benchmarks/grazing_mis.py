"""A lever measured and not kept (docs/study.md): MIS helpers restricted to where photon planes
graze.

Photon planes' per-photon variance at K = 2..3 comes mostly from the few hits where the plane
is seen nearly edge-on (|(w1 x w2) . psi| small: on ``study_medium``, 86 % of the second
moment from 1.7 % of the hits, below 0.1). A helper technique restricted to that domain
``D = {|(w1 x w2) . psi| < tau}`` (its effective density ``Q_j 1_D`` in every weight, its own
hits outside ``D`` dropped) keeps the balance heuristic unbiased (photon planes cover every
path) and makes only the hits in ``D``. This measures, in numpy, what it would buy: the MIS
weights are recomputed from every hit's reconstructed path with the helpers (every member
after the first) restricted, on passes through the pixel centres (``Vp`` alone).

Usage::

    python benchmarks/grazing_mis.py SCENE.toml KMIN KMAX SPEC PHOTONS PASSES TAU
    python benchmarks/grazing_mis.py scenes/study_medium.toml 2 3 mis:planes+cone-short 1000 60 0.1

Prints ``Vp`` of the set with its own weights and with the restricted helpers, and each
member's hits per photon (all, and kept in ``D``). ``Vp x hits`` against ``planes`` alone is
the comparison of ``benchmarks/coverage_floor.py``.
"""

from __future__ import annotations

import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from psurf_core import render as render_mod  # noqa: E402
from psurf_core.camera import camera_rays  # noqa: E402
from psurf_core.estimators import parse_estimator  # noqa: E402
from psurf_core.geometry import blockers_of  # noqa: E402
from psurf_core.mis import member_densities  # noqa: E402
from psurf_core.render import PassRecord, RenderSettings, render_pass  # noqa: E402
from psurf_core.scene_io import load_scene  # noqa: E402
from psurf_core.techniques.base import PassContext  # noqa: E402


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 7:
        print(__doc__)
        return 2
    scene = load_scene(argv[0]).with_scatter(int(argv[1]), int(argv[2]))
    spec, n, passes, tau = argv[3], int(argv[4]), int(argv[5]), float(argv[6])
    est = parse_estimator(spec, scene)
    group = est.sets[0][1]
    blk = blockers_of(scene)
    npix = scene.camera.height * scene.camera.width
    own, restricted = [], []
    hits = {m.name: [0, 0] for m in group}
    real = render_mod.camera_rays
    render_mod.camera_rays = lambda *a, **k: camera_rays(*a, jitter=False, **k)
    try:
        for i in range(passes):
            rec = PassRecord()
            img_own, img_res = np.zeros((npix, 3)), np.zeros((npix, 3))

            def tally(tech, h, prims, rays, raw, val, rec=rec, i=i, img_own=img_own,
                      img_res=img_res):
                ctx = PassContext(scene, blk, 0.0, i)
                r = tech.reconstruct(h, prims, rec.paths[-1], rays, ctx)
                # Sample counts (``@share``): the heuristic weighs n_j Q_j and a member's
                # hits stand for all photons (/ n_me), as psurf_core.mis.mis_weights.
                n_j = np.array([float(getattr(m, "share", 1.0)) for m in group])
                q = member_densities(r, group, ctx) * n_j[:, None]
                me = next(j for j, m in enumerate(group) if m is tech)
                grazing = (np.abs(np.einsum("ij,ij->i", np.cross(r.w1, r.w2), r.psi)) < tau) \
                    & (r.K >= 2)
                q[1:] *= grazing  # the helpers' densities: 0 outside D
                den = q.sum(axis=0)
                w = np.where(den > 0, q[me] / np.where(den > 0, den, 1.0), 0.0) / n_j[me]
                keep = np.ones(len(h), bool) if me == 0 else grazing
                pix = rays.pixel[h.ray]
                for c in range(3):
                    img_res[:, c] += np.bincount(pix, raw[:, c] * w * keep, minlength=npix)
                    img_own[:, c] += np.bincount(pix, val[:, c], minlength=npix)
                hits[tech.name][0] += len(h)
                hits[tech.name][1] += int(keep.sum())

            render_pass(scene, est, i, 5, RenderSettings(photons=n), record=rec, tally=tally)
            own.append(img_own / n)
            restricted.append(img_res / n)
    finally:
        render_mod.camera_rays = real
    a, b = np.array(own), np.array(restricted)
    print(f"# python benchmarks/grazing_mis.py {' '.join(argv)}")
    print(f"{spec}: image mean {a.mean():.5g} (restricted {b.mean():.5g}); Vp per photon: "
          f"own weights {a.var(0, ddof=1).mean() * n:.4g}, helpers restricted to "
          f"|(w1 x w2).psi| < {tau:g}: {b.var(0, ddof=1).mean() * n:.4g}")
    for name, (h_all, h_kept) in hits.items():
        print(f"  {name:>20}: hits per photon {h_all / n / passes:.1f}, in D "
              f"{h_kept / n / passes:.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
