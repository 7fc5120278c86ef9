"""Reference renderer: a vectorized volumetric path tracer from the camera (the oracle).

This is the "reference" of ESTIMATORS.md section 4, independent of the photon techniques.
Every path segment (the camera ray's medium part, then each scattered ray up to its exit,
occluder or emitter) gets

* an **equiangular** direct-light sample (Kulla and Fajardo 2012): a light point by power
  and area, a distance on the segment with density proportional to ``1 / r^2`` about it,
  a shadow ray;
* the path's **next vertex**, at a distance drawn from the defensive mixture of free flight
  and equiangular sampling about a light centre (:func:`_sample_distance`), where
  **next-event estimation** (NEE: a light point by power and area) runs and the
  **scattering direction** is drawn from the defensive mixture of the phase function and a
  lobe aimed at a light (:func:`_scatter`); where that direction meets an emitter's front
  side first, it scores too.

The three direct-light techniques meet in the balance heuristic, their densities written in
the measure ``dt dA`` of (distance on the segment, point on the light) that they share
(:func:`_direct`); every contribution is bounded. Light sampling by area alone has infinite
variance near an emitter (the ``r^2 / cos`` of the area-to-solid-angle change): the hits of
sampled directions bound it. Point lights are deltas, reached by NEE and equiangular
sampling only; single-scattering point-light scenes use :func:`single_scatter_quadrature`.

Why the guidance (issue 15, measured in ``docs/reference.md`` with
``benchmarks/reference_dense.py``): in ``scenes/dense_mesh_light.toml`` (optical depth 9
across the box, a mesh light 0.15 in radius, an occluder, K = 1..4) the path tracer of
before (free-flight distances, phase-sampled directions, NEE + phase-sampled hits by MIS;
``strategy="mis-free-flight"``) was skewed per pixel exactly as reported: at 32x24 pixels
after 800 passes (240 s of 64x48 work) its median pixel sat 12 % below paper-full's and its
mean |z| against paper-full was 2.1 while the image sum agreed within 1 %. The cause is
where its vertices go, not its MIS: almost all emitted light first scatters within a mean
free path (0.22) of the small light, and a path from the camera reaches that glow only
through long free flights that happen to head for it. Those are rare (about
``exp(-st d)``) and carry weights of order 1 (free flight's ``Tr / pdf`` cancels the
transmittance), so their direct-light estimates are huge samples: one pass of 128 rays per
pixel at 64x48 had 0.1 % of its samples (emitter hits and NEE at vertices next to the light)
hold 15 % of the image, and in the dark half of the image NEE at K = 3, 4 held 58 % of the
second moment. Most pixels had not yet seen their share of such passes, so their means and
their variances were both too low. Not the cause: Russian roulette (off: ``max_scatter``
caps the depth), NEE's area sampling (half of the blob faces away: zeros, no tail), NEE +
hit MIS (bounded), single scattering (the quadrature tests pass for both samplers). The
equiangular samples, the guided directions and the guided distances each remove part of it
(the strategies ``mis-unguided``, ``mis-directions`` and ``mis`` isolate them); at equal
CPU time the current sampler's mean |z| is 0.92 and its median pixel is within 1 %.

All rays are traced at once as arrays; a path's scatter count ``k`` is the loop index, and
dead paths are compacted away after every vertex. Surfaces are black; light seen straight
from the camera (``k = 0``) is not counted (SCENES.md "What an image is"). Every random
number of a pass comes from the generator it is given.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from . import sampling
from .camera import Rays
from .constants import SHADOW_EPS
from .geometry import Blockers, blockers_of, ray_box, ray_parallelogram
from .scene import AreaLight, MeshLight, PointLight, Scene
from .trace import roulette_survival, trace_depth

#: What each strategy of :func:`reference_pass` does: its direct-light techniques (combined
#: by the balance heuristic: NEE at sampled vertices, emitter hits of sampled directions,
#: equiangular vertices; point lights cannot be hit, so without NEE or equiangular they use
#: NEE), whether scattering directions are guided towards the lights (:func:`_scatter`), and
#: whether the distances to the next vertex are (:func:`_sample_distance`). The default is
#: ``'mis'``; the others isolate one change each (the diagnosis in the module docstring).
_STRATEGIES = {
    "mis": (("nee", "phase", "equiangular"), True, True),
    "mis-directions": (("nee", "phase", "equiangular"), True, False),
    "mis-unguided": (("nee", "phase", "equiangular"), False, False),
    "mis-free-flight": (("nee", "phase"), False, False),
    "nee": (("nee",), False, False),
    "phase": (("phase",), False, False),
    "equiangular": (("equiangular",), False, False),
}

#: Strategies of :func:`reference_pass`.
STRATEGIES = tuple(_STRATEGIES)

#: Probability of sampling the phase function in the guided direction mixture (the rest:
#: towards a light); it bounds every direction weight ``rho / p`` by ``1 / GUIDE_PHASE``.
GUIDE_PHASE = 0.5

#: Probability of free flight in the guided distance mixture (the rest: equiangular about a
#: light centre); it bounds every distance weight ``Tr ss / p`` by ``albedo / GUIDE_FLIGHT``.
GUIDE_FLIGHT = 0.5

#: Version of the default sampler, part of a reference checkpoint's identity (a checkpoint
#: of another sampler must not be resumed: the result would not be any one run's).
SAMPLER = "mis-equiangular-guided-1"

#: Below this rate the guided lobe is sampled as uniform in the polar angle (its limit).
_LAM_MIN = 1e-9

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


@dataclass(frozen=True)
class _Use:
    """Which direct-light techniques run for one kind of light.

    ``nee``: a light point by area at a free-flight vertex; ``phase``: the scattering
    direction sampled at a free-flight vertex hits an emitter; ``ea``: an equiangular vertex
    on the segment about a light point chosen by area, then a shadow ray to that point.
    """

    nee: bool
    phase: bool
    ea: bool


@dataclass(frozen=True)
class _Plan:
    """What a strategy does (:data:`_STRATEGIES`).

    Attributes
    ----------
    area, point : _Use
        Direct-light techniques for area/mesh lights and for point lights (a delta cannot be
        hit by a sampled direction, so without NEE or equiangular it falls back to NEE).
    centres : (L, 3) float
        The point of each light that guided directions and distances aim at.
    directions, distances : bool
        Guided scattering directions; guided distances to the next vertex.
    """

    area: _Use
    point: _Use
    centres: np.ndarray
    directions: bool
    distances: bool

    @classmethod
    def of(cls, scene: Scene, strategy: str) -> _Plan:
        tech, directions, distances = _STRATEGIES[strategy]
        area = _Use("nee" in tech, "phase" in tech, "equiangular" in tech)
        point = _Use(area.nee or not area.ea, False, area.ea)
        return cls(area, point, _light_centres(scene), directions, distances)


@dataclass
class _LightPoints:
    """Points on the lights (sampled, or where a sampled direction hit an emitter).

    Attributes
    ----------
    y : (M, 3) float
        Point on the light (the position of a point light).
    le : (M, 3) float
        Radiance (area, mesh; 0 on an emitter's back side) or intensity (point).
    normal : (M, 3) float
        Emitting-side unit normal (zero for a point light).
    p_area : (M,) float
        Density of NEE's light point per unit area there, ``P_L / A_L`` (the probability
        ``P_L`` for a point light).
    point : (M,) bool
        Point light.
    """

    y: np.ndarray
    le: np.ndarray
    normal: np.ndarray
    p_area: np.ndarray
    point: np.ndarray

    @classmethod
    def empty(cls, m: int) -> _LightPoints:
        return cls(np.zeros((m, 3)), np.zeros((m, 3)), np.zeros((m, 3)), np.zeros(m),
                   np.zeros(m, dtype=bool))

    def take(self, idx: np.ndarray) -> _LightPoints:
        return _LightPoints(self.y[idx], self.le[idx], self.normal[idx], self.p_area[idx],
                            self.point[idx])


def _sample_light_points(scene: Scene, rng: np.random.Generator, m: int) -> _LightPoints:
    """``m`` light points: light ``L`` with probability ``P_L`` (power), then uniform by area."""
    pmf = scene.light_pmf
    choice = sampling.sample_discrete(pmf, rng, m)
    lp = _LightPoints.empty(m)
    for li, lt in enumerate(scene.lights):
        sel = np.flatnonzero(choice == li)
        if sel.size == 0:
            continue
        if isinstance(lt, PointLight):
            lp.y[sel] = lt.position
            lp.le[sel] = lt.intensity
            lp.p_area[sel] = pmf[li]
            lp.point[sel] = True
        elif isinstance(lt, AreaLight):
            uv = rng.random((sel.size, 2))
            lp.y[sel] = lt.corner + uv[:, :1] * lt.edge_u + uv[:, 1:] * lt.edge_v
            lp.le[sel] = lt.radiance
            lp.normal[sel] = lt.normal
            lp.p_area[sel] = pmf[li] / lt.area
        elif isinstance(lt, MeshLight):
            areas = lt.areas
            k = sampling.sample_discrete(areas / areas.sum(), rng, sel.size)
            b = sampling.sample_triangle_barycentric(rng, sel.size)
            v0, v1, v2 = (lt.triangles[k, i] for i in range(3))
            lp.y[sel] = v0 + b[:, :1] * (v1 - v0) + b[:, 1:] * (v2 - v0)
            lp.le[sel] = lt.radiance
            lp.normal[sel] = lt.normals[k]
            lp.p_area[sel] = pmf[li] / areas.sum()
        else:  # pragma: no cover - the scene loader admits no other light
            raise TypeError(f"unknown light {lt!r}")
    return lp


# --------------------------------------------------------------------------- guided directions
def _light_centres(scene: Scene) -> np.ndarray:
    """(L, 3) the point each light's guided lobe aims at: a point light's position, a
    parallelogram's centre, a mesh's area-weighted triangle centroid."""
    out = []
    for lt in scene.lights:
        if isinstance(lt, PointLight):
            out.append(lt.position)
        elif isinstance(lt, AreaLight):
            out.append(lt.corner + 0.5 * (lt.edge_u + lt.edge_v))
        else:
            a = lt.areas
            out.append((lt.triangles.mean(axis=1) * a[:, None]).sum(axis=0) / a.sum())
    return np.array(out, dtype=float).reshape(-1, 3)


def _guide_frame(st: float, centre: np.ndarray, x: np.ndarray):
    """Axis (unit direction from ``x`` (M, 3) to ``centre``; +z where they coincide) and the
    rate ``lam = st |centre - x|`` of the guided lobe about it."""
    v = centre - x
    d = np.sqrt(_dot(v, v))
    axis = np.where((d > 0)[:, None], v / np.where(d > 0, d, 1.0)[:, None], (0.0, 0.0, 1.0))
    return axis, st * d


def _sample_guided(scene: Scene, centres: np.ndarray, x: np.ndarray,
                   rng: np.random.Generator) -> np.ndarray:
    """Directions aimed at the lights (a light by power, then a lobe about its centre).

    The polar angle ``theta`` about the direction to the centre has density
    ``lam exp(-lam theta) / (1 - exp(-lam pi))`` on ``[0, pi]`` (``lam = st d``, ``d`` the
    distance to the centre; uniform as ``lam -> 0``), the azimuth is uniform. Why this shape:
    the direct light gathered along a segment leaving ``x`` at a small angle ``theta`` to a
    small light is about ``pi / (d theta)`` (the equiangular integral of ``1 / r^2``) times
    ``exp(-st d theta)`` (the detour's extra transmittance); per unit solid angle
    ``sin theta dtheta dphi`` that is proportional to this density.

    Returns
    -------
    (M, 3) float
        Unit directions.
    """
    m = x.shape[0]
    choice = sampling.sample_discrete(scene.light_pmf, rng, m)
    axis, lam = _guide_frame(scene.medium.sigma_t, centres[choice], x)
    u = rng.random(m)
    with np.errstate(divide="ignore", invalid="ignore"):
        th = np.where(lam > _LAM_MIN, -np.log1p(u * np.expm1(-lam * np.pi)) / lam, np.pi * u)
    return sampling.direction_about(axis, np.cos(th), 2.0 * np.pi * rng.random(m))


def _guided_pdf(scene: Scene, centres: np.ndarray, x: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Solid-angle density (1/sr) of :func:`_sample_guided` at unit directions ``w`` (M, 3)
    leaving ``x`` (M, 3): the light mixture of ``p(theta) / (2 pi sin theta)``."""
    pmf = scene.light_pmf
    out = np.zeros(x.shape[0])
    for li in range(centres.shape[0]):
        axis, lam = _guide_frame(scene.medium.sigma_t, centres[li], x)
        sin = np.linalg.norm(np.cross(w, axis), axis=1)
        th = np.arctan2(sin, _dot(w, axis))
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            p_th = np.where(lam > _LAM_MIN, lam * np.exp(-lam * th) / -np.expm1(-lam * np.pi),
                            1.0 / np.pi)
            out += pmf[li] * p_th / (2.0 * np.pi * sin)
    return out


def _direction_pdf(scene: Scene, plan: _Plan, x, w_in, w) -> tuple[np.ndarray, np.ndarray]:
    """Phase value ``rho(w_in . w)`` and the density the strategy samples scattering
    directions ``w`` with at ``x``: ``rho`` itself, or the defensive mixture
    ``GUIDE_PHASE rho + (1 - GUIDE_PHASE) p_guided``."""
    rho = sampling.phase_value(_dot(w_in, w), scene.medium.phase.g)
    if not plan.directions:
        return rho, rho
    p = GUIDE_PHASE * rho + (1.0 - GUIDE_PHASE) * _guided_pdf(scene, plan.centres, x, w)
    return rho, p


def _scatter(scene: Scene, plan: _Plan, x, w_in, rng):
    """Sample the scattering direction at vertices ``x`` reached along ``w_in``.

    Returns
    -------
    w : (M, 3) float
        New propagation directions.
    p : (M,) float
        Their solid-angle density.
    weight : (M,) float
        ``rho / p`` (1 for phase sampling alone; at most ``1 / GUIDE_PHASE`` guided).
    """
    g = scene.medium.phase.g
    if not plan.directions:
        w = sampling.sample_phase(w_in, g, rng)
        rho = sampling.phase_value(_dot(w_in, w), g)
        return w, rho, np.ones(x.shape[0])
    phase = rng.random(x.shape[0]) < GUIDE_PHASE
    w = np.empty_like(w_in)
    w[phase] = sampling.sample_phase(w_in[phase], g, rng)
    w[~phase] = _sample_guided(scene, plan.centres, x[~phase], rng)
    rho, p = _direction_pdf(scene, plan, x, w_in, w)
    with np.errstate(divide="ignore", invalid="ignore"):
        weight = np.where(p > 0, rho / p, 0.0)
    return w, p, weight


# --------------------------------------------------------------------------- guided distances
def _centre_frames(plan: _Plan, o, w, t_end):
    """:func:`_equiangular_frame` of every light centre on the segments (one tuple per
    light); ``h`` is kept away from 0 (a segment through a centre: a measure-zero event)."""
    frames = []
    for c in plan.centres:
        delta, h, _, _ = _equiangular_frame(o, w, t_end, np.broadcast_to(c, o.shape))
        h = np.maximum(h, 1e-12)
        frames.append((delta, h, np.arctan2(-delta, h), np.arctan2(t_end - delta, h)))
    return frames


def _distance_density(scene: Scene, plan: _Plan, o, w, t_end, t) -> np.ndarray:
    """Density of :func:`_sample_distance` at distances ``t`` (M,) of segments ``o + t w``
    with free length ``t_end``, divided by the transmittance ``exp(-st t)`` (``st`` for free
    flight alone): what the vertex techniques' MIS densities and the distance weight
    ``ss / density`` need, without overflow or underflow of either factor."""
    st = scene.medium.sigma_t
    if not plan.distances:
        return np.full(np.shape(t), st)
    ea = np.zeros(np.shape(t))
    for p_l, (delta, h, th_a, th_b) in zip(scene.light_pmf, _centre_frames(plan, o, w, t_end),
                                           strict=True):
        with np.errstate(divide="ignore", invalid="ignore"):
            p = h / ((th_b - th_a) * (h * h + (t - delta) ** 2))
        ea += p_l * np.where(th_b > th_a, p, 0.0)
    with np.errstate(over="ignore", invalid="ignore"):
        return GUIDE_FLIGHT * st + (1.0 - GUIDE_FLIGHT) * np.where(ea > 0, ea * np.exp(st * t),
                                                                     0.0)


def _sample_distance(scene: Scene, plan: _Plan, o, w, t_end, rng):
    """The distance to the next vertex on each segment.

    Free flight (density ``st exp(-st t)``; a vertex only where ``t < t_end``), or, guided,
    the defensive mixture of free flight and equiangular sampling about a light centre
    (light by power): a path heading for a light can then reach it in one step, carrying
    the transmittance in its weight, instead of reaching it only by the rare free flights
    that happen to be long (whose weight ignores the transmittance).

    Returns
    -------
    t : (M,) float
        Distances (``>= t_end``: no vertex, the path leaves the segment).
    density : (M,) float
        :func:`_distance_density` at ``t``.
    """
    st = scene.medium.sigma_t
    m = o.shape[0]
    if not plan.distances:
        return sampling.sample_free_flight(st, rng, m), np.full(m, st)
    flight = rng.random(m) < GUIDE_FLIGHT
    t = np.empty(m)
    t[flight] = sampling.sample_free_flight(st, rng, int(flight.sum()))
    ea = np.flatnonzero(~flight)
    choice = sampling.sample_discrete(scene.light_pmf, rng, ea.size)
    u = rng.random(ea.size)
    frames = _centre_frames(plan, o[ea], w[ea], t_end[ea])
    for li, (delta, h, th_a, th_b) in enumerate(frames):
        sel = choice == li
        t[ea[sel]] = np.clip(delta[sel] + h[sel] * np.tan(th_a[sel] + u[sel] * (th_b[sel]
                                                                                - th_a[sel])),
                             0.0, t_end[ea[sel]])
    return t, _distance_density(scene, plan, o, w, t_end, t)


# --------------------------------------------------------------------------- direct light
def _equiangular_frame(o, w, t_end, y):
    """Where light points sit relative to segments ``o + t w``, ``0 <= t <= t_end``.

    Returns
    -------
    delta, h : (M,) float
        Distance along ``w`` to the foot of the perpendicular from ``y``, and its length.
    th_a, th_b : (M,) float
        Angles (at ``y``, from the perpendicular) of the segment's ends: the equiangular
        density on the segment is ``h / ((th_b - th_a) (h^2 + (t - delta)^2))``.
    """
    v = y - o
    delta = _dot(v, w)
    h = np.sqrt(np.clip(_dot(v, v) - delta * delta, 0.0, None))
    return delta, h, np.arctan2(-delta, h), np.arctan2(t_end - delta, h)


def _direct(scene, plan, by, w, t, t_end, frame, dens, x, lp, beta):
    """Balance-heuristic contribution of direct-light samples of segments (no visibility).

    A sample is a vertex at distance ``t`` on a segment (arriving along ``w``) and a point
    ``y`` on a light, in the measure ``dt dA(y)`` shared by the three techniques. Their
    densities, each multiplied by ``r^2 / Tr(t)`` (``r = |y - x|``, ``Tr(t) = exp(-st t)``)
    so that no term is singular or underflows (``p_t``: the density the path's next vertex
    is sampled with, :func:`_sample_distance`; ``dens = p_t / Tr``, ``st`` for free flight):

    * NEE at the path's vertex: ``p_t(t) p_A r^2 / Tr = dens p_A r^2``,
    * the scattering direction sampled at the path's vertex hits ``y``:
      ``dens p_w cos_L`` (``p_w``: the direction density, the phase function or the guided
      mixture, :func:`_direction_pdf`),
    * an equiangular vertex about ``y``, with ``y`` by area: ``p_A h / ((th_b - th_a) Tr)``.

    The integrand times the same factor is ``beta ss rho cos_L exp(-st r) Le``, so wherever
    NEE or the hit technique is enabled every contribution is at most
    ``beta (ss / st) Le / (GUIDE_FLIGHT GUIDE_PHASE)`` (without the guided mixtures,
    ``beta (ss / st) Le``): bounded, whatever the geometry.

    Parameters
    ----------
    plan : _Plan
    by : {'nee', 'phase', 'ea'}
        The technique that drew the samples (contributions are 0 where it is not enabled).
    w : (M, 3) float
        Unit direction of each segment.
    t, t_end : (M,) float
        Vertex distance along the segment and the segment's free length.
    frame : tuple of (M,) float
        :func:`_equiangular_frame` of ``lp.y`` on the segments.
    dens : (M,) float
        :func:`_distance_density` of the segments at ``t``.
    x : (M, 3) float
        The vertices ``o + t w``.
    lp : _LightPoints
    beta : (M,) float
        Path throughput at the segment's origin (before this segment's free flight).

    Returns
    -------
    (M, 3) float
        Radiance towards the camera (RGB).
    """
    _, h, th_a, th_b = frame
    st = scene.medium.sigma_t
    v = lp.y - x
    r2 = _dot(v, v)
    r = np.sqrt(r2)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        u = v / r[:, None]
        # One-sided emitters: cos_L > 0 on the front only; 1 for point lights.
        cos_l = np.where(lp.point, 1.0, -_dot(u, lp.normal))
        rho, p_w = _direction_pdf(scene, plan, x, w, u)
        ea_term = lp.p_area * h / (th_b - th_a) * np.exp(st * t)
    on = {name: np.where(lp.point, getattr(plan.point, name), getattr(plan.area, name))
          for name in ("nee", "phase", "ea")}
    denom = np.where(on["nee"], dens * lp.p_area * r2, 0.0)
    denom += np.where(on["phase"], dens * p_w * cos_l, 0.0)
    denom += np.where(on["ea"] & (th_b > th_a), ea_term, 0.0)
    live = on[by] & (r > 0) & (cos_l > 0) & (denom > 0) & (t >= 0) & (t < t_end)
    j = np.flatnonzero(live)
    out = np.zeros((r.size, 3))
    val = beta[j] * scene.medium.sigma_s * rho[j] * cos_l[j] * np.exp(-st * r[j]) / denom[j]
    out[j] = val[:, None] * lp.le[j]
    return out


def _shadowed(out, x, y, blockers):
    """Zero the contributions (M, 3) whose shadow segment ``x -> y`` is blocked."""
    idx = np.flatnonzero(np.any(out > 0, axis=1))
    out[idx[blockers.occluded(x[idx], y[idx])]] = 0.0
    return out


def _nee(scene, plan, w, t_end, t, dens, x, beta, rng, blockers):
    """Next-event estimates at the path's vertices ``x`` (M, 3), reached at distance ``t``
    along segments of direction ``w`` and free length ``t_end`` (``dens``: their
    :func:`_distance_density`); ``beta`` is the throughput at the segments' origins.
    Returns (M, 3)."""
    lp = _sample_light_points(scene, rng, x.shape[0])
    frame = _equiangular_frame(x - t[:, None] * w, w, t_end, lp.y)
    return _shadowed(_direct(scene, plan, "nee", w, t, t_end, frame, dens, x, lp, beta), x,
                     lp.y, blockers)


def _equiangular(scene, plan, o, w, t_end, beta, rng, blockers):
    """Equiangular direct-light samples, one per segment (Kulla and Fajardo 2012).

    A light point ``y`` is chosen by power and area, then a distance on the segment with
    density proportional to ``1 / |o + t w - y|^2``: vertices land where the light is close,
    whatever the free-flight density says. Drawn for every segment, whether or not its free
    flight produced a vertex. Returns (M, 3).
    """
    m = o.shape[0]
    lp = _sample_light_points(scene, rng, m)
    frame = delta, h, th_a, th_b = _equiangular_frame(o, w, t_end, lp.y)
    th = th_a + rng.random(m) * (th_b - th_a)
    t = np.clip(delta + h * np.tan(th), 0.0, t_end)
    x = o + t[:, None] * w
    dens = _distance_density(scene, plan, o, w, t_end, t)
    return _shadowed(_direct(scene, plan, "ea", w, t, t_end, frame, dens, x, lp, beta), x,
                     lp.y, blockers)


def _emitter_hits(scene, x, w):
    """Nearest front- or back-side hit of sampled directions with any area or mesh light.

    Returns
    -------
    t : (M,) float
        Hit distance (``inf`` on a miss).
    lp : _LightPoints
        The hit points, their light's radiance (0 on a back side or a miss), normal and
        ``P_L / A_L`` (what NEE's and equiangular sampling's densities need there).
    """
    m = x.shape[0]
    pmf = scene.light_pmf
    t_best = np.full(m, np.inf)
    lp = _LightPoints.empty(m)
    for li, lt in enumerate(scene.lights):
        if isinstance(lt, AreaLight):
            t = ray_parallelogram(x, w, lt.corner, lt.edge_u, lt.edge_v)
            t = np.where(t > SHADOW_EPS, t, np.inf)
            nrm = np.broadcast_to(lt.normal, (m, 3))
        elif isinstance(lt, MeshLight):
            t, k = _ray_mesh(x, w, lt.triangles)
            nrm = lt.normals[np.maximum(k, 0)]
        else:
            continue
        near = t < t_best
        t_best = np.where(near, t, t_best)
        front = near & (_dot(w, nrm) < 0)
        lp.le[near] = np.where(front[near, None], lt.radiance, 0.0)
        lp.normal[near] = nrm[near]
        lp.p_area[near] = pmf[li] / lt.area
    hit = np.isfinite(t_best)
    lp.y[hit] = x[hit] + t_best[hit, None] * w[hit]
    return t_best, lp


def _add(out, rays, values, tally, k, technique) -> None:
    """``out[rays] += values`` (ray indices are unique within a batch), shown to ``tally``."""
    if tally is not None:
        tally(k, technique, rays, values)
    out[rays] += values


def reference_pass(
    scene: Scene,
    rays: Rays,
    rng: np.random.Generator,
    blockers: Blockers | None = None,
    *,
    strategy: str = "mis",
    tally: Callable[[int, str, np.ndarray, np.ndarray], None] | None = None,
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
        Every random number of the pass comes from it (same state, same estimate).
    blockers : Blockers, optional
        ``blockers_of(scene)`` (pass it to avoid rebuilding).
    strategy : str
        One of :data:`STRATEGIES` (all unbiased): ``'mis'`` (the default: NEE, emitter hits
        of the sampled directions and equiangular vertices by the balance heuristic, with
        guided scattering directions), ``'mis-unguided'`` (the same with phase-sampled
        directions), ``'mis-free-flight'`` (NEE and phase-sampled hits at free-flight
        vertices only: the reference before issue 15), or one technique alone with
        phase-sampled directions, ``'nee'``, ``'phase'`` or ``'equiangular'`` ('nee' alone
        has infinite variance near area/mesh emitters).
    tally : callable(k, technique, rays, values), optional
        Sees every batch of direct-light contributions before it is added: the scatter
        count ``k``, the technique (``'nee'``, ``'phase'``: an emitter hit of a sampled
        direction, ``'ea'``: an equiangular vertex), the camera-ray indices (M,) and the
        (M, 3) values (what ``benchmarks/reference_dense.py`` breaks the image down by).

    Returns
    -------
    (N, 3) float64
        Radiance estimate per ray (RGB); average per pixel for the image.
    """
    if strategy not in STRATEGIES:
        raise ValueError(f"strategy must be one of {STRATEGIES}, got {strategy!r}")
    blockers = blockers_of(scene) if blockers is None else blockers
    med = scene.medium
    k_max = trace_depth(scene)
    plan = _Plan.of(scene, strategy)
    points = any(isinstance(lt, PointLight) for lt in scene.lights)
    nee = plan.area.nee or (plan.point.nee and points)
    # Emitter hits of sampled directions matter only with area/mesh lights.
    hits = plan.area.phase and any(not isinstance(lt, PointLight) for lt in scene.lights)
    out = np.zeros((len(rays), 3))

    # Segment 1 is the camera ray's medium part: from the box entry to the exit or the first
    # (black or emitting, not counted at k = 0) surface. Segment k + 1 leaves vertex k.
    seg = np.flatnonzero(rays.s_max > rays.s_min)
    seg_o = rays.o[seg] + rays.s_min[seg, None] * rays.d[seg]
    seg_w = rays.d[seg]
    seg_tend = (rays.s_max - rays.s_min)[seg]
    beta = np.ones(seg.size)  # throughput at the segment's origin
    k = 1
    while seg.size:
        counts = k >= scene.min_scatter
        if counts and plan.area.ea:
            val = _equiangular(scene, plan, seg_o, seg_w, seg_tend, beta, rng, blockers)
            _add(out, seg, val, tally, k, "ea")
        t, dens = _sample_distance(scene, plan, seg_o, seg_w, seg_tend, rng)
        go = np.flatnonzero(t < seg_tend)
        idx, w, tend, t, dens, beta = (a[go] for a in (seg, seg_w, seg_tend, t, dens, beta))
        x = seg_o[go] + t[:, None] * w
        if counts and nee:
            val = _nee(scene, plan, w, tend, t, dens, x, beta, rng, blockers)
            _add(out, idx, val, tally, k, "nee")
        if k >= k_max and not (hits and counts):
            break
        # Roulette once per vertex, before sampling its direction (depth only, as trace).
        q = roulette_survival(scene, k)
        if q < 1.0:
            keep = rng.random(idx.size) < q
            idx, w, tend, t, dens, beta, x = (a[keep] for a in (idx, w, tend, t, dens, beta, x))
            beta = beta / q
        w_new, _, w_weight = _scatter(scene, plan, x, w, rng)
        _, t_box = ray_box(x, w_new, med.bounds_min, med.bounds_max)
        t_next = np.minimum(t_box, blockers.first_hit(x, w_new))
        if hits and counts:
            t_e, lp = _emitter_hits(scene, x, w_new)
            # The emitter is the first surface iff nothing nearer (tolerance for rounding).
            j = np.flatnonzero(np.isfinite(t_e) & (t_e <= t_next * (1 + 1e-9) + 1e-12))
            if j.size:
                # Transmittance analytic: the emitter is inside the (convex) box.
                lj = lp.take(j)
                frame = _equiangular_frame(x[j] - t[j, None] * w[j], w[j], tend[j], lj.y)
                val = _direct(scene, plan, "phase", w[j], t[j], tend[j], frame, dens[j], x[j],
                              lj, beta[j])
                _add(out, idx[j], val, tally, k, "phase")
            t_next = np.minimum(t_next, t_e)
        if k >= k_max:
            break
        seg, seg_o, seg_w, seg_tend = idx, x, w_new, t_next
        # Tr ss / p_t (albedo for free flight alone) times rho / p_w.
        beta = beta * (med.sigma_s / dens) * w_weight
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
