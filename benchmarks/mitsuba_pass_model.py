"""Where psurf loses to Mitsuba: both pass models on a case of ``vs_mitsuba.py``, in CPU time.

psurf (``benchmarks/pass_model.py``): a pass of ``N`` photons costs ``c0 + c1 N`` CPU seconds
and has per-pixel variance ``Vj + Vp / N`` (``Vj`` the pixel jitter's, ``Vp`` one photon's).
At the best pass size ``N* = sqrt(Vp c0 / (Vj c1))`` the variance of the final image times the
CPU seconds spent on it is

    ``psurf: (sqrt(Vj c0) + sqrt(Vp c1))^2``

so the per-pass fixed cost and the pixel jitter enter only as their product ``Vj c0``, the
photons only as ``Vp c1``; with ``c0 -> 0`` or ``Vj -> 0`` it tends to ``Vp c1``.
Mitsuba: a pass of ``s`` samples per pixel costs ``m0 + m1 s`` and has variance ``Vm / s``
(every sample a new path: the pixel jitter is inside ``Vm``), so

    ``Mitsuba: Vm (m0 / s + m1) -> Vm m1``.

Every variance here is a relVar (the per-pixel variance divided by ``R^2 + eps mean(R)^2``, R
the case's reference, averaged: ``psurf_core.metrics.var_relmse``), so the ratio of the two
products is the relMSE ratio at equal CPU time without the reference's floor. One thread
each (numba and Dr.Jit), so CPU time is one core's.

With ``--time S`` both also render ``S`` CPU seconds ``--runs`` times (psurf:
``psurf_core.study.compare`` with ``clock="cpu"``, ``photons="auto"``; Mitsuba: a pass count
timed in CPU seconds) and are scored against the reference (relMSE, relVar).

Usage::

    python benchmarks/mitsuba_pass_model.py CASE [--spec fast-single] [--passes 16]
        [--spp 1[,K...]] [--mitsuba-spp 4,32] [--time 20 --runs 2]
        [--reference FILE.npz | --work out/vs_mitsuba --ref-time 300]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numba
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import mitsuba_renders as mr  # noqa: E402
import mitsuba_scene as ms  # noqa: E402
import vs_mitsuba  # noqa: E402

from psurf_core import render as render_mod  # noqa: E402
from psurf_core import study  # noqa: E402
from psurf_core.accumulate import Welford  # noqa: E402
from psurf_core.camera import camera_rays  # noqa: E402
from psurf_core.estimators import parse_estimator  # noqa: E402
from psurf_core.metrics import relmse, var_relmse  # noqa: E402
from psurf_core.render import RenderSettings, render_pass, warm_up  # noqa: E402
from psurf_core.scene_io import load_scene  # noqa: E402

#: psurf's two pass sizes (photons), as benchmarks/pass_model.py.
SIZES = (256, 2048)


def _relvar(var: np.ndarray, ref: np.ndarray) -> float:
    return var_relmse(var, ref)


def psurf_passes(scene, est, photons, passes, jitter, spp, ref) -> tuple[float, float]:
    """(relVar of one pass, median CPU seconds a pass) of ``passes`` passes."""
    real = render_mod.camera_rays
    render_mod.camera_rays = lambda *a, **k: camera_rays(*a, jitter=jitter, **k)
    try:
        acc = Welford.empty(ref.shape)
        cpu = []
        for i in range(passes):
            a = time.process_time()
            img = render_pass(scene, est, i, 7, RenderSettings(photons=photons, spp=spp))
            cpu.append(time.process_time() - a)
            acc.add(img)
    finally:
        render_mod.camera_rays = real
    return _relvar(acc.variance, ref), float(np.median(cpu))


def psurf_model(scene, spec, passes, spp, ref) -> dict:
    """``c0, c1, Vj, Vp`` (relVar units), ``N*`` and ``var x CPU s`` at ``N*``."""
    est = parse_estimator(spec, scene)
    warm_up(scene, est, RenderSettings(photons=64))
    na, nb = SIZES
    va, ta = psurf_passes(scene, est, na, passes, False, spp, ref)
    vb, tb = psurf_passes(scene, est, nb, passes, False, spp, ref)
    vjb, tj = psurf_passes(scene, est, nb, passes, True, spp, ref)
    vp = (va * na + vb * nb) / 2
    c1 = max((tb - ta) / (nb - na), 1e-12)
    c0 = max(ta - c1 * na, 1e-4)
    vj = max(vjb - vb, 0.0)
    n_star = math.sqrt(vp * c0 / (vj * c1)) if vj > 0 else float("inf")
    return {"spec": spec, "spp": spp, "c0": c0, "c1": c1, "Vj": vj, "Vp": vp,
            "Vp_each": (va * na, vb * nb), "N*": n_star, "jittered_pass_cpu": tj,
            "jitter_term": vj * c0, "photon_term": vp * c1,
            "var_time": (math.sqrt(vj * c0) + math.sqrt(vp * c1)) ** 2}


def mitsuba_model(scene, spps, passes, ref) -> dict:
    """``m0, m1, Vm`` (relVar units) of Mitsuba on one Dr.Jit thread, CPU time."""
    var, cpu = [], []
    for s in spps:
        r = ms.MitsubaRenderer(scene, spp=s, threads=1)
        r.pass_image(seed=ms.pass_seed(5, 0, tag=3))  # compiles
        acc, t = Welford.empty(ref.shape), []
        for i in range(passes):
            a = time.process_time()
            img = r.pass_image(seed=ms.pass_seed(5, i + 1, tag=3))
            t.append(time.process_time() - a)
            acc.add(img)
        var.append(_relvar(acc.variance, ref) * s)
        cpu.append(float(np.median(t)))
    (sa, sb), (ta, tb) = spps, cpu
    m1 = max((tb - ta) / (sb - sa), 1e-12)
    m0 = max(ta - m1 * sa, 0.0)
    vm = float(np.mean(var))
    return {"m0": m0, "m1": m1, "Vm": vm, "Vm_each": tuple(var), "spp": tuple(spps),
            "var_time": vm * m1, "var_time_at": {s: vm * (m0 / s + m1) for s in spps}}


def equal_time(scene, specs, seconds, runs, ref_path, ref) -> dict:
    """Each side renders ``seconds`` CPU seconds ``runs`` times: mean relMSE, relVar, CPU s."""
    c = study.compare(scene, list(specs), seconds, runs=runs, clock="cpu", reference=ref_path,
                      photons="auto")
    out = {"floor": c["reference"]["relmse_floor"]}
    for row in c["results"]:
        out[row["estimator"]] = {"relmse": row["relmse"], "relvar": row["relmse_from_variance"],
                                 "photons": row["photons_per_pass"],
                                 "passes": row["passes_per_run"],
                                 "cpu_seconds": float(np.mean(row["cpu_seconds_per_run"]))}
    spp, n = mr.mitsuba_cpu_plan(scene, seconds, 1)
    mi = []
    for r in range(runs):
        rr = ms.MitsubaRenderer(scene, spp=spp, threads=1)
        a = time.process_time()
        m = rr.render(passes=n, seed=r, warmup=False)
        mi.append({"cpu_seconds": time.process_time() - a, "passes": m.passes,
                   "relmse": relmse(m.mean, ref),
                   "relvar": var_relmse(m.var / m.passes, ref)})
    out["mitsuba"] = {"relmse": float(np.mean([x["relmse"] for x in mi])),
                      "relvar": float(np.mean([x["relvar"] for x in mi])), "spp": spp,
                      "passes": [x["passes"] for x in mi],
                      "cpu_seconds": float(np.mean([x["cpu_seconds"] for x in mi]))}
    return out


def main(argv=None) -> int:
    """Command line (module docstring)."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("case", choices=[c[0] for c in vs_mitsuba.CASES])
    ap.add_argument("--spec", default=None,
                    help="psurf estimators, comma-separated (default: recommended())")
    ap.add_argument("--passes", type=int, default=16, help="passes per size and side")
    ap.add_argument("--spp", default="1", help="psurf camera rays per pixel per pass, e.g. 1,4")
    ap.add_argument("--mitsuba-spp", default="4,32", help="Mitsuba's two pass sizes")
    ap.add_argument("--time", type=float, default=None, help="also render S CPU s each side")
    ap.add_argument("--runs", type=int, default=2)
    ap.add_argument("--reference", default=None, help="reference .npz (default: the cached "
                    "sum of vs_mitsuba.py, --work and --ref-time)")
    ap.add_argument("--work", default="out/vs_mitsuba")
    ap.add_argument("--ref-time", type=float, default=300.0)
    ap.add_argument("--variant", default=None)
    args = ap.parse_args(argv)
    case, scene_path, kmin, kmax = next(c for c in vs_mitsuba.CASES if c[0] == args.case)
    specs = (args.spec or vs_mitsuba.recommended(kmin, kmax)).split(",")
    ref_path = args.reference or str(mr.composite_path(args.work, case, "composite", kmin,
                                                       kmax, args.ref_time))
    if not Path(ref_path).exists():
        ap.error(f"no reference {ref_path}: run vs_mitsuba.py --refs-only --cases {case} "
                 "first, or give --reference")
    ms.pick_variant(args.variant)
    numba.set_num_threads(1)
    scene = load_scene(vs_mitsuba.ROOT / scene_path).with_scatter(kmin, kmax)
    ref = mr.load_npz(Path(ref_path))["mean"]
    print(f"# python benchmarks/mitsuba_pass_model.py {' '.join(sys.argv[1:] or argv or [])}")
    print(f"# {case}: {scene_path} K={kmin}..{kmax}, reference {ref_path}; relVar units, "
          "CPU seconds, one thread each")
    mi = mitsuba_model(scene, [int(x) for x in args.mitsuba_spp.split(",")], args.passes, ref)
    print(f"mitsuba: Vm {mi['Vm']:.3g} (at {mi['spp']} spp: {mi['Vm_each'][0]:.3g}, "
          f"{mi['Vm_each'][1]:.3g}) m0 {mi['m0'] * 1e3:.1f} ms m1 {mi['m1'] * 1e3:.2f} ms/spp "
          f"var*t {mi['var_time']:.3g}", flush=True)
    for spec, spp in ((a, int(b)) for a in specs for b in args.spp.split(",")):
        p = psurf_model(scene, spec, args.passes, spp, ref)
        vt = p["var_time"]
        print(f"psurf {spec} spp {spp}: Vp {p['Vp']:.3g} ({p['Vp_each'][0]:.3g}, "
              f"{p['Vp_each'][1]:.3g}) Vj {p['Vj']:.3g} c0 {p['c0'] * 1e3:.1f} ms "
              f"c1 {p['c1'] * 1e6:.1f} us N* {p['N*']:.0f} var*t {vt:.3g} "
              f"ratio to Mitsuba {vt / mi['var_time']:.3g}", flush=True)
        print(f"  terms: Vj*c0 {p['jitter_term']:.3g}, Vp*c1 {p['photon_term']:.3g}; ratio "
              f"with c0/2 {_ratio_with(p, 0.5) / mi['var_time']:.3g}, c0/4 "
              f"{_ratio_with(p, 0.25) / mi['var_time']:.3g}, c0 or Vj -> 0 "
              f"{p['photon_term'] / mi['var_time']:.3g}", flush=True)
    if args.time:
        e = equal_time(scene, specs, args.time, args.runs, ref_path, ref)
        mt = e["mitsuba"]
        print(f"equal CPU time, {args.time:g} s x {args.runs} runs, reference floor "
              f"{e['floor']:.3g}: Mitsuba relMSE {mt['relmse']:.3g} relVar {mt['relvar']:.3g} "
              f"({mt['spp']} spp, passes {mt['passes']}, {mt['cpu_seconds']:.1f} CPU s)")
        for spec in specs:
            ps = e[spec]
            rt = ps["relvar"] * ps["cpu_seconds"] / (mt["relvar"] * mt["cpu_seconds"])
            print(f"  psurf {spec}: relMSE {ps['relmse']:.3g} relVar {ps['relvar']:.3g} "
                  f"({ps['photons']} photons, passes {ps['passes']}); ratios to Mitsuba: "
                  f"relMSE {ps['relmse'] / mt['relmse']:.3g}, relVar "
                  f"{ps['relvar'] / mt['relvar']:.3g} (x CPU s {rt:.3g})", flush=True)
    return 0


def _ratio_with(p: dict, c0_factor: float) -> float:
    """psurf's ``var x time`` at ``N*`` with ``c0`` scaled by ``c0_factor``."""
    return (math.sqrt(p["jitter_term"] * c0_factor) + math.sqrt(p["photon_term"])) ** 2


if __name__ == "__main__":
    sys.exit(main())
