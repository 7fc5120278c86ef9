"""The compiled Trace equals the numpy reference bit for bit.

``trace(..., reference=True)`` runs the vectorized numpy implementation of
``psurf_core/trace.py``; the default runs ``psurf_core/trace_compiled.py``. On every bundled
scene (point, area and mesh lights, occluders, Henyey-Greenstein, roulette with
``max_scatter = -1``) and the scenes of ``trace_scenes``, every ``PhotonPaths`` field must have
the same bytes and the generator must be left in the same state. Each compiled twin is also
checked against its numpy function, edge cases included.
"""

from __future__ import annotations

from dataclasses import fields, replace

import numpy as np
import pytest
from numba import njit
from trace_scenes import BUILT, BUNDLED, scene

from psurf_core import trace as ref
from psurf_core import (
    trace_buffers,
    trace_compiled,  # noqa: F401 (registers the twins of trace.py)
    trace_emit,
    trace_emit_compiled,
    trace_shadow,
)
from psurf_core.constants import BOX_EPS
from psurf_core.geometry import blockers_of, inside_box
from psurf_core.kernels.buffers import HitBuffers
from psurf_core.trace import PhotonPaths, trace

FIELDS = [f.name for f in fields(PhotonPaths)]


def dense(name: str = "hg"):
    """A scene whose photons scatter ~15 times on average (records outgrow the first
    buffer; roulette decides most depths)."""
    s = scene(name)
    return replace(s, medium=replace(s.medium, sigma_s=6.0, sigma_a=0.05))


def _both(sc, n, seed, max_depth=None):
    out = []
    for reference in (True, False):
        rng = np.random.default_rng(seed)
        paths = trace(sc, n, rng, blockers=blockers_of(sc), max_depth=max_depth,
                      reference=reference)
        out.append((paths, rng.random(8)))
    return out


def _assert_same(sc_name, got):
    (want, want_next), (paths, rng_next) = got
    assert paths.n_emitted == want.n_emitted
    for f in FIELDS[1:]:
        a, b = getattr(paths, f), getattr(want, f)
        assert a.dtype == b.dtype and a.shape == b.shape, (sc_name, f, a.shape, b.shape)
        assert a.tobytes() == b.tobytes(), (
            f"{sc_name}.{f}: {np.count_nonzero(a != b)} elements differ")
    assert rng_next.tobytes() == want_next.tobytes(), f"{sc_name}: other draws consumed"


@pytest.mark.parametrize("name", BUNDLED + BUILT)
def test_compiled_equals_reference(name):
    sc = scene(name)
    _assert_same(name, _both(sc, 3000, 7))


@pytest.mark.parametrize(("name", "k", "n", "depth"), [
    ("area", 2, 500, None), ("hg", 3, 500, None), ("mesh_light", 1, 500, None),
    ("point", None, 300, 1), ("area", None, 1, None), ("area", None, 0, None),
    ("multi_light", 4, 2000, None), ("study_occluder", None, 2000, 2),
])
def test_compiled_equals_reference_limits(name, k, n, depth):
    sc = scene(name) if k is None else scene(name).with_scatter(max_scatter=k)
    _assert_same(f"{name}/k={k}/n={n}/depth={depth}", _both(sc, n, 11, depth))


@pytest.mark.parametrize("name", ["hg", "area_occluder"])
def test_long_paths(name):
    """Deep roulette paths: the records grow past their first buffer."""
    sc = dense(name)
    got = _both(sc, 4000, 5)
    assert got[0][0].alive.sum() > 8 * 4000  # more vertices than the first record buffer
    _assert_same(f"dense {name}", got)


def test_workspace_reuse(monkeypatch):
    """A thread's kept workspace (grown, reused by smaller calls) and a call's own (past
    ``KEEP_PHOTONS``) give the reference's arrays."""
    monkeypatch.setattr(trace_buffers, "KEEP_PHOTONS", 1500)
    monkeypatch.setattr(trace_buffers._local, "ws", None, raising=False)
    sc = scene("multi_light")
    for n in (1000, 300, 1400, 2500, 50, 1000):
        _assert_same(f"n={n}", _both(sc, n, n))
    assert trace_buffers._local.ws.n == 1400


