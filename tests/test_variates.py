"""``psurf_core.variates``: the azimuth's cosine and sine and the exponential variate, in
``+ - * /`` only. Accuracy against extended-precision references, and the compiled twins
equal to the numpy functions bit for bit (what lets Trace's compiled path compute them in its
loops and still return the reference's arrays)."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit

from psurf_core import (
    variates,
    variates_compiled,  # noqa: F401 - registers the twins
)

#: 2 pi to 36 digits, for the extended-precision reference (numpy's long double: 64-bit
#: mantissa on x86; where long double is double the accuracy bounds below are skipped).
TWO_PI = np.longdouble("6.283185307179586476925286766559005768")
EXTENDED = np.finfo(np.longdouble).eps < 1e-18


def _variates(n=400_000):
    rng = np.random.default_rng(7)
    k = np.arange(1, 2000)
    return np.concatenate([
        rng.random(n),
        np.arange(4096) / 4096.0,  # every quarter, eighth, ... turn: the reduction's edges
        k * 2.0**-53, 1.0 - k * 2.0**-53,  # numpy's smallest and largest variates
        [0.0, 0.25 - 2**-53, 0.5 - 2**-53, 0.5 + 2**-53, 0.75 - 2**-53, 0.125 + 2**-50]])


@njit
def _compiled(u, c, s, t):
    for i in range(u.shape[0]):
        c[i], s[i] = variates.cos_sin_turn(u[i])
        t[i] = variates.neg_log_complement(u[i])


def test_twins_equal_the_numpy_functions_bit_for_bit():
    u = _variates()
    c, s, t = np.empty_like(u), np.empty_like(u), np.empty_like(u)
    _compiled(u, c, s, t)
    want_c, want_s = variates.cos_sin_turn(u)
    assert c.tobytes() == want_c.tobytes()
    assert s.tobytes() == want_s.tobytes()
    assert t.tobytes() == variates.neg_log_complement(u).tobytes()


@pytest.mark.skipif(not EXTENDED, reason="needs an extended long double for the reference")
def test_cos_sin_turn_is_accurate_and_unit():
    u = _variates()
    c, s = variates.cos_sin_turn(u)
    phi = TWO_PI * u.astype(np.longdouble)
    # numpy's own cos(2 pi u) is 6.4e-16 off here (the rounded product 2 pi u).
    assert float(np.max(np.abs(c - np.cos(phi)))) < 3e-16
    assert float(np.max(np.abs(s - np.sin(phi)))) < 3e-16
    assert np.max(np.abs(c * c + s * s - 1.0)) < 5e-16


def test_quarter_turns_are_exact():
    c, s = variates.cos_sin_turn(np.array([0.0, 0.25, 0.5, 0.75]))
    assert np.array_equal(np.abs(c), [1.0, 0.0, 1.0, 0.0])
    assert np.array_equal(c[[0, 2]], [1.0, -1.0])
    assert np.array_equal(s[[1, 3]], [1.0, -1.0])
    assert np.array_equal(np.abs(s[[0, 2]]), [0.0, 0.0])


@pytest.mark.skipif(not EXTENDED, reason="needs an extended long double for the reference")
def test_neg_log_complement_is_accurate_to_the_smallest_variate():
    u = _variates()
    t = variates.neg_log_complement(u)
    want = -np.log1p(-u.astype(np.longdouble))
    pos = want > 0
    rel = np.abs(t[pos] - want[pos]) / want[pos]
    assert float(rel.max()) < 5e-16  # log1p's own: 1.5e-16
    assert np.all(t >= 0.0)


def test_neg_log_complement_of_zero_is_positive_zero():
    t = variates.neg_log_complement(np.array([0.0]))
    assert t[0] == 0.0 and not np.signbit(t[0])
