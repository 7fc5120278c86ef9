"""One pass (Trace -> Create -> Intersect -> Evaluate -> image) and the progressive render.

Everything random in pass ``i`` comes from ``SeedSequence([seed, i])``: its first child drives
the camera-ray jitter, its second the photons (in fixed-size batches, each with its own
grandchild), so a pass is the same wherever and whenever it runs, whatever the memory budget.
(The ``r2`` pixel sampler, :mod:`.pixel_jitter`, takes the jitter from the pass index and one
per-seed draw instead: as deterministic.)
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from .accumulate import Welford
from .binning import candidate_pairs
from .camera import Rays, camera_rays
from .constants import BYTES_PER_PAIR, DEFAULT_MEMORY_BUDGET_MIB
from .estimators import Estimator
from .geometry import Blockers, blockers_of
from .interrupt import check, held
from .kernels.fused import MisSet, fused_pass
from .memory_release import trim_now_and_then
from .mis import mis_weights
from .photon_sampler import batch_draws, check_photon_sampler, sequence_start
from .pixel_jitter import check_sampler, pass_jitter
from .scene import Scene
from .techniques.base import PassContext, Technique
from .trace import trace, trace_depth

#: Photons traced together; fixed (not derived from the memory budget) so images do not
#: depend on the budget.
PHOTON_BATCH = 1 << 15

#: ``tally(tech, hits, prims, rays, unweighted, weighted)``: see :func:`photon_pass`.
Tally = Callable[[Technique, object, object, Rays, np.ndarray, np.ndarray], None]


@dataclass(frozen=True)
class RenderSettings:
    """Per-pass budget of a photon estimator (the reference uses ``spp`` only).

    Attributes
    ----------
    photons : int
        Photons emitted per pass.
    spp : int
        Camera rays per pixel per pass.
    radius : float or None
        Initial kernel radius ``r_0`` (scene units) for kernel techniques; ``None`` takes
        each technique's ``default_radius_fraction`` of the medium box diagonal.
    radius_shrink : float
        ``alpha`` of the progressive schedule ``r_i = r_0 gamma_i^(1/d)``,
        ``gamma_i = prod_{k<i} (k + alpha)/(k + 1)``; 1 keeps the radius fixed.
    memory_budget_mib : int
        Bound on the chunked rays x primitives work.
    pixel_sampler : str
        Where each pass's rays go inside their pixels (:mod:`psurf_core.pixel_jitter`):
        ``"independent"`` (a fresh uniform point every pass) or ``"r2"`` (a low-discrepancy
        sequence over the passes, randomly shifted per pixel and seed).
    photon_sampler : str
        Where each batch's photons take their random numbers
        (:mod:`psurf_core.photon_sampler`): ``"independent"``, ``"sobol"`` (each photon a
        point of a scrambled Sobol set drawn for the batch) or ``"sobol-seq"`` (one scrambled
        Sobol sequence over the passes).
    """

    photons: int = 20_000
    spp: int = 1
    radius: float | None = None
    radius_shrink: float = 1.0
    memory_budget_mib: int = DEFAULT_MEMORY_BUDGET_MIB
    pixel_sampler: str = "independent"
    photon_sampler: str = "independent"

    def __post_init__(self):
        check_sampler(self.pixel_sampler)
        check_photon_sampler(self.photon_sampler)

    @property
    def independent_passes(self) -> bool:
        """Whether a render's passes are independent estimates: not with the ``r2`` pixel
        sampler or the ``sobol-seq`` photon sampler, whose passes share one low-discrepancy
        sequence, so per-pass variance / passes overstates the final image's variance."""
        return self.pixel_sampler == "independent" and self.photon_sampler != "sobol-seq"

    @property
    def max_pairs(self) -> int:
        return max(4096, self.memory_budget_mib * (1 << 20) // BYTES_PER_PAIR)


def pass_generators(seed: int, pass_index: int):
    """The pass's ``(ray_rng, photon_seedseq)``."""
    ss = np.random.SeedSequence([int(seed), int(pass_index)])
    ray_ss, photon_ss = ss.spawn(2)
    return np.random.default_rng(ray_ss), photon_ss


def kernel_radius(tech: Technique, scene: Scene, settings: RenderSettings, pass_index: int):
    """Kernel radius of ``tech`` in pass ``pass_index`` (0-based) of the progressive schedule."""
    if tech.kernel_dim == 0:
        return 0.0
    r0 = settings.radius
    if r0 is None:
        r0 = tech.default_radius_fraction * scene.medium.diagonal
    a = settings.radius_shrink
    k = np.arange(1, pass_index + 1, dtype=float)
    gamma = float(np.prod((k + a) / (k + 1.0)))
    return float(r0 * gamma ** (1.0 / tech.kernel_dim))


@dataclass
class PassRecord:
    """What one pass computed, kept when asked (the UI's step-through reads it)."""

    rays: Rays | None = None
    paths: list = field(default_factory=list)  # one PhotonPaths per batch
    prims: dict = field(default_factory=dict)  # (technique name, batch) -> Primitives
    hits: dict = field(default_factory=dict)  # (technique name, batch) -> (Hits, values)


def _accumulate(img: np.ndarray, pixel: np.ndarray, values: np.ndarray) -> None:
    n = img.shape[0]
    for c in range(3):
        img[:, c] += np.bincount(pixel, weights=values[:, c], minlength=n)


def batch_paths(scene: Scene, settings: RenderSettings, batch_ss, b: int,
                seed: int | None, pass_index: int, blockers: Blockers):
    """The traced photons of batch ``b`` of pass ``pass_index`` (``batch_ss``: the pass's
    per-batch SeedSequences; :func:`~.photon_sampler.batch_draws` by the settings' photon
    sampler): the one place a pass's photons are drawn and traced, for the pass and for the
    inspector's coverage alike."""
    n = min(PHOTON_BATCH, settings.photons - b * PHOTON_BATCH)
    draws = batch_draws(settings.photon_sampler, np.random.default_rng(batch_ss[b]), scene, n,
                        trace_depth(scene), seed,
                        sequence_start(pass_index, settings.photons, b, PHOTON_BATCH))
    return trace(scene, n, draws, blockers=blockers)


def pass_rays(scene: Scene, settings: RenderSettings, seed: int, pass_index: int, ray_rng,
              blockers: Blockers, pixels: np.ndarray | None = None) -> Rays:
    """The camera rays of pass ``pass_index`` (its pixel sampler's jitter from ``ray_rng``,
    :func:`pass_generators`' first), for the pass and the inspector's coverage alike."""
    jit = pass_jitter(settings.pixel_sampler, scene.camera.n_pixels, settings.spp, seed,
                      pass_index, ray_rng)
    return camera_rays(scene, settings.spp, pixels=pixels, blockers=blockers, jitter_xy=jit)


def photon_pass(
    scene: Scene,
    estimator: Estimator,
    rays: Rays,
    photon_ss: np.random.SeedSequence,
    settings: RenderSettings,
    pass_index: int,
    blockers: Blockers,
    record: PassRecord | None = None,
    tally: Tally | None = None,
    seed: int | None = None,
) -> np.ndarray:
    """Sum of per-photon contributions per ray (R, 3), not yet divided by the photon count.

    ``seed``: the render's seed, which the ``sobol-seq`` photon sampler's sequence needs
    (without it, that sampler scrambles each batch apart, as ``sobol``).

    ``tally(tech, hits, prims, rays, unweighted, weighted)`` (optional) sees every chunk of
    hits with its per-photon contributions before (``unweighted``, (H, 3)) and after
    (``weighted``) the MIS weight; both are the same array for a technique alone in its
    group.
    """
    out = np.zeros((len(rays), 3))
    # Hits are materialized only for those who read them; otherwise the compiled walkers
    # add their weighted values to ``out`` directly.
    emit = record is not None or tally is not None
    n_batches = -(-settings.photons // PHOTON_BATCH)
    batch_ss = photon_ss.spawn(n_batches)
    for b in range(n_batches):
        paths = batch_paths(scene, settings, batch_ss, b, seed, pass_index, blockers)
        if record is not None:
            record.paths.append(paths)
        for group, full_group in estimator.sets:
            # A member with a share sweeps the batch's first photons (alone: all of them).
            used = {id(t): photons_used(t, len(paths)) if len(group) > 1 else len(paths)
                    for t in group}
            mis = None
            if len(group) > 1:
                mis = MisSet(group, full_group, estimator.weighting,
                             member_shares(group, len(paths), full_group))
            for tech in group:
                ctx = PassContext(scene, blockers, kernel_radius(tech, scene, settings, pass_index),
                                  pass_index, settings.max_pairs)
                mine = paths if used[id(tech)] == len(paths) else paths.subset(
                    np.arange(used[id(tech)]))
                prims = tech.create(mine, ctx)
                if record is not None:
                    record.prims[(tech.name, b)] = prims
                chunks, compiled = _chunks(tech, prims, paths, rays, ctx, mis, emit, out)
                for hits, raw, w in chunks:
                    check()  # a held Ctrl-C (interrupt.held): between chunks
                    if len(hits) == 0:
                        continue
                    # The compiled walker added final values to ``out`` itself.
                    added = compiled and (mis is None or w is not None)
                    val = raw
                    if mis is not None:
                        if w is None:
                            w = mis_weights(tech, full_group, estimator.weighting, hits,
                                            prims, paths, rays, ctx, mis.shares)
                        val = val * w[:, None]
                    if tally is not None:
                        tally(tech, hits, prims, rays, raw, val)
                    if record is not None:
                        record.hits.setdefault((tech.name, b), []).append((hits, val))
                    if not added:
                        _accumulate(out, hits.ray, val)
    return out


def member_shares(group, n: int, over=None) -> np.ndarray:
    """(J,) float: the sample count of each member of an MIS set in a batch of ``n`` photons,
    as the MIS weights use it: the share :func:`photons_used` sweeps for the members of
    ``group`` (those on), 0 for the others. ``over``: the members to list, in order (default
    ``group``; ``render_pass`` lists the ``full_group`` its kernels are compiled for)."""
    on = {id(m) for m in group}
    return np.array([photons_used(m, n) / n if id(m) in on else 0.0
                     for m in (group if over is None else over)])


def photons_used(tech: Technique, n: int) -> int:
    """Photons of a batch of ``n`` that ``tech`` sweeps: the first ``round(share n)`` (at
    least one), all of them for a technique alone or with share 1."""
    if tech.share >= 1.0:
        return n
    return int(min(n, max(1, round(tech.share * n))))


def _chunks(tech, prims, paths, rays, ctx, mis, emit, out):
    """``(chunks, compiled)``: ``(Hits, unweighted values, MIS weights or None)`` of
    ``tech``'s primitives from its compiled walker where it has one
    (:func:`~psurf_core.kernels.fused.fused_pass`, which adds the final values to ``out``
    itself, in the same order whether it emits the hits or not, so reading them changes no
    bit of the image), else from the stages (``compiled`` False: the caller adds them)."""
    run = fused_pass(tech, prims, paths, rays, ctx, mis, emit=emit, out=out,
                     add_emitted=True)
    if run is not None:
        return run, True
    legacy = getattr(tech, "fused_pass", None)
    chunks = legacy(prims, paths, rays, ctx) if legacy is not None else None
    if chunks is None:
        chunks = stage_chunks(tech, prims, paths, rays, ctx)
    return ((h, v, None) for h, v in chunks), False


def stage_chunks(tech: Technique, prims, paths, rays: Rays, ctx: PassContext):
    """``(Hits, per-photon values (H, 3))`` chunks of ``tech`` by the stages: binning ->
    :meth:`~Technique.intersect` -> :meth:`~Technique.evaluate`, at most ``ctx.max_pairs``
    candidate pairs at a time. The reference the fused kernels are checked against."""
    for ray, prim in candidate_pairs(ctx.scene.camera, rays, prims.lo, prims.hi,
                                     ctx.max_pairs, prims.hull, prims.clip_box(ctx.scene)):
        hits = tech.intersect(prims, rays, ray, prim, ctx)
        if len(hits):
            yield hits, tech.evaluate(hits, prims, paths, rays, ctx)


def render_pass(
    scene: Scene,
    estimator: Estimator,
    pass_index: int,
    seed: int,
    settings: RenderSettings,
    *,
    blockers: Blockers | None = None,
    pixels: np.ndarray | None = None,
    record: PassRecord | None = None,
    tally: Tally | None = None,
) -> np.ndarray:
    """Render pass ``pass_index``: the per-pixel estimate of this pass alone.

    Parameters
    ----------
    pixels : (Q,) int, optional
        Flat pixel indices to estimate (others stay 0); all by default. A pixel's value does
        not depend on which other pixels are rendered.
    record : PassRecord, optional
        Filled with the pass's rays, paths, primitives and hits.
    tally : callable, optional
        Passed to :func:`photon_pass` (per-technique / per-K breakdowns). Values it sees are
        per photon and per ray: divide by ``settings.photons`` and ``settings.spp``.

    Returns
    -------
    (H, W, 3) float64
    """
    cam = scene.camera
    blockers = blockers_of(scene) if blockers is None else blockers
    ray_rng, photon_ss = pass_generators(seed, pass_index)
    rays = pass_rays(scene, settings, seed, pass_index, ray_rng, blockers, pixels)
    if record is not None:
        record.rays = rays
    if estimator.reference:
        from .reference import reference_pass

        per_ray = reference_pass(scene, rays, np.random.default_rng(photon_ss), blockers)
    else:
        per_ray = photon_pass(scene, estimator, rays, photon_ss, settings, pass_index,
                              blockers, record, tally, seed) / settings.photons
    # Freed memory is kept for the next pass (memory_release); long runs hand it back.
    trim_now_and_then()
    return pass_image(cam, rays, per_ray, settings.spp)


def pass_image(cam, rays: Rays, per_ray: np.ndarray, spp: int) -> np.ndarray:
    """(H, W, 3) the pass image of per-ray estimates ``per_ray`` ((R, 3), one per ray of
    ``rays``): each pixel the mean of its ``spp`` rays' (pixels without rays stay 0)."""
    img = np.zeros((cam.n_pixels, 3))
    _accumulate(img, rays.pixel, per_ray / spp)
    return img.reshape(cam.height, cam.width, 3)


@dataclass
class RenderResult:
    """A progressive render: the mean image, per-pass variance and provenance."""

    mean: np.ndarray  # (H, W, 3) float64
    var: np.ndarray  # (H, W, 3) float64, variance of one pass's estimate
    passes: int
    photons_per_pass: int
    spp: int
    seconds: float
    estimator: str
    seed: int
    accumulator: Welford | None = None

    @property
    def sum_var(self) -> np.ndarray | None:
        """(3,) float64 variance across passes of one pass's image sum per channel
        (``Welford.sum_variance``; correlated pixels included), ``None`` when unknown."""
        return None if self.accumulator is None else self.accumulator.sum_variance


#: Resolution and photons of :func:`warm_up`'s throw-away pass: enough pixels for the fused
#: path (it declines 64 or fewer), few enough that the pass is cheap.
_WARM_SIZE, _WARM_PHOTONS = (32, 24), 256


def warm_up(scene: Scene, estimator: Estimator, settings: RenderSettings) -> None:
    """Compile (or load from numba's cache) the compiled kernels ``estimator`` uses, so a
    wall-time budget started afterwards buys passes only.

    Compiled code costs seconds on its first call in a process (~11 s when numba compiles,
    ~1 s when it loads its cache): charged to a time budget, it would hand an equal-time
    comparison to whichever estimator is not compiled. This runs one throw-away pass of
    ``scene`` at 32x24 pixels and 256 photons (nothing is kept; its seed is unrelated to any
    render's), once per process and estimator spec; the path tracer is skipped.
    """
    if estimator.reference or estimator.spec in _WARMED:
        return
    from dataclasses import replace

    w, h = _WARM_SIZE
    small = replace(scene, camera=replace(scene.camera, width=w, height=h))
    render_pass(small, estimator, 0, 0, replace(settings, photons=_WARM_PHOTONS, spp=1))
    _WARMED.add(estimator.spec)


_WARMED: set[str] = set()


def render(
    scene: Scene,
    estimator: Estimator,
    settings: RenderSettings,
    *,
    passes: int | None = None,
    time_budget: float | None = None,
    seed: int = 0,
    accumulator: Welford | None = None,
    on_pass: Callable[[int, Welford, float], bool | None] | None = None,
) -> RenderResult:
    """Progressive render: whole passes until ``passes`` are done or ``time_budget`` seconds
    are spent (the pass in flight finishes; at least one pass runs).

    ``accumulator`` continues an earlier render (its ``n`` passes are skipped, so the result
    equals an uninterrupted run with the same seed). ``on_pass(i, acc, elapsed)`` is called
    after every pass; returning ``False`` stops early.
    """
    if passes is None and time_budget is None:
        passes = 1
    if time_budget is not None:
        warm_up(scene, estimator, settings)  # a budget buys passes, not compilation
    cam = scene.camera
    acc = accumulator if accumulator is not None else Welford.empty((cam.height, cam.width, 3))
    blockers = blockers_of(scene)
    t0 = time.perf_counter()
    done_before = acc.n
    # Ctrl-C (on the main thread) is raised between pieces of work, never inside a compiled
    # call (psurf_core.interrupt).
    with held():
        while True:
            check()
            i = acc.n
            acc.add(render_pass(scene, estimator, i, seed, settings, blockers=blockers))
            elapsed = time.perf_counter() - t0
            if on_pass is not None and on_pass(i, acc, elapsed) is False:
                break
            if passes is not None and acc.n >= passes:
                break
            if time_budget is not None and elapsed >= time_budget and acc.n > done_before:
                break
    return RenderResult(acc.mean.copy(), acc.variance, acc.n, settings.photons, settings.spp,
                        time.perf_counter() - t0, estimator.spec, seed, acc)
