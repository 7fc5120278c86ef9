"""The pixels one primitive reaches in a pass (numpy only): :func:`primitive_pixels`."""

from __future__ import annotations

import numpy as np

from ..binning import candidate_pairs
from ..geometry import blockers_of
from ..render import (
    PHOTON_BATCH,
    RenderSettings,
    batch_paths,
    kernel_radius,
    pass_generators,
    pass_rays,
)
from ..scene import Scene
from ..techniques.base import PassContext, Primitives, take
from .pixel import photon_estimator

__all__ = ["primitive_pixels"]

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

    est = photon_estimator(estimator, scene)
    techs = {t.name: t for t in est.techniques}
    if technique not in techs:
        raise ValueError(f"technique '{technique}' is not part of estimator '{est.spec}' "
                         f"(members: {', '.join(techs)})")
    tech = techs[technique]
    cam = scene.camera
    blockers = blockers_of(scene)
    # The pass's own rays and photons, as render_pass draws them (its pixel and photon
    # samplers), so the primitive is the one the pass's hit table lists.
    ray_rng, photon_ss = pass_generators(seed, pass_index)
    rays = pass_rays(scene, settings, seed, pass_index, ray_rng, blockers)
    n_batches = -(-settings.photons // PHOTON_BATCH)
    if not 0 <= batch < n_batches:
        raise ValueError(f"batch {batch} does not exist (the pass has {n_batches})")
    batch_ss = photon_ss.spawn(n_batches)
    paths = batch_paths(scene, settings, batch_ss, batch, seed, pass_index, blockers)
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
