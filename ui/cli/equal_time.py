"""The equal-time comparison numbers the image panels show: each estimator's variance of the
mean, "Var: N x" (variance x seconds relative to the first estimator; at equal passes when
the runs are untimed, as in screenshots) and relMSE against a reference.
"""

from __future__ import annotations

import numpy as np

__all__ = ["compare_rows"]


def compare_rows(runs, reference: np.ndarray | None = None) -> list[dict]:
    """The equal-time comparison numbers shown above the panels.

    Parameters
    ----------
    runs : list of EstimatorRun (or objects with ``label``, ``acc``, ``seconds``)
    reference : (H, W, 3) ndarray, optional
        Ground truth for relMSE (``psurf_core.study.relmse``).

    Returns
    -------
    list of dict
        ``label``, ``passes``, ``seconds``, ``mean_variance`` (``mean(var / passes)``, the
        variance of the current mean image; None below two passes), ``ratio``
        (``mean_variance * seconds`` over the first estimator's: the variance ratio at equal
        time, corrected for the last pass's overshoot; at equal passes (``mean_variance *
        passes``) when some run reports 0 seconds; None when undefined), ``equal``
        (``'time'`` or ``'passes'``), ``relmse``.
    """
    from psurf_core.study import relmse

    rows = []
    for r in runs:
        n = r.acc.n
        mv = float(np.mean(r.acc.variance) / n) if n >= 2 else None
        rows.append({
            "label": r.label, "passes": n, "seconds": float(r.seconds), "mean_variance": mv,
            "relmse": (relmse(r.acc.mean, reference) if reference is not None and n else None),
        })
    base = rows[0] if rows else None
    # Untimed runs (screenshots: fixed passes, every second reported as 0 so the picture is
    # deterministic) are compared at equal passes instead of at equal time.
    timed = all(row["seconds"] > 0 for row in rows)
    for row in rows:
        ok = (base is not None and row["mean_variance"] is not None
              and bool(base["mean_variance"]))
        if not ok:
            row["ratio"] = None
        elif timed:
            row["ratio"] = (row["mean_variance"] * row["seconds"]
                            / (base["mean_variance"] * base["seconds"]))
        else:
            row["ratio"] = row["mean_variance"] * row["passes"] / (
                base["mean_variance"] * base["passes"])
        row["equal"] = "time" if timed else "passes"
    return rows
