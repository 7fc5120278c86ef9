"""Reference renderer: a vectorized volumetric path tracer from the camera (the oracle).

This is the "reference" of ESTIMATORS.md section 4, independent of the photon techniques.
Every path segment (the camera ray's medium part, then each scattered ray up to its exit,
occluder or emitter) gets

* an **equiangular** direct-light sample (Kulla and Fajardo 2012): a light point by power
  and area, a distance on the segment with density proportional to ``1 / r^2`` about it,
  a shadow ray;
* the path's **next vertex**, at a distance drawn from the defensive mixture of free flight
  and equiangular sampling about a light centre (``reference_guide.sample_distance``),
  where **next-event estimation** (NEE: a light point by power and area) runs and the
  **scattering direction** is drawn from the defensive mixture of the phase function and a
  lobe aimed at a light (``reference_guide.scatter``); where that direction meets an
  emitter's front side first, it scores too.

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
dead paths are compacted away after every vertex. Where the paths go (the strategies, the
guided directions and distances) is :mod:`psurf_core.reference_guide`; the points on the
lights, :mod:`psurf_core.reference_lights`; the single-scattering oracle,
:mod:`psurf_core.reference_quadrature`. Surfaces are black; light seen straight
from the camera (``k = 0``) is not counted (SCENES.md "What an image is"). Every random
number of a pass comes from the generator it is given.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from . import reference_guide as guide
from . import reference_lights as lights
from .camera import Rays
from .geometry import Blockers, blockers_of, ray_box
from .reference_guide import GUIDE_FLIGHT, GUIDE_PHASE, PLANS
from .reference_quadrature import single_scatter_quadrature
from .scene import PointLight, Scene
from .trace import roulette_survival, trace_depth

__all__ = ["GUIDE_FLIGHT", "GUIDE_PHASE", "SAMPLER", "STRATEGIES", "reference_image",
           "reference_pass", "single_scatter_quadrature"]

#: Strategies of :func:`reference_pass` (what each does: ``reference_guide.PLANS``).
STRATEGIES = tuple(PLANS)

#: Version of the default sampler, part of a reference checkpoint's identity (a checkpoint
#: of another sampler must not be resumed: the result would not be any one run's).
SAMPLER = "mis-equiangular-guided-1"


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("ij,ij->i", a, b)


def _direct(scene, plan, by, w, t, t_end, frame, dens, x, lp, beta):
    """Balance-heuristic contribution of direct-light samples of segments (no visibility).

    A sample is a vertex at distance ``t`` on a segment (arriving along ``w``) and a point
    ``y`` on a light, in the measure ``dt dA(y)`` shared by the three techniques. Their
    densities, each multiplied by ``r^2 / Tr(t)`` (``r = |y - x|``, ``Tr(t) = exp(-st t)``)
    so that no term is singular or underflows (``p_t``: the density the path's next vertex
    is sampled with, :func:`reference_guide.sample_distance`; ``dens = p_t / Tr``, ``st``
    for free flight):

    * NEE at the path's vertex: ``p_t(t) p_A r^2 / Tr = dens p_A r^2``,
    * the scattering direction sampled at the path's vertex hits ``y``:
      ``dens p_w cos_L`` (``p_w``: the direction density, the phase function or the guided
      mixture, :func:`reference_guide.direction_pdf`),
    * an equiangular vertex about ``y``, with ``y`` by area: ``p_A h / ((th_b - th_a) Tr)``.

    The integrand times the same factor is ``beta ss rho cos_L exp(-st r) Le``, so wherever
    NEE or the hit technique is enabled every contribution is at most
    ``beta (ss / st) Le / (GUIDE_FLIGHT GUIDE_PHASE)`` (without the guided mixtures,
    ``beta (ss / st) Le``): bounded, whatever the geometry.

    Parameters
    ----------
    plan : reference_guide.Plan
    by : {'nee', 'phase', 'ea'}
        The technique that drew the samples (contributions are 0 where it is not enabled).
    w : (M, 3) float
        Unit direction of each segment.
    t, t_end : (M,) float
        Vertex distance along the segment and the segment's free length.
    frame : tuple of (M,) float
        :func:`reference_guide.equiangular_frame` of ``lp.y`` on the segments.
    dens : (M,) float
        :func:`reference_guide.distance_density` of the segments at ``t``.
    x : (M, 3) float
        The vertices ``o + t w``.
    lp : reference_lights.LightPoints
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
        rho, p_w = guide.direction_pdf(scene, plan, x, w, u)
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
    :func:`reference_guide.distance_density`); ``beta`` is the throughput at the segments' origins.
    Returns (M, 3)."""
    lp = lights.sample_light_points(scene, rng, x.shape[0])
    frame = guide.equiangular_frame(x - t[:, None] * w, w, t_end, lp.y)
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
    lp = lights.sample_light_points(scene, rng, m)
    frame = delta, h, th_a, th_b = guide.equiangular_frame(o, w, t_end, lp.y)
    th = th_a + rng.random(m) * (th_b - th_a)
    t = np.clip(delta + h * np.tan(th), 0.0, t_end)
    x = o + t[:, None] * w
    dens = guide.distance_density(scene, plan, o, w, t_end, t)
    return _shadowed(_direct(scene, plan, "ea", w, t, t_end, frame, dens, x, lp, beta), x,
                     lp.y, blockers)



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
    plan = guide.Plan.of(scene, strategy)
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
        t, dens = guide.sample_distance(scene, plan, seg_o, seg_w, seg_tend, rng)
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
        w_new, _, w_weight = guide.scatter(scene, plan, x, w, rng)
        _, t_box = ray_box(x, w_new, med.bounds_min, med.bounds_max)
        t_next = np.minimum(t_box, blockers.first_hit(x, w_new))
        if hits and counts:
            t_e, lp = lights.emitter_hits(scene, x, w_new)
            # The emitter is the first surface iff nothing nearer (tolerance for rounding).
            j = np.flatnonzero(np.isfinite(t_e) & (t_e <= t_next * (1 + 1e-9) + 1e-12))
            if j.size:
                # Transmittance analytic: the emitter is inside the (convex) box.
                lj = lp.take(j)
                frame = guide.equiangular_frame(x[j] - t[j, None] * w[j], w[j], tend[j], lj.y)
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

