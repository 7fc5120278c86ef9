"""``trace_shadow``'s verdicts never contradict ``Blockers.occluded``.

Trace skips ``Blockers.occluded`` where ``trace_shadow.shade`` decides the answer from error
bounds. A decided verdict must be what ``occluded`` answers in every array it could be
called with (BLAS rounds a row's dot products depending on the array). The segments are
adversarial: through the edges and corners of area lights and boxes within 1e-16 .. 1e-6,
tangent to spheres, crossing a surface at ``SHADOW_EPS`` from either end, grazing planes,
leaving an emitter; and plain random ones, which must nearly all be decided.
"""

from __future__ import annotations

import zlib

import numpy as np
import pytest
from numba import njit
from trace_scenes import scene

from psurf_core import trace_shadow as sh
from psurf_core.constants import SHADOW_EPS
from psurf_core.geometry import _crosses_plane, blockers_of
from psurf_core.kernels.shadow import BlockerRow
from psurf_core.records import load
from psurf_core.trace import trace


@njit
def _near(a, b, rows, test_all, out):
    """The step kernel's listing: the segment's box meets a blocker's padded box."""
    for i in range(a.shape[0]):
        ai, bi = (a[i, 0], a[i, 1], a[i, 2]), (b[i, 0], b[i, 1], b[i, 2])
        near = test_all
        for k in range(rows.shape[0]):
            near |= sh.meets(ai, bi, load(rows, k, BlockerRow))
        out[i] = near


def _classify(blockers, a, b):
    """Per segment: listed near, and ``shade``'s verdict (``CLEAR`` when not near)."""
    rows, test_all = sh.table(blockers)
    near = np.empty(len(a), dtype=bool)
    _near(a, b, rows, test_all, near)
    idx = np.flatnonzero(near)
    verdict = np.full(len(a), sh.CLEAR, dtype=np.int64)
    v, ok = np.empty(idx.size, dtype=np.int64), np.zeros(idx.size, dtype=bool)
    inside = np.ones(idx.size, dtype=bool)
    unsure = sh.shade(idx.size, a[idx], b[idx], inside, rows, test_all, ok,
                      np.arange(idx.size), v)
    assert unsure == (v == sh.DEFER).any()
    decided = v != sh.DEFER
    assert (ok[decided] == (v[decided] == sh.CLEAR)).all()
    verdict[idx] = v
    return near, verdict