@pytest.mark.parametrize("name", ["area_occluder", "mesh_light"])
def test_threads_change_nothing(monkeypatch, name):
    """The depth kernel, ``assemble`` and the shadow verdicts cut into pieces on two threads
    (thresholds lowered so that a small batch is cut) give the reference's bytes and leave
    the generator in the same state."""
    sc = dense(name)
    monkeypatch.setattr(trace_compiled, "thread_count", lambda: 2)
    monkeypatch.setattr(trace_compiled, "ASSEMBLE_MIN", 16)
    monkeypatch.setattr(trace_compiled, "STEP_MIN", 16)
    monkeypatch.setattr(trace_shadow, "SHADE_MIN", 16)
    pieces, cut = [], {}
    for mod in (trace_compiled, trace_shadow):
        def spy(fn, n, th, lo=1, real=mod.in_pieces, key=mod.__name__):
            cut[key] = cut.get(key, False) or (th == 2 and n >= 2 * lo)
            pieces.append((n, th, lo))
            return real(fn, n, th, lo)

        monkeypatch.setattr(mod, "in_pieces", spy)
    _assert_same(name, _both(sc, 3000, 5))
    # assemble and the shadow verdicts were each cut into pieces on two threads.
    assert cut == dict.fromkeys((trace_compiled.__name__, trace_shadow.__name__), True), pieces


def test_reused_outputs(monkeypatch):
    """The returned arrays live in reused buffers: one is reused once its arrays (and every
    view of them) are dropped, never while any is held."""
    monkeypatch.setattr(trace_compiled, "OUTPUTS", HitBuffers())
    sc = scene("area_occluder")
    bl = blockers_of(sc)
    first = trace(sc, 2000, np.random.default_rng(1), blockers=bl)
    held = first.x[:, 1]  # a view keeps first.x's buffer
    copy = {f: getattr(first, f).copy() for f in FIELDS[1:]}
    held_copy = held.copy()
    addr = first.x.ctypes.data
    del first
    for seed in range(2, 6):
        p = trace(sc, 2000, np.random.default_rng(seed), blockers=bl)
        assert p.x.ctypes.data != addr
        assert held.tobytes() == held_copy.tobytes()
        for f in FIELDS[1:]:
            assert getattr(p, f).flags.c_contiguous
    del held, p
    again = trace(sc, 2000, np.random.default_rng(1), blockers=bl)
    for f in FIELDS[1:]:
        assert getattr(again, f).tobytes() == copy[f].tobytes(), f
    dropped = trace(sc, 2000, np.random.default_rng(7), blockers=bl).x.ctypes.data
    assert trace(sc, 2000, np.random.default_rng(8), blockers=bl).x.ctypes.data == dropped


@pytest.mark.parametrize("name", BUNDLED + BUILT)
def test_emit_equals_reference(name):
    sc = scene(name)
    ra, rb = np.random.default_rng(3), np.random.default_rng(3)
    want, got = trace_emit.emit(sc, ra, 2000), trace_emit_compiled.emit(sc, rb, 2000)
    assert want.keys() == got.keys()
    for k in want:
        assert got[k].dtype == want[k].dtype and got[k].tobytes() == want[k].tobytes(), k
    assert ra.random(4).tobytes() == rb.random(4).tobytes()


# --------------------------------------------------------------------------- the twins
@njit
def _direction_about(axis, ct, cp, sp, out):
    for i in range(axis.shape[0]):
        a = (axis[i, 0], axis[i, 1], axis[i, 2])
        out[i] = trace_emit.direction_about(a, ct[i], cp[i], sp[i])


@njit
def _uniform_cosine(u, n, cp, sp, out_u, out_c):
    for i in range(u.shape[0]):
        out_u[i] = trace_emit.uniform_direction(u[i], cp[i], sp[i])
        out_c[i] = trace_emit.cosine_direction((n[i, 0], n[i, 1], n[i, 2]), u[i], cp[i], sp[i])


