"""Everything the UI shows for one pixel and one pass, as plain records (numpy only).

:func:`inspect_pixel` replays pass ``pass_index`` of a progressive render for a single pixel
(``render_pass(..., pixels=[p], record=...)``: the same rays, photons and primitives the full
pass used, see ``render.py``) and flattens what happened into a :class:`HitTable`, one row per
camera-ray/primitive hit, whose contributions sum to the pixel's value in that pass.
:func:`reconstruct_hit` gives the full path one hit implies and every MIS member's density on
it (the paper's Reconstruct stage); :func:`primitive_pixels` the pixels one primitive reaches.

Pixel coordinates are ``(X, Y)``: ``X`` the column from the left, ``Y`` the row from the top.

Units of the hit table (spec section 1: ``X_p`` is the per-photon contribution):

* ``value`` is the technique's Evaluate output ``X = f / (q |n . psi|)`` for the hit's photon,
  before the MIS weight and before the ``1 / (photons * spp)`` normalisation;
* ``contribution = mis_weight * value / (photons * spp)``: the hit's share of the pixel's value
  in this pass (what the renderer summed, to the last bit);
* ``f = value * |n . psi|``: the contribution before the Jacobian (``f / q``), NaN for the kernel
  baselines, which have no surface normal.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .constants import NEAR_SINGULAR
from .estimators import Estimator, parse_estimator
from .geometry import blockers_of
from .mis import member_densities, weights_from_densities
from .render import (
    PHOTON_BATCH,
    PassRecord,
    RenderSettings,
    kernel_radius,
    pass_generators,
    render_pass,
)
from .scene import Scene
from .techniques.base import Hits, PassContext, Primitives, Technique, fields_of, take

__all__ = [
    "HitTable",
    "PixelInspection",
    "inspect_pixel",
    "member_primitives",
    "primitive_pixels",
    "reconstruct_hit",
]

#: Relative tolerance of the "hit table sums to the pixel value" check.
SUM_RTOL = 1e-9


@dataclass(frozen=True)
class HitTable:
    """One row per hit of the inspected pixel's rays (leading axis N, all arrays flat).

    Attributes
    ----------
    technique, family : (N,) str (object arrays)
    group : (N,) int
        Index of the estimator group (an MIS set, or a single technique) of the technique.
    batch : (N,) int
        Photon batch of the pass (``render.PHOTON_BATCH`` photons each).
    index : (N,) int
        Row in ``PixelInspection.hits[(technique, batch)]``.
    prim, photon, K : (N,) int
        Primitive (row of ``prims[(technique, batch)]``), photon (row of ``paths[batch]``) and
        scatter count.
    ray : (N,) int
        Row of ``PixelInspection.rays``.
    s : (N,) float
        Distance of the hit along the camera ray.
    point : (N, 3) float
        The hit point ``y(s) = o + s psi``.
    psi : (N, 3) float
        Camera-ray direction.
    normal : (N, 3) float
        Scaled normal ``n`` of the swept surface at the hit (NaN where unknown: kernels).
    n_dot_psi : (N,) float
        ``|n . psi|``: ``hits.data['n_dot_psi']``, else ``|normal . psi|`` (NaN for kernels).
    value : (N, 3) float
        Per-photon Evaluate output (see the module docstring).
    mis_weight : (N,) float
        1 for a technique used alone.
    contribution : (N, 3) float
        Share of the pixel's pass value; the rows sum to it.
    f : (N, 3) float
        ``value * |n . psi|`` (NaN without a normal).
    near_singular : (N,) bool
        ``|n . psi| < constants.NEAR_SINGULAR``.
    """

    technique: np.ndarray
    family: np.ndarray
    group: np.ndarray
    batch: np.ndarray
    index: np.ndarray
    prim: np.ndarray
    photon: np.ndarray
    K: np.ndarray
    ray: np.ndarray
    s: np.ndarray
    point: np.ndarray
    psi: np.ndarray
    normal: np.ndarray
    n_dot_psi: np.ndarray
    value: np.ndarray
    mis_weight: np.ndarray
    contribution: np.ndarray
    f: np.ndarray
    near_singular: np.ndarray

    def __len__(self) -> int:
        return self.s.shape[0]

    @property
    def total(self) -> np.ndarray:
        """(3,) sum of the contributions."""
        return self.contribution.sum(axis=0)

    def by_contribution(self) -> np.ndarray:
        """Row order by decreasing mean-RGB contribution (stable)."""
        return np.argsort(-self.contribution.mean(axis=1), kind="stable")


@dataclass
class PixelInspection:
    """One pixel of one pass, everything recorded (see :func:`inspect_pixel`).

    Attributes
    ----------
    scene, estimator, seed, pass_index, settings
        What was replayed.
    pixel_xy : (int, int)
        ``(X, Y)``: column from the left, row from the top.
    pixel : int
        Flat index ``Y * width + X``.
    rays : Rays
        The pixel's camera rays in this pass (``settings.spp`` of them).
    paths : list of PhotonPaths
        The pass's photon subpaths, one entry per batch.
    prims : dict of (technique name, batch) -> Primitives
    hits : dict of (technique name, batch) -> Hits
        All hits of the pixel's rays, chunks concatenated.
    techniques : dict of technique name -> Technique
    radii : dict of technique name -> float
        Kernel radius in this pass (0 for unbiased techniques).
    table : HitTable
    pixel_value : (3,) float
        The pixel's value in this pass, from ``render_pass``.
    """

    scene: Scene
    estimator: Estimator
    seed: int
    pass_index: int
    settings: RenderSettings
    pixel_xy: tuple
    pixel: int
    rays: object
    paths: list
    prims: dict
    hits: dict
    techniques: dict
    radii: dict
    table: HitTable
    pixel_value: np.ndarray
    groups: tuple = field(default=())

    @property
    def table_sum(self) -> np.ndarray:
        """(3,) sum of the hit table's contributions."""
        return self.table.total

    @property
    def sum_matches(self) -> bool:
        """Whether the hit table sums to :attr:`pixel_value` (relative :data:`SUM_RTOL`)."""
        return bool(np.allclose(self.table_sum, self.pixel_value, rtol=SUM_RTOL,
                                atol=1e-300))

    @property
    def n_photons(self) -> int:
        return int(sum(p.n_emitted for p in self.paths))

    def context(self, technique: str) -> PassContext:
        """The :class:`PassContext` the pass used for ``technique``."""
        return PassContext(self.scene, blockers_of(self.scene), self.radii[technique],
                           self.pass_index, self.settings.max_pairs)


