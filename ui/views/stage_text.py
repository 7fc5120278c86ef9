"""The stage panel's text: what each stage says in numbers (plain Python, no VTK).

:func:`panel_text` is the whole panel for a :class:`ui.views.window.ViewState`; the evaluate
table (:func:`evaluate_table_text`) and the Reconstruct table (:func:`reconstruct_text`) are
the core's records (:mod:`psurf_core.inspect`) as monospace text. Names are never cut: each
column is as wide as its longest entry (the views shrink the font to fit the panel instead).
"""

from __future__ import annotations

import os
import textwrap

import numpy as np

from .stepper import STAGES

__all__ = ["coverage_target", "default_hit", "evaluate_table_text", "hit_order", "panel_text",
           "reconstruct_text"]

#: Rows of the evaluate table shown (largest contributions first).
TABLE_ROWS = 9
#: Normals and psi are drawn at this many hits (largest contributions).
NORMAL_ROWS = 3
#: Width the panel's paragraphs wrap at (the table lines are as long as they need).
WRAP = 76


def hit_order(inspection) -> np.ndarray:
    """Table rows by decreasing contribution: row ``i`` of the display is ``hit_order[i]``."""
    return inspection.table.by_contribution()


def default_hit(inspection) -> int | None:
    """The hit the Reconstruct stage shows when none is asked: the largest contribution."""
    t = inspection.table
    return None if len(t) == 0 else int(t.by_contribution()[0])


def _g(x: float) -> str:
    if not np.isfinite(x):
        return "   -   "
    return f"{x:7.1e}" if (x != 0 and (abs(x) < 1e-2 or abs(x) >= 1e3)) else f"{x:7.3f}"


def evaluate_table_text(inspection, max_rows: int = TABLE_ROWS) -> str:
    """The evaluate table as monospace text (largest contributions first).

    Columns: display index, technique (its full name) and primitive id (its row in that
    technique's primitives of the hit's photon batch), K, distance ``s``, ``|n.psi|``, the
    Jacobian factor ``1/|n.psi|``, ``f = value |n.psi|``, MIS weight ``w`` and the
    contribution (mean over RGB); ``!`` marks a near-singular hit, ``x`` one whose path is
    invalid (Evaluate returned 0: occluded, or a vertex outside). A first line names each
    technique's family.
    """
    t = inspection.table
    px, py = inspection.pixel_xy
    fam: dict = {}
    for n, f in zip(t.technique, t.family, strict=True):
        fam.setdefault(str(f), {})[str(n)] = None
    lines = [f"pixel ({px}, {py})  pass {inspection.pass_index}  "
             f"{len(t)} hits  {inspection.n_photons} photons"]
    lines += textwrap.wrap("; ".join(f"{f}: {' '.join(ns)}" for f, ns in fam.items()) or "-",
                           width=WRAP, initial_indent="families: ", subsequent_indent="  ")
    order = hit_order(inspection)
    shown = order[:max_rows]
    nw = max([len("technique")] + [len(str(t.technique[r])) for r in shown])
    pw = max([4] + [len(str(int(t.prim[r]))) for r in shown])
    lines.append(f" #  {'technique':<{nw}s} {'prim':>{pw}s}  K       s  |n.psi| 1/|n.psi|"
                 f"       f     w  contrib")
    with np.errstate(divide="ignore", invalid="ignore"):
        jac = 1.0 / t.n_dot_psi
    for i, r in enumerate(shown):
        mark = "x" if not np.any(t.value[r]) else ("!" if t.near_singular[r] else " ")
        lines.append(f"{i:2d}{mark} {str(t.technique[r]):<{nw}s} {int(t.prim[r]):>{pw}d} "
                     f"{int(t.K[r]):2d} {t.s[r]:7.3f} {_g(t.n_dot_psi[r])}   {_g(jac[r])} "
                     f"{_g(float(np.mean(t.f[r])))} {t.mis_weight[r]:5.2f} "
                     f"{_g(float(np.mean(t.contribution[r])))}")
    if len(t) > max_rows:
        rest = order[max_rows:]
        lines.append(f"    ... {len(rest)} more hits, together "
                     f"{_g(float(np.mean(t.contribution[rest].sum(axis=0)))).strip()}")
    total = float(np.mean(t.total))
    pv_ = float(np.mean(inspection.pixel_value))
    ok = "= pixel value (check ok)" if inspection.sum_matches else "!= pixel value (MISMATCH)"
    lines.append(f"sum {_g(total).strip()} {ok} {_g(pv_).strip()}")
    if any(not np.any(t.value[r]) for r in shown):
        lines.append("x invalid path (occluded or outside the box): adds 0")
    if len(shown) and t.near_singular[shown].any():
        lines.append("! near-singular: |n.psi| < 1e-3, huge 1/|n.psi|")
    return "\n".join(lines)


