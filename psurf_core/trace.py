"""Trace: photon subpaths from the lights, sampled as in an infinite medium (spec section 4).

The box and the blockers never stop a photon. They are recorded instead: ``prefix_ok[:, j]``
says whether the photon's own vertices ``1..j`` lie in the box and its segments ``1..j`` are
unoccluded, which every technique checks for the sampled part of a path it reconstructs.
A photon is extended only while some technique could still use its next segment (the
deepest look-back of any technique is three segments: the generalized planes rebuild
``x2, x1`` from ``x3``), so escaped photons cost a bounded amount of work and bias nothing.

Speed (issue #6): the random numbers are drawn depth by depth exactly as the numpy
implementation drew them (the same stream, in the same order, of the same sizes) and
``cos``/``sin``/``log1p`` stay numpy's; the per-photon arithmetic of emission and of a depth
step, and the final scatter into the arrays below, run in compiled loops
(:mod:`psurf_core.trace_kernels`) with the same IEEE operations. ``Blockers.occluded`` gets
exactly the segments it always got (its BLAS dot products round differently in other arrays)
or, when it provably finds nothing, is not called. The output is bit-identical to the numpy
implementation's (``tests/test_trace_identity.py``).

Vertex numbering: ``x[:, 0]`` is the light point and ``x[:, j]`` the photon's ``j``-th
scattering vertex; segment ``j`` (stored at index ``j - 1``) goes from vertex ``j - 1`` to
vertex ``j`` along ``w[:, j-1]`` with sampled length ``t[:, j-1]``. In the spec's notation of
a K-event path, tracer vertex ``j`` is ``x_{K-j}``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import sampling
from .compiled import ctrl_c_kept
from .constants import HG_ISOTROPIC_G, MAX_TRACE_DEPTH, ROULETTE_START, SHADOW_EPS
from .geometry import Blockers, blockers_of
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
    from . import trace_kernels as tk  # numba: imported on first use, not with psurf_core

    pmf = scene.light_pmf
    light = _sample_discrete(pmf, rng, n, tk)
    # Every photon has a light and every light writes x0, w1, normal and beta of its photons.
    x0, w1, normal, beta = np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3))
    uv = np.zeros((n, 2))
    tri = np.full(n, -1, dtype=np.int64)
    for li, lt in enumerate(scene.lights):
        sel = np.flatnonzero(light == li)
        m = sel.size
        if m == 0:
            continue
        # One light for every photon (the usual case): the kernels write the outputs directly.
        whole = m == n
        rows = slice(None) if whole else sel
        xo = x0 if whole else np.empty((m, 3))
        wo = w1 if whole else np.empty((m, 3))
        beta[rows] = lt.power_rgb / pmf[li]
        # One rng.random call per light: the same stream as the samplers' separate draws
        # (each listed below in their order).
        if isinstance(lt, PointLight):
            r = rng.random(2 * m)  # sample_uniform_sphere: z, azimuth
            phi = 2.0 * np.pi * r[m:]
            tk.emit_point(r[:m], np.cos(phi), np.sin(phi), wo)
            x0[rows] = lt.position
            normal[rows] = lt.axis
        elif isinstance(lt, AreaLight):
            r = rng.random(4 * m)  # (u, v) per photon; sample_cosine_hemisphere: cos^2, azimuth
            u = r[: 2 * m].reshape(m, 2)
            phi = 2.0 * np.pi * r[3 * m :]
            nl = lt.normal
            tk.emit_area(u, r[2 * m : 3 * m], np.cos(phi), np.sin(phi), lt.corner, lt.edge_u,
                         lt.edge_v, nl, xo, wo)
            uv[rows] = u
            normal[rows] = nl
        elif isinstance(lt, MeshLight):
            k = _sample_discrete(lt.areas / lt.area, rng, m, tk)
            # sample_triangle_barycentric: sqrt-variate, second variate; then cos^2, azimuth
            r = rng.random(4 * m)
            phi = 2.0 * np.pi * r[3 * m :]
            bo = uv if whole else np.empty((m, 2))
            no = normal if whole else np.empty((m, 3))
            tk.emit_mesh(k, r[:m], r[m : 2 * m], r[2 * m : 3 * m], np.cos(phi), np.sin(phi),
                         np.ascontiguousarray(lt.triangles, dtype=float),
                         np.ascontiguousarray(lt.normals, dtype=float), bo, xo, no, wo)
            tri[sel] = k
            if not whole:
                uv[sel], normal[sel] = bo, no
        else:  # pragma: no cover - the scene loader admits no other light
            raise TypeError(f"unknown light {lt!r}")
        if not whole:
            if not isinstance(lt, PointLight):
                x0[sel] = xo
            w1[sel] = wo
    return dict(light=light, light_pmf=pmf[light], light_uv=uv, tri=tri, light_normal=normal,
                x0=x0, w1=w1, beta=beta)


def _sample_discrete(pmf: np.ndarray, rng: np.random.Generator, n: int, tk) -> np.ndarray:
    """:func:`sampling.sample_discrete` (same draws, same indices) with a compiled search:
    picking among a mesh light's triangles was the slowest step of emission.

    Returns
    -------
    (n,) intp
    """
    if len(pmf) == 1:
        return sampling.sample_discrete(pmf, rng, n)  # no search at all
    cdf = np.cumsum(pmf)
    cdf /= cdf[-1]
    k = np.empty(n, dtype=np.intp)
    tk.search_right(cdf, rng.random(n), k)
    return np.minimum(k, len(pmf) - 1)


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
    blockers : Blockers, optional
        ``blockers_of(scene)`` (built here when not given).
    max_depth : int, optional
        Segments to trace (default :func:`trace_depth`).

    Returns
    -------
    PhotonPaths
    """
    with ctrl_c_kept():
        return _trace(scene, n_photons, rng, blockers, max_depth)


