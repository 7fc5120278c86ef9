"""Why a photon cone's candidate pairs miss: each candidate ray-cone pair of the compiled
path's screen spans, classified by how far its better root got.

One pass's photons (pass 0 of ``--seed``, as ``render_pass`` draws them) make the cones; the
spans are ``kernels.spans.hull_spans`` of their footprint clouds (the walker's candidates);
``--sample`` of the pairs are drawn at random and each root is tested as the walker tests it,
in this order: a real root, on the photon's nappe, within ``T1`` (short cones), inside the
ray's medium interval ``(s_min, s_max)``, not grazing. It prints the share of pairs with a hit,
the share of misses by the furthest test a root passed, and the share of pairs whose ray
segment inside the medium meets the footprint solid at all (the per-ray bound of any
footprint clipped to the box; every hit must be among them, checked).

Usage::

    python benchmarks/cone_misses.py SCENE.toml KMIN KMAX [--spec cone-short] [--photons 900]
        [--resolution 256,192] [--sample 300000] [--seed 0]
    python benchmarks/cone_misses.py scenes/study_medium.toml 2 3 --resolution 256,192

Not a test; numpy, a few seconds.
"""

from __future__ import annotations

import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from benchmarks.scene_args import add_scene_args, scene_of  # noqa: E402
from psurf_core.camera import camera_rays  # noqa: E402
from psurf_core.estimators import parse_estimator  # noqa: E402
from psurf_core.geometry import blockers_of  # noqa: E402
from psurf_core.kernels.spans import hull_spans  # noqa: E402
from psurf_core.render import RenderSettings, kernel_radius, pass_generators  # noqa: E402
from psurf_core.techniques import cones  # noqa: E402
from psurf_core.techniques.base import PassContext  # noqa: E402
from psurf_core.trace import trace  # noqa: E402

REASONS = ("hit", "no real root", "mirror nappe", "t1 >= T1", "outside the ray's interval",
           "grazing")


def candidates(scene, tech, photons, seed):
    """The cones of one pass, the camera rays, the candidate pairs ``(prim, pixel)``, and
    the pass's photons and context (what the walker takes)."""
    blockers = blockers_of(scene)
    st = RenderSettings(photons=photons)
    ray_rng, ss = pass_generators(seed, 0)
    rays = camera_rays(scene, 1, ray_rng, blockers=blockers)
    paths = trace(scene, photons, np.random.default_rng(ss), blockers=blockers)
    ctx = PassContext(scene, blockers, kernel_radius(tech, scene, st, 0), 0, st.max_pairs)
    prims = tech.create(paths, ctx)
    box = (scene.medium.bounds_min, scene.medium.bounds_max)
    prim, row, c0, c1 = hull_spans(scene.camera, prims.lo, prims.hi, prims.cloud, box,
                                   cloud=True)
    n = c1 - c0
    first = np.repeat(np.cumsum(n) - n, n)
    col = np.repeat(c0, n) + (np.arange(n.sum()) - first)
    pix = np.repeat(row, n) * scene.camera.width + col
    return prims, rays, np.repeat(prim, n), pix, paths, ctx


def classify(prims, rays, p, pix, short):
    """(N, 2) reason codes (:data:`REASONS`) of both roots of pairs ``(p, pix)``."""
    G = prims.data[p]
    o, psi = rays.o[pix], rays.d[pix]
    r = cones.roots(G, o, psi)
    why = np.zeros((p.size, 2), int)
    for j in range(2):
        s = r[j]
        real = np.isfinite(s)
        ok, hit = cones.accept(G, o, psi, np.where(real, s, 0.0), short)
        nappe = (hit.t1 > 0) & (np.sum(hit.w1 * G.w2, axis=1) * G.c1 > 0)
        within = ~np.asarray(short) | (hit.t1 < G.T1)
        inray = real & (s > rays.s_min[pix]) & (s < rays.s_max[pix])
        why[:, j] = np.select([~real, ~nappe, ~within, ~inray, ~ok], [1, 2, 3, 4, 5], 0)
    return why


def meets_solid(cloud, o, psi, s_min, s_max):
    """(N,) bool: the ray segment ``o + s psi``, ``s_min < s < s_max``, meets the pyramid of
    ``cloud`` (apex, then a ring)."""
    apex, ring = cloud[:, 0], cloud[:, 1:]
    centre = cloud.mean(axis=1)
    lo, hi = s_min.copy(), s_max.copy()
    v = ring.shape[1]
    planes = [(np.cross(ring[:, k] - apex, ring[:, (k + 1) % v] - apex), apex)
              for k in range(v)]
    planes.append((np.cross(ring[:, 1] - ring[:, 0], ring[:, 2] - ring[:, 0]), ring[:, 0]))
    for normal, point in planes:
        off = np.sum(normal * point, axis=1)
        sign = np.where(np.sum(normal * centre, axis=1) >= off, 1.0, -1.0)
        a = sign * (np.sum(normal * o, axis=1) - off)
        b = sign * np.sum(normal * psi, axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = -a / b
        lo = np.where(b > 0, np.maximum(lo, t), lo)
        hi = np.where(b < 0, np.minimum(hi, t), hi)
        hi = np.where((b == 0) & (a < 0), -np.inf, hi)
    return lo <= hi


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_scene_args(ap)
    ap.add_argument("--spec", default="cone-short", choices=("cone", "cone-short"))
    ap.add_argument("--photons", type=int, default=900)
    ap.add_argument("--sample", type=int, default=300_000)
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    scene = scene_of(a)
    tech = parse_estimator(a.spec, scene).sets[0][0][0]
    prims, rays, p, pix, _, _ = candidates(scene, tech, a.photons, a.seed)
    print(f"# python benchmarks/cone_misses.py {' '.join(sys.argv[1:])}")
    print(f"{len(prims)} cones, {p.size} candidate pairs")
    k = np.random.default_rng(1).choice(p.size, min(a.sample, p.size), replace=False)
    p, pix = p[k], pix[k]
    why = classify(prims, rays, p, pix, tech.short)
    hit = (why == 0).any(axis=1)
    print(f"pairs with a hit: {hit.mean():.3f}")
    best = np.where(why == 0, 99, why).max(axis=1)[~hit]
    for code in range(1, len(REASONS)):
        print(f"  misses, furthest test failed {REASONS[code]!r}: {np.mean(best == code):.3f}")
    meets = meets_solid(prims.cloud[p], rays.o[pix], rays.d[pix], rays.s_min[pix],
                        rays.s_max[pix])
    assert not np.any(hit & ~meets), "a hit outside its footprint solid"
    print(f"pairs whose ray inside the medium meets the footprint solid: {meets.mean():.3f} "
          f"(of those, with a hit: {hit[meets].mean():.3f})")


if __name__ == "__main__":
    main()
