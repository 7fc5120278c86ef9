"""Reference renderer: a vectorized volumetric path tracer from the camera (the oracle).

This is the "reference" of ESTIMATORS.md section 4, independent of the photon techniques:
free-flight sampling along the camera ray and from every scattering vertex, next-event
estimation (NEE) to one light chosen by power, and, for area and mesh lights, phase-sampled
rays that hit an emitter's front side, combined with NEE by the balance heuristic (as
Mitsuba's volpath). Light sampling by area alone has infinite variance near an emitter
(the ``r^2 / cos`` of the area-to-solid-angle change); the phase-sampled hits bound it.
Point lights are deltas, so they are reached by NEE only; NEE to a point light still has
infinite variance for two or more scattering events (and in the light's own pixel), so
point-light scenes use :func:`single_scatter_quadrature` as their oracle instead.

All rays are traced at once as arrays; a path's scatter count ``k`` is the loop index, and
dead paths are compacted away after every vertex. Surfaces are black; light seen straight
from the camera (``k = 0``) is not counted (SCENES.md "What an image is").
"""

from __future__ import annotations

import numpy as np

from . import sampling
from .camera import Rays
from .constants import SHADOW_EPS
from .geometry import Blockers, blockers_of, ray_box, ray_parallelogram
from .scene import AreaLight, MeshLight, PointLight, Scene
from .trace import roulette_survival, trace_depth

#: Strategies of :func:`reference_pass`: balance-heuristic MIS, light sampling only, or
#: phase-sampled emitter hits only (point lights always use NEE: a delta cannot be hit).
STRATEGIES = ("mis", "nee", "phase")

#: Ray x triangle elements per chunk of the emitter-mesh test.
_TRI_CHUNK = 1 << 18

#: Quadrature points (rays x nodes) per chunk of :func:`single_scatter_quadrature`.
_QUAD_CHUNK = 1 << 18


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("ij,ij->i", a, b)


def _ray_mesh(o: np.ndarray, d: np.ndarray, tris: np.ndarray):
    """Nearest triangle hit beyond ``SHADOW_EPS`` (Moller-Trumbore) and its index.

    ``geometry.ray_triangles_first`` returns only the distance; the emitter test also needs
    which triangle was hit (its normal decides the side, its light the radiance).

    Parameters
    ----------
    o, d : (N, 3) float
    tris : (F, 3, 3) float

    Returns
    -------
    t : (N,) float
        ``inf`` where no triangle is hit.
    tri : (N,) int
        Hit triangle, ``-1`` where none.
    """
    n, f = o.shape[0], tris.shape[0]
    best_t, best_k = np.full(n, np.inf), np.full(n, -1, dtype=np.int64)
    v0, e1, e2 = tris[:, 0], tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
    step = max(1, _TRI_CHUNK // max(f, 1))
    for a in range(0, n, step):
        oo, dd = o[a : a + step, None, :], d[a : a + step, None, :]
        p = np.cross(dd, e2[None])
        det = np.sum(p * e1[None], axis=-1)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            tv = oo - v0[None]
            u = np.sum(tv * p, axis=-1) * inv
            q = np.cross(tv, e1[None])
            v = np.sum(dd * q, axis=-1) * inv
            t = np.sum(q * e2[None], axis=-1) * inv
        ok = (np.abs(det) > 1e-14) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > SHADOW_EPS)
        t = np.where(ok, t, np.inf)
        k = np.argmin(t, axis=1)
        tk = t[np.arange(t.shape[0]), k]
        best_t[a : a + step] = tk
        best_k[a : a + step] = np.where(np.isfinite(tk), k, -1)
    return best_t, best_k


