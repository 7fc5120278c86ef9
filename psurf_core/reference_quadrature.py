"""Deterministic single scattering from point lights along camera rays, by composite
Gauss-Legendre quadrature: the oracle of the single-scattering tests
(:func:`single_scatter_quadrature`)."""

from __future__ import annotations

import numpy as np

from . import sampling
from .camera import clip_rays, pixel_directions
from .geometry import Blockers, blockers_of
from .scene import PointLight, Scene

__all__ = ["gauss_legendre_panels", "pixel_quadrature", "single_scatter_quadrature"]

#: Quadrature points (rays x nodes) per chunk of :func:`single_scatter_quadrature`.
_QUAD_CHUNK = 1 << 18


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("ij,ij->i", a, b)


def gauss_legendre_panels(n: int, order: int = 8):
    """``n`` composite Gauss-Legendre nodes and weights on [0, 1] (panels of ``order``).

    Panels (rather than one high-order rule) keep the error small where the shadow term
    ``V`` jumps.
    """
    panels = max(1, n // order)
    xg, wg = np.polynomial.legendre.leggauss(order)
    left = np.arange(panels)[:, None] / panels
    nodes = (left + (xg[None] + 1.0) / (2.0 * panels)).ravel()
    weights = np.broadcast_to(wg / (2.0 * panels), (panels, order)).ravel()
    return nodes, weights


def single_scatter_quadrature(
    scene: Scene,
    o: np.ndarray,
    d: np.ndarray,
    s_min: np.ndarray,
    s_max: np.ndarray,
    n: int = 4096,
    blockers: Blockers | None = None,
) -> np.ndarray:
    """Deterministic single scattering from point lights along each ray (the oracle).

    Computes ``int_{s_min}^{s_max} exp(-st (s - s_min)) ss rho(mu) I exp(-st |x - L|)
    V(x, L) / |x - L|^2 ds`` with ``x = o + s d`` and ``mu = ((x - L)/|x - L|) . (-d)``,
    summed over the lights, by composite Gauss-Legendre. ``exp(-st |x - L|)`` is exact
    because ``x`` and ``L`` lie in the convex box.

    Parameters
    ----------
    scene : Scene
        Must hold point lights only.
    o, d : (N, 3) float
        Ray origins and unit directions.
    s_min, s_max : (N,) float
        In-medium interval (as ``Rays``); empty where ``s_max <= s_min``.
    n : int
        Quadrature nodes per ray.
    blockers : Blockers, optional

    Returns
    -------
    (N, 3) float64
    """
    if not all(isinstance(lt, PointLight) for lt in scene.lights):
        raise ValueError("single_scatter_quadrature supports point lights only")
    blockers = blockers_of(scene) if blockers is None else blockers
    med = scene.medium
    st, ss, g = med.sigma_t, med.sigma_s, med.phase.g
    o, d = np.asarray(o, float), np.asarray(d, float)
    s_min = np.asarray(s_min, float)
    length = np.clip(np.asarray(s_max, float) - s_min, 0.0, None)
    u, wu = gauss_legendre_panels(n)
    n_nodes = u.size
    out = np.zeros((o.shape[0], 3))
    step = max(1, _QUAD_CHUNK // n_nodes)
    for a in range(0, o.shape[0], step):
        sl = slice(a, a + step)
        c = o[sl].shape[0]
        s_rel = length[sl, None] * u[None]  # (c, n) distance past the box entry
        x = o[sl, None] + (s_min[sl, None] + s_rel)[..., None] * d[sl, None]
        cam = np.exp(-st * s_rel) * ss * wu[None] * length[sl, None]
        for lt in scene.lights:
            v = (x - lt.position).reshape(-1, 3)
            r = np.linalg.norm(v, axis=1)
            with np.errstate(divide="ignore", invalid="ignore"):
                mu = -_dot(v, np.repeat(d[sl], n_nodes, axis=0)) / r
                val = sampling.phase_value(mu, g) * np.exp(-st * r) / (r * r)
            val = np.where(r > 0, val, 0.0)
            vis = ~blockers.occluded(x.reshape(-1, 3), np.broadcast_to(lt.position, v.shape))
            radial = np.sum((cam.ravel() * val * vis).reshape(c, n_nodes), axis=1)
            out[sl] += radial[:, None] * lt.intensity[None]
    return out


def pixel_quadrature(scene: Scene, n_sub: int, n_nodes: int = 512,
                     pixels: np.ndarray | None = None,
                     rng: np.random.Generator | None = None) -> np.ndarray:
    """(H, W, 3) point-light single scattering averaged over each pixel's area (SCENES.md's
    box filter), each sub-pixel ray's line integral by :func:`single_scatter_quadrature`.

    Parameters
    ----------
    n_sub : int
        Sub-pixel points a side: the ``n_sub x n_sub`` Gauss-Legendre product rule, or with
        ``rng`` one uniform point in each of ``n_sub x n_sub`` strata (jittered: a pixel that
        holds a light's 1/r^2 peak, where a product rule converges erratically).
    n_nodes : int
        Quadrature nodes a ray.
    pixels : (Q,) int, optional
        Flat pixel indices to compute (the others stay 0); default all.
    """
    cam = scene.camera
    q = np.arange(cam.n_pixels) if pixels is None else np.asarray(pixels, np.int64)
    row, col = np.divmod(q, cam.width)
    if rng is None:
        xg, wg = np.polynomial.legendre.leggauss(n_sub)
        xg, wg = (xg + 1.0) / 2.0, wg / 2.0
        fx = np.broadcast_to(xg[None, :, None], (q.size, n_sub, n_sub)).ravel()
        fy = np.broadcast_to(xg[None, None, :], (q.size, n_sub, n_sub)).ravel()
        w = np.outer(wg, wg).ravel()
    else:
        g = np.arange(n_sub) / n_sub
        fx = (np.broadcast_to(g[None, :, None], (q.size, n_sub, n_sub)).ravel()
              + rng.random(q.size * n_sub * n_sub) / n_sub)
        fy = (np.broadcast_to(g[None, None, :], (q.size, n_sub, n_sub)).ravel()
              + rng.random(q.size * n_sub * n_sub) / n_sub)
        w = np.full(n_sub * n_sub, 1.0 / (n_sub * n_sub))
    px = np.repeat(col, n_sub * n_sub) + fx
    py = np.repeat(row, n_sub * n_sub) + fy
    d = pixel_directions(cam, px, py)
    o = np.broadcast_to(cam.position, d.shape).copy()
    bl = blockers_of(scene)
    s0, s1 = clip_rays(scene, o, d, bl)
    v = single_scatter_quadrature(scene, o, d, s0, s1, n=n_nodes, blockers=bl)
    out = np.zeros((cam.n_pixels, 3))
    out[q] = (v.reshape(q.size, n_sub * n_sub, 3) * w[None, :, None]).sum(axis=1)
    return out.reshape(cam.height, cam.width, 3)
