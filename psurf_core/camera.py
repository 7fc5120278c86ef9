"""Camera rays (jittered per pass, or through pixel centres) and screen projection."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .geometry import Blockers, blockers_of, ray_box
from .pixel_jitter import independent_jitter
from .scene import Camera, Scene


@dataclass(frozen=True)
class Rays:
    """Camera (query) rays ``y(s) = o + s d``, ordered pixel-major: ray ``i`` belongs to
    pixel ``i // spp``.

    Attributes
    ----------
    o, d : (N, 3) float
        Origins (the camera position) and unit directions ``psi``.
    s_min, s_max : (N,) float
        The part of the ray inside the medium box and before the first occluder or emitter
        hit. ``s_max <= s_min`` marks a ray that sees no medium.
    pixel : (N,) int
        Flat pixel index ``row * width + col`` (row 0 = top).
    spp : int
        Rays per pixel.
    origin : (3,) float or None
        The common origin of all rays (a pinhole camera), which lets techniques move work
        from ray-primitive pairs to primitives; ``None`` when origins differ.
    """

    o: np.ndarray
    d: np.ndarray
    s_min: np.ndarray
    s_max: np.ndarray
    pixel: np.ndarray
    spp: int
    origin: np.ndarray | None = None

    def __len__(self) -> int:
        return self.d.shape[0]

    def subset(self, idx: np.ndarray) -> Rays:
        """The rays at ``idx`` (keeps ``spp`` for bookkeeping only)."""
        return Rays(self.o[idx], self.d[idx], self.s_min[idx], self.s_max[idx],
                    self.pixel[idx], self.spp, self.origin)


def _tan_half(cam: Camera) -> float:
    return float(np.tan(np.radians(cam.fov_y) / 2.0))


def pixel_directions(cam: Camera, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """Unit directions through continuous image coordinates.

    Parameters
    ----------
    px, py : (N,) float
        Column and row coordinates in pixels (``0..width``, ``0..height``; row 0 at the top).

    Returns
    -------
    (N, 3) float
    """
    th = _tan_half(cam)
    aspect = cam.width / cam.height
    x = (2.0 * px / cam.width - 1.0) * th * aspect
    y = (1.0 - 2.0 * py / cam.height) * th
    d = cam.forward[None] + x[:, None] * cam.right[None] + y[:, None] * cam.image_up[None]
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def project(cam: Camera, points: np.ndarray):
    """Project world points to continuous pixel coordinates.

    Parameters
    ----------
    points : (N, 3) float

    Returns
    -------
    px, py, depth : (N,) float
        Column, row (row 0 at the top) and depth along ``forward``; only points with
        ``depth > 0`` project meaningfully.
    """
    v = points - cam.position
    depth = v @ cam.forward
    th = _tan_half(cam)
    aspect = cam.width / cam.height
    with np.errstate(divide="ignore", invalid="ignore"):
        x = (v @ cam.right) / (depth * th * aspect)
        y = (v @ cam.image_up) / (depth * th)
    return (x + 1.0) * 0.5 * cam.width, (1.0 - y) * 0.5 * cam.height, depth


def clip_rays(scene: Scene, o: np.ndarray, d: np.ndarray, blockers: Blockers | None = None):
    """In-medium interval of rays: box entry/exit, cut at the first occluder or emitter.

    Returns
    -------
    s_min, s_max : (N,) float
    """
    med = scene.medium
    te, tx = ray_box(o, d, med.bounds_min, med.bounds_max)
    s_min = np.maximum(te, 0.0)
    blockers = blockers_of(scene) if blockers is None else blockers
    hit = blockers.first_hit(o, d, np.zeros(len(d)), np.full(len(d), np.inf))
    s_max = np.minimum(tx, hit)
    s_max = np.where(s_max > s_min, s_max, s_min)
    return s_min, s_max


def camera_rays(
    scene: Scene,
    spp: int = 1,
    rng: np.random.Generator | None = None,
    *,
    jitter: bool = True,
    pixels: np.ndarray | None = None,
    blockers: Blockers | None = None,
    jitter_xy: tuple[np.ndarray, np.ndarray] | None = None,
) -> Rays:
    """Camera rays for every pixel (or the given flat ``pixels``), ``spp`` per pixel.

    With ``jitter`` each ray goes through a uniformly random point of its pixel (a box
    filter: the pixel value is the area average); without it, through pixel centres
    (for tests against a one-ray quadrature). ``jitter_xy``: the points, (n_pixels * spp,)
    each in [0, 1), given (:func:`psurf_core.pixel_jitter.pass_jitter`) instead of drawn
    from ``rng``.
    """
    cam = scene.camera
    # Jitter is drawn for every pixel even when only some are wanted, so that replaying one
    # pixel of a pass sees exactly the rays the full pass saw.
    all_pix = np.repeat(np.arange(cam.n_pixels), spp)
    if jitter_xy is not None:
        jx, jy = jitter_xy
    elif jitter:
        if rng is None:
            raise ValueError("jittered camera rays need a Generator")
        jx, jy = independent_jitter(all_pix.size, rng)
    else:
        jx = jy = np.full(all_pix.size, 0.5)
    if pixels is None:
        sel = np.arange(all_pix.size)
    else:
        p = np.sort(np.asarray(pixels, dtype=np.int64))
        sel = (p[:, None] * spp + np.arange(spp)[None]).ravel()
    pix, jx, jy = all_pix[sel], jx[sel], jy[sel]
    row, col = np.divmod(pix, cam.width)
    d = pixel_directions(cam, col + jx, row + jy)
    o = np.broadcast_to(cam.position, d.shape).copy()
    s_min, s_max = clip_rays(scene, o, d, blockers)
    return Rays(o, d, s_min, s_max, pix, spp, np.array(cam.position, dtype=float))