def _nee(scene, x, w_cur, beta, rng, blockers, strategy):
    """Next-event estimate at scattering vertices (one light chosen by power per vertex).

    Parameters
    ----------
    x, w_cur : (M, 3) float
        Vertices and the backward (camera-to-vertex) direction that reached them.
    beta : (M,) float
        Grey path throughput up to and including the scattering at ``x`` (``ss/st``).

    Returns
    -------
    (M, 3) float
        Radiance contribution towards the camera (RGB).
    """
    m = x.shape[0]
    med = scene.medium
    pmf = scene.light_pmf
    choice = sampling.sample_discrete(pmf, rng, m)
    x_l = np.zeros((m, 3))
    le = np.zeros((m, 3))  # radiance (area/mesh) or intensity (point)
    cos_l = np.ones(m)  # cosine at the light (1 for points)
    area = np.zeros(m)  # total emitting area of the chosen light (0 marks a point light)
    for li, lt in enumerate(scene.lights):
        sel = np.flatnonzero(choice == li)
        if sel.size == 0:
            continue
        if isinstance(lt, PointLight):
            x_l[sel] = lt.position
            le[sel] = lt.intensity
        elif isinstance(lt, AreaLight):
            uv = rng.random((sel.size, 2))
            x_l[sel] = lt.corner + uv[:, :1] * lt.edge_u + uv[:, 1:] * lt.edge_v
            le[sel] = lt.radiance
            cos_l[sel] = _dot(x[sel] - x_l[sel], np.broadcast_to(lt.normal, (sel.size, 3)))
            area[sel] = lt.area
        elif isinstance(lt, MeshLight):
            k = sampling.sample_discrete(lt.areas / lt.area, rng, sel.size)
            b = sampling.sample_triangle_barycentric(rng, sel.size)
            v0, v1, v2 = (lt.triangles[k, i] for i in range(3))
            x_l[sel] = v0 + b[:, :1] * (v1 - v0) + b[:, 1:] * (v2 - v0)
            le[sel] = lt.radiance
            cos_l[sel] = _dot(x[sel] - x_l[sel], lt.normals[k])
            area[sel] = lt.area
        else:  # pragma: no cover - the scene loader admits no other light
            raise TypeError(f"unknown light {lt!r}")
    v = x_l - x
    r2 = _dot(v, v)
    r = np.sqrt(r2)
    is_point = area == 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        cos_l = np.where(is_point, 1.0, cos_l / r)  # one-sided: > 0 only on the front
        rho = sampling.phase_value(_dot(v, w_cur) / r, med.phase.g)
    p_l = pmf[choice]
    live = (r > 0) & (cos_l > 0)
    if strategy == "phase":
        live &= is_point  # area/mesh light is left to the phase-sampled hits
    idx = np.flatnonzero(live)
    idx = idx[~blockers.occluded(x[idx], x_l[idx])]
    out = np.zeros((m, 3))
    if idx.size == 0:
        return out
    base = beta[idx] * rho[idx] * np.exp(-med.sigma_t * r[idx])
    ca = cos_l[idx] * area[idx]
    pt = is_point[idx]
    # Solid-angle pdfs times cos_L: NEE p_l r^2 / A, phase rho cos_L. The product form keeps
    # the balance-heuristic weight finite as cos_L -> 0 or r -> 0.
    if strategy == "mis":
        denom = np.where(pt, p_l[idx] * r2[idx], p_l[idx] * r2[idx] + rho[idx] * ca)
    else:
        denom = p_l[idx] * r2[idx]
    out[idx] = (base * np.where(pt, 1.0, ca) / denom)[:, None] * le[idx]
    return out


def _emitter_hits(scene, x, w):
    """Nearest front- or back-side hit of phase-sampled rays with any area or mesh light.

    Returns
    -------
    t : (M,) float
        Hit distance (``inf`` on a miss).
    le, cos_area_over_pl : (M, 3), (M,) float
        Radiance of the hit light (0 on its back side or a miss), and ``cos_L A / P_L``
        (``A``: that light's total area, so ``P_L / A`` is NEE's area density).
    """
    m = x.shape[0]
    pmf = scene.light_pmf
    t_best = np.full(m, np.inf)
    le = np.zeros((m, 3))
    cap = np.zeros(m)
    for li, lt in enumerate(scene.lights):
        if isinstance(lt, AreaLight):
            t = ray_parallelogram(x, w, lt.corner, lt.edge_u, lt.edge_v)
            t = np.where(t > SHADOW_EPS, t, np.inf)
            cos = -(w @ lt.normal)
        elif isinstance(lt, MeshLight):
            t, k = _ray_mesh(x, w, lt.triangles)
            cos = -_dot(w, lt.normals[np.maximum(k, 0)])
        else:
            continue
        near = t < t_best
        t_best = np.where(near, t, t_best)
        front = near & (cos > 0)
        le[near] = np.where(front[near, None], lt.radiance, 0.0)
        cap[near] = np.where(front[near], cos[near] * lt.area / pmf[li], 0.0)
    return t_best, le, cap


