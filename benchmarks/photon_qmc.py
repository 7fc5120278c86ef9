"""Would low-discrepancy photons pay? One photon's variance with the photons' random numbers
drawn from several point sets (``psurf_core.photon_sampler`` offers ``independent`` and
``sobol``; this tries two more).

Each photon of a batch takes one point of a ``D``-dimensional set, each stage of Trace taking
the set's next dimensions (:class:`psurf_core.photon_sampler.SobolDraws`' layout, the
compiled tracer, any scene). Every point is uniform on ``[0, 1)^D``, so every photon, and
every pass, stays unbiased; only the photons' joint distribution within a batch changes:

* ``independent``: the tracer's own draws (``--photon-sampler independent``);
* ``sobol``: scrambled Sobol points (``--photon-sampler sobol``);
* ``kron``: the Kronecker (R_D) sequence ``frac(j alpha + shift)``, one uniform shift a batch;
* ``lhs``: each dimension stratified independently (Latin hypercube).

Per estimator it prints ``Vp``, one photon's variance (mean per-pixel variance of passes
through the pixel centres times the photons a pass, as ``benchmarks/ablation.py``). At equal
time only the ratio between two estimators' gains moves a comparison.

Usage::

    python benchmarks/photon_qmc.py MODE SCENE.toml KMIN KMAX "SPEC:PASSES;..." [--photons N]
        [--seed S] [--resolution W,H]
    python benchmarks/photon_qmc.py sobol scenes/study_medium.toml 2 3 "fast-multi:400;planes:2500"

Not a test; ``planes``' ``Vp`` is heavy-tailed (repeat with more passes and other seeds
before trusting a difference of a few tens of percent).
"""

from __future__ import annotations

import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import psurf_core.render as render_mod  # noqa: E402
from benchmarks.pass_model import passes_of  # noqa: E402
from benchmarks.scene_args import add_scene_args, scene_of  # noqa: E402
from psurf_core.estimators import parse_estimator  # noqa: E402
from psurf_core.photon_sampler import (  # noqa: E402
    PHOTON_SAMPLERS,
    SobolDraws,
    batch_draws,
    photon_dimensions,
)

MODES = ("independent", "sobol", "kron", "lhs")


def golden(d: int) -> float:
    """The generalized golden ratio of dimension ``d``: the root > 1 of ``x^(d+1) = x + 1``."""
    x = 2.0
    for _ in range(200):
        x = (1.0 + x) ** (1.0 / (d + 1))
    return x


class PointDraws(SobolDraws):
    """:class:`SobolDraws` with another point set (``kron`` or ``lhs``): the same layout."""

    def __init__(self, mode: str, rng: np.random.Generator, n: int, dims: int):
        self.rng, self.n, self.dims, self.next = rng, int(n), int(dims), 0
        if mode == "kron":
            alpha = (1.0 / golden(dims)) ** np.arange(1, dims + 1) % 1.0
            self.points = (np.arange(n)[:, None] * alpha + rng.random(dims)) % 1.0
        else:
            self.points = (np.argsort(rng.random((dims, n)), axis=1).T
                           + rng.random((n, dims))) / n


def draws_of(mode: str):
    """``render.batch_draws`` drawing every batch from ``mode``'s set."""

    def draws(sampler, rng, scene, n, depth):
        if mode in PHOTON_SAMPLERS:
            return batch_draws(mode, rng, scene, n, depth)
        return PointDraws(mode, rng, n, photon_dimensions(scene, depth))

    return draws


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("mode", choices=MODES)
    add_scene_args(ap)
    ap.add_argument("specs", help='"SPEC:PASSES;SPEC:PASSES"')
    ap.add_argument("--photons", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=7)
    args = ap.parse_args(argv)
    scene = scene_of(args)
    render_mod.batch_draws = draws_of(args.mode)
    for item in args.specs.split(";"):
        spec, passes = item.rsplit(":", 1)
        v, c = passes_of(scene, parse_estimator(spec, scene), args.photons, int(passes), False,
                         args.seed)
        print(f"{args.mode:11s} {spec:14s} {passes:>5} passes of {args.photons}: "
              f"Vp {v * args.photons:.4e}, {c * 1e3:.1f} CPU ms a pass", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
