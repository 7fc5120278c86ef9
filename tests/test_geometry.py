"""Camera rays, pixel orientation, box and blocker clipping, screen-space binning."""

import numpy as np
import pytest
from small_scenes import POINT, make_scene

from psurf_core.binning import candidate_pairs, screen_rects
from psurf_core.camera import camera_rays, pixel_directions, project
from psurf_core.geometry import blockers_of, ray_box, ray_triangles_first
from psurf_core.scene import AreaLight, BoxOccluder, MeshLight, SphereOccluder

#: The image size of these tests (pixels).
SIZE = (32, 24)


def test_pixel_orientation():
    """Row 0 is the top, column 0 the left, as seen from the camera."""
    cam = make_scene([POINT], size=SIZE).camera
    d = pixel_directions(cam, np.array([0.5, cam.width - 0.5, cam.width / 2, cam.width / 2]),
                         np.array([cam.height / 2, cam.height / 2, 0.5, cam.height - 0.5]))
    # Camera looks along +z with up +y: image right is forward x up = -x.
    assert d[0] @ cam.right < 0 < d[1] @ cam.right
    assert d[2][1] > 0 > d[3][1]
    assert np.allclose(cam.right, [-1, 0, 0])


def test_fov_and_projection_roundtrip():
    cam = make_scene([POINT], size=SIZE).camera
    d = pixel_directions(cam, np.array([cam.width / 2.0]), np.array([0.0]))[0]
    angle = np.degrees(np.arccos(d @ cam.forward))
    assert angle == pytest.approx(cam.fov_y / 2, rel=1e-9)
    rng = np.random.default_rng(0)
    px, py = rng.uniform(0, cam.width, 50), rng.uniform(0, cam.height, 50)
    pts = cam.position + 3.0 * pixel_directions(cam, px, py)
    qx, qy, depth = project(cam, pts)
    assert np.allclose(qx, px) and np.allclose(qy, py) and np.all(depth > 0)


def test_jitter_stays_in_pixel_and_subset_replays():
    sc = make_scene([POINT], size=SIZE)
    rays = camera_rays(sc, 3, np.random.default_rng(1))
    px, py, _ = project(sc.camera, rays.o + rays.d)
    row, col = np.divmod(rays.pixel, sc.camera.width)
    assert np.all((px >= col) & (px < col + 1) & (py >= row) & (py < row + 1))
    sub = camera_rays(sc, 3, np.random.default_rng(1), pixels=np.array([77]))
    assert np.array_equal(sub.d, rays.d[rays.pixel == 77])


def test_ray_box_slab():
    o = np.array([[0.0, 0.0, -4.0], [0.0, 5.0, -4.0], [0.0, 0.0, 0.0]])
    d = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    te, tx = ray_box(o, d, -np.ones(3), np.ones(3))
    assert te[0] == pytest.approx(3.0) and tx[0] == pytest.approx(5.0)
    assert te[1] >= tx[1]
    assert te[2] == pytest.approx(-1.0) and tx[2] == pytest.approx(1.0)


