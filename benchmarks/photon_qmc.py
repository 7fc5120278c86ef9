"""Would low-discrepancy photons pay? One photon's variance with the photons' random numbers
drawn as randomized quasi-Monte Carlo points instead of independently (an experiment; psurf's
tracer keeps independent photons).

Each photon of a batch takes one point of a ``D``-dimensional set (``D``: the light point
``u, v``, the emission direction's two numbers, the first flight, and per later segment the
roulette number, the phase cosine, the azimuth and the flight), its coordinates in the order
the tracer consumes them (``psurf_core.trace_numpy``; one area light only). Every point is
uniform on ``[0, 1)^D``, so every photon, and every pass, stays unbiased; only the photons'
joint distribution within a batch changes:

* ``iid``: independent numbers (the tracer's distribution, from another generator);
* ``kron``: the Kronecker (R_D) sequence ``frac(j alpha + shift)``, one uniform shift a batch;
* ``sobol``: scrambled Sobol points (``scipy.stats.qmc``);
* ``lhs``: each dimension stratified independently (Latin hypercube).

Per estimator it prints ``Vp``, one photon's variance (mean per-pixel variance of passes
through the pixel centres times the photons a pass, as ``benchmarks/ablation.py``). An
estimator whose ``Vp`` falls most gains most; at equal time only the ratio between two
estimators' gains moves a comparison.

Usage::

    python benchmarks/photon_qmc.py MODE SCENE.toml KMIN KMAX "SPEC:PASSES;..." [--photons N]
        [--seed S] [--resolution W,H]
    python benchmarks/photon_qmc.py kron scenes/study_medium.toml 2 3 "fast-multi:200;planes:600"

Not a test; ``planes``' ``Vp`` is heavy-tailed (repeat with more passes before trusting a
difference of a few tens of percent).
"""

from __future__ import annotations

import argparse
import os
import sys
from dataclasses import replace

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from scipy.stats import qmc  # noqa: E402

import psurf_core.render as render_mod  # noqa: E402
from benchmarks.pass_model import passes_of  # noqa: E402
from psurf_core import trace_numpy as tn  # noqa: E402
from psurf_core.estimators import parse_estimator  # noqa: E402
from psurf_core.scene import AreaLight  # noqa: E402
from psurf_core.scene_io import load_scene  # noqa: E402
from psurf_core.trace_emit import cosine_direction, direction_about, parallelogram_point  # noqa: E402
from psurf_core.variates import cos_sin_turn  # noqa: E402

MODES = ("iid", "kron", "sobol", "lhs")


def golden(d: int) -> float:
    """The generalized golden ratio of dimension ``d``: the root > 1 of ``x^(d+1) = x + 1``."""
    x = 2.0
    for _ in range(200):
        x = (1.0 + x) ** (1.0 / (d + 1))
    return x


def points(mode: str, n: int, d: int, rng: np.random.Generator) -> np.ndarray:
    """(n, d) points in ``[0, 1)^d``, each uniform (module docstring)."""
    if mode == "iid":
        return rng.random((n, d))
    if mode == "kron":
        alpha = (1.0 / golden(d)) ** np.arange(1, d + 1) % 1.0
        return (np.arange(n)[:, None] * alpha + rng.random(d)) % 1.0
    if mode == "sobol":
        return qmc.Sobol(d, scramble=True, seed=rng).random(n)
    if mode == "lhs":
        return (np.argsort(rng.random((d, n)), axis=1).T + rng.random((n, d))) / n
    raise ValueError(mode)


def tracer(mode: str):
    """``trace(scene, n, rng, blockers=...)`` drawing photon ``j``'s numbers from point ``j``
    of ``mode``'s set (the numpy reference's stages, one area light)."""

    def trace(scene, n, rng, blockers=None, max_depth=None, reference=False):
        med = scene.medium
        box = (np.asarray(med.bounds_min, float), np.asarray(med.bounds_max, float))
        depth = tn.trace_depth(scene) if max_depth is None else int(max_depth)
        u = points(mode, n, 5 + 4 * (depth - 1), rng)
        lt = scene.lights[0]
        nl = np.broadcast_to(lt.normal, (n, 3))
        e = dict(light=np.zeros(n, np.intp), light_pmf=np.full(n, scene.light_pmf[0]),
                 light_uv=u[:, :2].copy(), tri=np.full(n, -1, np.int64),
                 light_normal=np.array(nl),
                 x0=parallelogram_point(lt.corner, lt.edge_u, lt.edge_v, u[:, :2]),
                 w1=cosine_direction(nl, u[:, 2], *cos_sin_turn(u[:, 3])),
                 beta=np.tile(lt.power_rgb / scene.light_pmf[0], (n, 1)))
        photon, x, w, beta = np.arange(n), e["x0"], e["w1"], e["beta"]
        oks, steps, col = [np.ones(n, bool)], [], 5
        for j in range(1, depth + 1):
            if j > 1:
                q = tn.roulette_survival(scene, j - 1)
                keep = tn.survives(oks[max(j - tn.LOOKBACK, 0)][photon],
                                   u[photon, col] if q < 1.0 else None, q)
                photon, x, w = photon[keep], x[keep], w[keep]
                beta = tn.scattered_weight(beta[keep], q, med.albedo)
                w = direction_about(w, tn.phase_cosine(med.phase.g, u[photon, col + 1]),
                                    *cos_sin_turn(u[photon, col + 2]))
                t = tn.free_flight(u[photon, col + 3], med.sigma_t)
                col += 4
            else:
                t = tn.free_flight(u[:, 4], med.sigma_t)
            s, ok = tn.step(photon, x, w, beta, t, oks[-1], box, blockers)
            steps.append(s)
            oks.append(ok)
            x = s.x_end
            if photon.size == 0:
                break
        return tn.assemble(e, steps, oks)

    return trace


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("mode", choices=MODES)
    ap.add_argument("scene")
    ap.add_argument("kmin", type=int)
    ap.add_argument("kmax", type=int)
    ap.add_argument("specs", help='"SPEC:PASSES;SPEC:PASSES"')
    ap.add_argument("--photons", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--resolution", default=None, metavar="W,H")
    args = ap.parse_args(argv)
    scene = load_scene(args.scene).with_scatter(args.kmin, args.kmax)
    if args.resolution:
        w, h = (int(v) for v in args.resolution.split(","))
        scene = replace(scene, camera=replace(scene.camera, width=w, height=h))
    if len(scene.lights) != 1 or not isinstance(scene.lights[0], AreaLight):
        ap.error(f"{args.scene}: one area light only (this experiment's emission)")
    render_mod.trace = tracer(args.mode)
    for item in args.specs.split(";"):
        spec, passes = item.rsplit(":", 1)
        v, c = passes_of(scene, parse_estimator(spec, scene), args.photons, int(passes), False,
                         args.seed)
        print(f"{args.mode:6s} {spec:14s} {passes:>5} passes of {args.photons}: "
              f"Vp {v * args.photons:.4e}, {c * 1e3:.1f} CPU ms a pass", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
