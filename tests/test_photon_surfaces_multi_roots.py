"""Multiple-scattering photon surfaces: roots and degenerate configurations.

* The root solvers of the surfaces of revolution (hyperboloid, torus) find every root of the
  unsquared equations (against sign changes on a fine grid) and report no spurious one.
* Degenerate configurations (``th1 = 0, pi``, tiny radii, rays along axes and generators,
  parallel to planes) stay finite without floating-point warnings.
"""

from __future__ import annotations

import numpy as np
import pytest
from photon_surfaces_multi_support import MINE_K2, MINE_K3, point_scene, unit

from psurf_core.camera import Rays
from psurf_core.geometry import blockers_of
from psurf_core.mis import member_densities, weights_from_densities
from psurf_core.sampling import sample_uniform_sphere
from psurf_core.techniques import get_technique
from psurf_core.techniques.base import PassContext
from psurf_core.trace import PhotonPaths


def crafted_paths(x2, w2, T2, w1, T1, axis, w3=None, T3=None):
    """PhotonPaths of 2 (or 3, with ``w3, T3``) segments whose prefixes are all valid."""
    n = x2.shape[0]
    segs = [(w2, T2), (w1, T1)] if w3 is None else [(w3, T3), (w2, T2), (w1, T1)]
    start = x2 if w3 is None else x2 - T3[:, None] * w3
    xs = [start]
    for w, t in segs:
        xs.append(xs[-1] + t[:, None] * w)
    d = len(segs)
    return PhotonPaths(n, np.zeros(n, np.int64), np.ones(n), np.zeros((n, 2)),
                       np.full(n, -1), axis, np.stack(xs, 1), np.stack([w for w, _ in segs], 1),
                       np.stack([t for _, t in segs], 1), np.ones((n, d, 3)),
                       np.ones((n, d), bool), np.ones((n, d + 1), bool), np.zeros((n, d, 2)))


def _radius(v, A):
    """Distances of points ``v`` (N, 3) from the axis through the origin along ``A``."""
    return np.linalg.norm(v - (v @ A)[:, None] * A, axis=1)


def brute_roots(fun, s_lo, s_hi, m=6000):
    """Sign changes of ``fun(s) -> (value, defined)`` on a grid, refined by bisection."""
    s = np.linspace(s_lo, s_hi, m)
    v, ok = fun(s)
    idx = np.flatnonzero(ok[:-1] & ok[1:] & (np.sign(v[:-1]) * np.sign(v[1:]) < 0))
    lo, hi = s[idx], s[idx + 1]
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        vm, _ = fun(mid)
        left = np.sign(vm) == np.sign(fun(lo)[0])
        lo, hi = np.where(left, mid, lo), np.where(left, hi, mid)
    return 0.5 * (lo + hi)


@pytest.mark.parametrize("name", ["hyperboloid", "torus"])
def test_revolution_roots_are_complete(name):
    rng = np.random.default_rng(21)
    n = 150
    scene = point_scene(2)
    x2 = rng.uniform(-0.3, 0.3, (n, 3))
    w2, w1, axis = (sample_uniform_sphere(rng, n) for _ in range(3))
    T2, T1 = rng.uniform(0.2, 1.0, n), rng.uniform(0.2, 1.0, n)
    paths = crafted_paths(x2, w2, T2, w1, T1, axis)
    o = rng.uniform(-1, 1, (n, 3)) + np.array([0, 0, -3.0])
    d = unit(x2 + rng.normal(scale=0.4, size=(n, 3)) - o)
    rays = Rays(o, d, np.full(n, 0.5), np.full(n, 6.0), np.arange(n), 1)
    tech = get_technique(name)
    ctx = PassContext(scene, blockers_of(scene))
    prims = tech.create(paths, ctx)
    hits = tech.intersect(prims, rays, np.arange(n), np.arange(n), ctx)
    found = total = 0
    for i in range(n):
        A, q0 = axis[i], T2[i] * w2[i]
        c1p = w1[i] @ w2[i]
        e_r = (w1[i] - c1p * w2[i]) / np.sqrt(1 - c1p**2)

        def fun(s, i=i, A=A, q0=q0, e_r=e_r):
            P = o[i] + s[:, None] * d[i] - x2[i]
            if name == "hyperboloid":  # equal heights fix t; then equal radii
                t = (P @ A - q0 @ A) / (w1[i] @ A)
                L = q0 + t[:, None] * w1[i]
                return _radius(P, A) - _radius(L, A), t > 0
            c1 = (np.sum(P * P, 1) - T2[i] ** 2 - T1[i] ** 2) / (2 * T1[i] * T2[i])
            s1 = np.sqrt(np.clip(1 - c1 * c1, 0, None))
            return P @ A - T2[i] * (w2[i] @ A) - T1[i] * (c1 * (w2[i] @ A) + s1 * (e_r @ A)), \
                np.abs(c1) < 1

        want = brute_roots(fun, 0.5, 6.0)
        got = np.sort(hits.s[hits.ray == i])
        total += want.size
        for r in want:
            found += np.any(np.abs(got - r) < 1e-7)
        # And nothing spurious: every reported root solves the unsquared equation.
        if got.size:
            v, ok = fun(got)
            assert np.all(ok) and np.all(np.abs(v) < 1e-7), (i, got, v)
    assert total > 60 and found == total, (found, total)


