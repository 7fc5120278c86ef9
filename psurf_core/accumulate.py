"""Welford mean and variance across passes, with the exact parallel merge (Chan et al.), plus
the third and fourth central moments and the largest pass value (Pébay 2008).

The variance is the per-pixel sample variance of *one pass's* estimate across passes, so the
variance of the mean image is ``var / passes``. Merging accumulators in pass order gives the
same numbers as one accumulator that saw every pass (resume, distributed passes).

The higher moments say whether that variance can be trusted: a heavy-tailed pixel (a few
rare, huge passes) has a large skewness and kurtosis, and its sample variance understates
the error of its mean until the rare passes have been seen often enough
(:mod:`psurf_core.reliability` turns them into a per-pixel flag). They are updated next to
``mean`` and ``m2`` without changing a single operation of those two, so images and
variances stay bit-identical to accumulators that never kept them (older checkpoints).

The image sum of a pass (per channel, over every pixel) gets its own Welford sum ``sum_m2``:
its variance is *not* the sum of the per-pixel variances when the pixels of a pass are
correlated, as they are for photon estimators (one photon's surface reaches many pixels), so
a standard error of the image sum needs the passes' sums themselves (``sum_variance``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Welford:
    """Running mean and central-moment sums of float64 images.

    Attributes
    ----------
    n : int
        Passes seen.
    mean : (H, W, C) float64
        Mean of the passes.
    m2, m3, m4 : (H, W, C) float64
        Sums over passes of the 2nd, 3rd and 4th powers of the deviation from ``mean``.
        ``m3``, ``m4`` (and ``peak``) are ``None`` when unknown: an accumulator restored
        from a checkpoint written before they were kept. They then stay unknown (they cannot
        be recovered from ``mean`` and ``m2``), while ``mean`` and ``m2`` go on exactly.
    peak : (H, W, C) float64 or None
        The largest pass value seen per pixel (``-inf`` before the first pass).
    sum_m2 : (C,) float64 or None
        Sum over passes of the squared deviation of a pass's image sum (over every axis but
        the last) from the mean image sum (``mean`` summed likewise). ``None`` when unknown
        (restored from a checkpoint written before it was kept); it then stays unknown.
    """

    n: int
    mean: np.ndarray
    m2: np.ndarray
    m3: np.ndarray | None = None
    m4: np.ndarray | None = None
    peak: np.ndarray | None = None
    sum_m2: np.ndarray | None = None

    @classmethod
    def empty(cls, shape) -> Welford:
        """No pass yet, every moment known; ``shape`` is the image's, e.g. ``(H, W, C)``."""
        return cls(0, np.zeros(shape), np.zeros(shape), np.zeros(shape), np.zeros(shape),
                   np.full(shape, -np.inf), np.zeros(shape[-1:]))

    @property
    def has_tails(self) -> bool:
        """Whether the higher moments and the peak are known."""
        return self.m3 is not None and self.m4 is not None and self.peak is not None

    def copy(self) -> Welford:
        """An independent copy (arrays copied)."""
        def c(a):
            return None if a is None else a.copy()

        return Welford(self.n, self.mean.copy(), self.m2.copy(), c(self.m3), c(self.m4),
                       c(self.peak), c(self.sum_m2))

    def add(self, x: np.ndarray) -> None:
        """Add one pass's image (non-finite values are a bug upstream and are refused)."""
        x = np.asarray(x, dtype=np.float64)
        if not np.all(np.isfinite(x)):
            raise FloatingPointError("a pass produced a non-finite pixel")
        self.n += 1
        delta = x - self.mean
        self.mean += delta / self.n
        if self.sum_m2 is not None:
            # Welford on the image sums: their deviation is delta's sum, and the new mean
            # sum is off the pass's sum by (n - 1) / n of it.
            ds = delta.sum(axis=_pixel_axes(delta))
            self.sum_m2 = self.sum_m2 + ds * ds * ((self.n - 1) / self.n)
        if self.has_tails:
            # Pébay's one-pass update; m4 and m3 need the old m2 (and m4 the old m3).
            n = float(self.n)
            dn = delta / n
            dn2 = dn * dn
            term = delta * dn * (n - 1.0)
            self.m4 += term * dn2 * (n * n - 3.0 * n + 3.0) + 6.0 * dn2 * self.m2 \
                - 4.0 * dn * self.m3
            self.m3 += term * dn * (n - 2.0) - 3.0 * dn * self.m2
            np.maximum(self.peak, x, out=self.peak)
        self.m2 += delta * (x - self.mean)

    def merge(self, other: Welford) -> None:
        """Fold ``other`` (later passes) into this accumulator exactly.

        The higher moments merge by Pébay's pairwise formulas, ``sum_m2`` by Chan's (with the
        difference of the mean images summed over the pixels); each becomes unknown when
        either side does not know its own.
        """
        if other.n == 0:
            return
        if self.n == 0:
            o = other.copy()
            self.n, self.mean, self.m2 = o.n, o.mean, o.m2
            self.m3, self.m4, self.peak, self.sum_m2 = o.m3, o.m4, o.peak, o.sum_m2
            return
        na, nb = float(self.n), float(other.n)
        n = na + nb
        delta = other.mean - self.mean
        if self.has_tails and other.has_tails:
            d2 = delta * delta
            m4 = (self.m4 + other.m4 + d2 * d2 * (na * nb * (na * na - na * nb + nb * nb) / n**3)
                  + 6.0 * d2 * (na * na * other.m2 + nb * nb * self.m2) / (n * n)
                  + 4.0 * delta * (na * other.m3 - nb * self.m3) / n)
            m3 = (self.m3 + other.m3 + d2 * delta * (na * nb * (na - nb) / (n * n))
                  + 3.0 * delta * (na * other.m2 - nb * self.m2) / n)
            self.m3, self.m4 = m3, m4
            self.peak = np.maximum(self.peak, other.peak)
        else:
            self.m3 = self.m4 = self.peak = None
        if self.sum_m2 is not None and other.sum_m2 is not None:
            ds = delta.sum(axis=_pixel_axes(delta))
            self.sum_m2 = self.sum_m2 + other.sum_m2 + ds * ds * (na * nb / n)
        else:
            self.sum_m2 = None
        total = self.n + other.n  # mean and m2 exactly as before the higher moments were kept
        self.mean = self.mean + delta * (other.n / total)
        self.m2 = self.m2 + other.m2 + delta**2 * (self.n * other.n / total)
        self.n = total

    @property
    def variance(self) -> np.ndarray:
        """Per-pixel sample variance of one pass (zeros when fewer than two passes)."""
        if self.n < 2:
            return np.zeros_like(self.mean)
        return self.m2 / (self.n - 1)

    @property
    def sum_variance(self) -> np.ndarray | None:
        """(C,) sample variance across passes of one pass's image sum (over every pixel), per
        channel; zeros when fewer than two passes, ``None`` when unknown. The variance of the
        mean image's sum is ``sum_variance / n``, whatever the correlation between pixels."""
        if self.sum_m2 is None:
            return None
        if self.n < 2:
            return np.zeros_like(self.sum_m2)
        return self.sum_m2 / (self.n - 1)


def _pixel_axes(a: np.ndarray) -> tuple[int, ...]:
    """Every axis but the last (the channels): what an image sum sums over."""
    return tuple(range(a.ndim - 1))
