"""``make bench``'s headline figures against the previous run's: a drop beyond the machine's
noise is printed as such, so that a regression shows in the run that made it.

Session 23's regression (every walker's shadow argument a tuple: ``planes`` 1.16e7 hits/s
against 1.87e7 the run before) was visible only to whoever remembered the previous figure.
:func:`compare` reads both runs' ``headline`` blocks; :func:`report` prints one line per
figure with the ratio new / previous and flags a figure that got worse than the run's other
figures by more than ``tolerance`` (:func:`compare`): this shared machine's speed drifts by up
to 0.57x between two back-to-back runs of one commit, every figure alike, while a change in
one code path moves only its own figures (session 23's: ``planes`` and ``paper-single``
1.28x the time, the others unchanged).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

#: Figures that are ratios of two measurements of one run (judged against 1, not the drift).
MACHINE_FREE = ("hit_cost_ratio", "hit_cost_ratio_separate_runs")

#: Figures where larger is better (the others, CPU ns per hit and the cost ratio, smaller).
HIGHER_IS_BETTER = ("hits_per_second", "photon_vertices_per_second")

#: A figure this fraction below the median drift of its run: flagged.
TOLERANCE = 0.25


def flatten(headline: dict) -> dict[str, float]:
    """``{"hits_per_second": {"planes": x}, "hit_cost_ratio": y}`` ->
    ``{"hits_per_second.planes": x, "hit_cost_ratio": y}``."""
    flat = {}
    for key, value in headline.items():
        if isinstance(value, dict):
            flat.update({f"{key}.{k}": float(v) for k, v in value.items()})
        else:
            flat[key] = float(value)
    return flat


def compare(new: dict, previous: dict, tolerance: float = TOLERANCE) -> list[dict]:
    """One row per headline figure both runs have.

    Each figure's ``speed`` is its ratio turned so that above 1 is faster (new / previous for
    rates, previous / new for costs). The machine's own drift between two runs moves every
    figure alike (two back-to-back runs of one commit on 2026-12-04 differed by 0.57-0.75x
    in every figure), a change in one code path moves its figures alone: a figure is
    ``worse`` when its speed falls more than ``tolerance`` below the median speed of the
    run's figures (``shift``), and ``slower`` when it falls that far below 1 (both runs'
    machines alike).

    Parameters
    ----------
    new, previous : dict
        Two ``out/bench.json`` documents (``previous`` the older).
    tolerance : float
        The fraction beyond which a figure is flagged.

    Returns
    -------
    list of dict
        ``figure``, ``new``, ``previous``, ``ratio`` (new / previous), ``speed``, ``shift``
        (the median speed), ``worse`` and ``slower`` (bool).
    """
    a, b = flatten(new.get("headline", {})), flatten(previous.get("headline", {}))
    rows = []
    for figure in a:
        if figure not in b or not b[figure] > 0 or not a[figure] > 0:
            continue
        ratio = a[figure] / b[figure]
        higher = figure.split(".")[0] in HIGHER_IS_BETTER
        rows.append({"figure": figure, "new": a[figure], "previous": b[figure],
                     "ratio": ratio, "speed": ratio if higher else 1.0 / ratio})
    timed = [r["speed"] for r in rows if r["figure"] not in MACHINE_FREE]
    shift = float(np.median(timed)) if timed else 1.0
    for r in rows:
        # A ratio of two costs measured in one run does not drift with the machine.
        own = 1.0 if r["figure"] in MACHINE_FREE else shift
        r["shift"] = shift
        r["worse"] = bool(r["speed"] < own * (1 - tolerance))
        r["slower"] = bool(r["speed"] < 1 - tolerance)
    return rows


def load_previous(path: str | Path) -> dict | None:
    """The previous run's document at ``path``, or None when there is none or it does not
    parse (a run killed while writing it leaves no file: ``run.py`` writes it whole)."""
    try:
        return json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None


def report(rows: list[dict], previous: dict, tolerance: float = TOLERANCE) -> str:
    """The comparison as text: a header naming the previous run and the machine's drift, one
    line per figure."""
    load = previous.get("machine", {}).get("load_average", [float("nan")])[0]
    shift = rows[0]["shift"] if rows else 1.0
    lines = [f"\nagainst the previous run ({previous.get('command', '?')}, load average "
             f"{load:.2f}): new / previous; the figures ran at {shift:.2f}x their "
             f"previous speed at the median (the machine's drift); '<< worse' more than "
             f"{100 * tolerance:.0f} % below that, '< slower' more than that below the "
             "previous run"]
    for r in rows:
        flag = "  << worse" if r["worse"] else ("  < slower" if r["slower"] else "")
        lines.append(f"  {r['figure']:<40} {r['new']:10.3g} {r['previous']:10.3g} "
                     f"{r['ratio']:6.2f}x{flag}")
    n = sum(r["worse"] for r in rows)
    lines.append(f"  {n} figure(s) worse than the run's median drift: look for the change"
                 if n else "  no figure worse than the run's median drift"
                 + (" (all slower alike: the machine; run again)"
                    if any(r["slower"] for r in rows) else ""))
    return "\n".join(lines)