def reference_pass(
    scene: Scene,
    rays: Rays,
    rng: np.random.Generator,
    blockers: Blockers | None = None,
    *,
    strategy: str = "mis",
) -> np.ndarray:
    """One path-traced radiance estimate per camera ray.

    Only paths with ``scene.min_scatter <= k <= scene.max_scatter`` scattering events count
    (``max_scatter = -1``: unlimited, Russian roulette by depth as in ``trace``, capped at
    ``trace_depth``).

    Parameters
    ----------
    scene : Scene
    rays : Rays
        N camera rays; the medium part of ray ``i`` is ``[s_min[i], s_max[i]]``.
    rng : numpy.random.Generator
    blockers : Blockers, optional
        ``blockers_of(scene)`` (pass it to avoid rebuilding).
    strategy : {'mis', 'nee', 'phase'}
        Balance heuristic of light sampling and phase-sampled emitter hits, or one of them
        alone (all unbiased; 'nee' alone has infinite variance near area/mesh emitters).

    Returns
    -------
    (N, 3) float64
        Radiance estimate per ray (RGB); average per pixel for the image.
    """
    if strategy not in STRATEGIES:
        raise ValueError(f"strategy must be one of {STRATEGIES}, got {strategy!r}")
    blockers = blockers_of(scene) if blockers is None else blockers
    med = scene.medium
    st, g, alb = med.sigma_t, med.phase.g, med.albedo
    k_max = trace_depth(scene)
    # Phase-sampled emitter hits matter only with area/mesh lights and a phase strategy.
    hits = strategy != "nee" and any(not isinstance(lt, PointLight) for lt in scene.lights)
    n = len(rays)
    out = np.zeros((n, 3))

    # First vertex: free flight from the box entry; past s_max the path left the box or
    # met a (black or emitting, not counted at k = 0) surface.
    s = rays.s_min + sampling.sample_free_flight(st, rng, n)
    idx = np.flatnonzero(s < rays.s_max)
    x = rays.o[idx] + s[idx, None] * rays.d[idx]
    w_cur = rays.d[idx]
    beta = np.full(idx.size, alb)  # exp(-st t) ss / (st exp(-st t))
    k = 1
    while idx.size:
        counts = k >= scene.min_scatter
        if counts:
            out[idx] += _nee(scene, x, w_cur, beta, rng, blockers, strategy)
        if k >= k_max and not (hits and counts):
            break
        # Roulette once per vertex, before sampling its direction (depth only, as trace).
        q = roulette_survival(scene, k)
        if q < 1.0:
            keep = rng.random(idx.size) < q
            idx, x, w_cur, beta = idx[keep], x[keep], w_cur[keep], beta[keep] / q
        w_new = sampling.sample_phase(w_cur, g, rng)  # pdf rho(w_new . w_cur), weight 1
        _, t_box = ray_box(x, w_new, med.bounds_min, med.bounds_max)
        t_end = np.minimum(t_box, blockers.first_hit(x, w_new))
        if hits and counts:
            t_e, le, cap = _emitter_hits(scene, x, w_new)
            # The emitter is the first surface iff nothing nearer (tolerance for rounding).
            hit = np.isfinite(t_e) & (t_e <= t_end * (1 + 1e-9) + 1e-12) & (cap > 0)
            t_end = np.minimum(t_end, t_e)
            j = np.flatnonzero(hit)
            if j.size:
                # Transmittance analytic: the emitter is inside the (convex) box.
                wgt = beta[j] * np.exp(-st * t_e[j])
                if strategy == "mis":
                    rho = sampling.phase_value(_dot(w_new[j], w_cur[j]), g)
                    wgt = wgt * rho * cap[j] / (rho * cap[j] + t_e[j] ** 2)
                out[idx[j]] += wgt[:, None] * le[j]
        if k >= k_max:
            break
        t = sampling.sample_free_flight(st, rng, idx.size)
        go = t < t_end
        idx, w_cur, beta = idx[go], w_new[go], beta[go] * alb
        x = x[go] + t[go, None] * w_cur
        k += 1
    return out


def reference_image(
    scene: Scene,
    rays: Rays,
    rng: np.random.Generator,
    blockers: Blockers | None = None,
    *,
    strategy: str = "mis",
) -> np.ndarray:
    """:func:`reference_pass` averaged per pixel.

    Parameters
    ----------
    rays : Rays
        ``rays.spp`` rays for every pixel (as from ``camera_rays``).

    Returns
    -------
    (H, W, 3) float64
        Pixels without rays are 0.
    """
    cam = scene.camera
    est = reference_pass(scene, rays, rng, blockers, strategy=strategy)
    img = np.stack(
        [np.bincount(rays.pixel, weights=est[:, c], minlength=cam.n_pixels) for c in range(3)],
        axis=-1,
    )
    return img.reshape(cam.height, cam.width, 3) / rays.spp


def _gauss_legendre_panels(n: int, order: int = 8):
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
    u, wu = _gauss_legendre_panels(n)
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
