"""The compiled per-row spans of projected polygons (``kernels.spans._row_spans_into``), which clip
each edge to the strips of the rows its ``y`` range reaches, against the definition: every
edge clipped to every row's strip ``[row - margin, row + 1 + margin]``, the row's span the
pixels from the least to the greatest ``x`` of those pieces (widened by the margin, within
the primitive's rectangle). Polygons are drawn to hit the cases that decide which rows an
edge reaches: vertices on a strip's edge to the last bit, flat edges, edges far off the
image, hulls of up to ``hull_width`` vertices, and the rectangle (``count = -1``) and empty
(``count = 0``) cases.
"""

from __future__ import annotations

import numpy as np
import pytest

from psurf_core.binning import _SPAN_MARGIN
from psurf_core.kernels.spans import _row_spans_into


def _definition(px, py, count, r0, nr, x0, x1):
    """Row by row, every edge (the numpy reference's arithmetic, ``binning._polygon_spans``)."""
    out = []
    for i in range(len(count)):
        for row in range(r0[i], r0[i] + nr[i]):
            if count[i] < 0:
                c0, c1 = x0[i], x1[i]
            else:
                xs = []
                for j in range(count[i]):
                    jn = (j + 1) % count[i]
                    xa, ya, xb, yb = px[i, j], py[i, j], px[i, jn], py[i, jn]
                    lo_y, hi_y = row - _SPAN_MARGIN, row + 1 + _SPAN_MARGIN
                    dy = yb - ya
                    if dy == 0:
                        t_lo, t_hi, hit = 0.0, 1.0, lo_y <= ya <= hi_y
                    else:
                        inv = 1.0 / dy
                        ta, tb = (lo_y - ya) * inv, (hi_y - ya) * inv
                        t_lo, t_hi = max(min(ta, tb), 0.0), min(max(ta, tb), 1.0)
                        hit = t_lo <= t_hi
                    if hit:
                        xs += [xa + t_lo * (xb - xa), xa + t_hi * (xb - xa)]
                if not xs:
                    continue
                c0 = int(max(np.floor(min(xs) - _SPAN_MARGIN), x0[i]))
                c1 = int(min(np.floor(max(xs) + _SPAN_MARGIN) + 1, x1[i]))
            if c1 > c0:
                out.append((i, row, c0, c1))
    return out


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_row_spans_are_every_edge_clipped_to_every_row(seed):
    rng = np.random.default_rng(seed)
    m, width = 600, 24
    px = rng.uniform(-5.0, 69.0, (m, width))
    py = rng.uniform(-5.0, 53.0, (m, width))
    # Vertices on a strip's edge (row - margin, row + 1 + margin) and on whole rows.
    k = rng.integers(0, 48, (m, width)).astype(float)
    on = rng.random((m, width))
    py = np.where(on < 0.15, k - _SPAN_MARGIN, np.where(on < 0.3, k + 1 + _SPAN_MARGIN,
                                                       np.where(on < 0.4, k, py)))
    # Flat edges: a vertex at its predecessor's y.
    flat = rng.random((m, width)) < 0.15
    py[:, 1:] = np.where(flat[:, 1:], py[:, :-1], py[:, 1:])
    # Some polygons reach far off the image.
    far = rng.random(m) < 0.1
    py[far, 0] = rng.choice([-1e12, 1e12, -3e5, 4e5], far.sum())
    count = rng.integers(0, width + 1, m).astype(np.int64)
    count[rng.random(m) < 0.05] = -1
    x0 = rng.integers(0, 30, m).astype(np.int64)
    x1 = x0 + rng.integers(0, 40, m)
    r0 = rng.integers(0, 40, m).astype(np.int64)
    nr = rng.integers(0, 20, m).astype(np.int64)
    prim, row, c0, c1 = (np.full(int(nr.sum()) + 1, -7, np.int64) for _ in range(4))
    none = np.zeros(0, np.int64)
    n, pairs, columns = _row_spans_into(px, py, count, r0, nr, x0, x1, 0, prim, row, c0, c1,
                                        0, none, 0, none)
    assert (prim[n:] == -7).all()  # nothing written past the entries it returns
    got = list(zip(prim[:n].tolist(), row[:n].tolist(), c0[:n].tolist(), c1[:n].tolist(),
                   strict=True))
    want = _definition(px, py, count, r0, nr, x0, x1)
    assert len(want) > 2000
    assert got == want
    assert pairs == columns == 0

    # Counted as they are written (``before``), from entry 5 on, primitives named from 100:
    # the pairs of the spans up to each entry, a span's the rays of its pixels.
    w, h = 70, 61
    cs = np.concatenate([[0], np.cumsum(rng.integers(0, 4, w * h))])
    o = [np.full(n + 5, -7, np.int64) for _ in range(4)]
    before = np.full(n + 6, -7, np.int64)
    n2, pairs, columns = _row_spans_into(px, py, count, r0, nr, x0, x1, 100, *o, 5, cs, w,
                                         before)
    assert n2 == n + 5
    np.testing.assert_array_equal(o[0][5:], prim[:n] + 100)
    for a, b in zip(o[1:], (row, c0, c1), strict=True):
        np.testing.assert_array_equal(a[5:], b[:n])
    span_pairs = cs[row[:n] * w + c1[:n]] - cs[row[:n] * w + c0[:n]]
    np.testing.assert_array_equal(before[6:], np.cumsum(span_pairs))
    assert (before[:6] == -7).all()
    assert pairs == span_pairs.sum() > 0 and columns == (c1[:n] - c0[:n]).sum()
