"""Can a render's per-pixel error estimate be trusted? Heavy-tail checks on the pass moments.

A progressive render estimates each pixel's error from the spread of its passes: the
standard error of the mean is ``sqrt(var / n)``. That is honest only when the mean is close
to normally distributed, which fails for a heavy-tailed estimator: most passes are small,
a rare pass is huge, and until the rare passes have been seen many times the mean sits
below the truth *and* the sample variance understates the error (the reference path tracer
on ``scenes/dense_mesh_light.toml`` before issue 15 was such a case). Two checks per pixel
and colour channel, from the central-moment sums :class:`~psurf_core.accumulate.Welford`
keeps (``m_k = sum (x_i - mean)^k`` over ``n`` passes):

``skew_of_mean = m3 / m2^(3/2)``
    The skewness of the *mean* (the per-pass skewness over ``sqrt(n)``). Normal-theory
    error bars are off by about this much (Edgeworth); when a few rare passes of size
    ``X`` dominate, it is ``1 / sqrt(number of them)``. Unreliable above :data:`SKEW_MAX`.
``effective_passes = 1 + 2 n / (kappa - (n - 3) / (n - 1))``, ``kappa = n m4 / m2^2``
    How many passes of a normal estimator would pin down the variance as well as these
    ``n`` do: the relative variance of the sample variance is ``(kappa - (n-3)/(n-1)) / n``,
    ``2 / (n - 1)`` for normal passes, so this is ``n`` for normal passes and about twice
    the number of dominating passes for a heavy tail. Unreliable below
    :data:`MIN_EFFECTIVE_PASSES` (the standard error itself uncertain by more than ~25 %).

A pixel is flagged when any channel with a non-zero variance fails either check. Pixels
with zero variance (no medium, or all passes equal) are not flagged. No statistic of the
passes can see a tail that has not shown up yet; in practice neighbouring pixels have, so
the count of flagged pixels over the image is the signal (:func:`summarize`).

``peak_share`` (the largest pass over the sum of the passes) is reported beside them: for a
non-negative estimator, the share of the pixel's value that one pass holds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["MIN_EFFECTIVE_PASSES", "SKEW_MAX", "WARN_FRACTION", "PixelReliability",
           "heavy_tail_note",
           "from_npz", "npz_fields", "of_accumulator", "pixel_reliability", "summarize"]

#: Largest trusted skewness of a pixel's mean (``|m3| / m2^1.5``).
SKEW_MAX = 0.5

#: Fewest trusted effective passes behind a pixel's variance estimate.
MIN_EFFECTIVE_PASSES = 8.0

#: :func:`summarize` warns when more than this fraction of the pixels with a non-zero
#: variance is flagged: scattered pixels (a ray grazing an emitter) do not warn, a heavy
#: tail over a region does. Measured (200 reference passes at 64x48): scenes/area.toml
#: 1.8 %, mesh_light 0.4 %, point 0.1 %, area_occluder 21 % (its volumetric shadow, lit
#: by K >= 2 only); dense_mesh_light at 32x24 after 800 passes of the sampler before
#: issue 15 62 % (mean |z| 2.1 against paper-full), after the same CPU time of the
#: current one 19 % (mean |z| 0.92). See docs/reference.md.
WARN_FRACTION = 0.05

#: The keys :func:`npz_fields` writes (and :func:`from_npz` reads) beside ``mean`` and
#: ``passes``.
NPZ_KEYS = ("m2", "m3", "m4", "peak")


@dataclass(frozen=True)
class PixelReliability:
    """Per-pixel heavy-tail statistics (worst colour channel) and the resulting flag.

    Attributes
    ----------
    n : int
        Passes.
    skew_of_mean : (H, W) float
        Largest ``|m3| / m2^1.5`` over the channels (0 where the variance is 0).
    effective_passes : (H, W) float
        Smallest effective pass count over the channels (``inf`` where the variance is 0).
    peak_share : (H, W) float
        Largest ``peak / (n mean)`` over the channels with a positive mean (0 elsewhere).
    varies : (H, W) bool
        Some channel has a non-zero variance.
    unreliable : (H, W) bool
        Flagged: ``skew_of_mean > SKEW_MAX`` or ``effective_passes < MIN_EFFECTIVE_PASSES``.
    """

    n: int
    skew_of_mean: np.ndarray
    effective_passes: np.ndarray
    peak_share: np.ndarray
    varies: np.ndarray
    unreliable: np.ndarray


def pixel_reliability(n: int, mean, m2, m3, m4, peak=None, *, skew_max: float = SKEW_MAX,
                      min_effective: float = MIN_EFFECTIVE_PASSES) -> PixelReliability:
    """Flag the pixels whose error estimate is unreliable (module docstring).

    Parameters
    ----------
    n : int
        Passes (at least 1).
    mean, m2, m3, m4 : (H, W, C) float
        Mean of the passes and the sums of the 2nd, 3rd and 4th central powers.
    peak : (H, W, C) float, optional
        Largest pass value per pixel and channel.
    skew_max, min_effective : float
        The thresholds (defaults :data:`SKEW_MAX`, :data:`MIN_EFFECTIVE_PASSES`).

    Returns
    -------
    PixelReliability
        With one pass there is no error estimate: every pixel that is not 0 is flagged.
    """
    mean, m2, m3, m4 = (np.asarray(a, dtype=np.float64) for a in (mean, m2, m3, m4))
    n = int(n)
    if n < 1:
        raise ValueError(f"reliability needs at least one pass, got {n}")
    # A variance of rounding size (relative to the mean) is no variance at all.
    tiny = 1e-24 * np.maximum(mean * mean * n, np.finfo(float).tiny)
    var = m2 > tiny
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        skew = np.where(var, np.abs(m3) / m2**1.5, 0.0)
        kappa = n * m4 / (m2 * m2)
        excess = kappa - (n - 3.0) / (n - 1.0) if n > 1 else np.full_like(m2, np.inf)
        neff = np.where(var & (excess > 0), 1.0 + 2.0 * n / excess, np.inf)
        share = (np.where(mean > 0, np.asarray(peak, float) / (n * mean), 0.0)
                 if peak is not None else np.zeros_like(mean))
    skew = np.nan_to_num(skew, nan=np.inf)
    neff = np.nan_to_num(neff, nan=0.0)
    if n == 1:  # no spread to judge: anything that is not 0 is unchecked
        var = mean != 0
        bad = var
    else:
        bad = var & ((skew > skew_max) | (neff < min_effective))
    return PixelReliability(n, skew.max(axis=-1), neff.min(axis=-1), share.max(axis=-1),
                            var.any(axis=-1), bad.any(axis=-1))


def of_accumulator(acc) -> PixelReliability | None:
    """:func:`pixel_reliability` of a :class:`~psurf_core.accumulate.Welford` (``None`` when
    it has no pass or does not know its higher moments)."""
    if acc is None or acc.n < 1 or not acc.has_tails:
        return None
    return pixel_reliability(acc.n, acc.mean, acc.m2, acc.m3, acc.m4, acc.peak)


def npz_fields(acc) -> dict:
    """The accumulator's moment sums and peak as float64 arrays for an output ``.npz``
    (``m2``, ``m3``, ``m4``, ``peak``); empty when they are not known."""
    if acc is None or not acc.has_tails:
        return {}
    return {"m2": np.asarray(acc.m2, np.float64), "m3": np.asarray(acc.m3, np.float64),
            "m4": np.asarray(acc.m4, np.float64), "peak": np.asarray(acc.peak, np.float64)}


def from_npz(data: dict) -> PixelReliability | None:
    """:func:`pixel_reliability` from the arrays of an ``app.py render`` / ``compare`` .npz
    (``None`` for a file written before :func:`npz_fields` existed, or without passes)."""
    if not all(k in data for k in (*NPZ_KEYS, "mean", "passes")):
        return None
    n = int(data["passes"])
    if n < 1:
        return None
    mean = np.asarray(data["mean"], np.float64)
    arrays = [np.asarray(data[k], np.float64) for k in NPZ_KEYS]
    if any(a.shape != mean.shape for a in arrays):
        return None
    return pixel_reliability(n, mean, *arrays)


def summarize(rel: PixelReliability | None, what: str = "the reference") -> dict:
    """Counts and a one-paragraph verdict for a report.

    Returns
    -------
    dict
        ``checked`` (False when ``rel`` is None), ``passes``, ``pixels`` (with a non-zero
        variance), ``unreliable`` (flagged pixels), ``fraction``, ``worst_skew_of_mean``,
        ``fewest_effective_passes``, ``largest_peak_share``, ``thresholds``, ``warn``
        (more than :data:`WARN_FRACTION` flagged, or not checked) and ``message``.
    """
    thresholds = {"skew_of_mean": SKEW_MAX, "effective_passes": MIN_EFFECTIVE_PASSES,
                  "warn_fraction": WARN_FRACTION}
    if rel is None:
        return {"checked": False, "warn": True, "thresholds": thresholds,
                "message": (f"the reliability of {what}'s error estimate could not be checked "
                            "(no higher pass moments: an .npz or checkpoint from before they "
                            "were recorded; re-render it to check)")}
    pixels = int(rel.varies.sum())
    bad = int(rel.unreliable.sum())
    frac = bad / pixels if pixels else 0.0
    out = {
        "checked": True,
        "passes": int(rel.n),
        "pixels": pixels,
        "unreliable": bad,
        "fraction": frac,
        "worst_skew_of_mean": float(rel.skew_of_mean[rel.varies].max()) if pixels else 0.0,
        "fewest_effective_passes": (float(rel.effective_passes[rel.varies].min())
                                    if pixels else None),
        "largest_peak_share": float(rel.peak_share.max()),
        "thresholds": thresholds,
        "warn": frac > WARN_FRACTION,
    }
    if out["warn"]:
        out["message"] = (
            f"{bad} of {pixels} pixels ({100 * frac:.1f}%) of {what} have unreliable error "
            f"estimates (heavy-tailed passes: skewness of the mean > {SKEW_MAX:g} or fewer "
            f"than {MIN_EFFECTIVE_PASSES:g} effective passes behind the variance, after "
            f"{rel.n} passes): its noise floor and any error measured against it are "
            "understated there. Render it longer, or use an estimator with lighter tails "
            "(e.g. paper-full) as the reference.")
    else:
        out["message"] = (f"{bad} of {pixels} pixels of {what} flagged as heavy-tailed "
                          f"(at most {100 * WARN_FRACTION:g}% allowed): error estimate "
                          "looks reliable")
    return out


def heavy_tail_note(fractions) -> str | None:
    """A compared estimator's note when its own passes are heavy-tailed: ``fractions`` holds,
    per run, the share of its pixels :func:`summarize` flags (None: not checked). ``None``
    when no run flags more than :data:`WARN_FRACTION`.

    Photon planes at K >= 2 are the case in point (their second moment diverges where a
    plane is seen edge-on, docs/study.md): a sample variance of a heavy-tailed estimator is
    most often below its mean, so its Var, and every ratio taken against it, read in its
    favour."""
    flagged = [(f, r) for r, f in enumerate(fractions) if f is not None and f > WARN_FRACTION]
    if not flagged:
        return None
    worst, r = max(flagged)
    return (f"heavy-tailed passes: {100 * worst:.1f}% of the pixels of run {r + 1} flag their "
            f"error estimate (more than {100 * WARN_FRACTION:g}%; {len(flagged)} of "
            f"{len(fractions)} runs): its measured variance is likely below its true one, so "
            "Var ratios against it read in its favour")