def reconstruct_text(inspection, recon: dict, display_index: int | None = None) -> str:
    """The Reconstruct stage's panel: the hit, its path and every MIS member's ``Q`` and
    weight on that same path (``>`` marks the hit's own technique)."""
    t = inspection.table
    k = recon["row"]
    idx = f"#{display_index}" if display_index is not None else f"row {k}"
    lines = [f"hit {idx}: {recon['technique']}  K={recon['K']}  s={t.s[k]:.3f}",
             "path: " + " -> ".join(lb.split(" ")[0] for lb in recon["labels"])]
    if not recon["available"]:
        lines.append(recon["note"])
        return "\n".join(lines)
    if recon["weighting"]:
        lines.append(f"MIS weighting: {recon['weighting']} heuristic over "
                     f"{len(recon['members'])} members")
    else:
        lines.append(f"MIS weighting: none ({inspection.estimator.spec} is a single "
                     "technique: weight 1)")
    nw = max([len("member")] + [len(name) for name, _, _ in recon["members"]])
    lines.append(f"  {'member':<{nw}s}  Q = q|n.psi|   weight")
    for name, q, w in recon["members"]:
        me = ">" if name == recon["technique"] else " "
        lines.append(f"{me} {name:<{nw}s}  {_g(q):>12s}   {w:6.3f}")
    wsum = sum(w for _, _, w in recon["members"])
    lines.append(f"weights sum to {wsum:.3f}; contribution "
                 f"{_g(float(np.mean(t.contribution[k]))).strip()}")
    return "\n".join(lines)


# --------------------------------------------------------------------------- the panel
def _plural(n: int, word: str) -> str:
    return f"{n} {word}" + ("" if n == 1 else "es" if word.endswith("s") else "s")


def waiting_text(state) -> str:
    """What the panel says while the pixel's inspection is being computed."""
    secs = state.inspector.busy("pixel") if state.inspector is not None else None
    line = (f"computing... pixel ({state.pixel_xy[0]}, {state.pixel_xy[1]}), "
            f"pass {state.pass_index} of {state.estimator.spec}")
    if secs is not None and secs >= 3.0:
        line += f" ({secs:.0f} s; the first run compiles kernels)"
    return line


def head_text(state) -> str:
    """The panel's first two lines: scene, inspected estimator, seed, passes, pixel."""
    return (f"{os.path.basename(state.scene_path)}   inspecting {state.estimator.spec}   "
            f"seed {state.seed}\n"
            f"{_plural(state.acc.n, 'pass')}   photons/pass {state.settings.photons}   "
            f"pixel ({state.pixel_xy[0]}, {state.pixel_xy[1]})")


def _trace(ins, state) -> str:
    paths = ins.paths
    events = [int(p.alive.sum(axis=1).mean() * 100) / 100 for p in paths]
    inbox = [float(p.prefix_ok[:, 1].mean()) for p in paths if p.depth]
    return (f"pass {ins.pass_index}: {ins.n_photons} photons in {len(paths)} batch(es)\n"
            f"mean traced segments per photon: {np.mean(events):.2f}\n"
            f"first vertex inside the box: {100 * np.mean(inbox):.0f}%\n"
            f"drawn: the first {min(state.n_paths, ins.n_photons)} subpaths (+/- to change)")


