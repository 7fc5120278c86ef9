"""Where the reference renderer's paths go (:mod:`psurf_core.reference`): the strategies'
plans (:class:`Plan`), the scattering directions (:func:`scatter`: the phase function, or
its defensive mixture with a lobe aimed at a light) and the distances to the next vertex
(:func:`sample_distance`: free flight, or its defensive mixture with equiangular sampling
about a light centre), each with the density it samples by.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import sampling
from .reference_lights import light_centres
from .scene import Scene

__all__ = ["GUIDE_FLIGHT", "GUIDE_PHASE", "PLANS", "Plan", "Use", "direction_pdf",
           "distance_density", "equiangular_frame", "sample_distance", "scatter"]

#: What each strategy of :func:`psurf_core.reference.reference_pass` does: its direct-light
#: techniques (combined by the balance heuristic: NEE at sampled vertices, emitter hits of
#: sampled directions, equiangular vertices; point lights cannot be hit, so without NEE or
#: equiangular they use NEE), whether scattering directions are guided towards the lights
#: (:func:`scatter`), and whether the distances to the next vertex are
#: (:func:`sample_distance`). The default is ``'mis'``; the others isolate one change each
#: (the diagnosis in :mod:`psurf_core.reference`'s docstring).
PLANS = {
    "mis": (("nee", "phase", "equiangular"), True, True),
    "mis-directions": (("nee", "phase", "equiangular"), True, False),
    "mis-unguided": (("nee", "phase", "equiangular"), False, False),
    "mis-free-flight": (("nee", "phase"), False, False),
    "nee": (("nee",), False, False),
    "phase": (("phase",), False, False),
    "equiangular": (("equiangular",), False, False),
}

#: Probability of sampling the phase function in the guided direction mixture (the rest:
#: towards a light); it bounds every direction weight ``rho / p`` by ``1 / GUIDE_PHASE``.
GUIDE_PHASE = 0.5

#: Probability of free flight in the guided distance mixture (the rest: equiangular about a
#: light centre); it bounds every distance weight ``Tr ss / p`` by ``albedo / GUIDE_FLIGHT``.
GUIDE_FLIGHT = 0.5

#: Below this rate the guided lobe is sampled as uniform in the polar angle (its limit).
_LAM_MIN = 1e-9


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("ij,ij->i", a, b)


@dataclass(frozen=True)
class Use:
    """Which direct-light techniques run for one kind of light.

    ``nee``: a light point by area at a free-flight vertex; ``phase``: the scattering
    direction sampled at a free-flight vertex hits an emitter; ``ea``: an equiangular vertex
    on the segment about a light point chosen by area, then a shadow ray to that point.
    """

    nee: bool
    phase: bool
    ea: bool


@dataclass(frozen=True)
class Plan:
    """What a strategy does (:data:`PLANS`).

    Attributes
    ----------
    area, point : Use
        Direct-light techniques for area/mesh lights and for point lights (a delta cannot be
        hit by a sampled direction, so without NEE or equiangular it falls back to NEE).
    centres : (L, 3) float
        The point of each light that guided directions and distances aim at.
    directions, distances : bool
        Guided scattering directions; guided distances to the next vertex.
    """

    area: Use
    point: Use
    centres: np.ndarray
    directions: bool
    distances: bool

    @classmethod
    def of(cls, scene: Scene, strategy: str) -> Plan:
        tech, directions, distances = PLANS[strategy]
        area = Use("nee" in tech, "phase" in tech, "equiangular" in tech)
        point = Use(area.nee or not area.ea, False, area.ea)
        return cls(area, point, light_centres(scene), directions, distances)



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


def direction_pdf(scene: Scene, plan: Plan, x, w_in, w) -> tuple[np.ndarray, np.ndarray]:
    """Phase value ``rho(w_in . w)`` and the density the strategy samples scattering
    directions ``w`` with at ``x``: ``rho`` itself, or the defensive mixture
    ``GUIDE_PHASE rho + (1 - GUIDE_PHASE) p_guided``."""
    rho = sampling.phase_value(_dot(w_in, w), scene.medium.phase.g)
    if not plan.directions:
        return rho, rho
    p = GUIDE_PHASE * rho + (1.0 - GUIDE_PHASE) * _guided_pdf(scene, plan.centres, x, w)
    return rho, p


def scatter(scene: Scene, plan: Plan, x, w_in, rng):
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
    rho, p = direction_pdf(scene, plan, x, w_in, w)
    with np.errstate(divide="ignore", invalid="ignore"):
        weight = np.where(p > 0, rho / p, 0.0)
    return w, p, weight


# --------------------------------------------------------------------------- guided distances
def _centre_frames(plan: Plan, o, w, t_end):
    """:func:`equiangular_frame` of every light centre on the segments (one tuple per
    light); ``h`` is kept away from 0 (a segment through a centre: a measure-zero event)."""
    frames = []
    for c in plan.centres:
        delta, h, _, _ = equiangular_frame(o, w, t_end, np.broadcast_to(c, o.shape))
        h = np.maximum(h, 1e-12)
        frames.append((delta, h, np.arctan2(-delta, h), np.arctan2(t_end - delta, h)))
    return frames


def distance_density(scene: Scene, plan: Plan, o, w, t_end, t) -> np.ndarray:
    """Density of :func:`sample_distance` at distances ``t`` (M,) of segments ``o + t w``
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


def sample_distance(scene: Scene, plan: Plan, o, w, t_end, rng):
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
        :func:`distance_density` at ``t``.
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
    return t, distance_density(scene, plan, o, w, t_end, t)



def equiangular_frame(o, w, t_end, y):
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
