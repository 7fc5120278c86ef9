"""Trace, the numpy reference: photon subpaths as structs of arrays over the active photons,
one loop over depth (:func:`trace_numpy`: ``emit``, :func:`step`, :func:`assemble`), built from
elementary formulas vectorized over photons (``direction_about``, :func:`phase_cosine`,
:func:`free_flight`, :func:`segment_clip`, ...), and the record they fill
(:class:`PhotonPaths`).

Each formula has a compiled scalar twin of the same name in :mod:`psurf_core.trace_compiled`;
:func:`psurf_core.trace.trace` runs that compiled path by default and this one with
``reference=True`` (see :mod:`psurf_core.trace` for what both compute).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import sampling
from .constants import MAX_TRACE_DEPTH, PARALLEL_EPS, ROULETTE_START
from .geometry import Blockers, inside_box
from .photon_sampler import uniforms
from .scene import Scene
from .trace_emit import direction_about, emit
from .variates import cos_sin_turn, neg_log_complement

__all__ = ["LOOKBACK", "PhotonPaths", "assemble", "roulette_survival", "step", "trace_depth",
           "trace_numpy"]

#: Deepest look-back (in segments) of any technique; see the module docstring.
LOOKBACK = 3


@dataclass(frozen=True)
class PhotonPaths:
    """Photon subpaths of one pass as a struct of arrays (P photons, D segments).

    Attributes
    ----------
    n_emitted : int
        Photons emitted in the pass (the ``N`` of the ``1/N`` normalisation).
    light : (P,) int
        Index of the emitting light in ``scene.lights``.
    light_pmf : (P,) float
        ``P_L`` of that light (already divided out of ``beta``).
    light_uv : (P, 2) float
        ``(u, v)`` on the parallelogram, barycentric ``(u, v)`` on the triangle; 0 for points.
    tri : (P,) int
        Emitting triangle of a mesh light, -1 otherwise.
    light_normal : (P, 3) float
        ``n_L`` / ``n_k`` for area and mesh lights; the light's ``axis`` for point lights.
    x : (P, D + 1, 3) float
        Vertices (scene units): ``x[:, 0]`` on the light, ``x[:, j]`` the ``j``-th scattering
        vertex; past a photon's last segment, its last vertex repeated.
    w : (P, D, 3) float
        Unit direction of segment ``j`` at index ``j - 1``.
    t : (P, D) float
        Sampled free-flight length (scene units) of segment ``j`` at index ``j - 1``.
    beta : (P, D, 3) float
        Weight leaving vertex ``j - 1`` along segment ``j`` (W; the emitted power over
        ``P_L``, times ``ss/st`` per scattering, over roulette survival).
    alive : (P, D) bool
        Segment was sampled (false after roulette, past the depth cap, or once no
        technique can use it; ``w``, ``t``, ``beta`` and ``clip`` are 0 there).
    prefix_ok : (P, D + 1) bool
        Vertices ``1..j`` inside the box and segments ``1..j`` unoccluded.
    clip : (P, D, 2) float
        In-medium part ``[a, b]`` of each segment (along it, within ``[0, t]``) for drawing;
        ``a >= b`` where the segment is outside the box.
    """

    n_emitted: int
    light: np.ndarray
    light_pmf: np.ndarray
    light_uv: np.ndarray
    tri: np.ndarray
    light_normal: np.ndarray
    x: np.ndarray
    w: np.ndarray
    t: np.ndarray
    beta: np.ndarray
    alive: np.ndarray
    prefix_ok: np.ndarray
    clip: np.ndarray

    @property
    def depth(self) -> int:
        """Number of segment slots ``D``."""
        return self.t.shape[1]

    def __len__(self) -> int:
        return self.light.shape[0]

    def subset(self, idx) -> PhotonPaths:
        """The photons at ``idx`` (``n_emitted`` unchanged, so normalisation is kept)."""
        return PhotonPaths(
            self.n_emitted, *(getattr(self, f)[idx] for f in _PER_PHOTON)
        )


_PER_PHOTON = ("light", "light_pmf", "light_uv", "tri", "light_normal", "x", "w", "t", "beta",
               "alive", "prefix_ok", "clip")


def trace_depth(scene: Scene) -> int:
    """Segments to trace: ``max_scatter`` (every technique at K events uses segments up to
    K), or the roulette cap when unlimited."""
    return scene.max_scatter if scene.max_scatter > 0 else MAX_TRACE_DEPTH


def roulette_survival(scene: Scene, vertex: int) -> float:
    """Survival probability before sampling the segment that leaves ``vertex`` (depth only)."""
    if scene.max_scatter > 0 or vertex < ROULETTE_START:
        return 1.0
    return min(max(float(scene.medium.albedo), 0.25), 0.9)


# --------------------------------------------------------------------------- formulas
# Each has a compiled scalar twin of the same name in trace_compiled (same operations, same
# order; a (3,) vector there is a 3-tuple).
def phase_cosine(g, u):
    """Scattering cosine ``mu`` with density ``2 pi rho(mu)`` from its variate ``u``
    (``sampling.sample_phase_cos``: isotropic below ``HG_ISOTROPIC_G``).

    Parameters
    ----------
    g : float
    u : (M,) float

    Returns
    -------
    (M,) float
    """
    return sampling.sample_phase_cos(g, u)


def free_flight(u, sigma_t):
    """Free-flight lengths ``t = -log(1 - u) / sigma_t`` (scene units; pdf
    ``sigma_t exp(-sigma_t t)``, ``sampling.sample_free_flight``), the logarithm by
    :func:`psurf_core.variates.neg_log_complement`.

    Parameters
    ----------
    u : (M,) float
        Uniform variates in ``[0, 1)``.
    sigma_t : float
        Extinction (1 / scene unit).

    Returns
    -------
    (M,) float
    """
    return neg_log_complement(u) / sigma_t


def advance(x, w, t):
    """Segment ends ``x + t w``: (M, 3) from (M, 3), (M, 3), (M,)."""
    return x + t[:, None] * w


def segment_clip(x, w, t, bmin, bmax):
    """In-box part of segments ``x + s w``, ``s`` in ``[0, t]``: ``geometry.ray_box``'s slab
    test (directions below ``PARALLEL_EPS`` treated as ``PARALLEL_EPS``), the largest entry and
    the smallest exit, each clipped to ``[0, t]``. Written with comparisons (``where``), as
    the compiled twin is, so that both agree on signed zeros too.

    Parameters
    ----------
    x, w : (M, 3) float
    t : (M,) float
    bmin, bmax : (3,) float

    Returns
    -------
    (M, 2) float
        ``[enter, exit]``; ``enter >= exit`` where the segment misses the box.
    """
    inv = 1.0 / np.where(np.abs(w) < PARALLEL_EPS, PARALLEL_EPS, w)
    p = (bmin - x) * inv
    q = (bmax - x) * inv
    lo, hi = np.where(p < q, p, q), np.where(p < q, q, p)
    enter, leave = lo[:, 0], hi[:, 0]
    for c in (1, 2):
        enter = np.where(lo[:, c] > enter, lo[:, c], enter)
        leave = np.where(hi[:, c] < leave, hi[:, c], leave)
    enter, leave = np.where(enter > 0.0, enter, 0.0), np.where(leave > 0.0, leave, 0.0)
    return np.stack([np.where(enter < t, enter, t), np.where(leave < t, leave, t)], axis=-1)


def survives(ok_look, u, q):
    """(M,) bool: a photon goes on while a technique can still use its next segment
    (``ok_look``: ``prefix_ok`` at the deepest vertex a technique looks back to) and it
    survives roulette (``u < q``; no variates, ``u`` ignored, when ``q >= 1``)."""
    return ok_look & (u < q) if q < 1.0 else ok_look


def scattered_weight(beta, q, albedo):
    """Weights after a phase-sampled scattering: ``beta / q * albedo`` (``/ q`` only under
    roulette). (M, 3) W from (M, 3) W."""
    return (beta / q if q < 1.0 else beta) * albedo


# --------------------------------------------------------------------------- stages
@dataclass(frozen=True)
class Step:
    """The segments one depth sampled, for its ``m`` active photons (struct of arrays).

    Attributes
    ----------
    photon : (m,) int
        Photon index, increasing.
    t : (m,) float
    w, beta, x_end : (m, 3) float
        Direction, weight (W), end vertex.
    clip : (m, 2) float
    """

    photon: np.ndarray
    t: np.ndarray
    w: np.ndarray
    beta: np.ndarray
    x_end: np.ndarray
    clip: np.ndarray


def step(photon, x, w, beta, t, ok_prev, box, blockers: Blockers):
    """Segment ``j`` of the active photons: its end vertices, in-box part and the new
    vertex's ``prefix_ok`` (the previous one, the end inside the box (``geometry.inside_box``),
    the segment unoccluded).

    Parameters
    ----------
    photon : (m,) int
    x, w, beta : (m, 3) float
        Start vertex, direction, weight of each active photon.
    t : (m,) float
        Sampled lengths.
    ok_prev : (N,) bool
        ``prefix_ok`` of the start vertex, per photon.
    box : tuple of (3,) float
        ``(bmin, bmax)``: the medium box.
    blockers : Blockers

    Returns
    -------
    Step
    ok : (N,) bool
        ``prefix_ok`` of the end vertex (false for photons not in ``photon``).
    """
    bmin, bmax = box
    x_end = advance(x, w, t)
    ok = np.zeros(ok_prev.shape[0], dtype=bool)
    sel = ok_prev[photon]
    ok[photon[sel]] = inside_box(x_end[sel], bmin, bmax) & ~blockers.occluded(x[sel], x_end[sel])
    return Step(photon, t, w, beta, x_end, segment_clip(x, w, t, bmin, bmax)), ok


def assemble(e: dict, steps: list[Step], oks: list[np.ndarray]) -> PhotonPaths:
    """Scatter the per-depth steps into ``PhotonPaths``' photon-major arrays: zeros (and
    ``alive`` false) past a photon's last segment, its last vertex carried forward in ``x``.

    Parameters
    ----------
    e : dict
        :func:`emit`'s output.
    steps : list of Step
        One per traced depth (``D``).
    oks : list of (N,) bool
        ``prefix_ok`` per vertex (``D + 1``).
    """
    n, d = e["x0"].shape[0], len(steps)
    x = np.empty((d + 1, n, 3))  # depth-major: a row copy carries the last vertex forward
    x[0] = e["x0"]
    w, beta, clip = np.zeros((n, d, 3)), np.zeros((n, d, 3)), np.zeros((n, d, 2))
    t, alive = np.zeros((n, d)), np.zeros((n, d), dtype=bool)
    for j, s in enumerate(steps):
        x[j + 1] = x[j]
        x[j + 1, s.photon] = s.x_end
        w[s.photon, j], beta[s.photon, j], t[s.photon, j] = s.w, s.beta, s.t
        clip[s.photon, j], alive[s.photon, j] = s.clip, True
    return PhotonPaths(n_emitted=n, light=e["light"], light_pmf=e["light_pmf"],
                       light_uv=e["light_uv"], tri=e["tri"], light_normal=e["light_normal"],
                       x=np.ascontiguousarray(x.transpose(1, 0, 2)), w=w, t=t, beta=beta,
                       alive=alive, prefix_ok=np.stack(oks, axis=1), clip=clip)


def trace_numpy(scene: Scene, n_photons: int, rng: np.random.Generator, blockers: Blockers,
                depth: int) -> PhotonPaths:
    """Trace ``n_photons`` photon subpaths of ``depth`` segments at most, vectorized over the
    photons (the reference the compiled path is held bit-identical to)."""
    med = scene.medium
    bmin = np.asarray(med.bounds_min, dtype=float)
    bmax = np.asarray(med.bounds_max, dtype=float)
    box = (bmin, bmax)
    e = emit(scene, rng, n_photons)
    photon, x, w, beta = np.arange(n_photons), e["x0"], e["w1"], e["beta"]
    oks, steps = [np.ones(n_photons, dtype=bool)], []
    for j in range(1, depth + 1):
        # Segment j leaves vertex j-1. Roulette decides before sampling it (depth only), and
        # a photon goes on only while a technique can still use the segment.
        if j > 1:
            q = roulette_survival(scene, j - 1)
            u = uniforms(rng, 1, photon.size, rows=photon) if q < 1.0 else None
            keep = survives(oks[max(j - LOOKBACK, 0)][photon], u, q)
            photon, x, w = photon[keep], x[keep], w[keep]
            beta = scattered_weight(beta[keep], q, med.albedo)
            m = photon.size
            # The phase cosine, the azimuth, the flight: one call.
            r = uniforms(rng, 3, m, rows=photon)
            w = direction_about(w, phase_cosine(med.phase.g, r[:m]), *cos_sin_turn(r[m : 2 * m]))
            t = free_flight(r[2 * m :], med.sigma_t)
        else:
            t = free_flight(uniforms(rng, 1, n_photons), med.sigma_t)
        s, ok = step(photon, x, w, beta, t, oks[-1], box, blockers)
        steps.append(s)
        oks.append(ok)
        x = s.x_end
        if photon.size == 0:
            break
    return assemble(e, steps, oks)
