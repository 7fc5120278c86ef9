"""The candidate pairs before each span, counted as the spans are written
(``kernels.spans.counted_spans``, what the walk's chunks and pieces are cut by): the same as
counting the finished spans (``fused.spans_before``), on one thread or cut into pieces for
several, where pieces leave rows without a span (closed up) and where they do not."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from psurf_core.kernels import spans as sp
from psurf_core.kernels.fused import spans_before
from psurf_core.scene_io import load_scene
from psurf_core.techniques.bounds import hit_boxes

ROOT = Path(__file__).resolve().parent.parent


def _parallelograms(scene, m, seed, case):
    rng = np.random.default_rng(seed)
    org = rng.uniform(-1.5, 1.5, (m, 3))
    a, b = rng.normal(size=(m, 3)), rng.normal(size=(m, 3))
    hull = np.stack([org, org + a, org + a + b, org + b], axis=1)
    med = (scene.medium.bounds_min, scene.medium.bounds_max)
    lo, hi = np.maximum(hull.min(axis=1), med[0]), np.minimum(hull.max(axis=1), med[1])
    if case == "narrow":  # screen rectangles of half the bounds: rows the polygon misses
        return lo, lo + 0.5 * (hi - lo), hull, med
    if case == "medium box":
        return lo, hi, hull, med
    blo = rng.uniform(-1.0, 0.3, (m, 3))
    box, lo, hi = hit_boxes(scene, blo, np.minimum(blo + rng.uniform(0.1, 1.5, (m, 3)), 1.0),
                            lo, hi)
    return lo, hi, hull, (box[:, 0], box[:, 1])


@pytest.mark.parametrize("threads", [1, 2, 3])
@pytest.mark.parametrize("case", ["medium box", "own boxes", "narrow"])
def test_pairs_counted_with_the_spans_are_those_of_the_finished_spans(monkeypatch, threads,
                                                                      case):
    scene = load_scene(ROOT / "scenes" / "study_medium.toml")
    cam = replace(scene.camera, width=48, height=36)
    m = 2 * sp._THREADED_MIN_PRIMS  # enough for pieces
    lo, hi, hull, box = _parallelograms(scene, m, 4, case)
    rng = np.random.default_rng(5)
    cs = np.concatenate([[0], np.cumsum(rng.integers(0, 5, cam.width * cam.height))])
    monkeypatch.setattr(sp, "thread_count", lambda: threads)
    spans, before, columns = sp.counted_spans(cam, lo, hi, hull, box, cs, cam.width)
    prim, row, c0, c1 = spans
    assert prim.size > 2000
    want, _ = spans_before(cs, row, c0, c1, cam.width, 1)
    np.testing.assert_array_equal(before, want)
    assert columns == (c1 - c0).sum()
    # the spans are hull_spans' (counted or not), whatever the thread count
    monkeypatch.setattr(sp, "thread_count", lambda: 1)
    for g, w in zip(spans, sp.hull_spans(cam, lo, hi, hull, box), strict=True):
        np.testing.assert_array_equal(g, w)
    # Rows without a span (the pieces close up) where the rectangles are narrow; none else.
    x0, x1, y0, y1 = sp._screen_rects(lo, hi, sp.camera_row(cam))
    planes = sp._clip_planes(cam, box)
    nr = sp._clip_project(hull, (x1 > x0) & (y1 > y0), planes, sp.camera_row(cam), x0, x1,
                          y0, y1)[-1]
    assert (nr.sum() > prim.size) == (case == "narrow")
