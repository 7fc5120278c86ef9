"""Reconstruct & Evaluate: multiple importance sampling of photon-surface techniques.

For a hit of technique ``i``, the technique reconstructs the full path the hit implies
(:class:`~psurf_core.path_record.PathRecord`); every member ``j`` of the MIS set that can
produce a path of that scatter count from that kind of light evaluates its effective density
``Q_j`` on that same record, and the hit is weighted by ``w_i = Q_i^b / sum_j Q_j^b``
(balance ``b = 1``, power ``b = 2``). Weights sum to one on every path, so the combination is
unbiased whatever the ``Q``'s are (spec section 2).

:func:`mis_weights` runs the compiled kernel of :mod:`psurf_core.mis_fused` (the same
reconstruct, densities and heuristic per hit, no (J, H) temporaries) wherever it covers the
set's techniques; ``reconstruct`` / ``density`` / :func:`member_densities` here are the
reference it is tested against and the path for everything else.

Also the spec grammar ``mis:A+B``, ``mis-power:A+B`` and the paper's presets.
"""

from __future__ import annotations

import numpy as np

from .estimators import PRESETS, Estimator
from .path_record import PathRecord
from .scene import Scene, SceneError
from .techniques import REGISTRY, Technique, UnknownTechnique, get_technique


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


def weights_from_densities(q: np.ndarray, weighting: str | None) -> np.ndarray:
    """(J, H) MIS weights from (J, H) densities; columns with no density get weight 0."""
    b = 2.0 if weighting == "power" else 1.0
    qb = q**b
    den = qb.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        w = np.where(den > 0, qb / den, 0.0)
    return w


def mis_weights(tech: Technique, group, weighting, hits, prims, paths, rays, ctx,
                fast: bool = True) -> np.ndarray:
    """(H,) MIS weight of ``tech``'s hits within ``group``.

    ``fast`` (default): the compiled kernel of :mod:`psurf_core.mis_fused` where it covers
    ``tech``, every member and the hits' data (the paper's presets), else (and with
    ``fast=False``) the reference numpy path: ``tech.reconstruct``, each member's
    ``density`` (:func:`member_densities`), :func:`weights_from_densities`.
    """
    if fast and len(hits):
        from .mis_fused import fast_weights  # numba: imported on the first MIS chunk

        w = fast_weights(tech, group, weighting, hits, prims, paths, rays, ctx)
        if w is not None:
            return w
    rec = tech.reconstruct(hits, prims, paths, rays, ctx)
    q = member_densities(rec, group, ctx)
    me = [i for i, m in enumerate(group) if m is tech][0]
    return weights_from_densities(q, weighting)[me]


# ------------------------------------------------------------------------- parsing
def _check_member(name: str) -> Technique:
    base = name[:-6] if name.endswith("-short") else name
    if base in PRESETS or name in PRESETS:
        raise UnknownTechnique(f"MIS member '{name}' is a preset; list techniques instead")
    tech = get_technique(name)
    entry = REGISTRY.get(base)
    if entry is not None and not entry.mis_ok:
        raise UnknownTechnique(f"MIS member '{name}' is a kernel baseline; MIS combines "
                               "unbiased photon-surface techniques only")
    return tech


def _applicable(group, scene: Scene | None, spec: str):
    """Drop members that apply to no light of ``scene`` (with a warning)."""
    if scene is None:
        return group, ()
    kept, notes = [], []
    for t in group:
        if any(t.applies_to(lt) for lt in scene.lights):
            kept.append(t)
        else:
            notes.append(f"MIS member '{t.name}' applies to no light of {scene.path}; dropped")
    if not kept:
        raise SceneError(f"{scene.path}: estimator '{spec}' has no member that applies to "
                         "a light of this scene")
    return kept, tuple(notes)


def parse_mis(spec: str, scene: Scene | None = None) -> Estimator:
    """Parse ``mis:A+B+...`` or ``mis-power:A+B+...``."""
    head, _, body = spec.partition(":")
    weighting = "power" if head == "mis-power" else "balance"
    names = [n.strip() for n in body.split("+")]
    if not body.strip() or any(not n for n in names):
        raise UnknownTechnique(f"malformed MIS spec '{spec}': expected {head}:A+B+...")
    if len(set(names)) != len(names):
        raise UnknownTechnique(f"malformed MIS spec '{spec}': a member is listed twice")
    group = [_check_member(n) for n in names]
    group, notes = _applicable(group, scene, spec)
    return Estimator(spec, groups=(tuple(group),), weighting=weighting, notes=notes)


def _only(tech: Technique, kinds: tuple) -> Technique:
    """Restrict a technique instance to some light kinds (a preset's per-light choice)."""
    tech.lights = tuple(k for k in tech.lights if k in kinds)
    return tech


def _paper_single():
    return (*(get_technique(n) for n in ("ss-plane-uv", "ss-plane-ut", "ss-plane-vt")),
            get_technique("ss-cone"), get_technique("ss-sphere"),
            _only(get_technique("ss-disk"), ("point",)))


def _paper_multi():
    return tuple(get_technique(n) for n in
                 ("plane-t1t2", "plane-t1t3", "plane-t2t3", "cone", "cylinder"))


def _preset(groups_fn):
    def build(spec: str, scene: Scene | None) -> Estimator:
        groups, notes = [], []
        for g in groups_fn():
            kept, n = _applicable(list(g), scene, spec) if scene is not None else (list(g), ())
            groups.append(tuple(kept))
            notes.extend(n)
        return Estimator(spec, groups=tuple(groups), weighting="balance", notes=tuple(notes))

    return build


def register_presets() -> None:
    """Install the paper's presets (all long techniques, balance heuristic)."""
    PRESETS["paper-single"] = _preset(lambda: [_paper_single()])
    PRESETS["paper-multi"] = _preset(lambda: [_paper_multi()])
    PRESETS["paper-full"] = _preset(lambda: [_paper_single(), _paper_multi()])


register_presets()
