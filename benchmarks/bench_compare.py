"""``make bench``'s headline figures against the previous run's: a drop beyond the machine's
noise is printed as such, so that a regression shows in the run that made it.

Session 23's regression (every walker's shadow argument a tuple: ``planes`` 1.16e7 hits/s
against 1.87e7 the run before) was visible only to whoever remembered the previous figure.
:func:`compare` reads both runs' ``headline`` blocks; :func:`report` prints one line per
figure with the ratio new / previous and flags a figure that got worse by more than
``tolerance``. The default, 30 %, is above the spread of idle runs on this shared 2-core
machine (``planes``: 1.44e7 to 2.06e7 hits/s over four idle runs on 2026-12-04, 0.70x; README
"make bench") and below that regression (0.62x). A flagged figure means: run again; flagged
twice, look for the change.
"""

from __future__ import annotations

import json
from pathlib import Path

#: Figures where larger is better (the others, CPU ns per hit and the cost ratio, smaller).
HIGHER_IS_BETTER = ("hits_per_second", "photon_vertices_per_second")

#: Worse by more than this fraction: flagged.
TOLERANCE = 0.30


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

    Parameters
    ----------
    new, previous : dict
        Two ``out/bench.json`` documents (``previous`` the older).
    tolerance : float
        A figure ``tolerance`` (fraction) or more worse than before is flagged.

    Returns
    -------
    list of dict
        ``figure``, ``new``, ``previous``, ``ratio`` (new / previous) and ``worse`` (bool).
    """
    a, b = flatten(new.get("headline", {})), flatten(previous.get("headline", {}))
    rows = []
    for figure in a:
        if figure not in b or not b[figure] > 0:
            continue
        ratio = a[figure] / b[figure]
        higher = figure.split(".")[0] in HIGHER_IS_BETTER
        worse = ratio < 1 - tolerance if higher else ratio > 1 / (1 - tolerance)
        rows.append({"figure": figure, "new": a[figure], "previous": b[figure],
                     "ratio": ratio, "worse": bool(worse)})
    return rows


def load_previous(path: str | Path) -> dict | None:
    """The previous run's document at ``path``, or None when there is none or it does not
    parse (a run killed while writing it leaves no file: ``run.py`` writes it whole)."""
    try:
        return json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None


def report(rows: list[dict], previous: dict, tolerance: float = TOLERANCE) -> str:
    """The comparison as text: a header naming the previous run, one line per figure."""
    load = previous.get("machine", {}).get("load_average", [float("nan")])[0]
    lines = [f"\nagainst the previous run ({previous.get('command', '?')}, load average "
             f"{load:.2f}): new / previous, '<< worse' beyond {100 * tolerance:.0f} %"]
    for r in rows:
        flag = "  << worse" if r["worse"] else ""
        lines.append(f"  {r['figure']:<40} {r['new']:10.3g} {r['previous']:10.3g} "
                     f"{r['ratio']:6.2f}x{flag}")
    n = sum(r["worse"] for r in rows)
    lines.append(f"  {n} figure(s) worse than the previous run beyond the noise" if n else
                 "  no figure worse than the previous run beyond the noise")
    return "\n".join(lines)