def _create(ins, state) -> str:
    lines = [f"pass {ins.pass_index}: primitives per technique"]
    for name, tech in ins.techniques.items():
        n = sum(len(p) for (t, _), p in ins.prims.items() if t == name)
        ks = [p.K for (t, _), p in ins.prims.items() if t == name and len(p)]
        kr = (f"K {int(min(k.min() for k in ks))}..{int(max(k.max() for k in ks))}"
              if ks else "no K")
        lines.append(f"  {name} [{tech.family}]: {n}  ({kr})")
    lines.append(f"drawn: those of the first {state.n_paths} photons")
    return "\n".join(lines)


def _intersect(ins) -> str:
    t = ins.table
    r = ins.rays
    lines = [f"{_plural(len(r), 'ray')}; in the medium for s in "
             f"[{r.s_min[0]:.2f}, {r.s_max[0]:.2f}]", f"{_plural(len(t), 'hit')}:"]
    for name in ins.techniques:
        m = t.technique == name
        if m.any():
            lines.append(f"  {name}: {_plural(int(m.sum()), 'hit')}, s {t.s[m].min():.2f}.."
                         f"{t.s[m].max():.2f}")
        else:
            lines.append(f"  {name}: no hit")
    if len(t):
        nd = t.n_dot_psi[np.isfinite(t.n_dot_psi)]
        if nd.size:
            lines.append(f"|n.psi| from {nd.min():.1e} to {nd.max():.1e}")
        lines.append("arrows at the largest hits:")
        for i, r in enumerate(hit_order(ins)[:NORMAL_ROWS]):
            lines.append(f"  #{i} {t.technique[r]}  s {t.s[r]:.3f}  "
                         f"|n| {np.linalg.norm(t.normal[r]):.3g}  "
                         f"|n.psi| {t.n_dot_psi[r]:.3g}")
    lines.append(f"drawn: primitives of the top {TABLE_ROWS} hits")
    return "\n".join(lines)


def stage_body(state, recon=None, k=None) -> str:
    """The stage's own lines (``recon``, ``k``: the selected hit's reconstruction and display
    index, for Reconstruct)."""
    ins = state.inspection
    if ins is None:
        return waiting_text(state)
    stage = state.stage
    if stage == "trace":
        return _trace(ins, state)
    if stage == "create":
        return _create(ins, state)
    if stage == "intersect":
        return _intersect(ins)
    if stage == "evaluate":
        return evaluate_table_text(ins)
    assert stage == STAGES[-1]
    if recon is None:
        return "no hit in this pass: move the pixel (arrows) or the pass (, .)"
    return reconstruct_text(ins, recon, k) + "\n[ / ] other hits"


def coverage_target(state):
    """``(technique, batch, prim)`` whose coverage is shown: the primitive picked in the 3D
    view, else the selected hit's; None when there is no hit (or no inspection yet)."""
    if state.coverage_pick is not None:
        return state.coverage_pick
    if state.inspection is None:
        return None
    t = state.inspection.table
    if len(t) == 0:
        return None
    order = hit_order(state.inspection)
    r = int(order[min(max(state.hit, 0), len(order) - 1)])
    return str(t.technique[r]), int(t.batch[r]), int(t.prim[r])


def coverage_text(state) -> str:
    """The panel's coverage lines (empty when coverage is off)."""
    if not state.coverage:
        return ""
    target = coverage_target(state)
    if target is None:
        return "\ncoverage: no hit selected (move the pixel)"
    if state.coverage_mask is None:
        return "\ncoverage: computing..."
    name, batch, prim = target
    src = "picked in 3D" if state.coverage_pick is not None else f"hit #{state.hit}"
    return (f"\ncoverage ({src}): {name} primitive {prim}, batch {batch}\n"
            f"  reaches {int(state.coverage_mask.sum())} pixels in pass {state.pass_index}")


def panel_text(state, recon=None, k=None) -> str:
    """The stage panel's whole text (head, the stage's lines, coverage)."""
    return head_text(state) + "\n\n" + stage_body(state, recon, k) + coverage_text(state)
