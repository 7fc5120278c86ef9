"""What the image panels show in each mode, as plain records (no VTK): :func:`mode_areas`
turns the progressive runs into :class:`Area` s of :class:`Tile` s that
:class:`ui.views.image_panels.PanelView` draws (the window, figures, recordings; the browser
version can draw the same records).

Modes (the window's ``m`` key): ``render`` (each estimator's render and the variance of its
mean, side by side at equal time, "Var: 0.23x" relative to the first estimator, relMSE with a
reference), ``techniques`` (each MIS technique's weighted contribution and its weight map)
and ``bounces`` (the image per scatter count K; each technique unweighted vs weighted).

The variance maps of all estimators share one colour scale (:class:`VarScale`): set from the
first estimates and then fixed, so a map that converges visibly darkens; unlocked, it follows
the data every frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from psurf_core import images as im
from psurf_core.accumulate import Welford

from .palette import technique_colour

__all__ = ["MODES", "MODE_HELP", "Area", "Entry", "Tile", "VarScale", "entries_of",
           "mode_areas", "next_mode"]

#: Panel modes, in the order the window's ``m`` key cycles them.
MODES = ("render", "techniques", "bounces")
MODE_HELP = {
    "render": "each estimator's render and variance, side by side at equal time",
    "techniques": "MIS: each technique's weighted contribution and its weight map",
    "bounces": "per scatter count K; each technique unweighted vs weighted at one K",
}
VARIANCE_CMAP = "viridis"
#: Colour-blind-safe maps: viridis for variance, cividis for weights (linear, [0, 1]).
WEIGHT_CMAP = "cividis"
MEAN_VARIANCE_BAR = "variance of the mean (log)"
WEIGHT_BAR = "share of the pixel (mean MIS weight)"


def next_mode(mode: str) -> str:
    """The mode after ``mode`` (the window's ``m`` key)."""
    return MODES[(MODES.index(mode) + 1) % len(MODES)] if mode in MODES else MODES[0]


def plural(n: int, word: str) -> str:
    """``"1 pass"``, ``"2 passes"``."""
    return f"{n} {word}" + ("" if n == 1 else "es" if word.endswith("s") else "s")


@dataclass
class Entry:
    """One estimator as the panels see it (``label``, ``acc``, ``seconds``, ``breakdown``;
    ``note``: what to say before its first pass, e.g. "compiling kernels (first run)")."""

    label: str
    acc: Welford
    seconds: float = 0.0
    breakdown: object = None
    note: str = ""


def entries_of(source) -> list:
    """Normalise a panel source: a ``Progressive``, a list of its runs, a ``{label: Welford}``
    dict or one ``Welford``."""
    if isinstance(source, Welford):
        return [Entry("render", source)]
    if isinstance(source, dict):
        return [Entry(str(k), v) for k, v in source.items()]
    runs = getattr(source, "runs", source)
    out = []
    for r in runs:
        if isinstance(r, Entry):
            out.append(r)
            continue
        note = r.note() if callable(getattr(r, "note", None)) else ""
        out.append(Entry(getattr(r, "label", getattr(r, "spec", "?")), r.acc,
                         float(getattr(r, "seconds", 0.0)), getattr(r, "breakdown", None),
                         note))
    return out


@dataclass
class Tile:
    """One image of a panel: ``rgb`` (H, W, 3) uint8, or ``values`` (H, W) float drawn in
    false colour with range ``clim`` (log scale when ``log``); ``frame`` outlines it (the
    inspected estimator), ``pixel`` outlines the picked pixel."""

    title: str
    rgb: np.ndarray | None = None
    values: np.ndarray | None = None
    clim: tuple = (1e-3, 1.0)
    log: bool = True
    cmap: str = VARIANCE_CMAP
    pixel: bool = False
    frame: bool = False
    colour: str | None = None  # the technique's (its title is set on it), or None
    #: What the picture was made from (None: unknown): a tile whose key is the one drawn
    #: last time in its place is not uploaded again (``PanelView``).
    key: tuple | None = None


@dataclass
class Area:
    """What one subplot shows: a header line, tiles on a grid, an optional colour bar."""

    header: str
    tiles: list
    rows: int | None = None  # None: the grid that makes tiles largest
    bar: str | None = None  # colour-bar title (for the false-colour tiles)


class VarScale:
    """The variance maps' shared colour scale (log range of the variance of the mean).

    Fixed by default: :meth:`update` sets it from the maps it is given until every one of
    them has an estimate (two passes), then keeps it, so the maps darken as the renders
    converge. :meth:`toggle` unlocks it (it then follows every frame's maps) or locks it at
    the current range; :meth:`reset` forgets it (a new scene or estimator set).
    """

    #: Headroom around the first maps' range (log10 decades below and above).
    PAD = (0.5, 0.5)

    def __init__(self, locked: bool = True, clim: tuple | None = None, keys: bool = True):
        self.locked = bool(locked)
        self.keys = bool(keys)  # name the window's key in the bar's title
        self.clim = clim
        self._complete = clim is not None

    def reset(self) -> None:
        if self.locked and self._complete:
            self.clim, self._complete = None, False

    def toggle(self) -> bool:
        """Lock (at the current range) or unlock; returns :attr:`locked`."""
        self.locked = not self.locked
        self._complete = self.locked and self.clim is not None
        return self.locked

    def update(self, maps: list, complete: bool) -> tuple:
        """The range for this frame's ``maps`` ((H, W) arrays); ``complete``: every
        estimator shown has a variance estimate."""
        if self.clim is not None and self.locked and self._complete:
            return self.clim
        vals = [np.asarray(m, float).ravel() for m in maps]
        v = np.concatenate(vals) if vals else np.zeros(0)
        v = v[np.isfinite(v) & (v > 0)]
        if v.size == 0:
            return self.clim or (1e-3, 1.0)
        lo, hi = float(np.percentile(v, 1.0)), float(np.percentile(v, 99.9))
        if not hi > lo:
            lo, hi = hi / 10.0, hi * 10.0
        if self.locked:
            lo, hi = lo / 10 ** self.PAD[0], hi * 10 ** self.PAD[1]
        self.clim = (max(lo, 1e-30), hi)
        self._complete = bool(complete)
        return self.clim

    @property
    def label(self) -> str:
        if not self.keys:
            return "fixed scale" if self.locked else "auto scale"
        return "fixed scale (l: auto)" if self.locked else "auto scale (l: fix)"


def _fmt_ratio(r) -> str:
    return "Var n/a" if r is None else f"Var {r:.2g}\u00d7"


def _k_of(layout, k) -> int:
    return layout.k_min + 1 if k is None and layout.n_k > 1 and layout.k_min < 2 else (
        layout.k_min if k is None else int(k))


#: Per-estimator results of recent frames: ``(what, id(acc), passes, ...) -> (acc, value)``.
#: A frame after one estimator's new pass recomputes that estimator's pictures only (the
#: entry keeps its accumulator alive, so its id cannot be reused by another one meanwhile).
_SEEN: dict = {}


def _per_run(what: str, acc: Welford, extra, make):
    key = (what, id(acc), acc.n, extra)
    hit = _SEEN.get(key)
    if hit is not None and hit[0] is acc:
        return hit[1]
    if len(_SEEN) >= 64:
        _SEEN.clear()
    value = make()
    _SEEN[key] = (acc, value)
    return value


def _render_areas(ents, reference, clim, scale: VarScale | None, inspected) -> list:
    from ui.cli.equal_time import compare_rows

    rows = compare_rows(ents, reference)
    exposure = min(_per_run("exposure", e.acc, None, lambda e=e: im.auto_exposure(e.acc.mean))
                   for e in ents)
    var_means = [_per_run("var", e.acc, None, lambda e=e: (
        e.acc.variance.mean(axis=-1) if e.acc.variance.ndim == 3 else e.acc.variance)
        / max(e.acc.n, 1)) for e in ents]
    have = [e.acc.n >= 2 for e in ents]
    if clim is None:
        shown = [v for v, ok in zip(var_means, have, strict=True) if ok] or var_means
        clim = (scale.update(shown, all(have)) if scale is not None
                else im.log_range(np.concatenate([v.ravel() for v in shown])))
    lo, hi = clim
    many = len(ents) > 1
    # Screenshots report every run's seconds as 0 (equal passes); a live render reports
    # seconds, but not yet for an estimator still waiting for its first pass (it has a note:
    # "compiling kernels (first run)", "waiting for the first pass...").
    timed = rows[0]["equal"] == "time" or any(e.seconds > 0 or (e.acc.n == 0 and e.note)
                                              for e in ents)
    tiles_a, tiles_b = [], []
    for i, (e, row, v) in enumerate(zip(ents, rows, var_means, strict=True)):
        mark = inspected is not None and i == inspected and many
        took = f", {e.seconds:.1f} s" if e.seconds > 0 else ""
        second = e.note if e.acc.n == 0 and e.note else f"{plural(e.acc.n, 'pass')}{took}"
        rgb = _per_run("rgb", e.acc, exposure, lambda e=e: im.tone_map(e.acc.mean, exposure))
        tiles_a.append(Tile(f"{e.label}\n{second}", rgb=rgb, pixel=True, frame=mark,
                            key=("rgb", id(e.acc), e.acc.n, exposure)))
        title = f"{e.label}: {_fmt_ratio(row['ratio'])}" if many else e.label
        if e.acc.n < 2:
            title = f"{e.label}: {'needs 2 passes' if e.acc.n else 'no pass yet'}"
        if row["relmse"] is not None:
            title += f"\nrelMSE {row['relmse']:.2g}"
        tiles_b.append(Tile(title, values=v, clim=(lo, hi), pixel=True, frame=mark,
                            key=("var", id(e.acc), e.acc.n, lo, hi)))
    if many:
        first = ents[0].label
        head_a = ("renders at equal time, one exposure" if timed
                  else "renders at equal passes, one exposure")
        head_b = (f"variance of the mean; Var = variance x {'time' if timed else 'passes'}, "
                  f"relative to {first}")
    else:
        head_a, head_b = "progressive render", "variance of the mean"
    bar = MEAN_VARIANCE_BAR + (f", {scale.label}" if scale is not None else "")
    grid_rows = 1 if len(ents) <= 3 else None
    return [Area(head_a, tiles_a, rows=grid_rows), Area(head_b, tiles_b, rows=grid_rows,
                                                        bar=bar)]


def mode_areas(source, mode: str, *, reference: np.ndarray | None = None,
               estimator: int | None = None, technique=None, k: int | None = None,
               clim: tuple | None = None, scale: VarScale | None = None,
               inspected: int | None = None) -> list:
    """The two areas (images, then maps) of ``mode`` for ``source``.

    Parameters
    ----------
    mode : {'render', 'techniques', 'bounces'}
    reference : (H, W, 3) ndarray, optional
        Ground truth: relMSE is shown per estimator in ``render`` mode.
    estimator : int, optional
        Which estimator the ``techniques``/``bounces`` modes break down (default: the
        ``inspected`` one when it has a breakdown, else the first MIS set).
    technique : str or int, optional
        ``bounces``: show this technique's images per K (unweighted vs weighted) instead of
        every technique at one K.
    k : int, optional
        ``bounces``: the scatter count compared across techniques (default 2 when the
        breakdown has it, else its first K).
    clim : (float, float), optional
        ``render``: the variance maps' colour range (e.g. a lecture's pinned range); default
        ``scale``'s, or the maps' own.
    scale : VarScale, optional
        The shared, fixed-over-time colour scale of the variance maps.
    inspected : int, optional
        The estimator the stages inspect: its tiles are framed.

    Returns
    -------
    list of Area
        Two areas; a mode without data (no breakdown) gives areas with one message tile.
    """
    ents = entries_of(source)
    if mode not in MODES:
        raise ValueError(f"unknown panel mode {mode!r} (one of {', '.join(MODES)})")
    if mode == "render":
        return _render_areas(ents, reference, clim, scale, inspected)
    pick = [i for i, e in enumerate(ents) if e.breakdown is not None]
    # By default the inspected estimator, else the first MIS set (the pictures are about MIS),
    # or the first estimator that has ``technique``.
    pick.sort(key=lambda i: (i != inspected, len(ents[i].breakdown.layout.techniques) < 2))
    if technique is not None and isinstance(technique, str):
        pick = [i for i in pick if technique in ents[i].breakdown.layout.techniques] or pick
    if estimator is not None:
        pick = [int(estimator)] if ents[int(estimator)].breakdown is not None else []
    if not pick or ents[pick[0]].breakdown.n == 0:
        msg = ("no breakdown: start the render with breakdown=True" if not pick
               else f"{ents[pick[0]].label}: {ents[pick[0]].note or 'waiting for the first pass'}")
        blank = Tile(msg, rgb=np.full((*ents[0].acc.mean.shape[:2], 3), 255, np.uint8))
        return [Area(MODE_HELP[mode], [blank]), Area("", [])]
    e = ents[pick[0]]
    b = e.breakdown
    lay = b.layout
    names = lay.techniques
    total = b.image
    exposure = im.auto_exposure(total)
    if mode == "techniques":
        imgs = b.technique_images()
        w = b.technique_weights()
        tiles_a = [Tile(f"{e.label}: the sum", rgb=im.tone_map(total, exposure))]
        tiles_a += [Tile(f"{n}", rgb=im.tone_map(x, exposure), colour=technique_colour(n))
                    for n, x in zip(names, imgs, strict=True)]
        tiles_b = [Tile(n, values=x, clim=(0.0, 1.0), log=False, cmap=WEIGHT_CMAP,
                        colour=technique_colour(n)) for n, x in zip(names, w, strict=True)]
        return [Area(f"weighted contributions, {plural(b.n, 'pass')}", tiles_a),
                Area("weight maps: share of each pixel", tiles_b, bar=WEIGHT_BAR)]
    # bounces
    kimg = b.k_images()
    tiles_a = [Tile(lbl, rgb=im.tone_map(x, exposure)) for lbl, x in zip(lay.labels, kimg,
                                                                         strict=True)]
    area_a = Area(f"{e.label} per scatter count K, {plural(b.n, 'pass')}", tiles_a)
    if technique is not None:
        t = b.index(technique)
        un = b.unweighted.mean[t]
        we = b.weighted.mean[t]
        ex = im.auto_exposure(un)
        tiles_b = ([Tile(f"{lbl} unweighted", rgb=im.tone_map(x, ex))
                    for lbl, x in zip(lay.labels, un, strict=True)]
                   + [Tile(f"{lbl} weighted", rgb=im.tone_map(x, ex))
                      for lbl, x in zip(lay.labels, we, strict=True)])
        for tile in tiles_b:
            tile.colour = technique_colour(names[t])
        return [area_a, Area(f"{names[t]}: unweighted / weighted", tiles_b, rows=2)]
    kk = _k_of(lay, k)
    kb = lay.k_bin(kk)
    ex = im.auto_exposure(kimg[kb])  # every unweighted image estimates this bin
    # Techniques that cannot produce this K (plane-t1t3 at K = 2) would be black tiles.
    ts = [t for t in range(len(names)) if b.unweighted.mean[t, kb].any()] or \
        list(range(len(names)))
    tiles_b = ([Tile(f"{names[t]} unweighted", rgb=im.tone_map(b.unweighted.mean[t, kb], ex),
                     colour=technique_colour(names[t])) for t in ts]
               + [Tile(f"{names[t]} weighted", rgb=im.tone_map(b.weighted.mean[t, kb], ex),
                       colour=technique_colour(names[t])) for t in ts])
    return [area_a, Area(f"{lay.labels[kb]}: unweighted / weighted", tiles_b, rows=2)]
