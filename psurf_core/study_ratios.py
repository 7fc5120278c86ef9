"""The ratios of an equal-time study's rows against its first estimator's (the fields of
:mod:`psurf_core.study`'s module docstring: ``ratio``, ``relmse_ratio``, ...)."""

from __future__ import annotations

import numpy as np


def _ratio(a, b) -> float | None:
    if a is None or b is None or not b > 0:
        return None
    return float(a / b)


def add_ratios(results: list[dict]) -> None:
    """Add to each row of ``results`` (in place) its ratios against ``results[0]``."""
    first = results[0]
    for row in results:
        row["ratio"] = _ratio(row["image_variance"], first["image_variance"])
        row["relmse_ratio"] = _ratio(row["relmse"], first["relmse"])
        tn = (None if row["image_variance"] is None else
              row["image_variance"] * float(np.mean(row["seconds_per_run"])))
        tn0 = (None if first["image_variance"] is None else
               first["image_variance"] * float(np.mean(first["seconds_per_run"])))
        row["ratio_time_normalized"] = _ratio(tn, tn0)
        row["run_variance_ratio"] = _ratio(row["run_variance"], first["run_variance"])
        row["per_photon_variance"] = (None if row["per_pass_variance"] is None
                                      or row["photons_per_pass"] is None
                                      else row["per_pass_variance"] * row["photons_per_pass"])
    for row in results:
        row["ratio_equal_photons"] = _ratio(row["per_photon_variance"],
                                            first["per_photon_variance"])
        # Run r against the first estimator's run r: one run's spike (photon planes' second
        # moment diverges where they graze, docs/study.md) moves the mean, not the median.
        row["run_ratios"] = [_ratio(a["mean_variance"], b["mean_variance"])
                             for a, b in zip(row["runs"], first["runs"], strict=True)]
        ok = [r for r in row["run_ratios"] if r is not None]
        row["ratio_median_run"] = float(np.median(ok)) if ok else None
        row["relmse_from_variance_ratio"] = _ratio(row["relmse_from_variance"],
                                                   first["relmse_from_variance"])
