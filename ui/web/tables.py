"""The Evaluate and Reconstruct tables of the page, as rows of strings (plain Python).

The numbers are the core's records (:mod:`psurf_core.inspect`: the hit table and
``reconstruct_hit``), in the columns and order the window's stage panel uses
(:func:`ui.views.hits_view.evaluate_table_text`): largest contribution first, ``!`` a
near-singular hit, ``x`` a hit whose path is invalid (it adds 0).
"""

from __future__ import annotations

import numpy as np

#: Rows of the evaluate table shown (the rest are summed in a last line).
EVALUATE_ROWS = 12
EVALUATE_COLUMNS = (("#", "i"), ("technique", "technique"), ("prim", "prim"), ("K", "K"),
                    ("s", "s"), ("|n·ψ|", "ndotpsi"), ("1/|n·ψ|", "jacobian"), ("f", "f"),
                    ("w", "w"), ("contribution", "contribution"))
RECONSTRUCT_COLUMNS = (("member", "member"), ("Q = q|n·ψ|", "Q"), ("weight", "weight"))


def num(x: float) -> str:
    """A table number: 3 decimals, or 2 significant digits in e-notation when small or large;
    ``-`` when not finite."""
    x = float(x)
    if not np.isfinite(x):
        return "-"
    return f"{x:.1e}" if (x != 0 and (abs(x) < 1e-2 or abs(x) >= 1e3)) else f"{x:.3f}"


def evaluate_rows(inspection, max_rows: int = EVALUATE_ROWS) -> dict:
    """The evaluate table of one pixel and pass.

    Returns
    -------
    dict
        ``rows`` (list of dicts keyed by the second entries of :data:`EVALUATE_COLUMNS`),
        ``more`` (a line for the rows left out, or ""), ``total``, ``pixel`` (the pixel's
        value in the pass), ``check`` (True when the hits sum to it) and ``notes``.
    """
    t = inspection.table
    order = t.by_contribution()
    with np.errstate(divide="ignore", invalid="ignore"):
        jac = 1.0 / t.n_dot_psi
    rows = []
    for i, r in enumerate(order[:max_rows]):
        mark = "x" if not np.any(t.value[r]) else ("!" if t.near_singular[r] else "")
        rows.append({"i": f"{i}{mark}", "technique": str(t.technique[r]),
                     "prim": str(int(t.prim[r])), "K": str(int(t.K[r])), "s": num(t.s[r]),
                     "ndotpsi": num(t.n_dot_psi[r]), "jacobian": num(jac[r]),
                     "f": num(np.mean(t.f[r])), "w": f"{t.mis_weight[r]:.2f}",
                     "contribution": num(np.mean(t.contribution[r]))})
    more = ""
    if len(t) > max_rows:
        rest = order[max_rows:]
        more = (f"... {len(rest)} more hits, together "
                f"{num(np.mean(t.contribution[rest].sum(axis=0)))}")
    shown = order[:max_rows]
    notes = []
    if any(not np.any(t.value[r]) for r in shown):
        notes.append("x: invalid path (occluded or outside the box), adds 0")
    if len(shown) and t.near_singular[shown].any():
        notes.append("!: near-singular, |n·ψ| < 1e-3 (huge 1/|n·ψ|)")
    return {"rows": rows, "more": more, "total": num(np.mean(t.total)),
            "pixel": num(np.mean(inspection.pixel_value)), "check": bool(inspection.sum_matches),
            "notes": notes, "hits": len(t)}


def reconstruct_rows(inspection, recon: dict | None, display_index: int) -> dict:
    """The Reconstruct table: the selected hit, its path and every MIS member's density ``Q``
    and weight on that path (``recon`` from :func:`psurf_core.inspect.reconstruct_hit`;
    None when the pixel has no hit)."""
    if recon is None:
        return {"title": "no hit in this pass: pick another pixel", "path": "", "rows": [],
                "note": "", "sum": ""}
    t = inspection.table
    k = recon["row"]
    out = {"title": (f"hit #{display_index}: {recon['technique']}  K={recon['K']}  "
                     f"s={t.s[k]:.3f}"),
           "path": " → ".join(lb.split(" ")[0] for lb in recon["labels"]),
           "rows": [], "note": "", "sum": ""}
    if not recon["available"]:
        out["note"] = recon["note"]
        return out
    out["note"] = f"MIS weighting: {recon['weighting'] or 'none (single technique)'}"
    for name, q, w in recon["members"]:
        mark = " ◀" if name == recon["technique"] else ""
        out["rows"].append({"member": name + mark, "Q": num(q), "weight": f"{w:.3f}"})
    wsum = sum(w for _, _, w in recon["members"])
    out["sum"] = (f"weights sum to {wsum:.3f}; contribution "
                  f"{num(np.mean(t.contribution[k]))}")
    return out