# --------------------------------------------------------------------------- helpers
def _estimator(estimator, scene: Scene) -> Estimator:
    est = parse_estimator(estimator, scene) if isinstance(estimator, str) else estimator
    if est.reference:
        raise ValueError("the inspector needs a photon estimator, not 'reference' "
                         "(the path tracer has no photons, primitives or hits)")
    return est


def _pixel_index(scene: Scene, pixel_xy) -> int:
    x, y = (int(v) for v in pixel_xy)
    cam = scene.camera
    if not (0 <= x < cam.width and 0 <= y < cam.height):
        raise ValueError(f"pixel ({x}, {y}) is outside the {cam.width}x{cam.height} image "
                         f"(X in [0, {cam.width - 1}], Y in [0, {cam.height - 1}])")
    return y * cam.width + x


def _concat_hits(chunks: list) -> Hits:
    """One :class:`Hits` from the chunks recorded for a (technique, batch)."""
    if len(chunks) == 1:
        return chunks[0]
    if not isinstance(chunks[0].data, dict):  # declared hit records
        return Hits(np.concatenate([h.ray for h in chunks]),
                    np.concatenate([h.prim for h in chunks]),
                    np.concatenate([h.s for h in chunks]),
                    np.concatenate([h.data for h in chunks]).view(np.recarray))
    keys = set(chunks[0].data)
    for h in chunks[1:]:
        keys &= set(h.data)
    return Hits(np.concatenate([h.ray for h in chunks]),
                np.concatenate([h.prim for h in chunks]),
                np.concatenate([h.s for h in chunks]),
                {k: np.concatenate([h.data[k] for h in chunks]) for k in sorted(keys)})


