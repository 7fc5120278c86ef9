"""Welford mean and variance across passes, with the exact parallel merge (Chan et al.).

The variance is the per-pixel sample variance of *one pass's* estimate across passes, so the
variance of the mean image is ``var / passes``. Merging accumulators in pass order gives the
same numbers as one accumulator that saw every pass (resume, distributed passes).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Welford:
    """Running mean and sum of squared deviations of float64 images.

    Attributes
    ----------
    n : int
        Passes seen.
    mean, m2 : (H, W, C) float64
    """

    n: int
    mean: np.ndarray
    m2: np.ndarray

    @classmethod
    def empty(cls, shape) -> Welford:
        return cls(0, np.zeros(shape), np.zeros(shape))

    def add(self, x: np.ndarray) -> None:
        """Add one pass's image (non-finite values are a bug upstream and are refused)."""
        x = np.asarray(x, dtype=np.float64)
        if not np.all(np.isfinite(x)):
            raise FloatingPointError("a pass produced a non-finite pixel")
        self.n += 1
        delta = x - self.mean
        self.mean += delta / self.n
        self.m2 += delta * (x - self.mean)

    def merge(self, other: Welford) -> None:
        """Fold ``other`` (later passes) into this accumulator exactly."""
        if other.n == 0:
            return
        if self.n == 0:
            self.n, self.mean, self.m2 = other.n, other.mean.copy(), other.m2.copy()
            return
        n = self.n + other.n
        delta = other.mean - self.mean
        self.mean = self.mean + delta * (other.n / n)
        self.m2 = self.m2 + other.m2 + delta**2 * (self.n * other.n / n)
        self.n = n

    @property
    def variance(self) -> np.ndarray:
        """Per-pixel sample variance of one pass (zeros when fewer than two passes)."""
        if self.n < 2:
            return np.zeros_like(self.mean)
        return self.m2 / (self.n - 1)
