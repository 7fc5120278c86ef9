"""The UI side of one estimator in a progressive render: its merged passes, its seconds and
what the panels say before its first pass (:class:`EstimatorRun`, kept by
:class:`ui.cli.progressive.Progressive`)."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

from psurf_core.accumulate import Welford
from psurf_core.breakdown import BreakdownAccumulator

#: A warm-up longer than this (wall seconds) is shown as "compiling kernels (first run)" while
#: it lasts (numba loads a cached kernel in about a second).
COMPILE_NOTE_AFTER = 1.5


@dataclass
class EstimatorRun:
    """The UI side of one estimator: its accumulated passes.

    Attributes
    ----------
    spec : str
    estimator : Estimator
    acc : Welford
        (H, W, 3) mean and per-pass variance over the merged passes.
    seconds : float
        Wall seconds the worker(s) spent on the merged passes (compilation excluded).
    breakdown : BreakdownAccumulator or None
        When breakdowns were asked for and the estimator has techniques: while one worker
        renders, the means it sends (:class:`ShownBreakdown`; a restarted worker counts its
        passes anew), the exact accumulator once the job is done (``max_passes``,
        ``max_seconds``) and always with ``workers=0`` or several workers.
    compile_seconds : float
        Seconds spent compiling (or loading) its kernels, not counted in :attr:`seconds`.
    warming_since : float or None
        ``time.monotonic()`` when its kernels started compiling (None: not compiling now).
    """

    spec: str
    estimator: object
    acc: Welford
    seconds: float = 0.0
    breakdown: BreakdownAccumulator | None = None
    compile_seconds: float = 0.0
    warming_since: float | None = None
    pending: dict = field(default_factory=dict)  # pass index -> (image, seconds, stacks)

    @property
    def passes(self) -> int:
        return self.acc.n

    @property
    def label(self) -> str:
        return self.spec

    def note(self, now: float | None = None) -> str:
        """What the panels say about this run before its first pass ("" once it has one)."""
        if self.acc.n:
            return ""
        if self.warming_since is None:
            return "waiting for the first pass..."
        now = time.monotonic() if now is None else now
        if now - self.warming_since >= COMPILE_NOTE_AFTER:
            return f"compiling kernels (first run), {now - self.warming_since:.0f} s..."
        return "loading kernels..."