def test_camera_rays_clipped_by_occluders_and_emitters():
    sphere = SphereOccluder(np.array([0.0, 0.0, 0.0]), 0.3)
    box = BoxOccluder(np.array([0.5, 0.5, -0.2]), np.array([0.9, 0.9, 0.2]))
    area = AreaLight(np.array([-0.9, -0.9, 0.5]), np.array([0.6, 0, 0]), np.array([0, 0.6, 0]),
                     np.ones(3))
    sc = make_scene([area], (sphere, box), size=SIZE)
    rays = camera_rays(sc, 1, jitter=False)
    o, d = rays.o, rays.d
    # Brute force along each ray: first blocked point.
    s = np.linspace(0, 8, 16001)
    pts = o[:, None, :] + s[None, :, None] * d[:, None, :]
    in_sphere = np.linalg.norm(pts, axis=2) < 0.3
    in_box = np.all((pts > box.min) & (pts < box.max), axis=2)
    n = np.cross(area.edge_u, area.edge_v)
    side = (pts - area.corner) @ n
    uv = np.stack([(pts - area.corner) @ area.edge_u / 0.36, (pts - area.corner) @ area.edge_v
                   / 0.36], axis=2)
    crossing = np.zeros_like(side, bool)
    crossing[:, 1:] = (np.sign(side[:, 1:]) != np.sign(side[:, :-1])) & np.all(
        (uv[:, 1:] >= 0) & (uv[:, 1:] <= 1), axis=2)
    blocked = in_sphere | in_box | crossing
    first = np.where(blocked.any(1), s[np.argmax(blocked, 1)], np.inf)
    te, tx = ray_box(o, d, -np.ones(3), np.ones(3))
    expect = np.minimum(tx, first)
    has = expect > np.maximum(te, 0)
    assert np.allclose(rays.s_max[has], expect[has], atol=2e-3)
    assert np.all(rays.s_max[~has] <= rays.s_min[~has] + 2e-3)


def test_triangles_and_shadow_segments():
    tri = np.array([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]])
    o = np.array([[0.2, 0.2, -1.0], [0.8, 0.8, -1.0]])
    d = np.array([[0.0, 0, 1], [0, 0, 1]])
    t = ray_triangles_first(o, d, tri, np.zeros(2), np.full(2, np.inf))
    assert t[0] == pytest.approx(1.0) and np.isinf(t[1])
    mesh = MeshLight(tri * 0.5, np.ones(3))
    b = blockers_of(make_scene([mesh], size=SIZE))
    a = np.array([[0.1, 0.1, -0.5], [0.1, 0.1, -0.5], [0.1, 0.1, 0.0]])
    e = np.array([[0.1, 0.1, 0.5], [0.4, 0.4, -0.1], [0.1, 0.1, 0.5]])
    # Through the emitter; beside it; starting on the emitter (its own surface never blocks).
    assert b.occluded(a, e).tolist() == [True, False, False]


def test_binning_covers_every_hit():
    """Every ray that really meets a primitive's box is among the candidate pairs."""
    sc = make_scene([POINT], size=(20, 15), position=(0.3, 0.2, -3.0))
    rays = camera_rays(sc, 2, np.random.default_rng(3))
    rng = np.random.default_rng(4)
    c = rng.uniform(-1, 1, (300, 3))
    r = rng.uniform(0.01, 0.4, (300, 1))
    lo, hi = c - r, c + r
    got = set()
    for ray, prim in candidate_pairs(sc.camera, rays, lo, hi, max_pairs=5000):
        got.update(zip(ray.tolist(), prim.tolist(), strict=True))
    useful = rays.s_max > rays.s_min
    te, tx = ray_box(np.repeat(rays.o, 300, 0), np.repeat(rays.d, 300, 0),
                     np.tile(lo, (len(rays), 1)), np.tile(hi, (len(rays), 1)))
    hit = (te < tx) & (tx > 0) & np.repeat(useful, 300)
    ray_i, prim_i = np.divmod(np.flatnonzero(hit), 300)
    need = set(zip(ray_i.tolist(), prim_i.tolist(), strict=True))
    assert need <= got
    # and binning actually prunes
    assert len(got) < 0.6 * useful.sum() * 300


def test_screen_rects_behind_camera():
    cam = make_scene([POINT], size=SIZE).camera
    lo = np.array([[-0.1, -0.1, -5.0], [-1, -1, -4.5]])
    hi = np.array([[0.1, 0.1, -4.5], [1, 1, 0.0]])
    x0, x1, y0, y1 = screen_rects(cam, lo, hi)
    assert x1[0] == x0[0]  # entirely behind: nothing
    assert (x0[1], x1[1], y0[1], y1[1]) == (0, cam.width, 0, cam.height)  # straddles: all
