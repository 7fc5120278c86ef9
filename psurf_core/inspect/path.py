"""The Reconstruct stage of one hit of an inspected pixel (numpy only): the full path the hit
implies, every MIS member's density and weight on it (:func:`reconstruct_hit`), and the
primitive each member sweeps through that path (:func:`member_primitives`).

``inspection`` is a :class:`~psurf_core.inspect.pixel.PixelInspection`.
"""

from __future__ import annotations

import numpy as np

from ..mis import member_densities, weights_from_densities
from ..render import member_shares
from ..trace import PhotonPaths

__all__ = ["member_primitives", "reconstruct_hit"]

_LABELS = ("x3", "x2", "x1", "x0")


def reconstruct_hit(inspection, k: int) -> dict:
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
        # With the sample counts of render_pass (the table's mis_weight).
        shares = member_shares(group, len(paths))
        w = weights_from_densities(q[:, None], inspection.estimator.weighting, shares)[:, 0]
        out["members"] = [(m.name, float(q[j]), float(w[j])) for j, m in enumerate(group)]
    else:
        try:
            q = float(np.abs(tech.density(rec, ctx))[0])
        except NotImplementedError:
            q = float("nan")
        out["members"] = [(name, q, 1.0)]
    return out


def member_primitives(inspection, recon: dict) -> dict:
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

