"""What each lever bought at K = 2..3: the ladder from the paper's MIS set to ``fast-multi``,
each rung's per-photon variance and CPU cost against photon planes (issue 12's ablation).

Rungs (each changes one thing from the one above it):

1. ``paper-multi`` on the numpy stages (binning, intersect, evaluate, numpy MIS weights): no
   compiled walker;
2. ``paper-multi`` with compiled walkers but its MIS weights computed in numpy from the
   walkers' emitted hits (the walker without a fused weight);
3. ``paper-multi`` as it runs (walkers with the fused MIS weight);
4. its members short (each surface cut at the photon's own flights);
5. short members with sample counts (``@share``: the helpers sweep a share of the photons);
6. two helpers kept: ``planes`` + ``plane-t2t3-short@0.3`` + ``cone-short@0.2`` (``fast-multi``
   until 2026-12-05);
7. ``fast-multi`` as it is: for an area light the light strips that face the camera in place
   of ``plane-t2t3-short@0.3`` (docs/study.md, "Light strips").

Per rung: ``Vp``, one photon's variance (mean per-pixel variance of passes through the pixel
centres times the photons a pass; the same for rungs 1-3, which differ only in how the same
numbers are computed, and measured once, compiled), the CPU time a photon costs in a whole
pass (trace, primitives, walks, weights: ``time.process_time``, every thread; the median of
``--cost-passes`` passes of ``--photons`` photons after a warm-up), their product ``E`` (the
equal-time variance up to the clock, fixed per-pass costs included) and ``E`` over
``planes``'. ``planes``' ``Vp`` is heavy-tailed (grazing hits): it takes ``--baseline-passes``
passes (default 4x ``--passes``).

Usage::

    python benchmarks/ablation.py SCENE.toml KMIN KMAX [--photons 2000] [--passes 40]
        [--cost-passes 3] [--baseline-passes N] [--seed 7] [--skip-numpy]
        [--specs SPEC;SPEC;...] [--resolution W,H] [--photon-sampler sobol]
        [--reference REF.npz]
    python benchmarks/ablation.py scenes/study_medium.toml 2 3

``--specs`` measures the given estimators (``;``-separated) against ``planes`` instead of the
rungs: a preset's variants on the same footing. ``--reference`` weighs each pixel's variance
by ``1 / (R^2 + EPS mean(R)^2)`` of that image: ``Vp`` is then what a relMSE sees of one
photon's noise (its dim pixels count more than in the plain mean).

Not a test: CPU time moves with the machine's load; compare within one run.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from contextlib import contextmanager
from dataclasses import replace

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from benchmarks.pass_model import passes_of, reference_image  # noqa: E402
from benchmarks.scene_args import add_scene_args, scene_of  # noqa: E402
from psurf_core import render as render_mod  # noqa: E402
from psurf_core.estimators import parse_estimator  # noqa: E402
from psurf_core.kernels import fused as fused_mod  # noqa: E402
from psurf_core.photon_sampler import PHOTON_SAMPLERS  # noqa: E402
from psurf_core.render import RenderSettings, render_pass, warm_up  # noqa: E402

LONG = "mis:plane-t1t2+plane-t1t3+plane-t2t3+cone+cylinder"  # = paper-multi
SHORT = "mis:planes+plane-t1t3-short+plane-t2t3-short+cone-short+cylinder-short"
SHARED = ("mis:planes+plane-t1t3-short@0.3+plane-t2t3-short@0.3+cone-short@0.2"
          "+cylinder-short@0.2")

#: (label, spec, mode): mode "stages" (no compiled walker), "numpy weights" (walkers without
#: the fused MIS weight) or "" (as it runs).
RUNGS = (
    ("planes (baseline)", "planes", ""),
    ("1. paper-multi, numpy stages", "paper-multi", "stages"),
    ("2. + compiled walkers, numpy MIS weights", "paper-multi", "numpy weights"),
    ("3. + fused MIS weight (paper-multi today)", "paper-multi", ""),
    ("4. + short members", SHORT, ""),
    ("5. + sample counts (@share)", SHARED, ""),
    ("6. two helpers (fast-multi until 12-05)",
     "mis:planes+plane-t2t3-short@0.3+cone-short@0.2", ""),
    ("7. + light strips (fast-multi today)", "fast-multi", ""),
)


@contextmanager
def mode(name: str):
    """``render_pass`` on the numpy stages (``stages``), or with walkers that leave the MIS
    weight to numpy (``numpy weights``); as it runs for ``""``."""
    real_fused, real_weight = render_mod.fused_pass, fused_mod.weight_of
    if name == "stages":
        render_mod.fused_pass = lambda *a, **k: None
    elif name == "numpy weights":
        fused_mod.weight_of = lambda *a, **k: (None, None)
    try:
        yield
    finally:
        render_mod.fused_pass, fused_mod.weight_of = real_fused, real_weight


def photon_variance(scene, est, photons: int, passes: int, seed: int,
                    settings: RenderSettings, reference=None) -> float:
    """``Vp``: mean per-pixel variance of ``passes`` passes through the pixel centres (each
    over ``R^2 + EPS mean(R)^2`` with a ``reference``), times ``photons``
    (:func:`benchmarks.pass_model.passes_of`)."""
    return passes_of(scene, est, photons, passes, False, seed, settings, reference)[0] * photons


def photon_cost(scene, est, photons: int, passes: int, seed: int,
                settings: RenderSettings) -> float:
    """Median CPU seconds a photon costs in a whole (jittered) pass, after one warm-up
    pass."""
    render_pass(scene, est, 0, seed + 1, replace(settings, photons=photons))
    return passes_of(scene, est, photons, passes, True, seed + 2, settings)[1] / photons


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_scene_args(ap)
    ap.add_argument("--photons", type=int, default=2000)
    ap.add_argument("--passes", type=int, default=40)
    ap.add_argument("--cost-passes", type=int, default=3)
    ap.add_argument("--baseline-passes", type=int, default=None)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--skip-numpy", action="store_true", help="leave out rungs 1 and 2")
    ap.add_argument("--specs", default=None, help="';'-separated estimators instead of the rungs")
    ap.add_argument("--photon-sampler", choices=PHOTON_SAMPLERS, default="independent")
    ap.add_argument("--reference", default=None, metavar="REF.npz",
                    help="Vp of the relMSE's noise part: each pixel's variance over "
                         "R^2 + EPS mean(R)^2 of this reference (same size)")
    args = ap.parse_args(argv)
    scene = scene_of(args)
    settings = RenderSettings(photon_sampler=args.photon_sampler)
    ref = None if args.reference is None else reference_image(args.reference, scene)
    print(f"# python benchmarks/ablation.py {' '.join(sys.argv[1:] if argv is None else argv)}")
    print(f"# {args.scene} K={args.kmin}..{args.kmax}, {args.photons} photons a pass, "
          f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, "
          f"load {os.getloadavg()[0]:.2f}")
    print(f"{'rung':<44} {'Vp':>10} {'us/photon':>10} {'E = Vp c':>10} {'E / planes':>10} "
          f"{'Vp / planes':>11} {'c / planes':>10}")
    vps: dict[str, float] = {}
    base = None
    rungs = RUNGS if args.specs is None else (
        RUNGS[:1] + tuple((s, s, "") for s in args.specs.split(";")))
    for label, spec, m in rungs:
        if args.skip_numpy and m:
            continue
        est = parse_estimator(spec, scene)
        if spec not in vps:
            # The modes compute the same numbers (tests/test_walkers.py, test_twins.py):
            # the variance is measured once, on the compiled path.
            warm_up(scene, est, RenderSettings(photons=64))
            n = (args.baseline_passes or 4 * args.passes) if base is None else args.passes
            vps[spec] = photon_variance(scene, est, args.photons, n, args.seed, settings, ref)
        with mode(m):
            warm_up(scene, est, RenderSettings(photons=64))
            c = photon_cost(scene, est, args.photons, args.cost_passes, args.seed, settings)
        vp = vps[spec]
        base = base or (vp, c)
        print(f"{label:<44} {vp:10.3e} {c * 1e6:10.1f} {vp * c:10.3e} "
              f"{vp * c / (base[0] * base[1]):10.3f} {vp / base[0]:11.3f} {c / base[1]:10.2f}",
              flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