@njit
def _points(corner, eu, ev, uv, tri, out_p, out_b, out_t):
    c, e, f = (corner[0], corner[1], corner[2]), (eu[0], eu[1], eu[2]), (ev[0], ev[1], ev[2])
    for i in range(uv.shape[0]):
        out_p[i] = trace_emit.parallelogram_point(c, e, f, (uv[i, 0], uv[i, 1]))
        t = ((tri[i, 0, 0], tri[i, 0, 1], tri[i, 0, 2]), (tri[i, 1, 0], tri[i, 1, 1], tri[i, 1, 2]),
             (tri[i, 2, 0], tri[i, 2, 1], tri[i, 2, 2]))
        out_b[i], out_t[i] = trace_emit.triangle_point(t, uv[i, 0], uv[i, 1])


@njit
def _scalars(g, u, st, q, albedo, ok, out_mu, out_t, out_keep):
    for i in range(u.shape[0]):
        out_mu[i] = ref.phase_cosine(g, u[i])
        out_t[i] = ref.free_flight(u[i], st)
        out_keep[i] = ref.survives(ok[i], u[i], q)


@njit
def _segments(x, w, t, bmin, bmax, beta, q, albedo, out_x, out_c, out_in, out_b):
    b0, b1 = (bmin[0], bmin[1], bmin[2]), (bmax[0], bmax[1], bmax[2])
    for i in range(x.shape[0]):
        a, d = (x[i, 0], x[i, 1], x[i, 2]), (w[i, 0], w[i, 1], w[i, 2])
        e = ref.advance(a, d, t[i])
        out_x[i] = e
        out_c[i] = ref.segment_clip(a, d, t[i], b0, b1)
        out_in[i] = inside_box(e, b0, b1)
        out_b[i] = ref.scattered_weight((beta[i, 0], beta[i, 1], beta[i, 2]), q, albedo)


@njit
def _search(cdf, u, out):
    for i in range(u.shape[0]):
        out[i] = trace_emit.search_right(cdf, u[i])


def _same(a, b):
    return a.shape == b.shape and a.tobytes() == b.tobytes()


def _unit(v):
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def test_direction_twins():
    rng = np.random.default_rng(0)
    m = 4000
    axis = _unit(rng.normal(size=(m, 3)))
    axis[:6] = [[0, 0, 1], [0, 0, -1], [1, 0, 0], [0, -1, 0], [0, 1e-300, -1], [0.6, 0.8, -0.0]]
    axis[6:12, 2] = -1.0 + rng.random(6) * 1e-12  # near the frame's pole
    axis = _unit(axis)
    ct = np.r_[[1.0, -1.0, 0.0, 1 - 1e-16], 2 * rng.random(m - 4) - 1]
    phi = 2 * np.pi * rng.random(m)
    cp, sp = np.cos(phi), np.sin(phi)
    out = np.empty((m, 3))
    _direction_about(axis, ct, cp, sp, out)
    assert _same(out, trace_emit.direction_about(axis, ct, cp, sp))
    u = np.r_[[0.0, 1 - 2**-53, 0.5], rng.random(m - 3)]
    out_u, out_c = np.empty((m, 3)), np.empty((m, 3))
    _uniform_cosine(u, axis, cp, sp, out_u, out_c)
    assert _same(out_u, trace_emit.uniform_direction(u, cp, sp))
    assert _same(out_c, trace_emit.cosine_direction(axis, u, cp, sp))


def test_point_twins():
    rng = np.random.default_rng(1)
    m = 3000
    corner, eu, ev = rng.normal(size=3), rng.normal(size=3), rng.normal(size=3)
    uv = np.r_[[[0.0, 0.0], [1 - 2**-53, 1 - 2**-53]], rng.random((m - 2, 2))]
    tri = rng.normal(size=(m, 3, 3))
    out_p, out_b, out_t = np.empty((m, 3)), np.empty((m, 2)), np.empty((m, 3))
    _points(corner, eu, ev, uv, tri, out_p, out_b, out_t)
    assert _same(out_p, trace_emit.parallelogram_point(corner, eu, ev, uv))
    bary, x = trace_emit.triangle_point(tri, uv[:, 0], uv[:, 1])
    assert _same(out_b, bary) and _same(out_t, x)


