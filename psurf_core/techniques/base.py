"""The Technique protocol and the records that flow through Create -> Intersect -> Evaluate.

A technique (one estimator family member such as ``planes`` or ``cone-short``) is an object
with the small interface of :class:`Technique`. The render pass (``render.py``) calls

``create(paths, ctx) -> Primitives``      one primitive per (photon, scatter count K)
``intersect(prims, rays, ray, prim, ctx)`` roots of candidate pairs -> :class:`Hits`
``evaluate(hits, prims, paths, rays, ctx)`` per-hit per-photon contribution ``X`` (H, 3)

and never allocates a full ``rays x primitives`` array: the candidate pairs come from
``binning.py`` in bounded chunks. Contributions are per photon (the spec's ``X_p``, carrying
the full emitted power); the pass divides by photons emitted and by rays per pixel.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..geometry import Blockers, inside_box
from ..kernels.jit import twin
from ..scene import Scene
from .compiled import Compiled  # (the families import it from here)


@dataclass
class PassContext:
    """What every stage of one pass may read.

    Attributes
    ----------
    scene : Scene
    blockers : Blockers
    radius : float
        Kernel radius of this pass for kernel (biased) techniques, else unused.
    pass_index : int
    max_pairs : int
        Ray-primitive candidate pairs per chunk (from the memory budget).
    """

    scene: Scene
    blockers: Blockers
    radius: float = 0.0
    pass_index: int = 0
    max_pairs: int = 1 << 21


@dataclass
class Primitives:
    """Photon primitives of one technique for one pass (struct of arrays, leading axis M).

    Attributes
    ----------
    technique : str
    photon : (M,) int
        Photon (row of :class:`~psurf_core.trace.PhotonPaths`) the primitive was made from.
    K : (M,) int
        Scatter count of the paths this primitive estimates.
    lo, hi : (M, 3) float
        World-space bounds, clipped to the medium box (drive screen-space binning).
    data : dict of str to (M, ...) ndarray
        Family-specific geometry (origins, axes, sampled lengths, ...).
    hull : (M, V, 3) float or None
        Planar families: a convex polygon containing the primitive's part inside the box
        (binning tests only the pixels it covers); a row with a non-finite vertex, or
        ``None``, falls back to the screen rectangle of ``[lo, hi]``.
    cloud : (M, V, 3) float or None
        Curved families: a footprint solid containing the primitive: an apex then a convex
        polygon ring (V odd: a pyramid), or two such rings, vertex by vertex a translate of
        each other (V even: a right prism). The compiled walkers visit only the pixels the
        solid clipped to the box covers, within the rectangle
        (:mod:`psurf_core.kernels.cloud_spans`). A row with a point that is not finite, or
        clipped behind the camera, falls back to the rectangle. (The numpy stage path uses
        the rectangles.)
    box : (M, 2, 3) float or None
        Per primitive, ``(lo, hi)`` of a box where its hits can count (a light strip's,
        :func:`.bounds.hit_boxes`): both span paths clip the hull to it (:meth:`clip_box`).
    """

    technique: str
    photon: np.ndarray
    K: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    data: dict = field(default_factory=dict)
    hull: np.ndarray | None = None
    cloud: np.ndarray | None = None
    box: np.ndarray | None = None

    def __len__(self) -> int:
        return self.photon.shape[0]

    def clip_box(self, scene: Scene) -> tuple[np.ndarray, np.ndarray]:
        """``(lo, hi)`` the hulls are clipped to: :attr:`box`'s (M, 3), or the medium's."""
        if self.box is not None:
            return self.box[:, 0], self.box[:, 1]
        return scene.medium.bounds_min, scene.medium.bounds_max


@dataclass
class Hits:
    """Camera-ray/primitive hits as flat parallel arrays (leading axis H).

    Attributes
    ----------
    ray, prim : (H,) int
        Indices into the pass's :class:`~psurf_core.camera.Rays` and :class:`Primitives`.
    s : (H,) float
        Distance of the hit along the camera ray.
    data : dict of str to (H, ...) ndarray
        The roots of the integrated dimensions and anything evaluate needs.
    """

    ray: np.ndarray
    prim: np.ndarray
    s: np.ndarray
    data: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return self.ray.shape[0]

    def select(self, mask: np.ndarray) -> Hits:
        return Hits(self.ray[mask], self.prim[mask], self.s[mask], take(self.data, mask))


class Technique:
    """Base class of every technique; subclasses fill in the three stages.

    Class attributes
    ----------------
    name : str
        Registry name (``planes``, ``beams-long``, ``cone-short``, ...).
    family : str
        Primitive family for drawing and legends (``points``, ``beams``, ``planes``, ...).
    kernel_dim : int
        Blur dimension of a kernel estimator (3 points, 2 BRE, 1 beams); 0 if unbiased.
    min_k, max_k : int
        Scatter counts the technique can produce (``max_k`` None: unbounded).
    lights : tuple of str
        Light kinds it applies to.
    """

    name = "?"
    #: ``(long name, short name)`` of a technique built as ``Technique(short)`` (short name
    #: None: there is no short variant); None: the class sets ``name`` itself.
    names: tuple | None = None
    family = "?"
    #: The family's compiled declaration; None: the numpy stages only.
    compiled: Compiled | None = None
    kernel_dim = 0
    min_k = 1
    max_k: int | None = None
    lights = ("point", "area", "mesh")
    short = False
    #: Whether the technique sweeps a surface with a scaled normal (:meth:`scaled_normal`);
    #: False for the kernel estimators, which blur points or beams instead.
    surface = True
    #: Share of each pass's photons the technique sweeps inside an MIS set (``NAME@0.25``):
    #: the first ``round(share x batch)`` photons of every batch (photons are iid, so any
    #: subset of fixed size is an unbiased sample); the MIS weights use sample counts.
    share = 1.0

    def __init__(self, short: bool = False):
        self.short = bool(short)
        if self.names is not None:
            long_name, short_name = self.names
            if short and short_name is None:
                raise ValueError(f"{long_name} has no short variant")
            self.name = short_name if short else long_name

    @property
    def label(self) -> str:
        """The name with its share where it is not 1 (``cone@0.25``)."""
        return self.name if self.share == 1.0 else f"{self.name}@{self.share:g}"

    # ---------------------------------------------------------------- which paths
    def k_range(self, scene: Scene, depth: int) -> range:
        """Scatter counts K this technique estimates in ``scene`` with ``depth`` traced segments."""
        hi = depth if scene.max_scatter < 0 else min(scene.max_scatter, depth)
        if self.max_k is not None:
            hi = min(hi, self.max_k)
        return range(max(self.min_k, scene.min_scatter), hi + 1)

    def can_produce(self, K: np.ndarray, kind: np.ndarray) -> np.ndarray:
        """(H,) bool: can this technique produce paths of scatter count ``K`` from lights of
        kind code ``kind`` (:data:`psurf_core.path_record.KIND_CODE`)?"""
        from ..path_record import KIND_CODE

        ok = K >= self.min_k
        if self.max_k is not None:
            ok &= K <= self.max_k
        allowed = np.zeros(max(KIND_CODE.values()) + 1, dtype=bool)
        allowed[[KIND_CODE[k] for k in self.lights]] = True
        return ok & allowed[kind]

    def applies_to(self, light) -> bool:
        return light.kind in self.lights

    def light_mask(self, paths, scene: Scene) -> np.ndarray:
        """(P,) bool: photons emitted by a light this technique applies to."""
        ok = np.array([self.applies_to(lt) for lt in scene.lights], dtype=bool)
        return ok[paths.light]

    # ---------------------------------------------------------------- the stages
    # A family with a compiled declaration (``compiled``) gets Intersect, Evaluate,
    # Reconstruct and its MIS density from the numpy twins it declares: the same functions,
    # in the same order, as its compiled walker (psurf_core.kernels.walk).
    def create(self, paths, ctx: PassContext) -> Primitives:  # pragma: no cover - abstract
        raise NotImplementedError

    def intersect(self, prims: Primitives, rays, ray: np.ndarray, prim: np.ndarray,
                  ctx: PassContext) -> Hits:
        """Hits among candidate pairs ``(ray, prim)``: the family's ``roots``, the ray's
        valid interval, then its ``accept``."""
        fam = self._declared()
        roots = fam.roots(prims.data[prim], rays.o[ray], rays.d[ray])
        n_r = roots.shape[0]
        ray, prim, s = np.tile(ray, n_r), np.tile(prim, n_r), roots.reshape(-1)
        with np.errstate(invalid="ignore"):
            k = np.flatnonzero(on_ray(rays, ray, s))  # NaN: no root
        ray, prim, s = ray[k], prim[k], s[k]
        ok, hit = fam.accept(prims.data[prim], rays.o[ray], rays.d[ray], s, self.short)
        return Hits(ray[ok], prim[ok], s[ok], hit[ok])

    def evaluate(self, hits: Hits, prims: Primitives, paths, rays,
                 ctx: PassContext) -> np.ndarray:
        """Per-photon contributions (H, 3): the photon weight ``G.beta`` times the family's
        ``contribution`` where its ``visibility`` holds, else 0."""
        fam = self._declared()
        G = prims.data[hits.prim]
        x0 = rays.o[hits.ray] + hits.s[:, None] * rays.d[hits.ray]
        valid = fam.visibility(G, x0, hits.data, ctx.scene.medium, ctx.blockers)
        scal = fam.contribution(G, rays.d[hits.ray], hits.s, rays.s_min[hits.ray], hits.data,
                                self.short, ctx.scene.medium)
        with np.errstate(invalid="ignore"):
            return G.beta * np.where(valid, scal, 0.0)[:, None]

    def _declared(self) -> Compiled:
        if self.compiled is None:  # pragma: no cover - abstract
            raise NotImplementedError(f"{self.name} implements its own stages")
        return self.compiled

    # ---------------------------------------------------------------- MIS (Reconstruct)
    def reconstruct(self, hits: Hits, prims: Primitives, paths, rays, ctx: PassContext):
        """The full path (:class:`~psurf_core.path_record.PathRecord`) each hit implies."""
        if self.compiled is None or self.compiled.reconstruct is None:
            raise NotImplementedError(f"{self.name} has no MIS reconstruction")
        from ..path_record import photon_record

        p = hits.prim
        rec = photon_record(paths, prims.photon[p], prims.K[p], ctx.scene, rays, hits.ray,
                            hits.s)
        return self.compiled.reconstruct(rec, prims.data[p], hits.data)

    def density(self, rec, ctx: PassContext) -> np.ndarray:
        """Effective density ``Q = q |n . psi|`` of this technique on records ``rec`` (H,),
        without the factors shared by every technique (see ``path_record``)."""
        if self.compiled is None or self.compiled.density is None:
            raise NotImplementedError(f"{self.name} has no MIS density")
        return self.compiled.density(rec, self.short)

    # ---------------------------------------------------------------- the swept surface
    def scaled_normal(self, rec) -> np.ndarray:
        """(H, 3) scaled normal ``n`` of the surface this technique sweeps, at the paths
        ``rec`` (:class:`~psurf_core.path_record.PathRecord`). Every family with a surface
        provides it from its module's own ``scaled_normal``; a family without one (the kernel
        estimators) declares ``surface = False``."""
        raise NotImplementedError(f"{self.name} declares no scaled normal")

    def hit_normals(self, hits: Hits, prims: Primitives, paths, rays,
                    ctx: PassContext) -> np.ndarray:
        """(H, 3) scaled normal ``n`` at each hit: :meth:`scaled_normal` on the path each hit
        implies (:meth:`reconstruct`); NaN rows where the technique sweeps no surface."""
        if not self.surface:
            return np.full((len(hits), 3), np.nan)
        rec = self.reconstruct(hits, prims, paths, rays, ctx)
        return np.asarray(self.scaled_normal(rec), dtype=float)

    # ---------------------------------------------------------------- drawing
    #: The family module's ``surface_grid(G, short, far)`` (``G``: primitives' records), the
    #: points sweeping each primitive's surface; None where the family declares none.
    grid = None

    def surface_grid(self, prims: Primitives, idx: np.ndarray, far: float) -> np.ndarray:
        """(M, nu, nv, 3) points sweeping the surface of primitives ``idx`` (unclipped; a long
        primitive's unbounded extent stops at ``far``), what the Create view meshes."""
        if self.grid is None:
            raise NotImplementedError(f"{self.name} declares no surface grid")
        return self.grid(prims.data[idx], self.short, far)

    def kernel_extent(self, prims: Primitives, idx: np.ndarray, scene: Scene,
                      far: float) -> np.ndarray:
        """What a kernel estimator (``surface = False``) blurs, for drawing: (M, 1, 3) photon
        points or (K, 2, 3) beam segments inside the medium box."""
        raise NotImplementedError(f"{self.name} declares no kernel extent")


# ------------------------------------------------------------------------- shared helpers
def fields_of(data) -> dict:
    """``Primitives.data`` / ``Hits.data`` as a dict of columns (a family's record table, or
    the dict a family without declared records keeps)."""
    if isinstance(data, dict):
        return data
    return {name: data[name] for name in data.dtype.names}


def take(data, idx):
    """Rows ``idx`` of ``Primitives.data`` / ``Hits.data`` (record table or dict)."""
    if isinstance(data, dict):
        return {k: v[idx] for k, v in data.items()}
    return data[idx]


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise dot product of (N, 3) arrays."""
    return np.einsum("ij,ij->i", a, b)


@twin(dot, inline=True)
def _dot(a, b):
    """``dot`` of two 3-tuples, summed as numpy's ``einsum`` sums a C-contiguous row
    (``(a0 b0 + a2 b2) + a1 b1``: its two-way unrolled loop; measured), so that twins agree
    to the last bit where their numpy inputs are contiguous."""
    return (a[0] * b[0] + a[2] * b[2]) + a[1] * b[1]


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross product of (N, 3) arrays."""
    return np.cross(a, b)


@twin(cross, inline=True)
def _cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def camera_transmittance(scene: Scene, rays, ray_idx: np.ndarray, s: np.ndarray) -> np.ndarray:
    """``exp(-st (s - s_min))``: the camera segment is attenuated only inside the box."""
    return np.exp(-scene.medium.sigma_t * (s - rays.s_min[ray_idx]))


def on_ray(rays, ray_idx: np.ndarray, s: np.ndarray) -> np.ndarray:
    """(H,) bool: ``y(s)`` lies on the ray's in-medium, unblocked interval."""
    return (s > rays.s_min[ray_idx]) & (s < rays.s_max[ray_idx])


def in_medium(scene: Scene, x: np.ndarray) -> np.ndarray:
    """(H,) bool: points (H, 3) inside the medium box."""
    return inside_box(x, scene.medium.bounds_min, scene.medium.bounds_max)


def segments_clear(blockers: Blockers, *pairs, ok: np.ndarray | None = None,
                   known: np.ndarray | None = None) -> np.ndarray:
    """(H,) bool: every segment ``(a, b)`` given is unoccluded (one shadow test each).

    ``ok`` (H,) bool, optional: rows already known invalid (``False``) are not tested and stay
    ``False``. ``known`` (H,) bool, optional: rows known clear (:mod:`.shadow_cull`) are not
    tested either.
    """
    for a, b in pairs:
        if ok is None:
            ok = np.ones(a.shape[0], dtype=bool)
        idx = np.flatnonzero(ok if known is None else ok & ~known)
        if idx.size:
            ok[idx] = ~blockers.occluded(a[idx], b[idx])
    return ok


def on_own_segment(scene: Scene, paths, photon: np.ndarray, j: np.ndarray, t: np.ndarray,
                   T: np.ndarray, start: np.ndarray) -> np.ndarray:
    """(H,) bool: is ``start + t w`` (``0 < t < T``) known, without a test, to be inside the
    box and reached unoccluded along the photon's own segment ``j`` (tracer numbering: from
    vertex ``j - 1`` = ``start`` to vertex ``j``, sampled length ``T``)?

    ``prefix_ok[:, j]`` says the whole segment is unoccluded and vertices ``1..j`` lie in
    the box; a point before its end is then reached unoccluded, and lies in the (convex) box
    when the start does too (checked here when the start is the light, ``j = 1``). ``False``
    only means "not known": the caller tests those rows.
    """
    pk = paths.prefix_ok
    ok = pk.reshape(-1)[photon * pk.shape[1] + j] & (t < T)
    light = np.flatnonzero(ok & (j == 1))
    if light.size:
        ok[light] = in_medium(scene, start[light])
    return ok


def clear_from(scene: Scene, blockers: Blockers, start: np.ndarray, end: np.ndarray,
               known: np.ndarray) -> np.ndarray:
    """(H,) bool: ``end`` inside the box and ``start -> end`` unoccluded; rows ``known`` (from
    :func:`on_own_segment`) are true without a test."""
    ok = known.copy()
    idx = np.flatnonzero(~known)
    if idx.size:
        a, b = start[idx], end[idx]
        inb = in_medium(scene, b)
        res = np.zeros(idx.size, dtype=bool)
        k = np.flatnonzero(inb)
        if k.size:
            res[k] = ~blockers.occluded(a[k], b[k])
        ok[idx] = res
    return ok


def clip_bounds(scene: Scene, lo: np.ndarray, hi: np.ndarray):
    """Intersect per-primitive bounds (M, 3) with the medium box."""
    return (np.maximum(lo, scene.medium.bounds_min), np.minimum(hi, scene.medium.bounds_max))
