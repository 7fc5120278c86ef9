"""Borrowed views (:mod:`psurf_core.kernels.views`): the same elements, shape and dtype as
the array they view, one array or a tuple. (That the walkers then count no array per hit is
read from their IR by ``benchmarks/walk_ir.py``.)"""

import numpy as np
from numba import njit

from psurf_core.kernels.views import borrowed


@njit(cache=False)
def _copy(a):
    v = borrowed(a)
    out = np.empty_like(a)
    for i in range(v.shape[0]):
        for j in range(v.shape[1]):
            out[i, j] = v[i, j]
    return out, v.shape


@njit(cache=False)
def _tuple_sums(t):
    v = borrowed(t)
    return v[0].sum(), v[1].sum(), len(v)


def test_a_borrowed_view_reads_the_array():
    a = np.arange(12.0).reshape(3, 4) * 0.5
    out, shape = _copy(a)
    assert shape == (3, 4)
    np.testing.assert_array_equal(out, a)


def test_a_tuple_of_arrays_is_borrowed_element_by_element():
    f = np.linspace(0.0, 1.0, 7)
    i = np.arange(5, dtype=np.int64)
    assert _tuple_sums((f, i)) == (f.sum(), i.sum(), 2)
