"""What ``--photons auto`` chooses, and what the previous pilot chose: photons per pass of an
equal-time run from the pass model ``(Vj + Vp / N)(c0 + c1 N)`` (psurf_core/pass_size.py).

For each estimator it prints, per repeat, the pilot's ``c0, c1`` (timed passes, the same in
both), and

* ``split``: ``Vj, Vp`` from split passes (one set of camera rays, two photon halves; what
  ``pass_size.pilot`` does since 2026-12-05) and the ``N*`` they give;
* ``pilot``: the seconds ``pass_size.pilot`` took;
* ``two-size``: ``Vj, Vp`` fitted to the per-pass variances of the two timed sizes (6 passes
  of 128 and of 1024 photons: what ``pass_size.pilot`` did before), and its ``N*``.

Heavy tails (rare huge contributions, e.g. photon planes seen edge-on) are seen more often in
the larger passes, so their variance falls slower than ``1 / N`` and the two-size fit calls
the rest pixel variance ``Vj``: its ``N*`` is then too small (``planes``) or, where the fit
reads ``Vj`` ~0, capped at ``OVERHEAD_CAP c0 / c1`` (``fast-multi``).

Usage::

    python benchmarks/pilot_choice.py SCENE.toml KMIN KMAX SPEC [SPEC ...] [--repeats 3]
    python benchmarks/pilot_choice.py scenes/study_medium.toml 2 3 planes fast-multi

Not a test: the timings move with the machine's load.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import replace

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import numpy as np  # noqa: E402

from benchmarks.scene_args import add_scene_args, scene_of  # noqa: E402
from psurf_core import pass_size as ps  # noqa: E402
from psurf_core.accumulate import Welford  # noqa: E402
from psurf_core.estimators import parse_estimator  # noqa: E402
from psurf_core.render import RenderSettings, render_pass, warm_up  # noqa: E402

#: The previous pilot: passes of each of its two sizes.
TWO_SIZE_PASSES = 6


def two_size_terms(scene, est, settings) -> tuple[float, float]:
    """``(Vj, Vp)`` as the previous pilot fitted them: ``variance = Vj + Vp / N`` through
    the mean per-pass variances of :data:`TWO_SIZE_PASSES` passes of each pilot size."""
    (na, nb), var = ps.PILOT_PHOTONS, []
    for k, n in enumerate(ps.PILOT_PHOTONS):
        acc = Welford.empty((scene.camera.height, scene.camera.width, 3))
        for i in range(TWO_SIZE_PASSES):
            img = render_pass(scene, est, i, ps.PILOT_SEED + k, replace(settings, photons=n))
            acc.add(np.nan_to_num(img, nan=0.0, posinf=0.0, neginf=0.0))
        var.append(float(np.mean(acc.variance)))
    vp = max((var[0] - var[1]) / (1.0 / na - 1.0 / nb), 1e-300)
    return max(var[1] - vp / nb, 0.0), vp


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_scene_args(p)
    p.add_argument("specs", nargs="+")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--budget", type=float, default=30.0, help="seconds of the run (MIN_PASSES)")
    a = p.parse_args(argv)
    print(f"# python benchmarks/pilot_choice.py {' '.join(sys.argv[1:] if argv is None else argv)}")
    scene = scene_of(a)
    st = RenderSettings()
    for spec in a.specs:
        est = parse_estimator(spec, scene)
        warm_up(scene, est, st)
        old = two_size_terms(scene, est, st)
        for _ in range(a.repeats):
            t = time.perf_counter()
            c0, c1, vj, vp = ps.pilot(scene, est, st)
            t = time.perf_counter() - t
            print(f"{spec:12s} c0 {c0 * 1e3:6.2f} ms  c1 {c1 * 1e6:6.2f} us | split Vj {vj:.3g} "
                  f"Vp {vp:.3g} N* {ps.best_photons(c0, c1, vj, vp, a.budget):6d} | two-size "
                  f"Vj {old[0]:.3g} Vp {old[1]:.3g} N* "
                  f"{ps.best_photons(c0, c1, *old, a.budget):6d} | pilot {t:.1f} s", flush=True)


if __name__ == "__main__":
    main()