# ------------------------------------------------------------------------------ degenerate
def test_degenerate_configurations_stay_finite():
    """th1 = 0 / pi (exact and within 1e-15), tiny radii, rays along axes and generators,
    parallel to planes: no NaN/inf and no floating-point warning (pytest turns them into
    errors)."""
    z, x = np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0])
    eps = [0.0, 1e-15, 1e-9]
    w1s = [z, -z] + [unit(np.array([[e, 0, 1.0]]))[0] for e in eps[1:]] + \
          [unit(np.array([[e, 0, -1.0]]))[0] for e in eps[1:]] + [x, (z + x) / np.sqrt(2.0)]
    m = len(w1s)
    x2 = np.tile([0.0, 0.0, -0.5], (m, 1))
    w2 = np.tile(z, (m, 1))
    w1 = np.array(w1s)
    cases = []
    for T1 in (0.4, 1e-12):
        for w3 in (z, x):  # w3 parallel to w2 (and to some w1) or perpendicular
            cases.append(crafted_paths(x2, w2, np.full(m, 0.3), w1, np.full(m, T1),
                                       np.tile(z, (m, 1)), np.tile(w3, (m, 1)), np.full(m, 0.2)))
    # Rays: along the axis through x2/x1, parallel at the cylinder radius, along a cone
    # generator through x1, in the plane of w2 and x, and nearly so.
    # Plus generic rays through the neighbourhood, so that every technique has hits.
    o = np.array([[0, 0, -4.0], [0.4, 0, -4.0], [0, 0, -4.0], [0, 1e-13, -4.0],
                  [-4.0, 0, -0.2], [-4.0, 0, -0.5], [-4.0, 1e-14, -0.5]]
                 + [[0.5, 0.5, -4.0]] * 4)
    d = unit(np.array([[0, 0, 1.0], [0, 0, 1.0], [1e-13, 0, 1.0], [0, 0, 1.0],
                        [1.0, 0, 1.0], [1.0, 0, 0], [1.0, 0, 0]]
                       + [[-0.4, -0.45, 3.7], [-0.3, -0.5, 3.9], [-0.45, -0.4, 4.1],
                          [-0.2, -0.55, 3.8]]))
    rays = Rays(o, d, np.zeros(len(o)), np.full(len(o), 8.0), np.arange(len(o)), 1)
    mine = [get_technique(n) for n in MINE_K2 + MINE_K3]
    group = [*mine, get_technique("plane-t1t2")]  # MIS densities on every record
    for k in (3, 2):
        scene = point_scene(k)
        ctx = PassContext(scene, blockers_of(scene))
        for paths in cases:
            if k == 2:  # drop the first segment: a 2-segment path from x2
                paths = crafted_paths(paths.x[:, 1], paths.w[:, 1], paths.t[:, 1],
                                      paths.w[:, 2], paths.t[:, 2], paths.light_normal)
            for tech in mine:
                prims = tech.create(paths, ctx)
                assert not np.any(np.isnan(prims.lo) | np.isnan(prims.hi)), tech.name
                ray, prim = np.divmod(np.arange(len(rays) * len(prims)), max(len(prims), 1))
                hits = tech.intersect(prims, rays, ray, prim, ctx)
                if not len(hits):
                    continue
                val = tech.evaluate(hits, prims, paths, rays, ctx)
                assert np.all(np.isfinite(val)) and np.all(np.isfinite(hits.s)), tech.name
                rec = tech.reconstruct(hits, prims, paths, rays, ctx)
                q = member_densities(rec, group, ctx)
                assert np.all(np.isfinite(weights_from_densities(q, "balance")))


