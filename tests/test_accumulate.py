"""``Welford``'s variance of the per-pass image sum (``sum_m2``, ``sum_variance``).

The passes here have strongly correlated pixels (a common factor per pass, as one photon's
surface reaching many pixels gives), so the image sum's variance is far larger than the sum
of the per-pixel variances; ``sum_variance`` must be the sample variance of the passes' own
image sums, after sequential adds and after merges of any split, and mean and ``m2`` must not
change by a single bit for keeping it.
"""

from __future__ import annotations

import numpy as np
import pytest

from psurf_core.accumulate import Welford

SHAPE = (5, 4, 3)


def _passes(n: int, seed: int = 0, shape=SHAPE) -> np.ndarray:
    """(n, *shape) passes: a per-pass common factor times a pattern, plus pixel noise."""
    rng = np.random.default_rng(seed)
    pattern = rng.random(shape) + 0.5
    common = rng.lognormal(0.0, 0.8, size=(n, *(1,) * len(shape)))
    return common * pattern + 0.1 * rng.normal(size=(n, *shape))


def _fed(xs, known=True) -> Welford:
    acc = Welford.empty(xs.shape[1:]) if known else Welford(0, np.zeros(xs.shape[1:]),
                                                           np.zeros(xs.shape[1:]))
    for x in xs:
        acc.add(x)
    return acc


def _direct(xs) -> np.ndarray:
    """(C,) sample variance of the passes' image sums, from the sums themselves."""
    return np.var(xs.sum(axis=tuple(range(1, xs.ndim - 1))), axis=0, ddof=1)


def test_sum_variance_is_the_variance_of_the_pass_sums():
    xs = _passes(40)
    acc = _fed(xs)
    np.testing.assert_allclose(acc.sum_variance, _direct(xs), rtol=1e-10)
    assert acc.sum_variance.shape == (3,) and acc.sum_m2.dtype == np.float64
    # The passes are correlated: the independent-pixel sum is far smaller (what it replaces).
    assert np.all(acc.variance.sum(axis=(0, 1)) < 0.2 * acc.sum_variance)
    # Keeping it changes neither the mean nor m2, by a single bit.
    plain = _fed(xs, known=False)
    assert plain.sum_m2 is None and plain.sum_variance is None
    np.testing.assert_array_equal(plain.mean, acc.mean)
    np.testing.assert_array_equal(plain.m2, acc.m2)


def test_sum_variance_before_two_passes_and_of_stacks():
    acc = Welford.empty(SHAPE)
    np.testing.assert_array_equal(acc.sum_variance, np.zeros(3))
    acc.add(np.ones(SHAPE))
    np.testing.assert_array_equal(acc.sum_variance, np.zeros(3))
    # A breakdown stack (T, NK, H, W, C) sums over every axis but the channels.
    xs = _passes(12, seed=1, shape=(2, 3, 4, 5, 3))
    np.testing.assert_allclose(_fed(xs).sum_variance, _direct(xs), rtol=1e-10)


@pytest.mark.parametrize("split", [0, 1, 6, 17, 18])
def test_merges_of_any_split_equal_the_direct_variance(split):
    xs = _passes(18, seed=2)
    a, b = _fed(xs[:split]), _fed(xs[split:])
    a.merge(b)
    assert a.n == 18
    np.testing.assert_allclose(a.sum_variance, _direct(xs), rtol=1e-10)
    np.testing.assert_allclose(a.sum_variance, _fed(xs).sum_variance, rtol=1e-12)


def test_three_way_merge_copy_and_unknown_sides():
    xs = _passes(21, seed=3)
    parts = [_fed(xs[:5]), _fed(xs[5:13]), _fed(xs[13:])]
    acc = parts[0].copy()
    for p in parts[1:]:
        acc.merge(p)
    np.testing.assert_allclose(acc.sum_variance, _direct(xs), rtol=1e-10)
    # copy() is independent of its original.
    c = acc.copy()
    c.add(xs[0])
    assert c.sum_m2 is not acc.sum_m2 and not np.array_equal(c.sum_m2, acc.sum_m2)
    # An unknown side makes the merge unknown; an empty unknown side changes nothing.
    unknown = _fed(xs[:3], known=False)
    known = _fed(xs[3:])
    known.merge(unknown)
    assert known.sum_m2 is None
    fresh = Welford(0, np.zeros(SHAPE), np.zeros(SHAPE))
    fresh.merge(_fed(xs))
    np.testing.assert_allclose(fresh.sum_variance, _direct(xs), rtol=1e-10)