def _dot(a, b):
    return np.einsum("ij,ij->i", a, b)


def _scaled_normals(tech: Technique, hits: Hits, prims: Primitives, paths, rays,
                    ctx: PassContext) -> np.ndarray:
    """(H, 3) scaled normal ``n`` of the swept surface at each hit, by family; NaN rows where
    the family has no surface (kernels) or its layout is unknown to the inspector."""
    h = len(hits)
    nan = np.full((h, 3), np.nan)
    if h == 0:
        return nan
    d, p, hd = fields_of(prims.data), hits.prim, fields_of(hits.data)
    try:
        if hasattr(tech, "scaled_normal") and (tech.compiled is not None
                                               or getattr(tech, "family", "") == "single"):
            return np.asarray(tech.scaled_normal(tech.reconstruct(hits, prims, paths, rays, ctx)),
                              dtype=float)
        fam = tech.family
        with np.errstate(invalid="ignore", divide="ignore"):
            if fam == "planes" and "w1" in d and "x2" in d:
                return np.cross(d["w1"][p], d["w2"][p])
            if fam == "planes" and "v" in d and "w3" in d:
                return np.cross(d["v"][p], d["w3"][p])
            if fam == "spheres":
                return (d["T1"][p] ** 2)[:, None] * hd["w1"]
            if fam == "cones":
                w1, w2, t1 = hd["w1"], d["w2"][p], hd["t1"]
                return t1[:, None] * (w2 - _dot(w1, w2)[:, None] * w1)
            if fam == "cylinders":
                w1, w2, T1 = hd["w1"], d["w2"][p], d["T1"][p]
                return T1[:, None] * (_dot(w1, w2)[:, None] * w2 - w1)
            if fam == "disks":
                cr = np.cross(hd["w1"], d["w2"][p])
                return (hd["t1"] / _dot(cr, cr))[:, None] * cr
            if fam == "revolutions" and hasattr(tech, "_normal"):
                hit = rays.o[hits.ray] + hits.s[:, None] * rays.d[hits.ray]
                return np.asarray(tech._normal(hd["w2"], hd["w1"], hd["t1"], d["A3"][p],
                                               hit - d["x2"][p]), dtype=float)
    except (KeyError, NotImplementedError, AttributeError, ValueError, IndexError):
        return nan
    return nan


def _group_of(est: Estimator) -> dict:
    """Technique name -> (group index, group)."""
    out = {}
    for gi, g in enumerate(est.groups):
        for t in g:
            out.setdefault(t.name, (gi, g))
    return out


