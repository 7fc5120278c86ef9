"""How much memory and disk a run needs, known before anything is allocated.

A run's memory is linear in the sizes a user controls, so :class:`Need` keeps one coefficient
per size and sums them:

* **pixels** (``camera.resolution``): the accumulator (every array of
  :class:`~psurf_core.accumulate.Welford`, counted from the class itself), the checkpoint's
  snapshot of it, one pass's image, the update's temporaries, the result's copies and the
  float32 outputs; every image a command keeps beside (``compare``'s runs, the window's
  breakdown stacks, passes waiting to be merged in pass order);
* **camera rays** (pixels x ``spp``): the rays of one pass and their per-ray work;
* **photons** (``--photons``): one batch of at most
  :data:`~psurf_core.render.PHOTON_BATCH` photons is traced and turned into primitives at a
  time, so only ``min(photons, PHOTON_BATCH)`` count (a pixel inspection keeps every batch:
  all count); per photon, the trace and the technique's primitives grow with the number of
  segment slots traced (:func:`depth_slots`), and an MIS set adds its members' densities;
* **mesh triangles**: the blockers and the emitter's sampling tables (while loading, trimesh
  needs more: :data:`TRIANGLE_LOAD_BYTES`);
* **the ray x primitive work**, chunked to at most ``RenderSettings.max_pairs`` candidate
  pairs (``--memory-budget`` sets it), of which a chunk uses up to :data:`PAIR_FRACTION` of
  the budget;
* **worker processes** (``--jobs``, ``--workers``): each has its own interpreter and does its
  own pass work.

The coefficients were measured on this project's 2-core Linux machine with
``benchmarks/memory_model.py`` (peak RSS growth of a fresh process after a warm-up render, per
size; ``python benchmarks/memory_model.py`` prints measured against modelled) and rounded up:
the model is meant to be above the measurement (by up to ~2x), never far below it. What the
interpreter, numpy, numba and the compiled kernels occupy before the run (~200-300 MiB) is
not part of a run's need.

:mod:`psurf_core.budget_check` compares a need with the limit (``--memory-budget`` or the
memory available) and says what to change; its ``photon_limit`` is the window's photon
slider's bound. Nothing here allocates more than a few scalars, so every check runs before
the run's arrays exist.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

__all__ = ["Need", "accumulator_bytes_per_pixel", "checkpoint_bytes", "depth_slots",
           "format_bytes", "output_bytes", "photon_bytes", "picture_bytes", "progressive_need",
           "render_need", "scene_triangles"]

MIB = 1 << 20

#: Bytes per pixel beyond the accumulator and its snapshot: one pass's image (24), the
#: Welford update's temporaries (48), the result's mean and variance copies (48) and the
#: float32 ``mean``/``var`` of the output (24), rounded up.
PIXEL_BYTES = 160

#: Bytes per pass image waiting in the merge window (``--jobs``/``--workers``) or sent back
#: by a worker: one float64 RGB image and its unpickled copy.
PASS_IMAGE_BYTES = 48

#: Bytes per camera ray in one pass: its origin, direction, interval and pixel, the clipping
#: and jitter temporaries, and the per-ray sums (photon estimators: measured ~260; the path
#: tracer keeps its path state per ray: measured ~360).
RAY_BYTES = 320
REFERENCE_RAY_BYTES = 420

#: Trace bytes per photon: ``a + b x`` segment slots (measured 450 at 1 slot, 2200 at 16).
TRACE_BYTES = (450, 120)

#: Segment slots assumed for an unlimited scatter range (``max_scatter = -1``). The trace
#: stops when its last photon leaves the box or loses the roulette: 16 slots in the bundled
#: scenes (measured); dense, high-albedo media trace deeper (at most MAX_TRACE_DEPTH = 64),
#: where this estimate of the photon part is low by up to ~2.5x.
UNLIMITED_DEPTH_SLOTS = 24

#: Bytes per photon of a technique's primitives and their work: ``(a, b)`` for ``a + b x``
#: slots, by family (name prefix); measured per photon at 16 slots: points 1.3 k, planes 2.8 k,
#: spheres 4.2 k, beams 4.4 k, cones 7.8 k. Unknown families take the largest.
TECHNIQUE_BYTES = {
    "points": (700, 70), "bre": (700, 70),
    "beams": (2000, 200),
    "plane": (2000, 100), "ss-plane": (2000, 100),
    "sphere": (2500, 150), "ss-sphere": (2500, 150), "disk": (2500, 150),
    "ss-disk": (2500, 150), "hyperboloid": (2500, 150),
    "cone": (3200, 420), "ss-cone": (3200, 420), "cylinder": (3200, 420),
}
_LARGEST_TECHNIQUE = (3200, 420)

#: Bytes per photon per member of an MIS set (the members' densities at every hit; measured
#: paper-multi 13.9 k per photon at 16 slots against 7.8 k for its cone alone).
MIS_MEMBER_BYTES = 800

#: Bytes per photon and segment slot of one technique's primitives, kept (a pixel
#: inspection keeps every technique's for every photon of the pass).
KEPT_SLOT_BYTES = 100

#: Share of ``--memory-budget`` one chunk of the ray x primitive work uses at most: by the
#: stages (binning, intersect, evaluate; measured 0.23 for beams: peak growth per MiB of
#: budget between 16 and 2048 MiB), and in a technique's compiled walker, which keeps no
#: candidate pairs (``Technique.compiled``; measured 0.04 for planes between 512 and 2048).
PAIR_FRACTION = 0.35
COMPILED_PAIR_FRACTION = 0.10

#: Bytes per mesh triangle kept while rendering (triangles, bounds, planes, sampling tables,
#: the acceleration structure) and at most while trimesh loads it (measured 600-1050 while
#: loading, 740-1230 in all through a render).
TRIANGLE_BYTES = 600
TRIANGLE_LOAD_BYTES = 1400

#: What a scene with any mesh needs besides its triangles: trimesh and its imports (measured
#: 64 MiB) and one chunk of exact ray-triangle tests (``geometry._TRI_CHUNK`` = 2**21 pairs;
#: measured: a render with an 81920-triangle mesh light grew 322 MiB, one with 327680
#: triangles 230-297 MiB after trimesh was imported).
MESH_FIXED_BYTES = 192 * MIB

#: A worker process's interpreter with numpy, numba and the compiled kernels (measured peak
#: 219-280 MiB for ``--jobs`` workers); a Dask worker adds its own runtime.
WORKER_PROCESS_BYTES = 300 * MIB
DASK_WORKER_BYTES = 400 * MIB

#: Bytes per pixel of an off-screen picture (VTK's framebuffers and read-back, the frame;
#: measured 80: ``app.py screenshot`` at 1600x900 and 3200x1800 peaked at 620 and 950 MiB).
PICTURE_BYTES = 100

#: Bytes of a checkpoint's metadata and archive headers (the scene path, argv, identity).
CHECKPOINT_META_BYTES = 64 << 10


def accumulator_bytes_per_pixel() -> int:
    """Bytes per pixel of one :class:`~psurf_core.accumulate.Welford` (all its per-pixel
    arrays; its per-channel image-sum moment does not grow with the image)."""
    from .accumulate import Welford

    acc = Welford.empty((1, 1, 3))
    return int(sum(getattr(acc, f.name).nbytes for f in dataclasses.fields(acc)
                   if getattr(getattr(acc, f.name), "shape", None) == acc.mean.shape))


def format_bytes(n: float) -> str:
    """``"512 MiB"``, ``"1.8 TiB"`` (binary units, 3 significant digits)."""
    n = float(n)
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if abs(n) < 1024 or unit == "PiB":
            return f"{n:.0f} {unit}" if unit in ("B", "KiB") or n >= 100 else f"{n:.3g} {unit}"
        n /= 1024
    raise AssertionError("unreachable")


# --------------------------------------------------------------------------- the model


@dataclass(frozen=True)
class Need:
    """A run's memory as a linear function of its sizes (bytes).

    Attributes
    ----------
    width, height, spp, photons, triangles : int
        The sizes.
    per_pixel, per_ray, per_triangle : float
        Bytes per pixel, per camera ray (pixels x spp) and per mesh triangle, summed over
        the processes that hold them.
    per_photon : float
        Bytes per photon of the batch in flight (``min(photons, PHOTON_BATCH)`` of them),
        summed over the processes rendering.
    per_photon_kept : float
        Bytes per photon of a record that keeps every photon of a pass (pixel inspection).
    pairs, workers : float
        The chunked pair work and the worker processes' interpreters.
    processes : int
        Worker processes (0: passes render in this process, or elsewhere).
    extra : tuple of (str, float)
        Further fixed parts, named (e.g. :func:`picture_bytes` of a screenshot).
    """

    width: int
    height: int
    spp: int
    photons: int
    triangles: int
    per_pixel: float
    per_ray: float
    per_photon: float
    per_triangle: float
    per_photon_kept: float = 0.0
    pairs: float = 0.0
    workers: float = 0.0
    processes: int = 0
    extra: tuple = ()

    @property
    def pixels(self) -> int:
        return self.width * self.height

    def photon_bytes(self, photons: int | None = None) -> float:
        """Bytes of the photon part at ``photons`` per pass (default: this run's)."""
        from .render import PHOTON_BATCH

        p = self.photons if photons is None else int(photons)
        return min(p, PHOTON_BATCH) * self.per_photon + p * self.per_photon_kept

    def parts(self) -> dict[str, float]:
        """Bytes of each part (named for the message), largest first."""
        from .render import PHOTON_BATCH

        held = min(self.photons, PHOTON_BATCH)
        photons = (f"{self.photons:,} photons kept" if self.per_photon_kept else
                   f"{held:,} photons at a time")
        parts = {
            f"the {self.width}x{self.height} image": self.pixels * self.per_pixel,
            f"{self.pixels * self.spp:,} camera rays (spp {self.spp})":
                self.pixels * self.spp * self.per_ray,
            photons: self.photon_bytes(),
            f"{self.triangles:,} mesh triangles": self.triangles * self.per_triangle,
            "the chunked ray x primitive work": self.pairs,
            f"{self.processes} worker process{'es' if self.processes != 1 else ''}":
                self.workers,
            **dict(self.extra),
        }
        return dict(sorted(((k, v) for k, v in parts.items() if v > 0), key=lambda kv: -kv[1]))

    @property
    def total(self) -> float:
        return float(sum(self.parts().values()))

    def without(self, size: str) -> float:
        """Bytes of everything that does not grow with ``size`` ("pixels", "spp", "photons"
        or "triangles")."""
        rays = self.pixels * self.spp * self.per_ray
        drop = {"pixels": self.pixels * self.per_pixel + rays, "spp": rays,
                "photons": self.photon_bytes(),
                "triangles": self.triangles * self.per_triangle}[size]
        return self.total - drop

    def max_photons(self, cap: float) -> int:
        """The largest photon count per pass within ``cap`` bytes (everything else kept;
        ``2**62`` when any count fits, 0 when none does)."""
        room = cap - self.without("photons")
        if room < self.photon_bytes(1):
            return 0
        if self.per_photon_kept == 0:
            from .render import PHOTON_BATCH

            if self.photon_bytes(PHOTON_BATCH) <= room:
                return 1 << 62  # batched: any count fits
            return int(room // self.per_photon)
        lo, hi = 1, 2
        while self.photon_bytes(hi) <= room and hi < 1 << 62:
            lo, hi = hi, 2 * hi
        while hi - lo > 1:
            mid = (lo + hi) // 2
            lo, hi = (mid, hi) if self.photon_bytes(mid) <= room else (lo, mid)
        return lo


def depth_slots(scene, estimator) -> int:
    """Segment slots a photon batch traces (for the memory model): the scene's
    ``max_scatter``, or :data:`UNLIMITED_DEPTH_SLOTS` when unlimited, capped by the largest
    scatter count the estimator's techniques can use."""
    slots = scene.max_scatter if scene.max_scatter > 0 else UNLIMITED_DEPTH_SLOTS
    techs = _techniques(estimator)
    caps = [getattr(t, "max_k", None) for t in techs]
    if techs and all(c is not None for c in caps):
        slots = min(slots, max(caps))
    return max(1, int(slots))


def _techniques(estimator) -> tuple:
    return tuple(getattr(estimator, "techniques", ()) or ())


def _technique_bytes(name: str) -> tuple[int, int]:
    for prefix in sorted(TECHNIQUE_BYTES, key=len, reverse=True):
        if name.startswith(prefix):
            return TECHNIQUE_BYTES[prefix]
    return _LARGEST_TECHNIQUE


def photon_bytes(scene, estimator, *, keep_all: bool = False) -> float:
    """Bytes per photon in memory while a batch is processed (0 for the path tracer).

    ``keep_all``: every batch's paths and every technique's primitives are kept (a pixel
    inspection's record, whose work is one pixel's): :data:`KEPT_SLOT_BYTES` per technique
    and slot (measured per photon, kept over 16384-65536 photons: planes 3.9 k, paper-multi
    7.7 k; modelled 5.7 k and 15.3 k).
    """
    if getattr(estimator, "reference", False):
        return 0.0
    d = depth_slots(scene, estimator)
    techs = [_technique_bytes(t.name) for t in _techniques(estimator)] or [_LARGEST_TECHNIQUE]
    costs = sorted(a + b * d for a, b in techs)
    trace = TRACE_BYTES[0] + TRACE_BYTES[1] * d
    if keep_all:
        return trace + KEPT_SLOT_BYTES * d * len(costs)
    groups = getattr(estimator, "groups", ()) or ()
    mis = max((len(g) for g in groups if len(g) > 1), default=0) * MIS_MEMBER_BYTES
    return trace + costs[-1] + mis


def _mesh_parts(triangles: int, processes: int) -> tuple:
    """The named fixed part of meshes in ``processes`` processes (none without a mesh)."""
    if not triangles:
        return ()
    return (("trimesh and the ray-triangle tests", float(MESH_FIXED_BYTES) * processes),)


def scene_triangles(scene) -> int:
    """Mesh triangles of the scene's lights and occluders."""
    return int(sum(len(getattr(x, "triangles", ())) for x in (*scene.lights, *scene.occluders)
                   if getattr(x, "kind", "") == "mesh"))


def _pass_work(scene, estimators, settings_list):
    """One process's pass coefficients over estimators rendered one after the other (the
    largest counts): ``(per_ray, per_photon, photons, pairs)``."""
    per_ray = per_photon = pairs = 0.0
    photons = 0
    for est, st in zip(estimators, settings_list, strict=True):
        ref = getattr(est, "reference", False)
        per_ray = max(per_ray, REFERENCE_RAY_BYTES if ref else RAY_BYTES)
        if ref:
            continue
        photons = max(photons, int(st.photons))
        per_photon = max(per_photon, photon_bytes(scene, est))
        share = max((COMPILED_PAIR_FRACTION if getattr(t, "compiled", None) is not None
                     else PAIR_FRACTION for t in _techniques(est)), default=PAIR_FRACTION)
        pairs = max(pairs, share * st.memory_budget_mib * MIB)
    return per_ray, per_photon, photons, pairs


def render_need(scene, estimator, settings, *, jobs: int = 1, local_workers: int = 0,
                remote: bool = False, checkpoint: bool = False, kept_images: int = 0,
                estimators=None, settings_list=None) -> Need:
    """What ``render`` (or ``compare``, with ``estimators``) needs in memory on this machine.

    Parameters
    ----------
    scene : Scene
        After command-line overrides (resolution and meshes as loaded).
    estimator : Estimator
    settings : RenderSettings
    jobs : int
        ``--jobs``: local worker processes (1: passes render in this process).
    local_workers : int
        ``--workers``: a local Dask cluster of that many processes.
    remote : bool
        ``--dask ADDRESS``: passes render elsewhere; only the images are held here.
    checkpoint : bool
        A checkpoint snapshot of the accumulator is kept.
    kept_images : int
        Further float64 RGB images held beside (``compare``: mean and variance per run).
    estimators, settings_list : list, optional
        Several estimators rendered one after the other (``compare``; the largest pass work
        counts); ``estimator``/``settings`` are then ignored.

    Returns
    -------
    Need
    """
    ests = list(estimators) if estimators is not None else [estimator]
    sets = list(settings_list) if settings_list is not None else [settings] * len(ests)
    cam = scene.camera
    per_ray, per_photon, photons, pairs = _pass_work(scene, ests, sets)
    procs = 0 if remote else (local_workers or (jobs if jobs > 1 else 0))
    here = 0 if remote else max(procs, 1)  # processes rendering passes on this machine
    window = 2 * max(procs, 1) if (remote or procs) else 0  # passes waiting to be merged
    per_pixel = (accumulator_bytes_per_pixel() * (2 if checkpoint else 1) + PIXEL_BYTES
                 + 24 * kept_images + PASS_IMAGE_BYTES * (window + procs))
    per_worker = DASK_WORKER_BYTES if local_workers else WORKER_PROCESS_BYTES
    return Need(width=int(cam.width), height=int(cam.height), spp=int(max(s.spp for s in sets)),
                photons=photons, triangles=scene_triangles(scene), per_pixel=per_pixel,
                per_ray=per_ray * here, per_photon=per_photon * here,
                per_triangle=TRIANGLE_BYTES * (1 + procs), pairs=pairs * here,
                workers=per_worker * procs, processes=procs,
                extra=_mesh_parts(scene_triangles(scene), 1 + procs))


def progressive_need(scene, estimators, settings, *, workers: int = 1,
                     breakdown: bool = False, inspect: bool = False,
                     k_bins: int | None = None) -> Need:
    """What the window's (or ``record``'s) progressive render needs.

    Every estimator's accumulator (and with ``breakdown`` its per-technique, per-K stacks),
    passes rendered in ``workers`` background processes (0: in this one), and with
    ``inspect`` the stages' record of one whole pass of the first photon estimator (every
    photon batch and every technique's primitives are kept).
    """
    from .breakdown import DEFAULT_K_MAX

    ests = list(estimators)
    bins = DEFAULT_K_MAX if k_bins is None else int(k_bins)
    stacks = (sum(2 * len(_techniques(e)) * bins for e in ests if not e.reference)
              if breakdown else 0)
    per_ray, per_photon, photons, pairs = _pass_work(scene, ests, [settings] * len(ests))
    here = max(workers, 1)
    per_pixel = (accumulator_bytes_per_pixel() * (len(ests) + stacks) + PIXEL_BYTES
                 + PASS_IMAGE_BYTES * (1 + stacks) * here)
    kept = 0.0
    if inspect:
        first = [e for e in ests if not e.reference][:1]
        kept = photon_bytes(scene, first[0], keep_all=True) if first else 0.0
        photons = int(settings.photons) if first else photons
    return Need(width=int(scene.camera.width), height=int(scene.camera.height),
                spp=int(settings.spp), photons=photons, triangles=scene_triangles(scene),
                per_pixel=per_pixel, per_ray=per_ray * here, per_photon=per_photon * here,
                per_triangle=TRIANGLE_BYTES * (1 + workers), per_photon_kept=kept,
                pairs=pairs * here, workers=WORKER_PROCESS_BYTES * workers, processes=workers,
                extra=_mesh_parts(scene_triangles(scene), 1 + workers))


# --------------------------------------------------------------------------- disk


def checkpoint_bytes(scene) -> int:
    """Bytes of ``DIR/checkpoint.npz`` for ``scene`` (uncompressed: every accumulator array)."""
    cam = scene.camera
    return accumulator_bytes_per_pixel() * cam.width * cam.height + CHECKPOINT_META_BYTES


def output_bytes(scene, *, png: bool = False, exr: bool = False) -> int:
    """Upper bound of the bytes ``render`` writes: the compressed ``.npz`` (float32 ``mean``
    and ``var``, at worst incompressible), the PNG (8-bit RGB) and the EXR (float32 RGB)."""
    px = scene.camera.width * scene.camera.height
    return int(px * (24 + (3 if png else 0) + (12 if exr else 0)) * 1.01) + (256 << 10)


def picture_bytes(width: int, height: int) -> tuple[str, float]:
    """The named part of an off-screen picture of ``width x height`` (``--size``), for
    :attr:`Need.extra`."""
    return (f"the {width}x{height} picture (--size)", float(width) * height * PICTURE_BYTES)

