"""The per-primitive shadow cull (``psurf_core.techniques.shadow_cull``) and its users, the
light strips, photon planes, generalized planes, cones, disks, spheres and cylinders: a
segment a flag calls clear is one the full shadow test calls clear, on scenes whose blockers
their segments meet (the light itself, an occluder sphere and box, a second light in the first
one's plane, a mesh light), and the cull does skip tests where it should (every strip's first
segment under a light facing down)."""

from __future__ import annotations

import numpy as np
import pytest
from small_scenes import TETRA, TILTED_AREA, TOP_AREA, make_scene
from test_photon_surfaces_multi_forms import all_hits

from psurf_core.camera import camera_rays
from psurf_core.geometry import blockers_of
from psurf_core.scene import AreaLight, BoxOccluder, SphereOccluder
from psurf_core.techniques import (
    cones,
    cylinders,
    disks,
    generalized_planes,
    get_technique,
    light_planes,
    planes,
    spheres,
)
from psurf_core.techniques import shadow_cull as cull
from psurf_core.trace import trace

#: Beside TOP_AREA, in its plane, facing down too.
SIDE_AREA = AreaLight(corner=np.array([0.4, 0.95, -0.3]), edge_u=np.array([0.4, 0.0, 0.0]),
                      edge_v=np.array([0.0, 0.0, 0.6]), radiance=np.array([1.0, 1.0, 1.0]))

SCENES = {
    "top": lambda k: make_scene((TOP_AREA,), kmin=k, kmax=k, size=(32, 24)),
    "occluders": lambda k: make_scene(
        (TOP_AREA,), (SphereOccluder(np.array([0.5, -0.2, 0.1]), 0.3),
                      BoxOccluder(np.array([-0.9, -0.9, -0.9]), np.array([-0.6, -0.5, -0.6]))),
        kmin=k, kmax=k, size=(32, 24)),
    "coplanar": lambda k: make_scene((TOP_AREA, SIDE_AREA), kmin=k, kmax=k, size=(32, 24)),
    "tilted_mesh": lambda k: make_scene((TILTED_AREA, TETRA), g=0.4, kmin=k, kmax=k,
                                        size=(32, 24)),
}


#: Per technique: its module (``segments``) and its primitives' flags, one per segment of
#: ``segments`` (None: a segment the technique always tests).
FLAGS = {name: (light_planes, ("clear0", "clear1", "clear2"))
         for name in ("plane-ut-short", "plane-vt", "plane-vt-short")}
FLAGS.update({name: (planes, ("line", "clear")) for name in ("planes", "plane-t1t2")})
FLAGS.update({name: (generalized_planes, ("clear0", "clear1", "clear2"))
              for name in ("plane-t1t3", "plane-t1t3-short", "plane-t2t3", "plane-t2t3-short")})
FLAGS.update({name: (cones, ("clear",)) for name in ("cone", "cone-short")})
FLAGS.update({name: (disks, ("clear",)) for name in ("disk", "disk-short")})
FLAGS.update({"sphere": (spheres, ("clear",))})
FLAGS.update({name: (cylinders, ("line", "clear")) for name in ("cylinder", "cylinder-short")})


def _flags_and_verdicts(scene, name, photons=400, seed=3):
    """Per hit of technique ``name`` on one pass: its primitive's ``clear`` flags and the
    full test's verdict (True: blocked) on the rebuilt segments they stand for."""
    rng = np.random.default_rng(seed)
    blockers = blockers_of(scene)
    rays = camera_rays(scene, 1, rng, blockers=blockers)
    paths = trace(scene, photons, rng, blockers=blockers)
    module, names = FLAGS[name]
    flags, blocked, prims = [], [], None
    for hits, prims, _, _, _ in all_hits(get_technique(name), scene, paths, rays):
        G = prims.data[hits.prim]
        x0 = rays.o[hits.ray] + hits.s[:, None] * rays.d[hits.ray]
        flags.append(np.stack([np.zeros(len(hits)) if f is None else G[f] for f in names],
                              axis=1))
        blocked.append(np.stack([blockers.occluded(a, b) for a, b in
                                 module.segments(G, x0, hits.data)], axis=1))
    return prims, np.concatenate(flags), np.concatenate(blocked)