# --------------------------------------------------------------------------- inspect
def inspect_pixel(scene: Scene, estimator, seed: int, pass_index: int, pixel_xy,
                  settings: RenderSettings) -> PixelInspection:
    """Replay pass ``pass_index`` for one pixel and record every stage.

    Parameters
    ----------
    scene : Scene
    estimator : Estimator or str
        A photon estimator (a spec string is parsed against ``scene``).
    seed, pass_index : int
        The pass (``SeedSequence([seed, pass_index])``), as in a progressive render.
    pixel_xy : (int, int)
        ``(X, Y)``, column from the left and row from the top.
    settings : RenderSettings

    Returns
    -------
    PixelInspection

    Raises
    ------
    ValueError
        For the reference estimator or a pixel outside the image.
    """
    est = _estimator(estimator, scene)
    pix = _pixel_index(scene, pixel_xy)
    blockers = blockers_of(scene)
    rec = PassRecord()
    img = render_pass(scene, est, pass_index, seed, settings, blockers=blockers,
                      pixels=np.array([pix]), record=rec)
    pixel_value = img.reshape(-1, 3)[pix].copy()
    rays = rec.rays
    norm = float(settings.photons * settings.spp)
    techs = {t.name: t for t in est.techniques}
    radii = {n: kernel_radius(t, scene, settings, pass_index) for n, t in techs.items()}
    groups = _group_of(est)

    hits_all, rows = {}, []
    for (name, b), chunks in rec.hits.items():
        hits = _concat_hits([h for h, _ in chunks])
        val_w = np.concatenate([v for _, v in chunks], axis=0)  # as summed by the pass
        hits_all[(name, b)] = hits
        tech = techs[name]
        gi, group = groups[name]
        prims, paths = rec.prims[(name, b)], rec.paths[b]
        ctx = PassContext(scene, blockers, radii[name], pass_index, settings.max_pairs)
        if len(group) > 1:
            raw = tech.evaluate(hits, prims, paths, rays, ctx)
            r = tech.reconstruct(hits, prims, paths, rays, ctx)
            w = weights_from_densities(member_densities(r, group, ctx), est.weighting)
            w = w[[i for i, m in enumerate(group) if m is tech][0]]
        else:
            raw, w = val_w, np.ones(len(hits))
        normal = _scaled_normals(tech, hits, prims, paths, rays, ctx)
        if "n_dot_psi" in fields_of(hits.data):
            ndp = np.asarray(hits.data["n_dot_psi"], dtype=float)
        else:  # techniques that keep no |n . psi| in their hits (single scattering)
            ndp = np.abs(_dot(normal, rays.d[hits.ray]))
        rows.append(dict(
            technique=np.full(len(hits), name, dtype=object),
            family=np.full(len(hits), tech.family, dtype=object),
            group=np.full(len(hits), gi), batch=np.full(len(hits), b),
            index=np.arange(len(hits)), prim=hits.prim, photon=prims.photon[hits.prim],
            K=prims.K[hits.prim], ray=hits.ray, s=hits.s,
            point=rays.o[hits.ray] + hits.s[:, None] * rays.d[hits.ray], psi=rays.d[hits.ray],
            normal=normal,
            n_dot_psi=ndp, value=raw, mis_weight=w, contribution=val_w / norm,
            f=raw * ndp[:, None],
            near_singular=np.isfinite(ndp) & (ndp < NEAR_SINGULAR),
        ))
    table = _table(rows)
    return PixelInspection(
        scene=scene, estimator=est, seed=int(seed), pass_index=int(pass_index),
        settings=settings, pixel_xy=(int(pixel_xy[0]), int(pixel_xy[1])), pixel=pix,
        rays=rays, paths=rec.paths, prims=rec.prims, hits=hits_all, techniques=techs,
        radii=radii, table=table, pixel_value=pixel_value, groups=est.groups,
    )


_INT = ("group", "batch", "index", "prim", "photon", "K", "ray")
_VEC = ("point", "psi", "normal", "value", "contribution", "f")


def _table(rows: list) -> HitTable:
    names = HitTable.__dataclass_fields__.keys()
    if not rows:
        empty = {}
        for n in names:
            if n in ("technique", "family"):
                empty[n] = np.zeros(0, dtype=object)
            elif n in _INT:
                empty[n] = np.zeros(0, dtype=np.int64)
            elif n in _VEC:
                empty[n] = np.zeros((0, 3))
            elif n == "near_singular":
                empty[n] = np.zeros(0, dtype=bool)
            else:
                empty[n] = np.zeros(0)
        return HitTable(**empty)
    return HitTable(**{n: np.concatenate([r[n] for r in rows], axis=0) for n in names})


# --------------------------------------------------------------------------- reconstruct
_LABELS = ("x3", "x2", "x1", "x0")


