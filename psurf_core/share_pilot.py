"""The share of the photons ``fast-full``'s single-scattering set sweeps, chosen per scene by
pilot passes.

``fast-full`` sums two independent MIS sets, single scattering (K = 1) and multiple
scattering, and puts the first on a share ``s`` of each pass's photons (MIS with sample
counts: unbiased for any ``s``). A set on a share ``s`` costs ``s c`` a photon and has the
relative variance ``v / s`` a photon, so the sum's variance at equal time is

    ``(v_1 / s + v_2) (s c_1 + c_2)``, least at ``s* = sqrt(v_1 c_2 / (v_2 c_1))``.

The preset's shares per light kind (:data:`~psurf_core.estimators.FULL_SINGLE_SHARES`) are
the optima measured on bundled scenes, rounded up; a scene's own optimum can lie far below
(``dense_mesh_light`` 0.011, ``hg`` 0.015, where the preset's 0.15 leaves ~1.7x the
variance at equal time in the model: docs/vs_mitsuba.md) or above. :func:`choose_share`
measures ``c`` and ``v`` of each set alone on pilot passes and returns ``s*`` within
:data:`SHARE_RANGE`, with the spec that replays the choice (``fast-full@S``).

* ``c``: the slope of a pass's wall time in its photons (:func:`pass_size.timed_cost`: the
  fixed part of a pass is paid once for the sum, whatever the shares);
* ``v``: the photons' variance a photon from split passes (:func:`pass_size.split_variances`:
  two photon sets on one set of camera rays, so the pixel jitter cancels), each pixel
  weighted as a relMSE weighs it (:func:`metrics.relative_weight` of the estimator's mean
  over a few pilot passes).

A short pilot sees a heavy tail's rare large contributions less often than their share of
the variance: it reads ``v`` low. Low ``v_2`` raises ``s`` (safe: the single set costs a little
more); low ``v_1`` lowers it, so :data:`SHARE_RANGE` keeps ``s`` from going near 0 on a
misread (the model is flat about its optimum: on ``dense_mesh_light`` the floor 0.03 keeps
~90 % of what the optimum gains over 0.15). With an area light in the scene the floor is the
preset's share (:func:`share_floor`): the pilot may raise it, not lower it.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace

from .estimators import SHARED_PRESETS, Estimator, parse_estimator
from .metrics import relative_weight
from .pass_size import (
    PILOT_PASSES,
    PILOT_PHOTONS,
    PILOT_SEED,
    auto_pass_model,
    split_photons,
    split_variances,
    timed_cost,
)
from .render import RenderSettings, render_pass, warm_up

#: The range a chosen share is kept in (see the module docstring).
SHARE_RANGE = (0.03, 1.0)

#: Split pilot passes per set (more than the photon count's pilot: ``v`` of each set, not a
#: sum of both, decides the share).
SHARE_SPLIT_PASSES = 16

#: Pilot passes whose mean image gives the pixels' relative weights.
WEIGHT_PASSES = 4

#: First seed of the share pilot's passes (past the photon pilot's; no render uses them).
SHARE_SEED = PILOT_SEED + 64


def shared_preset(spec: str) -> str | None:
    """The preset ``spec`` names when its share is left to the pilot (``fast-full``, with no
    ``@S`` and no member left out); None otherwise."""
    spec = spec.strip()
    return spec if spec in SHARED_PRESETS else None


def set_alone(spec: str, scene, g: int) -> tuple[Estimator, float]:
    """Set ``g`` of ``spec`` on ``scene`` alone, its members' shares divided by the largest
    (the set on every photon, its members' proportions kept); and that largest share (the
    set's share of the photons in ``spec``). Parses ``spec`` afresh: the techniques of no
    other estimator are changed."""
    est = parse_estimator(spec, scene)
    group, full = est.sets[g]
    top = max(t.share for t in group)
    for t in group:
        t.share = min(1.0, t.share / top)
    return replace(est, groups=(group,), full_groups=(full,)), top


def best_share(v: tuple[float, float], c: tuple[float, float],
               lo: float = SHARE_RANGE[0]) -> float:
    """``s* = sqrt(v_1 c_2 / (v_2 c_1))`` for the first of two summed sets (the second on
    every photon), within ``[lo, SHARE_RANGE[1]]``; the top of the range where the second set
    has no measured variance."""
    (v1, v2), (c1, c2) = v, c
    if not v2 > 0.0:
        return SHARE_RANGE[1]
    s = math.sqrt(max(v1, 0.0) * c2 / (v2 * max(c1, 1e-12)))
    return float(min(max(s, lo), SHARE_RANGE[1]))


def share_floor(scene, preset_share: float) -> float:
    """The least share the pilot may choose on ``scene``: the preset's own where the scene has
    an area light (its single-scattering planes are heavy-tailed in the dim pixels a relMSE
    weighs: a pilot reads their variance low, and on ``area_occluder`` the share it chose,
    0.14 against the preset's 0.3, left 11x the relVar in one run, docs/vs_mitsuba.md), else
    :data:`SHARE_RANGE`'s floor."""
    if any(lt.kind == "area" for lt in scene.lights):
        return max(preset_share, SHARE_RANGE[0])
    return SHARE_RANGE[0]


def measure_set(scene, alone: Estimator, settings: RenderSettings, weight, sizes,
                passes: int, time_seed: int, split_passes: int, split_seed: int,
                half_photons: int | None = None) -> tuple[float, float, float]:
    """``(c0, c1, v)`` of one set on its own (:func:`set_alone`): the fixed and per-photon
    seconds of a pass (:func:`pass_size.timed_cost`, ``passes`` of each of ``sizes`` from
    ``time_seed``) and its relative variance a photon (:func:`pass_size.split_variances`,
    pixels weighted by ``weight``, ``split_passes`` from ``split_seed``, halves of
    ``half_photons`` photons, by default as many as :func:`pass_size.split_photons` allows).
    Shared by :func:`choose_share` and ``benchmarks/set_shares.py``."""
    c0, c1 = timed_cost(scene, alone, settings, sizes, passes, time_seed)
    half = replace(settings, photons=split_photons(c0, c1) if half_photons is None
                   else half_photons)
    _, vp = split_variances(scene, alone, half, weight=weight, passes=split_passes,
                            seed=split_seed)
    return c0, c1, vp


def model(v, c, s) -> float:
    """Variance at equal time (up to a constant) of summed sets on shares ``s`` (a sequence,
    one a set): ``(sum v_i / s_i) (sum s_i c_i)``; for :func:`choose_share`'s two sets,
    ``s = (S, 1)``. ``v``: relative variance a photon; ``c``: seconds a photon."""
    return sum(vi / si for vi, si in zip(v, s, strict=True)) * sum(
        si * ci for si, ci in zip(s, c, strict=True))


def choose_share(scene, spec: str, settings: RenderSettings) -> dict:
    """Measure both sets of the shared preset ``spec`` on ``scene`` and choose the first's
    share (module docstring).

    Returns
    -------
    dict
        ``{"spec": "fast-full@S", "share": S, "preset_share": the preset's, "sets": [{"c1":
        s a photon, "v": relative variance a photon}, ...], "model_vs_preset": the model's
        variance at ``S`` over that at the preset's share, "pilot_seconds": wall s}``.
    """
    t0 = time.perf_counter()
    est = parse_estimator(spec, scene)
    if len(est.sets) != 2:
        raise ValueError(f"'{spec}': a share is chosen for two summed sets, not "
                         f"{len(est.sets)}")
    warm_up(scene, est, settings)
    ref = sum(render_pass(scene, est, i, SHARE_SEED, replace(settings, photons=PILOT_PHOTONS[1]))
              for i in range(WEIGHT_PASSES)) / WEIGHT_PASSES
    weight = relative_weight(ref)
    rows, preset_share = [], None
    for g in range(2):
        alone, top = set_alone(spec, scene, g)
        preset_share = top if g == 0 else preset_share
        warm_up(scene, alone, settings)
        c0, c1, vp = measure_set(scene, alone, settings, weight, PILOT_PHOTONS, PILOT_PASSES,
                                 SHARE_SEED + 1 + 2 * g, SHARE_SPLIT_PASSES,
                                 SHARE_SEED + 8 + g)
        rows.append({"members": [t.label for t in alone.techniques], "c0": c0, "c1": c1,
                     "v": vp})
    v = (rows[0]["v"], rows[1]["v"])
    c = (rows[0]["c1"], rows[1]["c1"])
    lo = share_floor(scene, preset_share)
    # The spec's text is the record: round first (up, so that the floor holds).
    share = max(float(f"{best_share(v, c, lo):.2g}"), lo)
    gain = (model(v, c, (share, 1.0)) / model(v, c, (preset_share, 1.0)) if v[1] > 0.0
            else 1.0)
    return {"spec": f"{spec}@{share:g}", "share": share, "preset_share": preset_share,
            "sets": rows, "model_vs_preset": gain,
            "pilot_seconds": time.perf_counter() - t0}


def piloted(scene, est: Estimator, settings: RenderSettings,
            budget: float) -> tuple[Estimator, dict | None]:
    """The pilots of an equal-time run's estimator (``--photons auto``): a shared preset's
    share first (:func:`choose_share`; its passes are then sized for that share), then its
    photons a pass (:func:`pass_size.auto_pass_model`).

    Returns
    -------
    (Estimator, dict or None)
        The estimator to run (``fast-full@S`` for ``fast-full``; else ``est``) and the pass
        model, with the share's record as ``"share_model"`` where one was chosen (None for
        the path tracer)."""
    share = None
    if shared_preset(est.spec) is not None:
        share = choose_share(scene, est.spec, settings)
        est = parse_estimator(share["spec"], scene)
    m = auto_pass_model(scene, est, settings, budget)
    if m is not None and share is not None:
        m["share_model"] = share
    return est, m


def share_notes(model: dict | None, est: Estimator) -> list[str]:
    """The note a comparison's row gets where its share was chosen by :func:`piloted`."""
    share = (model or {}).get("share_model")
    if share is None:
        return []
    return [f"its single-scattering set on {share['share']:g} of the photons, chosen by the "
            f"pilot (the preset's {share['preset_share']:g}): --estimators {est.spec} "
            f"--photons {model['photons']} repeats the pilot's choices"]


__all__ = ["SHARE_RANGE", "best_share", "choose_share", "model", "piloted", "set_alone",
           "measure_set", "share_floor", "share_notes", "shared_preset"]