# ------------------------------------------------------------------------------ on-surface reads
def test_cone_slant_reads_the_slant_length_off_the_axis():
    """``cones.slant`` of points on a double cone: ``+|v|`` on the photon's nappe, ``-|v|``
    on the mirror one, to 1e-11 relative for every ``c1`` (the axis read ``h / c1`` from
    ``|c1| >= C1_DIRECT``, the norm below it, and ``c1 = 0``), and its compiled twin
    equal to it; ``cones.inverse_slant`` is its inverse, twins equal too."""
    from numba import njit

    from psurf_core.techniques import cones

    rng = np.random.default_rng(48)
    n = 4000
    w2 = unit(rng.normal(size=(n, 3)))
    c1 = np.concatenate([rng.uniform(-1, 1, n - 400), rng.uniform(-0.02, 0.02, 300),
                         np.zeros(50), np.full(50, cones.C1_DIRECT)])
    s1 = np.sqrt(1.0 - c1 * c1)
    e = rng.normal(size=(n, 3))
    e_r = unit(e - (e * w2).sum(1)[:, None] * w2)
    t = rng.uniform(0.01, 3.0, n)
    side = rng.choice([-1.0, 1.0], n)
    v = (side * t)[:, None] * (c1[:, None] * w2 + s1[:, None] * e_r)
    got = cones.slant(v, w2, c1)
    # c1 = 0: both nappes are one plane, where the side is 0 and the slant is -|v|.
    want = np.where(c1 == 0.0, -t, side * t)
    np.testing.assert_allclose(got, want, rtol=1e-11)
    assert np.any(np.abs(c1) < cones.C1_DIRECT) and np.any(np.abs(c1) >= cones.C1_DIRECT)
    twin = njit(lambda a, b, c: cones.slant(a, b, c))
    compiled = np.array([twin(tuple(v[i]), tuple(w2[i]), c1[i]) for i in range(n)])
    np.testing.assert_array_equal(compiled, got)
    # Its inverse (c1 / h where slant reads h / c1): 1 / slant to 1e-11 on the photon's
    # nappe and the mirror one alike (c1 = 0 aside: there h = 0 and the slant is -|v|).
    inv = cones.inverse_slant(v, w2, c1, got)
    np.testing.assert_allclose(inv, 1.0 / np.where(c1 == 0.0, -t, side * t), rtol=1e-11)
    twin = njit(lambda a, b, c, d: cones.inverse_slant(a, b, c, d))
    compiled = np.array([twin(tuple(v[i]), tuple(w2[i]), c1[i], got[i]) for i in range(n)])
    np.testing.assert_array_equal(compiled, inv)


def test_cylinder_radial_unit_on_its_roots():
    """``cylinders.radial_unit`` at the roots ``cylinders.roots`` finds: unit length to 1e-12
    (``|vp| = r`` at a root), equal to ``vp / |vp|``, and zero for a zero radius."""
    from psurf_core.records import table
    from psurf_core.techniques import cylinders
    from psurf_core.techniques.cylinders import CylinderGeometry

    rng = np.random.default_rng(49)
    n = 3000
    w2 = unit(rng.normal(size=(n, 3)))
    x2 = rng.uniform(-1, 1, (n, 3))
    T1, s1 = rng.uniform(0.05, 2.0, n), rng.uniform(0.01, 1.0, n)
    one = np.ones(n)
    G = table(CylinderGeometry, x2=x2, w2=w2, c1=np.sqrt(1 - s1 * s1), s1=s1, T1=T1, T2=T1,
              own=one, beta=np.ones((n, 3)), clear=one, line=one)
    o = x2 + rng.normal(scale=2.0, size=(n, 3))
    psi = unit(x2 + rng.normal(scale=0.5, size=(n, 3)) - o)
    r = cylinders.roots(G, o, psi)
    checked = 0
    for s in r:
        ok = np.isfinite(s)
        x0 = o[ok] + s[ok, None] * psi[ok]
        v = x0 - x2[ok]
        vp = v - (v * w2[ok]).sum(1)[:, None] * w2[ok]
        e_r = cylinders.radial_unit(vp, T1[ok] * s1[ok])
        np.testing.assert_allclose(np.linalg.norm(e_r, axis=1), 1.0, rtol=1e-12)
        np.testing.assert_allclose(e_r, vp / np.linalg.norm(vp, axis=1)[:, None], atol=1e-12)
        checked += ok.sum()
    assert checked > n  # most rays pass through the cylinders
    assert np.all(cylinders.radial_unit(np.ones((2, 3)), np.zeros(2)) == 0.0)