@njit
def _crosses(a, b, plane, out):
    p = (plane[0], plane[1], plane[2], plane[3])
    for i in range(a.shape[0]):
        ai, bi = (a[i, 0], a[i, 1], a[i, 2]), (b[i, 0], b[i, 1], b[i, 2])
        v0, v1, v2 = bi[0] - ai[0], bi[1] - ai[1], bi[2] - ai[2]
        ln = np.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
        out[i] = sh.crosses_plane(ai, bi, ln, 4.0 * sh.U * ln, p)


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _contexts(n, rng):
    """Index arrays of the arrays ``occluded`` is called with: whole, halves, odd rows,
    reversed, shuffled, one row at a time for the first few."""
    yield np.arange(n)
    yield np.arange(n // 2)
    yield np.arange(n // 2, n)
    yield np.arange(1, n, 2)
    yield np.arange(n)[::-1]
    yield rng.permutation(n)
    for i in range(min(n, 8)):
        yield np.array([i])


def _check(blockers, a, b, rng, min_decided=0.0):
    near, verdict = _classify(blockers, a, b)
    decided = verdict != sh.DEFER
    for idx in _contexts(len(a), rng):
        # ray_parallelogram multiplies inf by 0 for a segment exactly parallel to the light
        # (the box faces' segments): numpy warns, the answer stands.
        with np.errstate(invalid="ignore"):
            occ = blockers.occluded(a[idx], b[idx])
        bad = decided[idx] & (occ != (verdict[idx] == sh.BLOCKED))
        assert not bad.any(), (f"{bad.sum()} verdicts contradict occluded, e.g. "
                               f"a={a[idx][bad][0]!r} b={b[idx][bad][0]!r}")
    # A segment clear of every blocker's box is not occluded (occluded's own reject).
    assert not blockers.occluded(a[~near], b[~near]).any()
    assert decided.mean() >= min_decided, decided.mean()
    return decided.mean(), verdict


def _tiny(rng, m, lo=-16, hi=-6):
    return rng.choice([-1.0, 1.0], m) * 10.0 ** rng.uniform(lo, hi, m)


def _through(p, d, rng, m, before=(1e-7, 1.5), after=(1e-7, 1.5)):
    """Segments along ``d`` through points ``p``, extending a random length each way."""
    s0 = 10.0 ** rng.uniform(*np.log10(before), m)[:, None]
    s1 = 10.0 ** rng.uniform(*np.log10(after), m)[:, None]
    return p - s0 * d, p + s1 * d


def _quad_segments(light, rng, m):
    c, eu, ev = light.corner, light.edge_u, light.edge_v
    n = _unit(np.cross(eu, ev))
    uv = rng.random((m, 2))
    on = c + uv[:, :1] * eu + uv[:, 1:] * ev
    d = _unit(rng.normal(size=(m, 3)))
    fams = []
    # leaving the emitter, grazing down to 1e-12
    g = d.copy()
    k = m // 3
    g[:k] -= (g[:k] @ n)[:, None] * n
    g[:k] += _tiny(rng, k, -12, -3)[:, None] * n
    g = _unit(g)
    fams.append((on, on + (10.0 ** rng.uniform(-7, 0.5, m))[:, None] * g))
    # through the edges and corners, off by 1e-16 .. 1e-6 in the plane
    t = rng.random(m)
    side = rng.integers(0, 4, m)
    edge_uv = np.stack([np.where(side == 0, 0.0, np.where(side == 1, 1.0, t)),
                        np.where(side == 2, 0.0, np.where(side == 3, 1.0, t))], axis=1)
    corner_uv = rng.integers(0, 2, (m, 2)).astype(float)
    for base in (edge_uv, corner_uv):
        p = c + base[:, :1] * eu + base[:, 1:] * ev
        p += _tiny(rng, m)[:, None] * _unit(eu) + _tiny(rng, m)[:, None] * _unit(ev)
        fams.append(_through(p, d, rng, m))
    # crossing the inside at SHADOW_EPS (1 +- 1e-12 .. 1e-3) from the start or the end
    s = SHADOW_EPS * (1.0 + _tiny(rng, m, -12, -3))
    fams.append((on - s[:, None] * d, on + rng.uniform(0.1, 1, m)[:, None] * d))
    fams.append((on - rng.uniform(0.1, 1, m)[:, None] * d, on + s[:, None] * d))
    # ending on the plane, and segments of about 2 SHADOW_EPS
    fams.append((on - rng.uniform(1e-6, 1, m)[:, None] * d, on + _tiny(rng, m)[:, None] * n))
    fams.append(_through(on, d, rng, m, (0.9e-6, 1.1e-6), (0.9e-6, 1.1e-6)))
    return fams


def _sphere_segments(c, r, rng, m):
    radial = _unit(rng.normal(size=(m, 3)))
    tang = _unit(np.cross(radial, rng.normal(size=(m, 3))))
    fams = []
    # tangent lines, the distance r (1 +- 1e-15 .. 1e-5)
    p = c + (r * (1.0 + _tiny(rng, m, -15, -5)))[:, None] * radial
    fams.append(_through(p, tang, rng, m))
    # ending on (or starting from) the surface +- 1e-16 .. 1e-6
    s = c + (r + _tiny(rng, m))[:, None] * radial
    d = _unit(rng.normal(size=(m, 3)))
    fams.append((s - rng.uniform(1e-3, 1, m)[:, None] * d, s))
    fams.append((s, s + rng.uniform(1e-3, 1, m)[:, None] * d))
    # the surface at SHADOW_EPS (1 +- tiny) from the start
    e = SHADOW_EPS * (1.0 + _tiny(rng, m, -12, -3))
    fams.append((s - e[:, None] * radial, s + rng.uniform(0.1, 1, m)[:, None] * radial))
    return fams


def _box_segments(lo, hi, rng, m):
    fams = []
    ax = rng.integers(0, 3, m)
    # grazing a face: parallel to it (exactly, or 1e-13 off) at 1e-16 .. 1e-6 from it
    p = rng.uniform(lo, hi, (m, 3))
    face = np.where(rng.random(m) < 0.5, lo[ax], hi[ax])
    p[np.arange(m), ax] = face + _tiny(rng, m)
    d = _unit(rng.normal(size=(m, 3)))
    d[np.arange(m), ax] = np.where(rng.random(m) < 0.5, 0.0, _tiny(rng, m, -14, -11))
    fams.append(_through(p, _unit(d), rng, m))
    # through edges and corners +- tiny
    q = np.where(rng.random((m, 3)) < 0.5, lo, hi) + _tiny(rng, 3 * m).reshape(m, 3)
    free = rng.integers(0, 2, (m, 3)).astype(bool)
    q = np.where(free & (rng.random((m, 1)) < 0.5), rng.uniform(lo, hi, (m, 3)), q)
    fams.append(_through(q, _unit(rng.normal(size=(m, 3))), rng, m))
    # ending on a face
    fams.append((p - rng.uniform(1e-3, 1, m)[:, None] * d, p))
    return fams


def _random(rng, m):
    return rng.uniform(-1, 1, (m, 3)), rng.uniform(-1, 1, (m, 3))


@pytest.mark.parametrize("name", ["area", "study_area", "area_occluder", "study_occluder",
                                  "hg", "mixed_occluders", "multi_light"])
def test_verdicts_sound(name):
    sc = scene(name)
    bl = blockers_of(sc)
    rng = np.random.default_rng(zlib.crc32(name.encode()))
    m = 4000
    fams = [_random(rng, 20 * m)]
    for lt in sc.lights:
        if lt.kind == "area":
            fams += _quad_segments(lt, rng, m)
    for oc in sc.occluders:
        if oc.kind == "sphere":
            fams += _sphere_segments(oc.center, oc.radius, rng, m)
        elif oc.kind == "box":
            fams += _box_segments(oc.min, oc.max, rng, m)
    # Random segments: nearly all decided (all, without triangle blockers).
    frac, _ = _check(bl, *fams[0], rng, 0.4 if bl.triangles.shape[0] else 0.999)
    for a, b in fams[1:]:
        _check(bl, a, b, rng)


def test_edges_mostly_decided():
    """Through the edges of an area light within 1e-16 .. 1e-6: the verdict is left open only
    within rounding distance of an edge (here: for a small fraction of the segments)."""
    rng = np.random.default_rng(1)
    sc = scene("area")
    fams = _quad_segments(sc.lights[0], rng, 20_000)
    frac, _ = _check(blockers_of(sc), *fams[1], rng)
    assert 0.5 < frac < 1.0, frac  # offsets below ~1e-14 stay undecided, the rest decided


def test_crosses_plane_sound():
    """``crosses_plane`` agrees with ``geometry._crosses_plane`` wherever it decides: segments
    leaving the plane (as from an area light), grazing it, ending on it, crossing it near
    either end, clear of it."""
    rng = np.random.default_rng(3)
    light = scene("area").lights[0]
    nq = np.cross(light.edge_u, light.edge_v)
    plane = np.append(nq, nq @ light.corner)
    m = 20_000
    uv = rng.random((m, 2))
    on = light.corner + uv[:, :1] * light.edge_u + uv[:, 1:] * light.edge_v
    d = _unit(rng.normal(size=(m, 3)))
    k = m // 4  # grazing directions: normal component down to 1e-12
    d[:k, 1] = rng.choice([-1, 1], k) * 10.0 ** rng.uniform(-12, -3, k)
    length = 10.0 ** rng.uniform(-7, 0.5, m)
    cases = [
        (on, on + length[:, None] * d),  # leaving the plane
        (on + length[:, None] * d, on),  # arriving on it
        (on - SHADOW_EPS * d, on + length[:, None] * d),  # crossing just after the start
        (on - length[:, None] * d, on + 0.5 * SHADOW_EPS * rng.random((m, 1)) * d),  # near end
        (on + 0.3 * d, on + 0.7 * d),  # clear of it, either side
        (on - 0.3 * d, on + 0.7 * d),  # crossing it in the middle
    ]
    decided = []
    for a, b in cases:
        out = np.empty(m, dtype=np.int64)
        _crosses(a, b, plane, out)
        for sub in (np.s_[:], np.s_[1:4099], np.s_[7:10], np.s_[::3]):
            got = _crosses_plane(a[sub], b[sub], plane)
            assert not np.any((out[sub] == sh.NO) & got)
            assert not np.any((out[sub] == sh.YES) & ~got)
        decided.append(np.mean(out != sh.MAYBE))
    # Leaving the plane (but the most grazing), clear of it, crossing it: decided.
    assert decided[0] > 0.7 and decided[4] == 1.0 and decided[5] > 0.99, decided


@pytest.mark.parametrize("name", ["area", "area_occluder", "hg", "study_occluder"])
def test_trace_needs_no_numpy_shadow_test(name, monkeypatch):
    """Without triangle blockers every segment of a trace is decided (the speed of Trace
    depends on it): ``Blockers.occluded`` is never called."""
    calls = []
    monkeypatch.setattr(sh, "resolve", lambda *a: calls.append(a))
    sc = scene(name)
    trace(sc, 5000, np.random.default_rng(4), blockers=blockers_of(sc))
    assert not calls
