"""One pixel of one pass, every hit recorded: :func:`inspect_pixel` and its :class:`HitTable`.

:func:`inspect_pixel` replays pass ``pass_index`` of a progressive render for a single pixel
(``render_pass(..., pixels=[p], record=...)``: the same rays, photons and primitives the full
pass used, see ``render.py``) and flattens what happened into a :class:`HitTable`, one row per
camera-ray/primitive hit, whose contributions sum to the pixel's value in that pass.

Pixel coordinates are ``(X, Y)``: ``X`` the column from the left, ``Y`` the row from the top.

Units of the hit table (spec section 1: ``X_p`` is the per-photon contribution):

* ``value`` is the technique's Evaluate output ``X = f / (q |n . psi|)`` for the hit's photon,
  before the MIS weight and before the ``1 / (photons * spp)`` normalisation;
* ``contribution = mis_weight * value / (share * photons * spp)``: the hit's share of the
  pixel's value in this pass (what the renderer summed, to the last bit); ``share`` is the
  fraction of the photons the hit's MIS member swept (``NAME@0.3``; 1 otherwise), which
  ``mis_weight`` counts as a sample count;
* ``f = value * |n . psi|``: the contribution before the Jacobian (``f / q``), NaN for the kernel
  baselines, which have no surface normal.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..constants import NEAR_SINGULAR
from ..estimators import Estimator, parse_estimator
from ..geometry import blockers_of
from ..mis import member_densities, weights_from_densities
from ..render import PassRecord, RenderSettings, kernel_radius, member_shares, render_pass
from ..scene import Scene
from ..techniques.base import Hits, PassContext, Primitives, Technique, dot, fields_of

__all__ = ["HitTable", "PixelInspection", "inspect_pixel"]

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
        The balance (or power) weight with sample counts, ``n_i Q_i / sum_j n_j Q_j``; 1 for
        a technique used alone.
    share : (N,) float
        ``n_i``, the share of the batch's photons the hit's member swept (``NAME@0.3``);
        1 for a technique alone or a member without a share.
    contribution : (N, 3) float
        Share of the pixel's pass value, ``value * mis_weight / (share * photons * spp)``;
        the rows sum to it.
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
    share: np.ndarray
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
def photon_estimator(estimator, scene: Scene) -> Estimator:
    """``estimator`` parsed against ``scene``; ValueError for the reference (no photons)."""
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


def _scaled_normals(tech: Technique, hits: Hits, prims: Primitives, paths, rays,
                    ctx: PassContext) -> np.ndarray:
    """(H, 3) scaled normal ``n`` of the swept surface at each hit: the family's own
    ``scaled_normal`` (:meth:`Technique.hit_normals`); NaN rows where the family sweeps no
    surface (kernels) or cannot rebuild the hit's path."""
    if len(hits) == 0:
        return np.full((0, 3), np.nan)
    try:
        return tech.hit_normals(hits, prims, paths, rays, ctx)
    except (KeyError, NotImplementedError, AttributeError, ValueError, IndexError):
        return np.full((len(hits), 3), np.nan)


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
    est = photon_estimator(estimator, scene)
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
        share = 1.0
        if len(group) > 1:
            raw = tech.evaluate(hits, prims, paths, rays, ctx)
            r = tech.reconstruct(hits, prims, paths, rays, ctx)
            # The sample counts of render_pass: member j swept a share n_j of the batch.
            shares = member_shares(group, len(paths))
            me = [i for i, m in enumerate(group) if m is tech][0]
            w = weights_from_densities(member_densities(r, group, ctx), est.weighting,
                                       shares)[me]
            share = float(shares[me])
        else:
            raw, w = val_w, np.ones(len(hits))
        normal = _scaled_normals(tech, hits, prims, paths, rays, ctx)
        if "n_dot_psi" in fields_of(hits.data):
            ndp = np.asarray(hits.data["n_dot_psi"], dtype=float)
        else:  # techniques that keep no |n . psi| in their hits (single scattering)
            ndp = np.abs(dot(normal, rays.d[hits.ray]))
        rows.append(dict(
            technique=np.full(len(hits), name, dtype=object),
            family=np.full(len(hits), tech.family, dtype=object),
            group=np.full(len(hits), gi), batch=np.full(len(hits), b),
            index=np.arange(len(hits)), prim=hits.prim, photon=prims.photon[hits.prim],
            K=prims.K[hits.prim], ray=hits.ray, s=hits.s,
            point=rays.o[hits.ray] + hits.s[:, None] * rays.d[hits.ray], psi=rays.d[hits.ray],
            normal=normal,
            n_dot_psi=ndp, value=raw, mis_weight=w, share=np.full(len(hits), share),
            contribution=val_w / norm,
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

