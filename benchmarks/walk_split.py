"""Where one technique's walk goes: screen spans, candidate counts, the compiled walker and the
image addition (compact rows or the pieces' own images), per pass (wall clock), with the hits
per second ``make bench`` reports. (Hull and cloud footprints count their candidates as their
spans are written, ``kernels.spans.counted_spans``: inside ``spans`` here; the candidate
counts are ``fused.spans_before``'s on binning's rectangles alone.)

Usage::

    python benchmarks/walk_split.py scenes/area.toml planes 5000 [20]
"""

import sys
import time

import numpy as np

from psurf_core.camera import camera_rays
from psurf_core.estimators import parse_estimator
from psurf_core.geometry import blockers_of
from psurf_core.kernels import fused as kf
from psurf_core.render import RenderSettings, kernel_radius, pass_generators
from psurf_core.scene_io import load_scene
from psurf_core.techniques.base import PassContext
from psurf_core.trace import trace

scene = load_scene(sys.argv[1])
spec = sys.argv[2]
n = int(sys.argv[3])
est = parse_estimator(spec, scene)
st = RenderSettings(photons=n)
bl = blockers_of(scene)
T = {}


def wrap(obj, name, key):
    f = getattr(obj, name)

    def g(*a, **k):
        t = time.perf_counter()
        try:
            return f(*a, **k)
        finally:
            T[key] = T.get(key, 0) + time.perf_counter() - t

    setattr(obj, name, g)


wrap(kf._Run, "spans", "spans")
wrap(kf._Run, "walk_chunk", "walk_chunk")
wrap(kf, "spans_before", "spans_before")
wrap(kf, "accumulate", "accumulate")
wrap(kf, "add_images", "add_images")
tech = est.sets[0][0][0]


def one(seed):
    ray_rng, ss = pass_generators(seed, 0)
    rays = camera_rays(scene, 1, ray_rng, blockers=bl)
    paths = trace(scene, n, np.random.default_rng(ss), blockers=bl)
    ctx = PassContext(scene, bl, kernel_radius(tech, scene, st, 0), 0, st.max_pairs)
    t = time.perf_counter()
    prims = tech.create(paths, ctx)
    tc = time.perf_counter() - t
    out = np.zeros((len(rays), 3))
    stats = {}
    t = time.perf_counter()
    list(kf.fused_pass(tech, prims, paths, rays, ctx, None, emit=False, out=out, stats=stats))
    return tc, time.perf_counter() - t, stats["hits"], stats["candidates"]


for s in range(3):
    one(100 + s)
T.clear()
W = []
C = []
H = 0
R = int(sys.argv[4]) if len(sys.argv) > 4 else 20
N = 0
for s in range(R):
    tc, tw, h, nc = one(s)
    W.append(tw)
    C.append(tc)
    H += h
    N += nc
print(f"{spec} {n} photons: hits/pass {H / R:.0f}, walk {1e3 * np.median(W):.2f} ms median"
      f" ({1e3 * np.mean(W):.2f} mean), create {1e3 * np.median(C):.2f} ms;"
      f" hits/s {H / sum(W):.3g}; candidate pairs/pass {N / R:.0f} ({H / N:.2f} hit a pair)")
for k, v in T.items():
    print(f"  {k}: {1e3 * v / R:.2f} ms/pass")
