"""Where in the image an estimator's relMSE noise sits: one photon's variance over
``R^2 + EPS mean(R)^2`` (the relMSE's weight), summed over the pixels of each decile of the
reference's brightness, for estimators side by side.

A relMSE weighs dim pixels most; an estimator can win on the plain variance (bright pixels)
and less on relMSE. Per estimator and decile this prints the decile's share of the
estimator's total and, against the first estimator, the per-photon ratio in that decile.
Passes through the pixel centres (the photons' variance alone), the same seed for every
estimator (the same photons where their tracers agree).

Usage::

    python benchmarks/relvar_deciles.py SCENE.toml KMIN KMAX REF.npz "SPEC:PHOTONS:PASSES;..."
        [--resolution W,H] [--photon-sampler sobol] [--seed 77]
    python benchmarks/relvar_deciles.py scenes/study_medium.toml 2 3 \\
        out/study/refs256b/medium_k23.npz "planes:3000:150;fast-multi:1000:60" \\
        --resolution 256,192 --photon-sampler sobol

Not a test: a heavy-tailed estimator's deciles move from seed to seed.
"""

from __future__ import annotations

import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from benchmarks.pass_model import pass_variance, reference_image  # noqa: E402
from benchmarks.scene_args import add_scene_args, scene_of  # noqa: E402
from psurf_core.estimators import parse_estimator  # noqa: E402
from psurf_core.metrics import var_relmse_map  # noqa: E402
from psurf_core.photon_sampler import PHOTON_SAMPLERS  # noqa: E402
from psurf_core.render import RenderSettings, warm_up  # noqa: E402

DECILES = 10


def decile_masks(ref: np.ndarray) -> tuple[list[np.ndarray], np.ndarray]:
    """(H, W) masks of the pixels of each brightness decile of ``ref`` (channel mean) among
    those it lights, and the deciles' edges."""
    lum = ref.mean(axis=-1)
    lit = lum > 0
    edges = np.quantile(lum[lit], np.linspace(0.0, 1.0, DECILES + 1))
    return [lit & (lum >= lo) & ((lum < hi) if d < DECILES - 1 else (lum <= hi))
            for d, (lo, hi) in enumerate(zip(edges[:-1], edges[1:], strict=True))], edges


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_scene_args(ap)
    ap.add_argument("reference", help="the reference .npz (the scene's size)")
    ap.add_argument("specs", help='"SPEC:PHOTONS:PASSES;..." (the first is the baseline)')
    ap.add_argument("--photon-sampler", choices=PHOTON_SAMPLERS, default="independent")
    ap.add_argument("--seed", type=int, default=77)
    args = ap.parse_args(argv)
    scene = scene_of(args)
    ref = reference_image(args.reference, scene)
    masks, edges = decile_masks(ref)
    cmd = " ".join(sys.argv[1:] if argv is None else argv)
    print(f"# python benchmarks/relvar_deciles.py {cmd}")
    maps = {}
    for item in args.specs.split(";"):
        spec, photons, passes = item.rsplit(":", 2)
        est = parse_estimator(spec, scene)
        warm_up(scene, est, RenderSettings(photons=64))
        var, _ = pass_variance(scene, est, int(photons), int(passes), False, args.seed,
                               RenderSettings(photon_sampler=args.photon_sampler))
        maps[spec] = var_relmse_map(var, ref) * int(photons)
    names = list(maps)
    base = maps[names[0]]
    print(f"{'decile':>6} {'from':>9} " + " ".join(f"{'share ' + n:>18}" for n in names)
          + " " + " ".join(f"{n + ' / ' + names[0]:>24}" for n in names[1:]))
    for d, m in enumerate(masks):
        shares = [maps[n][m].sum() / maps[n].sum() for n in names]
        ratios = [maps[n][m].sum() / base[m].sum() for n in names[1:]]
        print(f"{d:>6} {edges[d]:9.3g} " + " ".join(f"{x:18.3f}" for x in shares) + " "
              + " ".join(f"{x:24.3f}" for x in ratios))
    print(f"{'all':>6} {'':>9} " + " ".join(f"{1.0:18.3f}" for _ in names) + " "
          + " ".join(f"{maps[n].sum() / base.sum():24.3f}" for n in names[1:]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
