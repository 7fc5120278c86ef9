"""Trace: photon subpaths from the lights, sampled as in an infinite medium (spec section 4).

The box and the blockers never stop a photon. They are recorded instead: ``prefix_ok[:, j]``
says whether the photon's own vertices ``1..j`` lie in the box and its segments ``1..j`` are
unoccluded, which every technique checks for the sampled part of a path it reconstructs.
A photon is extended only while some technique could still use its next segment (the
deepest look-back of any technique is three segments: the generalized planes rebuild
``x2, x1`` from ``x3``), so escaped photons cost a bounded amount of work and bias nothing.

Vertex numbering: ``x[:, 0]`` is the light point and ``x[:, j]`` the photon's ``j``-th
scattering vertex; segment ``j`` (stored at index ``j - 1``) goes from vertex ``j - 1`` to
vertex ``j`` along ``w[:, j-1]`` with sampled length ``t[:, j-1]``. In the spec's notation of
a K-event path, tracer vertex ``j`` is ``x_{K-j}``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import sampling
from .constants import MAX_TRACE_DEPTH, ROULETTE_START
from .geometry import Blockers, blockers_of, inside_box, ray_box
from .scene import AreaLight, MeshLight, PointLight, Scene

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
        Vertices: ``x[:, 0]`` on the light, ``x[:, j]`` the ``j``-th scattering vertex.
    w : (P, D, 3) float
        Unit direction of segment ``j`` at index ``j - 1``.
    t : (P, D) float
        Sampled free-flight length of segment ``j`` at index ``j - 1``.
    beta : (P, D, 3) float
        Weight leaving vertex ``j - 1`` along segment ``j`` (W; the emitted power over
        ``P_L``, times ``ss/st`` per scattering, over roulette survival).
    alive : (P, D) bool
        Segment was sampled (false after roulette, past the depth cap, or once no
        technique can use it).
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
    return float(np.clip(scene.medium.albedo, 0.25, 0.9))


def emit(scene: Scene, rng: np.random.Generator, n: int):
    """Sample ``n`` photon emissions (light chosen proportional to power).

    Returns
    -------
    dict of (n, ...) arrays: ``light, light_pmf, light_uv, tri, light_normal, x0, w1, beta``.
    """
    pmf = scene.light_pmf
    light = sampling.sample_discrete(pmf, rng, n)
    x0 = np.zeros((n, 3))
    w1 = np.zeros((n, 3))
    uv = np.zeros((n, 2))
    tri = np.full(n, -1, dtype=np.int64)
    normal = np.zeros((n, 3))
    beta = np.zeros((n, 3))
    for li, lt in enumerate(scene.lights):
        sel = np.flatnonzero(light == li)
        m = sel.size
        if m == 0:
            continue
        beta[sel] = lt.power_rgb / pmf[li]
        if isinstance(lt, PointLight):
            x0[sel] = lt.position
            w1[sel] = sampling.sample_uniform_sphere(rng, m)
            normal[sel] = lt.axis
        elif isinstance(lt, AreaLight):
            u = rng.random((m, 2))
            uv[sel] = u
            x0[sel] = lt.corner + u[:, :1] * lt.edge_u + u[:, 1:] * lt.edge_v
            nl = np.broadcast_to(lt.normal, (m, 3))
            normal[sel] = nl
            w1[sel] = sampling.sample_cosine_hemisphere(np.ascontiguousarray(nl), rng)
        elif isinstance(lt, MeshLight):
            k = sampling.sample_discrete(lt.areas / lt.area, rng, m)
            b = sampling.sample_triangle_barycentric(rng, m)
            tr = lt.triangles[k]
            uv[sel] = b
            tri[sel] = k
            x0[sel] = tr[:, 0] + b[:, :1] * (tr[:, 1] - tr[:, 0]) + b[:, 1:] * (tr[:, 2] - tr[:, 0])
            nk = lt.normals[k]
            normal[sel] = nk
            w1[sel] = sampling.sample_cosine_hemisphere(nk, rng)
        else:  # pragma: no cover - the scene loader admits no other light
            raise TypeError(f"unknown light {lt!r}")
    return dict(light=light, light_pmf=pmf[light], light_uv=uv, tri=tri, light_normal=normal,
                x0=x0, w1=w1, beta=beta)


def trace(
    scene: Scene,
    n_photons: int,
    rng: np.random.Generator,
    *,
    blockers: Blockers | None = None,
    max_depth: int | None = None,
) -> PhotonPaths:
    """Trace ``n_photons`` photon subpaths (spec sections 1 and 4).

    Parameters
    ----------
    scene : Scene
    n_photons : int
    rng : numpy.random.Generator
        The pass's photon generator.
    max_depth : int, optional
        Segments to trace (default :func:`trace_depth`).

    Returns
    -------
    PhotonPaths
    """
    med = scene.medium
    st, g = med.sigma_t, med.phase.g
    blockers = blockers_of(scene) if blockers is None else blockers
    depth = trace_depth(scene) if max_depth is None else int(max_depth)
    e = emit(scene, rng, n_photons)
    n = n_photons

    # Work only on the active photons (compacted index list `act`). Per-depth results are
    # kept compact (the active rows only) and scattered once into the full-size record at the
    # end: allocating and stacking full-size slices at every depth cost more than the work.
    oks_hist = [np.ones(n, dtype=bool)]  # prefix_ok per vertex
    steps = []  # per segment j: (act, t, w, beta, x_j, clip) of its active photons
    act = np.arange(n)
    w = e["w1"].copy()
    beta = e["beta"].copy()
    x = e["x0"].copy()  # current vertex of every photon (the last one for finished photons)
    for j in range(1, depth + 1):
        # Segment j leaves vertex j-1. Roulette decides before sampling it (depth only).
        if j > 1:
            q = roulette_survival(scene, j - 1)
            keep = oks_hist[max(j - LOOKBACK, 0)][act]  # can a technique still use it?
            if q < 1.0:
                keep &= rng.random(act.size) < q
                beta[act] /= q
            act = act[keep]
            w[act] = sampling.sample_phase(w[act], g, rng)
            beta[act] *= med.albedo
        ta = sampling.sample_free_flight(st, rng, act.size)
        xa, wa = x[act], w[act]
        xna = xa + ta[:, None] * wa
        # Validity of the sampled prefix: in box and unoccluded.
        ok = np.zeros(n, dtype=bool)
        sel = oks_hist[-1][act]
        chk = act[sel]
        if chk.size:
            inb = inside_box(xna[sel], med.bounds_min, med.bounds_max)
            ok[chk] = inb & ~blockers.occluded(xa[sel], xna[sel])
        te, tx = ray_box(xa, wa, med.bounds_min, med.bounds_max)
        clip = np.stack([np.clip(te, 0.0, ta), np.clip(tx, 0.0, ta)], axis=-1)
        steps.append((act, ta, wa, beta[act], xna, clip))
        x[act] = xna
        oks_hist.append(ok)
        if act.size == 0:
            break

    d = len(steps)
    # Vertices depth-major (contiguous row copies carry a finished photon's last vertex
    # forward), then one transposing copy; the rest is scattered into zeros directly.
    xd = np.empty((d + 1, n, 3))
    xd[0] = e["x0"]
    ws, betas = np.zeros((n, d, 3)), np.zeros((n, d, 3))
    ts, alives, clips = np.zeros((n, d)), np.zeros((n, d), dtype=bool), np.zeros((n, d, 2))
    for i, (a, ta, wa, ba, xna, clip) in enumerate(steps):
        xd[i + 1] = xd[i]
        xd[i + 1, a] = xna
        ws[a, i], betas[a, i], ts[a, i], alives[a, i], clips[a, i] = wa, ba, ta, True, clip
    xs = np.ascontiguousarray(xd.transpose(1, 0, 2))

    return PhotonPaths(
        n_emitted=n,
        light=e["light"],
        light_pmf=e["light_pmf"],
        light_uv=e["light_uv"],
        tri=e["tri"],
        light_normal=e["light_normal"],
        x=xs,
        w=ws,
        t=ts,
        beta=betas,
        alive=alives,
        prefix_ok=np.stack(oks_hist, axis=1),
        clip=clips,
    )
