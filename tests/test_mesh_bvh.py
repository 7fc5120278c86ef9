"""The triangles' hierarchy (``psurf_core.kernels.mesh_bvh``): its structure, its first hits
against the numpy reference ``geometry.ray_triangles_first``, and the compiled shadow test
(``kernels.shadow.occluded``) against ``Blockers.occluded`` on a mesh light's own segments."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from numba import njit

from psurf_core.constants import SHADOW_EPS
from psurf_core.geometry import blockers_of, ray_triangles_first
from psurf_core.kernels import mesh_bvh as mb
from psurf_core.kernels.shadow import BLOCKED, shadow_args, status
from psurf_core.records import load
from psurf_core.scene_io import load_scene

ROOT = Path(__file__).resolve().parents[1]


def _soup(n, seed):
    """``n`` random triangles of sizes 0.01-0.3 in the unit box (some nearly degenerate)."""
    rng = np.random.default_rng(seed)
    c = rng.uniform(-1, 1, (n, 1, 3))
    t = c + rng.uniform(0.01, 0.3, (n, 1, 1)) * rng.normal(size=(n, 3, 3))
    t[: n // 10, 2] = t[: n // 10, 0] + 1e-9 * (t[: n // 10, 1] - t[: n // 10, 0])  # slivers
    return t


def _rays(n, seed):
    rng = np.random.default_rng(seed)
    o = rng.uniform(-1.5, 1.5, (n, 3))
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    return o, d, np.full(n, SHADOW_EPS), rng.uniform(0.05, 4.0, n)


@pytest.mark.parametrize("n", [1, 4, 5, 37, 600])
def test_every_triangle_in_one_leaf_inside_every_box_above_it(n):
    tris = _soup(n, n)
    nodes, packed = mb.build(tris)
    seen = np.zeros(n, int)
    m = nodes.shape[0]
    for i in range(m):
        node = load(nodes, i, mb.BvhNode)
        assert i < node.skip <= m
        lo, hi = np.array(node.lo), np.array(node.hi)
        # every triangle of the subtree (the nodes i .. skip - 1) lies in the box
        for j in range(i, int(node.skip)):
            sub = load(nodes, j, mb.BvhNode)
            for k in range(int(sub.start), int(sub.start + sub.count)):
                tr = load(packed, k, mb.Triangle)
                v = np.array(tr.v0) + np.array([[0, 0, 0], tr.e1, tr.e2])
                assert np.all(v >= lo) and np.all(v <= hi)
        if node.count:
            assert 0 < node.count <= mb.LEAF_SIZE and node.skip == i + 1
            seen[int(node.start): int(node.start + node.count)] += 1
    assert np.all(seen == 1)
    # the packed rows are the input triangles, reordered
    v0 = packed[:, :3]
    assert sorted(map(tuple, v0.round(12))) == sorted(map(tuple, tris[:, 0].round(12)))


def test_no_triangles():
    nodes, packed = mb.build(np.zeros((0, 3, 3)))
    assert nodes.shape[0] == 0 and packed.shape[0] == 0
    o, d, t0, t1 = _rays(5, 0)
    assert np.all(np.isinf(mb.first_hits(o, d, t0, t1, nodes, packed)))


@pytest.mark.parametrize("seed", [0, 1])
def test_first_hits_match_the_numpy_reference(seed):
    tris = _soup(300, seed)
    nodes, packed = mb.build(tris)
    o, d, t0, t1 = _rays(20000, seed + 10)
    want = ray_triangles_first(o, d, tris, t0, t1)
    got = mb.first_hits(o, d, t0, t1, nodes, packed)
    hit = np.isfinite(want)
    assert 500 < hit.sum() < 19000  # both outcomes are exercised
    np.testing.assert_array_equal(np.isfinite(got), hit)
    np.testing.assert_allclose(got[hit], want[hit], rtol=0, atol=1e-12)


def _mesh_light_segments(scene, n, seed):
    """Segments from points on the scene's mesh light (as a single-scattering hit's shadow
    segment ends on its photon's light point) to random points of the medium, and random
    segments through the medium."""
    bl = blockers_of(scene)
    rng = np.random.default_rng(seed)
    tris = bl.triangles
    k = rng.integers(0, tris.shape[0], n)
    u, v = rng.random(n), rng.random(n)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    on = tris[k, 0] + u[:, None] * (tris[k, 1] - tris[k, 0]) + v[:, None] * (tris[k, 2]
                                                                              - tris[k, 0])
    med = scene.medium
    far = rng.uniform(med.bounds_min, med.bounds_max, (n, 3))
    a = np.concatenate([on, rng.uniform(med.bounds_min, med.bounds_max, (n, 3))])
    b = np.concatenate([far, far[::-1]])
    return bl, a, b


@pytest.mark.parametrize("scene_name", ["dense_mesh_light.toml", "mesh_light.toml"])
def test_compiled_shadow_verdicts_are_the_numpy_ones(scene_name):
    """Every segment gets the same verdict from the walkers' compiled test and from
    ``Blockers.occluded`` (both walk the same hierarchy): segments leaving the mesh light
    (blocked by the mesh itself behind the light point, or by the occluder) and through it."""
    scene = load_scene(ROOT / "scenes" / scene_name)
    bl, a, b = _mesh_light_segments(scene, 3000, 4)
    want = bl.occluded(a, b)
    args = shadow_args(bl)
    assert isinstance(args, tuple)  # the table and the hierarchy: this scene has triangles
    one = njit(lambda x, y, blk: status(x, y, blk))  # what a walker's visibility calls
    got = np.array([one(tuple(a[i]), tuple(b[i]), args) == BLOCKED for i in range(len(a))])
    assert 0.1 < want.mean() < 0.9  # both verdicts are exercised
    np.testing.assert_array_equal(got, want)
    # and they are right: against the brute-force numpy test of every triangle
    v = b - a
    ln = np.linalg.norm(v, axis=1)
    d = v / ln[:, None]
    tri = ray_triangles_first(a, d, bl.triangles, np.full(len(a), SHADOW_EPS), ln - SHADOW_EPS)
    other = bl.__class__(**{**bl.__dict__, "triangles": np.zeros((0, 3, 3)), "engine": None,
                            "bounds": None, "planes": None}).occluded(a, b)
    np.testing.assert_array_equal(want, np.isfinite(tri) | other)
