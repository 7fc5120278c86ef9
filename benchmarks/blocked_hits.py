"""Hits that cost a walk but add nothing: per technique of a spec, its hits, those not blocked
("valued"), and the share of its hits whose shadow statuses block them (a rebuilt vertex
outside the medium box, or a segment through a blocker or the light), slot by slot.

One pass's photons (pass 0 of ``--seed``, as ``render_pass`` draws them) make each member's
primitives; the compiled walk (``kernels.fused.fused_pass`` with ``emit``) gives every hit with
its shadow statuses (``kernels.shadow``: CLEAR, BLOCKED; slot 0 the segment to the first rebuilt
vertex, slot 1 the next, slot 2 the last one to ``x0``). A blocked hit skips its contribution and
MIS weight, but its roots, acceptance and status tests were paid; a footprint that leaves out
the pixels where hits cannot count (``techniques.bounds``) removes them. ``--outside`` also
counts, for photon planes and light strips, the hits whose rebuilt vertices leave the box.

Usage::

    python benchmarks/blocked_hits.py SCENE.toml KMIN KMAX SPEC [--photons 900]
        [--resolution 256,192] [--seed 0] [--outside]
    python benchmarks/blocked_hits.py scenes/study_medium.toml 2 3 fast-multi \
        --resolution 256,192 --outside

Not a test; a few seconds.
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
from psurf_core.geometry import blockers_of, inside_box  # noqa: E402
from psurf_core.kernels import fused  # noqa: E402
from psurf_core.kernels.shadow import BLOCKED  # noqa: E402
from psurf_core.render import RenderSettings, kernel_radius, pass_generators  # noqa: E402
from psurf_core.techniques import light_planes, planes  # noqa: E402
from psurf_core.techniques.base import PassContext  # noqa: E402
from psurf_core.trace import trace  # noqa: E402


def walk_statuses(tech, prims, paths, rays, ctx, mis):
    """``(hits, (H, 3) statuses, (H, 3) values)`` of one technique's compiled walk."""
    hits, stats, vals = [], [], []
    real = fused._Run.finish

    def finish(self, res, out):  # the full rows' statuses, which Hits does not keep
        starts, ends = res["full_ranges"]
        stats.append(np.concatenate([res["full"][-1][s:e] for s, e in
                                     zip(starts, ends, strict=True)]))
        yield from real(self, res, out)

    fused._Run.finish = finish
    try:
        for h, v, _ in fused.fused_pass(tech, prims, paths, rays, ctx, mis, emit=True):
            hits.append(h)
            vals.append(v)
    finally:
        fused._Run.finish = real
    if not hits:
        return None
    return hits, np.concatenate(stats), np.concatenate(vals)


def outside(tech, prims, hits, scene):
    """(H,) bool: the hit's rebuilt vertices leave the box (photon planes: ``x1*``; light
    strips: ``x_{K-1}*`` or ``x1*``), or None for other families."""
    med = scene.medium
    G = prims.data[hits.prim]
    if isinstance(tech, light_planes.LightPlane):
        _, xm, x1 = light_planes.vertices(G, hits.data)
        return ~(inside_box(xm, med.bounds_min, med.bounds_max)
                 & inside_box(x1, med.bounds_min, med.bounds_max))
    if isinstance(tech, planes.PhotonPlane):
        x1 = G.x2 + hits.data.t2[:, None] * G.w2
        return ~inside_box(x1, med.bounds_min, med.bounds_max)
    return None


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_scene_args(ap)
    ap.add_argument("spec")
    ap.add_argument("--photons", type=int, default=900)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--outside", action="store_true")
    a = ap.parse_args(argv)
    scene = scene_of(a)
    est = parse_estimator(a.spec, scene)
    st = RenderSettings(photons=a.photons)
    blockers = blockers_of(scene)
    ray_rng, photon_ss = pass_generators(a.seed, 0)
    rays = camera_rays(scene, st.spp, ray_rng, blockers=blockers)
    paths = trace(scene, a.photons, np.random.default_rng(photon_ss.spawn(1)[0]),
                  blockers=blockers)
    print(f"# python benchmarks/blocked_hits.py {' '.join(sys.argv[1:] if argv is None else argv)}")
    print(f"{'technique':<20} {'hits':>9} {'valued':>9} {'blocked':>8} {'slot 0':>7} "
          f"{'slot 1':>7} {'slot 2':>7}" + (f" {'outside':>8}" if a.outside else ""))
    for group, full in est.sets:
        mis = fused.MisSet(group, full, est.weighting) if len(group) > 1 else None
        for tech in group:
            ctx = PassContext(scene, blockers, kernel_radius(tech, scene, st, 0), 0,
                              st.max_pairs)
            prims = tech.create(paths, ctx)
            got = walk_statuses(tech, prims, paths, rays, ctx, mis)
            if got is None:
                print(f"{tech.name:<20} no compiled walk or no hits")
                continue
            hits, status, _ = got
            n = len(status)
            blocked = status == BLOCKED
            line = (f"{tech.name:<20} {n:>9} {int((~blocked.any(axis=1)).sum()):>9} "
                    f"{blocked.any(axis=1).mean():>8.3f} "
                    + " ".join(f"{blocked[:, c].mean():>7.3f}" for c in range(3)))
            if a.outside:
                out = [outside(tech, prims, h, scene) for h in hits]
                line += ("" if out[0] is None else
                         f" {np.concatenate(out).mean():>8.3f}")
            print(line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