@pytest.mark.parametrize(("key", "k", "name"), [
    (key, k, name) for key in sorted(SCENES) for k in (2, 3) for name in sorted(FLAGS)
    if k >= get_technique(name).min_k])
def test_a_culled_segment_is_never_blocked(key, k, name):
    prims, flags, blocked = _flags_and_verdicts(SCENES[key](k), name)
    assert flags.shape[0] > 100
    culled = flags != 0.0
    assert culled.shape == blocked.shape
    assert not np.any(culled & blocked), "a segment the cull skipped is blocked"
    assert blocked.any()  # (that some are culled: the next test)


@pytest.mark.parametrize("name", sorted(set(FLAGS) - {"disk"}))
def test_every_user_skips_some_tests(name):
    """Where an occluder and the light leave room (K = 3 beside a sphere and a box), every
    user of the cull skips some of its segments' tests: the check above is not vacuous. (Not
    the long disk: its half-plane reaches the box's walls, so its bounds meet a blocker's.)"""
    _, flags, blocked = _flags_and_verdicts(SCENES["occluders"](3), name)
    culled = flags != 0.0
    assert 0.01 < culled.any(axis=1).mean() and not np.any(culled & blocked)


def test_the_cull_skips_the_first_segment_under_a_light_facing_down():
    """Every strip's first segment leaves the light's plane downwards and meets nothing else;
    about half the last segments (those whose strip lies below the light) are skipped too."""
    for k in (2, 3):
        prims, flags, _ = _flags_and_verdicts(SCENES["top"](k), "plane-ut-short")
        assert np.all(prims.data.clear0 == 1.0)
        assert 0.3 < prims.data.clear2.mean() < 0.8
    # An occluder in the way: some first segments are tested again.
    prims, _, _ = _flags_and_verdicts(SCENES["occluders"](2), "plane-ut-short")
    assert 0.1 < prims.data.clear0.mean() < 0.9


class _Quad:
    """A blocker table with one quad in the plane y = 0 (normal +y) and one box."""

    bounds = np.array([[[-1.0, 0.0, -1.0], [1.0, 0.0, 1.0]], [[2.0, 2.0, 2.0], [3.0, 3.0, 3.0]]])
    planes = np.array([[0.0, 2.0, 0.0, 0.0], [np.nan] * 4])


class _Scene:
    class medium:  # noqa: N801 - a stand-in for Scene.medium
        bounds_min, bounds_max = -np.ones(3), np.ones(3)


def test_leaves_away_and_misses_on_hand_made_geometry():
    bl, sc = _Quad(), _Scene()

    def pts(*xs):
        return [np.array([x], float) for x in xs]

    on = pts([0.0, 0.0, 0.0], [0.5, 0.0, 0.0])  # on the plane
    below = pts([0.0, -0.5, 0.0], [0.5, -0.2, 0.3])
    up, flat = np.array([[0.0, 1.0, 0.0]]), np.array([[1.0, 0.0, 0.0]])
    assert cull.leaves(bl, sc, on, -up)[0].tolist() == [True, False]
    assert cull.leaves(bl, sc, on, up)[0].tolist() == [True, False]
    assert cull.leaves(bl, sc, on, flat)[0].tolist() == [False, False]  # grazing
    # From below the plane, upwards: it crosses.
    assert cull.leaves(bl, sc, below, up)[0].tolist() == [False, False]
    assert cull.away(bl, sc, on, below)[0].tolist() == [True, False]
    assert cull.away(bl, sc, below, on)[0].tolist() == [False, False]  # ends on the plane
    assert cull.away(bl, sc, below, [x + 2 * up for x in below])[0].tolist() == [False, False]
    assert cull.misses(bl, below)[0].tolist() == [True, True]
    assert cull.misses(bl, [x + 0.4 * up for x in below])[0].tolist() == [False, True]
    assert cull.misses(bl, pts([2.5, 2.5, 2.5]))[0].tolist() == [True, False]
    # Every blocker needs a reason; one reason each suffices.
    r1, r2 = np.array([[True, False]]), np.array([[False, True]])
    assert cull.clear(r1).tolist() == [0.0]
    assert cull.clear(r1, r2).tolist() == [1.0]