def reconstruct_hit(inspection: PixelInspection, k: int) -> dict:
    """The Reconstruct stage for row ``k`` of the hit table.

    Returns
    -------
    dict with
        ``row`` (int), ``technique``, ``family`` (str), ``K`` (int);
        ``available`` (bool) and ``note`` (str): False for techniques without a
        reconstruction (kernel baselines);
        ``record`` : PathRecord of length 1 (None when not available);
        ``polyline`` : (V, 3) the full path, light -> ... -> ``x0`` -> camera;
        ``labels`` : V names (``"light"``, ``"x3"``..``"x0"``, ``"camera"``);
        ``photon_polyline`` : (K, 3) the photon's own sampled vertices ``x_K .. x_1``
        (what the hit replaced is then visible beside the reconstruction);
        ``members`` : list of ``(name, Q, weight)``, one per member of the hit's MIS group
        (the technique alone: weight 1);
        ``weighting`` : ``"balance"``, ``"power"`` or None.
    """
    t = inspection.table
    if not 0 <= k < len(t):
        raise IndexError(f"hit {k} does not exist (the table has {len(t)} rows)")
    name, b, i = str(t.technique[k]), int(t.batch[k]), int(t.index[k])
    tech = inspection.techniques[name]
    hits = inspection.hits[(name, b)].select(np.array([i]))
    prims, paths = inspection.prims[(name, b)], inspection.paths[b]
    ctx = inspection.context(name)
    gi = int(t.group[k])
    group = inspection.groups[gi]
    K = int(t.K[k])
    photon = int(t.photon[k])
    cam = inspection.rays.o[int(t.ray[k])]
    out = dict(row=k, technique=name, family=str(t.family[k]), K=K, available=False,
               note="", record=None, members=[], weighting=inspection.estimator.weighting
               if len(group) > 1 else None)
    # The photon's own sampled vertices (tracer 0..K-1 are x_K..x_1).
    out["photon_polyline"] = paths.x[photon, :K].copy()
    try:
        rec = tech.reconstruct(hits, prims, paths, inspection.rays, ctx)
    except NotImplementedError:
        out["note"] = f"{name} is a kernel estimator: it has no exact path to reconstruct"
        labels = [f"x{K - j}" for j in range(K)] + ["x0", "camera"]
        labels[0] += " (light)"
        out["polyline"] = np.vstack([paths.x[photon, :K], t.point[k], cam])
        out["labels"] = labels
        out["members"] = [(name, float("nan"), float(t.mis_weight[k]))]
        return out
    out["available"], out["record"] = True, rec
    # Vertices before x3 are sampled identically by every technique: the photon's own.
    early = max(K - 3, 0)
    verts = [paths.x[photon, j] for j in range(early)]
    labels = [f"x{K - j}" for j in range(early)]
    for lab in _LABELS:
        v = getattr(rec, lab)[0]
        if np.all(np.isfinite(v)):
            verts.append(v)
            labels.append(lab)
    labels[0] += " (light)"
    verts.append(cam)
    labels.append("camera")
    out["polyline"] = np.vstack(verts)
    out["labels"] = labels
    if len(group) > 1:
        q = member_densities(rec, group, ctx)[:, 0]
        w = weights_from_densities(q[:, None], inspection.estimator.weighting)[:, 0]
        out["members"] = [(m.name, float(q[j]), float(w[j])) for j, m in enumerate(group)]
    else:
        try:
            q = float(np.abs(tech.density(rec, ctx))[0])
        except NotImplementedError:
            q = float("nan")
        out["members"] = [(name, q, 1.0)]
    return out


