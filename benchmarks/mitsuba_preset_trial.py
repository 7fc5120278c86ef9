"""A preset that does not exist yet, tried on a case of ``vs_mitsuba.py`` at equal CPU time.

The full presets are two independent groups, single scattering and two or more events
(``paper-full`` = ``paper-single``'s group + ``paper-multi``'s, ``fast-full`` = the ``fast-*``
ones). Whether a mix (say ``paper-single``'s group with ``fast-multi``'s) beats both on a
case is what this measures: it registers the mixed preset ``trial-SINGLE-MULTI`` (in this
process only: ``psurf_core.estimators.PRESETS``) and runs ``psurf_core.study.compare`` with
it beside the existing ones (photons per pass ``auto``, CPU clock) against the case's summed
reference from ``vs_mitsuba.py --refs-only`` (docs/vs_mitsuba.md).

Usage::

    python benchmarks/mitsuba_preset_trial.py CASE [--single paper] [--multi fast]
        [--against paper-full,fast-full] [--time 20] [--runs 2] [--ref-time 300]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import mitsuba_renders as mr  # noqa: E402
import vs_mitsuba  # noqa: E402

from psurf_core import estimators as E  # noqa: E402
from psurf_core import study  # noqa: E402
from psurf_core.scene_io import load_scene  # noqa: E402

GROUPS = {"single": {"paper": E._paper_single, "fast": E._fast_single},
          "multi": {"paper": E._paper_multi, "fast": E._fast_multi}}


def register(single: str, multi: str) -> str:
    """Register ``trial-SINGLE-MULTI`` (two groups) and return its name."""
    name = f"trial-{single}-{multi}"
    s, m = GROUPS["single"][single], GROUPS["multi"][multi]
    E.PRESETS[name] = E._preset(lambda kinds: [s(kinds) if s is E._fast_single else s(), m()])
    return name


def main(argv=None) -> int:
    """Command line (module docstring)."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("case", choices=[c[0] for c in vs_mitsuba.CASES])
    ap.add_argument("--single", choices=("paper", "fast"), default="paper")
    ap.add_argument("--multi", choices=("paper", "fast"), default="fast")
    ap.add_argument("--against", default="paper-full,fast-full")
    ap.add_argument("--time", type=float, default=20.0, help="CPU seconds per run")
    ap.add_argument("--runs", type=int, default=2)
    ap.add_argument("--work", default="out/vs_mitsuba")
    ap.add_argument("--ref-time", type=float, default=300.0)
    args = ap.parse_args(argv)
    case, scene_path, kmin, kmax = next(c for c in vs_mitsuba.CASES if c[0] == args.case)
    ref = mr.composite_path(args.work, case, "composite", kmin, kmax, args.ref_time)
    if not ref.exists():
        ap.error(f"no reference {ref}: run vs_mitsuba.py --refs-only --cases {case} first")
    specs = [*args.against.split(","), register(args.single, args.multi)]
    scene = load_scene(vs_mitsuba.ROOT / scene_path).with_scatter(kmin, kmax)
    c = study.compare(scene, specs, args.time, runs=args.runs, clock="cpu", reference=str(ref),
                      photons="auto")
    print(f"# python benchmarks/mitsuba_preset_trial.py {' '.join(sys.argv[1:])}")
    print(f"# {case}: K={kmin}..{kmax}, {args.time:g} CPU s x {args.runs} runs, reference "
          f"{ref} (floor {c['reference']['relmse_floor']:.3g})")
    for r in c["results"]:
        print(f"{r['estimator']:24s} photons {r['photons_per_pass']:5d} passes "
              f"{r['passes']:7.1f} Var {r['ratio']:.3g}x relVar {r['relmse_from_variance']:.3g} "
              f"({r['relmse_from_variance_ratio']:.3g}x) relMSE {r['relmse']:.3g} "
              f"({r['relmse_ratio']:.3g}x)", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