def _trace(scene, n_photons, rng, blockers, max_depth) -> PhotonPaths:
    """:func:`trace`: depth-major numpy draws, compiled steps (``trace_kernels``)."""
    from . import trace_kernels as tk  # numba: imported on first use, not with psurf_core
    from .geometry import _BOUNDS_PAD

    med = scene.medium
    st, g, albedo = med.sigma_t, med.phase.g, med.albedo
    hg = abs(g) >= HG_ISOTROPIC_G  # sampling.sample_phase_cos's isotropic cut-off
    bmin = np.asarray(med.bounds_min, dtype=float)
    bmax = np.asarray(med.bounds_max, dtype=float)
    blockers = blockers_of(scene) if blockers is None else blockers
    # Which segments Blockers.occluded must see: those whose box meets a blocker's box (its
    # own first reject, repeated in the step kernel), every one when it has no boxes, none
    # when nothing blocks. It then sees the rows it would have picked itself, in order.
    # It is skipped when it provably finds nothing (tk.step's `unsure`).
    bounds, planes, test_all = np.zeros((0, 2, 3)), np.zeros((0, 4)), False
    if not blockers.empty:
        if blockers.bounds is None or blockers.planes is None:
            test_all = True
        else:
            bounds = np.ascontiguousarray(blockers.bounds, dtype=float)
            planes = np.ascontiguousarray(blockers.planes, dtype=float)
    depth = trace_depth(scene) if max_depth is None else int(max_depth)
    e = emit(scene, rng, n_photons)
    n = n_photons

    # State of the active photons, compacted in place (rows 0..m-1, in photon order):
    # photon index, current vertex, direction of the next segment (the weights follow from
    # the roulette survivals `qs`: tk.assemble).
    idx = np.arange(n)
    x = e["x0"].copy()
    w = e["w1"].copy()
    m = n
    oks = [np.ones(n, dtype=bool)]  # prefix_ok per vertex, (N,) each
    # Step records, step-major (step j: rows rec_off[j-1] .. rec_off[j] - 1); grown by
    # doubling. Scattered photon-major once at the end (tk.assemble).
    cap = max(n * min(depth, 8), 1)
    rec_idx = np.empty(cap, dtype=np.int64)
    rec = np.empty((cap, tk.REC_COLS))
    rec_off = [0]
    qs = [1.0]  # roulette survival before each segment, for tk.assemble
    near_pos = np.empty(n, dtype=np.int64)
    near_a, near_b = np.empty((n, 3)), np.empty((n, 3))
    near_inb = np.empty(n, dtype=bool)
    empty = np.empty(0)
    for j in range(1, depth + 1):
        # Segment j leaves vertex j-1. Roulette decides before sampling it (depth only), and
        # a photon goes on only while a technique can still use the segment.
        scatter = j > 1
        if scatter:
            q = roulette_survival(scene, j - 1)
            qs.append(q)
            u = rng.random(m) if q < 1.0 else empty
            m = tk.select(m, idx, x, w, oks[max(j - LOOKBACK, 0)], u, q)
            # The draws of sample_phase (cosine, azimuth), then sample_free_flight: one call,
            # the same stream as three.
            r = rng.random(3 * m)
            u_mu = r[:m]
            phi = 2.0 * np.pi * r[m : 2 * m]
            cphi, sphi = np.cos(phi), np.sin(phi)
            lg = np.log1p(-r[2 * m :])
        else:
            u_mu = cphi = sphi = empty
            lg = np.log1p(-rng.random(m))
        off = rec_off[-1]
        if off + m > rec_idx.shape[0]:
            grow = max(2 * rec_idx.shape[0], off + m)
            rec_idx = np.concatenate([rec_idx[:off], np.empty(grow - off, dtype=np.int64)])
            rec = np.concatenate([rec[:off], np.empty((grow - off, tk.REC_COLS))])
        ok = np.zeros(n, dtype=bool)
        nn, unsure = tk.step(m, idx, x, w, scatter, hg, g, u_mu, cphi, sphi, lg, st,
                             bmin, bmax, oks[-1], ok, test_all, bounds, planes, _BOUNDS_PAD,
                             0.5 * SHADOW_EPS, rec_idx, rec, off, near_pos, near_a, near_b,
                             near_inb)
        if nn:
            # The exact test on exactly the rows it would have taken (its dot products are
            # BLAS's, whose rounding depends on the array), unless it provably finds nothing.
            if unsure:
                ok[near_pos[:nn]] = near_inb[:nn] & ~blockers.occluded(near_a[:nn], near_b[:nn])
            else:
                ok[near_pos[:nn]] = near_inb[:nn]
        rec_off.append(off + m)
        oks.append(ok)
        if m == 0:
            break

    d = len(oks) - 1
    xs = np.empty((n, d + 1, 3))
    ws, betas = np.empty((n, d, 3)), np.empty((n, d, 3))
    ts, alives, clips = np.empty((n, d)), np.empty((n, d), dtype=bool), np.empty((n, d, 2))
    prefix_ok = np.empty((n, d + 1), dtype=bool)
    tk.assemble(e["x0"], e["beta"], np.array(qs), albedo, np.stack(oks), rec_idx, rec,
                np.array(rec_off, dtype=np.int64), xs, ws, ts, betas, alives, clips, prefix_ok)

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
        prefix_ok=prefix_ok,
        clip=clips,
    )
