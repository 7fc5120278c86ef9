"""Numerics: no estimator lets a NaN or an infinity reach a crafted hit, whatever the geometry.

Property-based (hypothesis, derandomized, fixed example counts) over every registered
technique and its ``-short`` variant: **crafted photons** (``PhotonPaths`` built directly)
against **crafted camera rays**, all ray x primitive pairs (a superset of what binning hands
out): grazing rays (edge-on to a photon plane, ``|n . psi| -> 0``, exactly and within
``1e-9 .. 1e-15``), rays through a photon vertex, rays along a photon segment, zero-length
and 1e-300 segments, segments far longer than the box, ``th -> 0`` and ``th -> pi`` between
consecutive segments (cones and disks), tiny flights (spheres of radius -> 0), emission
grazing an area/mesh light, lights on the box boundary and at its corners, media from
``st = 1e-6`` to ``1e4``, ``|g|`` up to ``1 - 1e-9``. Every per-hit contribution, hit
distance and MIS weight (all MIS-capable techniques in one balance-heuristic group) must be
finite, and so must the per-ray sums accumulated in float64. Whole traced passes are in
``test_numerics_traced.py``.

**Singular hits.** Where the math itself is singular (a photon plane seen edge-on,
``n . psi = 0``; a cone or disk at ``th = 0, pi``; a sphere of radius 0), the set of such
configurations has measure zero. The estimators drop a hit when its Jacobian is exactly
zero or so small that ``f / |n . psi|`` would overflow (``surface_common.NDP_MIN`` for the
photon surfaces, a non-finite ``1 / det`` for ``planes``, ``PARALLEL_SIN`` for beams);
dropping a measure-zero set changes no expectation, so the estimators stay unbiased, and
every hit that is kept is finite. Near-singular hits are *large* (that is the heavy tail of
ESTIMATORS.md section 5), never NaN. These tests pin exactly that: finite per hit, finite
per image.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from numerics_support import (  # noqa: F401 - fixed_constant_pool is an autouse fixture
    CRAFTED,
    DEPTH,
    MIS_NAMES,
    NAMES,
    build_scene,
    fixed_constant_pool,
    media,
    unit,
)

from psurf_core.camera import Rays, clip_rays
from psurf_core.geometry import blockers_of, inside_box, ray_box
from psurf_core.mis import mis_weights
from psurf_core.scene import Scene
from psurf_core.techniques import get_technique
from psurf_core.techniques.base import PassContext
from psurf_core.trace import PhotonPaths

# ----------------------------------------------------------------------------- strategies
#: Segment lengths: ordinary ones (two chances in three) or zero, denormal-small, tiny,
#: longer than the box, absurd.
_ordinary = st.floats(0.05, 1.2)
lengths = _ordinary | _ordinary | st.sampled_from([0.0, 1e-300, 1e-12, 1e-6, 2.5, 50.0, 1e8])

#: How a direction relates to the previous one (or the light's axis / normal at emission).
turns = st.sampled_from(["random", "same", "opposite", "eps", "eps-opposite", "to-camera",
                         "from-camera", "perp-camera", "tangent"])

photon = st.fixed_dictionaries({
    "light": st.integers(0, 2),
    "uv": st.tuples(st.sampled_from([0.0, 1.0, 0.5]) | st.floats(0.0, 1.0),
                    st.sampled_from([0.0, 1.0, 0.5]) | st.floats(0.0, 1.0)),
    "tri": st.integers(0, 1),
    "turns": st.lists(turns, min_size=DEPTH, max_size=DEPTH),
    "lengths": st.lists(lengths, min_size=DEPTH, max_size=DEPTH),
    "seeds": st.lists(st.floats(-1.0, 1.0), min_size=3 * DEPTH, max_size=3 * DEPTH),
    "eps": st.sampled_from([1e-9, 1e-12, 1e-15, 1e-300]),
    "alive": st.sampled_from([DEPTH, DEPTH, DEPTH - 1, 1]),
})



# ----------------------------------------------------------------------------- crafting
def _perp(v: np.ndarray, hint: np.ndarray) -> np.ndarray:
    p = np.cross(v, hint)
    if np.linalg.norm(p) < 1e-6:
        p = np.cross(v, [0.3, 0.9, 0.1])
    return unit(p)


def _direction(turn: str, prev: np.ndarray, x: np.ndarray, cam: np.ndarray, seed, eps: float,
               emit_normal: np.ndarray | None) -> np.ndarray:
    seed = np.asarray(seed, dtype=float)
    rnd = unit(seed + [1e-3, 2e-3, 3e-3]) if np.linalg.norm(seed) > 1e-3 else unit([1, 2, 3])
    to_cam = cam - x
    to_cam = unit(to_cam) if np.linalg.norm(to_cam) > 1e-9 else rnd
    if turn == "random":
        d = rnd
    elif turn == "same":
        d = prev
    elif turn == "opposite":
        d = -prev
    elif turn == "eps":
        d = unit(prev + eps * _perp(prev, rnd))
    elif turn == "eps-opposite":
        d = unit(-prev + eps * _perp(prev, rnd))
    elif turn == "to-camera":
        d = to_cam
    elif turn == "from-camera":
        d = -to_cam
    elif turn == "perp-camera":
        d = _perp(to_cam, rnd)
    else:  # tangent to the previous direction (the light's surface at emission)
        d = _perp(prev, rnd)
    if emit_normal is not None:
        # One-sided emitters: the photon leaves on the front side (cos >= 0), possibly 0.
        c = float(d @ emit_normal)
        if c < 0.0:
            d = unit(d - 2.0 * c * emit_normal)
    return unit(d)


def craft_paths(scene: Scene, specs: list) -> PhotonPaths:
    """``PhotonPaths`` from photon specs, laid out exactly as ``trace`` lays them out."""
    blockers = blockers_of(scene)
    med = scene.medium
    pmf = scene.light_pmf
    cam = scene.camera.position
    n = len(specs)
    x = np.zeros((n, DEPTH + 1, 3))
    w = np.zeros((n, DEPTH, 3))
    t = np.zeros((n, DEPTH))
    beta = np.zeros((n, DEPTH, 3))
    alive = np.zeros((n, DEPTH), dtype=bool)
    light = np.zeros(n, dtype=np.int64)
    uv = np.zeros((n, 2))
    tri = np.full(n, -1, dtype=np.int64)
    normal = np.zeros((n, 3))
    for p, sp in enumerate(specs):
        li = sp["light"]
        lt = scene.lights[li]
        light[p] = li
        u, v = sp["uv"]
        if lt.kind == "point":
            x0, nrm, front = lt.position, lt.axis, None
        elif lt.kind == "area":
            uv[p] = (u, v)
            x0 = lt.corner + u * lt.edge_u + v * lt.edge_v
            nrm = front = lt.normal
        else:
            if u + v > 1.0:
                u, v = 1.0 - v, 1.0 - u
            k = sp["tri"]
            tri[p], uv[p] = k, (u, v)
            tr = lt.triangles[k]
            x0 = tr[0] + u * (tr[1] - tr[0]) + v * (tr[2] - tr[0])
            nrm = front = lt.normals[k]
        normal[p] = nrm
        x[p, 0] = x0
        prev = nrm
        b = lt.power_rgb / pmf[li]
        for j in range(sp["alive"]):
            d = _direction(sp["turns"][j], prev, x[p, j], cam, sp["seeds"][3 * j:3 * j + 3],
                           sp["eps"], front if j == 0 else None)
            if j > 0:
                b = b * med.albedo
            w[p, j], t[p, j], beta[p, j], alive[p, j] = d, sp["lengths"][j], b, True
            x[p, j + 1] = x[p, j] + t[p, j] * d
            prev = d
        for j in range(sp["alive"], DEPTH):
            x[p, j + 1] = x[p, j]
    ok = np.ones((n, DEPTH + 1), dtype=bool)
    clip = np.zeros((n, DEPTH, 2))
    for j in range(1, DEPTH + 1):
        idx = np.flatnonzero(alive[:, j - 1] & ok[:, j - 1])
        ok[:, j] = False
        ok[idx, j] = (inside_box(x[idx, j], med.bounds_min, med.bounds_max)
                      & ~blockers.occluded(x[idx, j - 1], x[idx, j]))
        te, tx = ray_box(x[:, j - 1], w[:, j - 1], med.bounds_min, med.bounds_max)
        clip[:, j - 1] = np.stack([np.clip(te, 0, t[:, j - 1]), np.clip(tx, 0, t[:, j - 1])], -1)
    return PhotonPaths(n, light, pmf[light], uv, tri, normal, x, w, t, beta, alive, ok, clip)


def craft_rays(scene: Scene, paths: PhotonPaths, eps: float):
    """Two ray sets: pinhole rays from the camera (through every photon vertex, along and
    against every photon segment, at a few fixed targets) and free rays (along photon
    segments, edge-on to the plane of two consecutive segments, and ``eps`` off it)."""
    cam = scene.camera.position
    pin, free_o, free_d = [], [], []
    for p in range(len(paths)):
        for j in range(DEPTH + 1):
            v = paths.x[p, j] - cam
            if np.all(np.isfinite(v)) and np.linalg.norm(v) > 1e-9:
                pin.append(unit(v))
        for j in range(DEPTH):
            if not paths.alive[p, j]:
                continue
            wj = paths.w[p, j]
            pin += [wj, -wj]
            free_o.append(paths.x[p, j + 1] - 3.0 * wj)  # a camera ray along the segment
            free_d.append(wj)
            if j + 1 < DEPTH and paths.alive[p, j + 1]:
                wn = paths.w[p, j + 1]
                n = np.cross(wj, wn)
                for a, b in ((1.0, 1.0), (1.0, -0.5), (0.2, 1.0)):
                    u = a * wj + b * wn
                    if np.linalg.norm(u) < 1e-9:
                        continue
                    u = unit(u)
                    # Edge-on: the ray lies in the photon plane through x_{j+1}.
                    free_o.append(paths.x[p, j + 1] - 2.0 * u)
                    free_d.append(u)
                    if np.linalg.norm(n) > 0:
                        d = unit(u + eps * unit(n))
                        free_o.append(paths.x[p, j + 1] - 2.0 * d)
                        free_d.append(d)
    for target in ([0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [-1.0, 1.0, -1.0], [0.3, -0.99, 0.2]):
        v = np.asarray(target) - cam
        if np.linalg.norm(v) > 1e-9:
            pin.append(unit(v))
    sets = []
    for o, d, origin in ((np.tile(cam, (len(pin), 1)), np.array(pin), cam.copy()),
                         (np.array(free_o).reshape(-1, 3), np.array(free_d).reshape(-1, 3),
                          None)):
        if len(d) == 0:
            continue
        s_min, s_max = clip_rays(scene, o, d)
        sets.append(Rays(o, d, s_min, s_max, np.arange(len(d)), 1, origin))
    return sets


def all_pairs(n_rays: int, n_prims: int):
    ray = np.repeat(np.arange(n_rays), n_prims)
    prim = np.tile(np.arange(n_prims), n_rays)
    return ray, prim


def check_technique(name: str, scene: Scene, paths: PhotonPaths, ray_sets) -> int:
    """Create -> Intersect (all pairs) -> Evaluate (-> MIS) on every ray set; returns hits."""
    blockers = blockers_of(scene)
    n_hits = 0
    for rays in ray_sets:
        tech = get_technique(name)  # fresh primitives per ray set (planes cache per origin)
        ctx = PassContext(scene, blockers, radius=0.05 * scene.medium.diagonal)
        prims = tech.create(paths, ctx)
        assert np.all(~np.isnan(prims.lo)) and np.all(~np.isnan(prims.hi)), "NaN bounds"
        if len(prims) == 0:
            continue
        ray, prim = all_pairs(len(rays), len(prims))
        hits = tech.intersect(prims, rays, ray, prim, ctx)
        if len(hits) == 0:
            continue
        n_hits += len(hits)
        assert np.all(np.isfinite(hits.s)), f"{name}: non-finite hit distance"
        val = tech.evaluate(hits, prims, paths, rays, ctx)
        assert val.shape == (len(hits), 3)
        bad = ~np.all(np.isfinite(val), axis=1)
        assert not bad.any(), (f"{name}: {bad.sum()} non-finite contributions, e.g. "
                               f"{val[bad][0]} at s={hits.s[bad][0]}")
        img = np.zeros((len(rays), 3))
        for c in range(3):
            img[:, c] += np.bincount(hits.ray, weights=val[:, c], minlength=len(rays))
        assert np.all(np.isfinite(img)), f"{name}: per-ray sums overflow"
        if name in MIS_NAMES:
            group = tuple(get_technique(n) if n != name else tech for n in MIS_NAMES)
            w = mis_weights(tech, group, "balance", hits, prims, paths, rays, ctx)
            assert np.all(np.isfinite(w)) and np.all((w >= 0) & (w <= 1 + 1e-12)), name
            assert np.all(np.isfinite(val * w[:, None]))
    return n_hits


# ----------------------------------------------------------------------------- tests
@pytest.mark.parametrize("name", NAMES)
def test_crafted_degenerate_geometry_stays_finite(name):
    hits = []

    @CRAFTED
    @given(medium=media, photons=st.lists(photon, min_size=1, max_size=4))
    def run(medium, photons):
        # Floating-point warnings are expected on this input (1/0 of an edge-on plane that
        # is then dropped, zero-length shadow segments): only the results are checked.
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore", RuntimeWarning)
            scene = build_scene(**medium)
            paths = craft_paths(scene, photons)
            rays = craft_rays(scene, paths, photons[0]["eps"])
            hits.append(check_technique(name, scene, paths, rays))

    run()
    assert sum(hits) > 0, f"{name}: no crafted example produced a hit (vacuous test)"