@pytest.mark.parametrize("g", [0.0, 5e-4, -5e-4, 1e-3, 0.6, -0.4, 0.999, -0.999])
@pytest.mark.parametrize("q", [1.0, 0.9, 0.25])
def test_scalar_twins(g, q):
    rng = np.random.default_rng(2)
    m = 3000
    u = np.r_[[0.0, 1 - 2**-53, 0.5, min(q, 0.5), np.nextafter(q, 0)], rng.random(m - 5)]
    ok = rng.random(m) < 0.8
    mu, t, keep = np.empty(m), np.empty(m), np.empty(m, dtype=bool)
    _scalars(g, u, 1.3, q, 0.8, ok, mu, t, keep)
    assert _same(mu, ref.phase_cosine(g, u))
    assert _same(t, ref.free_flight(u, 1.3))
    assert _same(keep, ref.survives(ok, u, q))


def test_segment_twins():
    """``advance``, ``segment_clip`` (from inside, outside, on the boundary, along a face,
    axis-parallel), ``geometry.inside_box`` as Trace calls it (on the slackened boundary) and
    ``scattered_weight``."""
    rng = np.random.default_rng(3)
    m = 6000
    bmin, bmax = np.array([-1.0, -0.5, -2.0]), np.array([1.0, 0.5, 2.0])
    hi = bmax + BOX_EPS
    x = rng.uniform(-3, 3, (m, 3))
    x[:500, 0] = bmin[0]  # on a face
    x[500:1000] = rng.choice([-1.0, 1.0], (500, 3)) * bmax  # on corners
    w = _unit(rng.normal(size=(m, 3)))
    w[1000:1500, rng.integers(0, 3)] = 0.0  # parallel to a slab
    w[1500:1600, 1] = 1e-13  # below PARALLEL_EPS
    w = _unit(w)
    w[1600:1700] = [0.0, 0.0, -1.0]
    t = -np.log1p(-rng.random(m)) / 0.7
    t[:20] = 0.0
    x[2000:2500] = rng.choice([-1.0, 1.0], (500, 3)) * hi  # ends on the slackened box
    w[2000:2500] = 0.0
    beta = rng.random((m, 3)) * 10
    for q in (1.0, 0.9):
        out_x, out_c = np.empty((m, 3)), np.empty((m, 2))
        out_in, out_b = np.empty(m, dtype=bool), np.empty((m, 3))
        _segments(x, w, t, bmin, bmax, beta, q, 0.8, out_x, out_c, out_in, out_b)
        assert _same(out_x, ref.advance(x, w, t))
        assert _same(out_c, ref.segment_clip(x, w, t, bmin, bmax))
        assert _same(out_in, inside_box(ref.advance(x, w, t), bmin, bmax))
        assert _same(out_b, ref.scattered_weight(beta, q, 0.8))


def test_search_right_is_searchsorted():
    """Emission's compiled search picks what ``numpy.searchsorted(side="right")`` picks:
    ties, repeated cdf values, NaN, keys outside [0, 1]."""
    rng = np.random.default_rng(0)
    for k in (1, 2, 3, 7, 320):
        for cdf in (np.cumsum(rng.random(k)), np.sort(rng.integers(1, 4, k)).astype(float),
                    np.r_[np.cumsum(rng.random(k)), [np.nan] * 3]):
            u = np.r_[rng.random(2000), cdf[:50], [0.0, 1.0, np.nan, -1.0, 2.0, np.inf]]
            out = np.empty(u.size, dtype=np.intp)
            _search(cdf, u, out)
            assert np.array_equal(out, trace_emit.search_right(cdf, u)), (k, cdf[:4])
