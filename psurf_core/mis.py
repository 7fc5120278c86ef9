"""Reconstruct & Evaluate: multiple importance sampling of photon-surface techniques.

For a hit of technique ``i``, the technique reconstructs the full path the hit implies
(:class:`~psurf_core.path_record.PathRecord`); every member ``j`` of the MIS set that can
produce a path of that scatter count from that kind of light evaluates its effective density
``Q_j`` on that same record, and the hit is weighted by ``w_i = Q_i^b / sum_j Q_j^b``
(balance ``b = 1``, power ``b = 2``). Weights sum to one on every path, so the combination is
unbiased whatever the ``Q``'s are (spec section 2).

:func:`mis_weights` is the numpy reference: the compiled walkers weight their hits in the
same loop that finds them, with the same reconstruct, densities and heuristic composed from
every member's compiled twins (:mod:`psurf_core.kernels.mis`), wherever every member of the
set has them; this path is what they are tested against and what runs for the others.

The spec grammar ``mis:A+B``, ``mis-power:A+B`` and the paper's presets are in
:mod:`psurf_core.estimators`.
"""

from __future__ import annotations

import numpy as np

from .path_record import PathRecord
from .techniques import Technique


def member_densities(rec: PathRecord, group, ctx) -> np.ndarray:
    """(J, H) effective densities of every member on records ``rec`` (0 where a member
    cannot produce the record's scatter count / light kind)."""
    out = np.zeros((len(group), len(rec)))
    for j, m in enumerate(group):
        ok = m.can_produce(rec.K, rec.kind)
        if ok.all():  # the common case: no copy of the record
            out[j] = np.nan_to_num(np.abs(m.density(rec, ctx)), nan=0.0, posinf=0.0)
        elif ok.any():
            q = m.density(rec.select(ok), ctx)
            out[j, ok] = np.nan_to_num(np.abs(q), nan=0.0, posinf=0.0)
    return out


def weights_from_densities(q: np.ndarray, weighting: str | None,
                           shares: np.ndarray | None = None) -> np.ndarray:
    """(J, H) MIS weights from (J, H) densities; columns with no density get weight 0.

    ``shares`` (J,): the share ``n_j`` of the pass's photons member ``j`` swept (default 1:
    every member sees every photon). With sample counts the heuristics weigh ``n_j Q_j``
    (Veach's multi-sample MIS); the weights still sum to one on every path."""
    b = 2.0 if weighting == "power" else 1.0
    if shares is not None:
        q = q * np.asarray(shares, dtype=float)[:, None]
    qb = q**b
    den = qb.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        w = np.where(den > 0, qb / den, 0.0)
    return w


def mis_weights(tech: Technique, group, weighting, hits, prims, paths, rays, ctx,
                shares: np.ndarray | None = None) -> np.ndarray:
    """(H,) factor of ``tech``'s hits' per-photon values within ``group``: its MIS weight
    (``tech.reconstruct``, each member's ``density`` (:func:`member_densities`),
    :func:`weights_from_densities`) divided by its share ``n_me`` of the photons (1 without
    ``shares``): a member that swept a fraction ``n`` of the photons stands for all of them,
    so the estimate stays unbiased."""
    rec = tech.reconstruct(hits, prims, paths, rays, ctx)
    q = member_densities(rec, group, ctx)
    me = [i for i, m in enumerate(group) if m is tech][0]
    w = weights_from_densities(q, weighting, shares)[me]
    return w if shares is None else w / float(shares[me])