def member_primitives(inspection: PixelInspection, recon: dict) -> dict:
    """The primitive every MIS member sweeps through the path a hit implies.

    The talk's Reconstruct picture: one full path, and every technique's surface through it
    (whose density ``Q_j`` on that path :func:`reconstruct_hit` gives). The path's vertices
    (light ``x_K`` .. ``x0``) become a one-photon :class:`~psurf_core.trace.PhotonPaths`
    (unit weights), and each member's own ``create`` makes its primitives of scatter count
    ``K`` from it. Every exact member's surface then contains ``x0``; a short (track-length)
    member's extent is the path's own segment lengths, so ``x0`` lies on its edge.

    Parameters
    ----------
    recon : dict
        :func:`reconstruct_hit` output with ``available`` True.

    Returns
    -------
    dict
        ``member name -> (technique, Primitives, rows)``; rows ``(n,) int`` of primitives
        with the hit's ``K`` (empty when the member cannot make this path, e.g. a
        single-scattering technique for ``K >= 2``). Empty for an unavailable reconstruction.
    """
    from .trace import PhotonPaths

    if not recon.get("available"):
        return {}
    rec = recon["record"]
    K = int(recon["K"])
    verts = np.asarray(recon["polyline"], dtype=float)[:-1]  # light x_K .. x0 (no camera)
    if verts.shape[0] != K + 1:
        return {}
    seg = np.diff(verts, axis=0)
    t = np.linalg.norm(seg, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        w = seg / t[:, None]
    if not (np.all(np.isfinite(w)) and np.all(t > 0)):
        return {}
    x = verts
    paths = PhotonPaths(
        n_emitted=1, light=np.asarray(rec.light[:1], dtype=np.int64),
        light_pmf=np.ones(1), light_uv=np.asarray(rec.uv[:1], dtype=float),
        tri=np.asarray(rec.tri[:1], dtype=np.int64),
        light_normal=np.asarray(rec.axis[:1], dtype=float), x=x[None], w=w[None], t=t[None],
        beta=np.ones((1, K, 3)), alive=np.ones((1, K), dtype=bool),
        prefix_ok=np.ones((1, K + 1), dtype=bool),
        clip=np.stack([np.zeros(K), t], axis=1)[None])
    group = inspection.groups[int(inspection.table.group[int(recon["row"])])]
    out = {}
    for tech in group:
        ctx = inspection.context(tech.name)
        try:
            prims = tech.create(paths, ctx)
        except (IndexError, ValueError):  # a member that needs more of the path than exists
            out[tech.name] = (tech, None, np.zeros(0, np.int64))
            continue
        out[tech.name] = (tech, prims, np.flatnonzero(prims.K == K))
    return out


# --------------------------------------------------------------------------- coverage
def primitive_pixels(scene: Scene, estimator, seed: int, pass_index: int, technique: str,
                     prim_id: int, settings: RenderSettings, *, batch: int = 0) -> np.ndarray:
    """Pixels primitive ``prim_id`` of ``technique`` contributes to in pass ``pass_index``.

    The pass's own jittered camera rays of every pixel are intersected with that one
    primitive; a pixel counts when some hit has a non-zero Evaluate value (before MIS
    weights).

    Parameters
    ----------
    technique : str
        A technique name of the estimator (as in the hit table, e.g. ``plane-t1t2-short``).
    prim_id : int
        Row of that technique's primitives in photon batch ``batch``.

    Returns
    -------
    (H, W) bool
        Row 0 at the top (index ``[Y, X]``).
    """
    from .binning import candidate_pairs
    from .camera import camera_rays
    from .trace import trace

    est = _estimator(estimator, scene)
    techs = {t.name: t for t in est.techniques}
    if technique not in techs:
        raise ValueError(f"technique '{technique}' is not part of estimator '{est.spec}' "
                         f"(members: {', '.join(techs)})")
    tech = techs[technique]
    cam = scene.camera
    blockers = blockers_of(scene)
    ray_rng, photon_ss = pass_generators(seed, pass_index)
    rays = camera_rays(scene, settings.spp, ray_rng, blockers=blockers)
    n_batches = -(-settings.photons // PHOTON_BATCH)
    if not 0 <= batch < n_batches:
        raise ValueError(f"batch {batch} does not exist (the pass has {n_batches})")
    batch_ss = photon_ss.spawn(n_batches)
    n = min(PHOTON_BATCH, settings.photons - batch * PHOTON_BATCH)
    paths = trace(scene, n, np.random.default_rng(batch_ss[batch]), blockers=blockers)
    ctx = PassContext(scene, blockers, kernel_radius(tech, scene, settings, pass_index),
                      pass_index, settings.max_pairs)
    prims = tech.create(paths, ctx)
    if not 0 <= prim_id < len(prims):
        raise ValueError(f"primitive {prim_id} does not exist ({technique} has {len(prims)} "
                         f"in batch {batch})")
    sel = np.array([prim_id])
    one = Primitives(prims.technique, prims.photon[sel], prims.K[sel], prims.lo[sel],
                     prims.hi[sel], take(prims.data, sel))
    mask = np.zeros(cam.n_pixels, dtype=bool)
    for ray, prim in candidate_pairs(cam, rays, one.lo, one.hi, settings.max_pairs):
        hits = tech.intersect(one, rays, ray, prim, ctx)
        if len(hits) == 0:
            continue
        val = tech.evaluate(hits, one, paths, rays, ctx)
        good = np.any(val != 0.0, axis=1)
        mask[rays.pixel[hits.ray[good]]] = True
    return mask.reshape(cam.height, cam.width)
