"""Trace's shadow tests, compiled: what ``Blockers.occluded`` answers for a segment, decided
per segment wherever rounding cannot change the answer.

The numpy reference (``trace.step``) calls ``Blockers.occluded`` on every segment whose start
is still valid. Its answer cannot be reproduced bit for bit here (its dot products are BLAS's,
whose rounding depends on the array), but every quantity it computes can be *bounded*: each
``e*`` below bounds ``|computed - exact|`` for any order of the sums and with or without fused
multiply-adds (the standard bounds: ``gamma_n = n u / (1 - n u)`` per ``n``-term dot product,
``u = 2^-53``, rounded up here). A comparison is decided (:func:`less`) only when the two sides
are apart by more than ``SAFETY`` times their bounds (2 for two computations, 2 to cover the
second-order terms and the rounding of the bounds themselves). Per segment, following
``Blockers.occluded`` step by step:

1. its bounding box meets no blocker's padded box: clear (the same exact comparisons);
2. otherwise it is *near* (kept by ``occluded``'s first reject). ``occluded`` tests it exactly
   only if it meets a non-planar blocker's box or, for a planar one (an area light), crosses
   its plane away from both ends (``geometry._crosses_plane``; :func:`crosses_plane`). A
   segment leaving an emitter (every first segment of an area light) does not;
3. the exact test (``Blockers.first_hit`` between ``SHADOW_EPS`` and ``|b - a| - SHADOW_EPS``
   against every blocker): :func:`sphere_hit` (``geometry.ray_sphere``), :func:`box_hit`
   (``geometry.ray_box``), :func:`quad_hit` (``geometry.ray_parallelogram``); triangles
   (``Blockers``' hierarchy, ``kernels.mesh_bvh``) are left undecided.

Logic is three-valued (``NO``, ``YES``, ``MAYBE``). The step kernel lists the near segments
(1.); :func:`shade` decides them (2., 3.). A depth with any undecided (``DEFER``) segment
calls ``Blockers.occluded`` on all its near segments (:func:`resolve`): exactly the rows that
``occluded`` keeps for its exact test when the reference calls it, so the same arrays and the
same rounding; otherwise it is not called. ``tests/test_trace_shadow.py`` checks the verdicts
against ``Blockers.occluded`` on adversarial segments (grazing the edges, ending on the
surfaces, tangent to the spheres).
"""

from __future__ import annotations

import numpy as np

from .constants import PARALLEL_EPS, SHADOW_EPS
from .geometry import Blockers
from .kernels.jit import inline, kernel
from .kernels.shadow import (  # meets: the box reject, one home with the walkers'
    BLOCKED,
    BOX,
    CLEAR,
    DEFER,
    QUAD,
    SPHERE,
    BlockerRow,
    blocker_table,
    meets,
)
from .kernels.threads import in_pieces
from .records import flat, load

#: Unit roundoff of float64.
U = 2.0**-53
#: Distance, in error bounds, between the two sides of a decided comparison.
SAFETY = 4.0
#: Absolute slack of every comparison (no bound is ever exactly 0).
TINY = 1e-290
#: Three-valued logic.
NO, YES, MAYBE = 0, 1, 2
#: Verdicts of :func:`shade` (``kernels.shadow``'s): ``CLEAR``, ``BLOCKED``, ``DEFER`` (left
#: to ``Blockers.occluded``).
__all__ = ["BLOCKED", "CLEAR", "DEFER", "resolve", "shade", "table"]


def table(blockers: Blockers) -> tuple[np.ndarray, bool]:
    """The blockers as the kernels see them: ``kernels.shadow.blocker_table``'s
    :class:`~psurf_core.kernels.shadow.BlockerRow` records (its spheres' radii, boxes, quads'
    planes, edges and inverse Gram matrices are ``geometry``'s own values), flat.

    Returns
    -------
    rows : (B, F) float
        One record per blocker box (empty when nothing blocks).
    test_all : bool
        Blockers without boxes: every segment is near and deferred.
    """
    tab = blocker_table(blockers)
    if tab is None:
        return np.zeros((0, 1)), True
    return flat(tab), False


# --------------------------------------------------------------------------- logic
@inline
def less(x, ex, y, ey):  # pragma: no cover - compiled
    """Is ``x' < y'`` (equally ``x' <= y'``) for every ``x'`` within ``ex`` of ``x`` and
    ``y'`` within ``ey`` of ``y`` (with ``SAFETY``)? ``YES``, ``NO`` or ``MAYBE``."""
    r = SAFETY * (ex + ey) + TINY
    if x + r < y:
        return YES
    if x - r > y:
        return NO
    return MAYBE


@inline
def and3(p, q):  # pragma: no cover - compiled
    if p == NO or q == NO:
        return NO
    return YES if p == YES and q == YES else MAYBE


@inline
def or3(p, q):  # pragma: no cover - compiled
    if p == YES or q == YES:
        return YES
    return NO if p == NO and q == NO else MAYBE


@inline
def in_range(t, et, t_max, et_max):  # pragma: no cover - compiled
    """``first_hit``'s ``SHADOW_EPS < t < t_max``."""
    return and3(less(SHADOW_EPS, 0.0, t, et), less(t, et, t_max, et_max))


# --------------------------------------------------------------------------- the tests
@inline
def crosses_plane(a, b, ln, eln, plane):  # pragma: no cover - compiled
    """``geometry._crosses_plane`` of segment ``a -> b`` (3-tuples; ``ln = |b - a|`` within
    ``eln``): ``da db <= 0`` and ``SHADOW_EPS / 2 <= da / (da - db) |b - a|
    <= |b - a| - SHADOW_EPS / 2``, with ``da = a . n - c``, ``db = b . n - c``."""
    n0, n1, n2, c = plane[0], plane[1], plane[2], plane[3]
    da = a[0] * n0 + a[1] * n1 + a[2] * n2 - c
    db = b[0] * n0 + b[1] * n1 + b[2] * n2 - c
    ea = 5.0 * U * (abs(a[0] * n0) + abs(a[1] * n1) + abs(a[2] * n2) + abs(c))
    eb = 5.0 * U * (abs(b[0] * n0) + abs(b[1] * n1) + abs(b[2] * n2) + abs(c))
    ra, rb = SAFETY * ea + TINY, SAFETY * eb + TINY
    sa, sb = abs(da), abs(db)
    half = 0.5 * SHADOW_EPS
    tiny = 1e-150  # |da|, |db| above it: their product cannot underflow to 0
    if sa > ra + tiny and sb > rb + tiny and (da > 0.0) == (db > 0.0):
        return NO  # both ends strictly on one side
    if sb <= rb:
        return MAYBE  # ends on the plane
    if sa <= ra:
        # Starts on the plane (a segment leaving an emitter): |t| <= r_hi |b - a|.
        r_hi = (sa + ra) / (sb - rb - (sa + ra)) if sb - rb > sa + ra else np.inf
        return NO if r_hi * (ln + SAFETY * eln) * (1.0 + 8.0 * U) < half else MAYBE
    # Strictly opposite sides: t = r |b - a|, r = sa / (sa + sb) (rounded within 4u).
    r_lo = (sa - ra) / (sa + ra + sb + rb) * (1.0 - 8.0 * U)
    r_hi = (sa + ra) / (sa - ra + sb - rb) * (1.0 + 8.0 * U)
    t_lo, t_hi = r_lo * (ln - SAFETY * eln), r_hi * (ln + SAFETY * eln)
    lo_ok = YES if t_lo > half else (NO if t_hi < half else MAYBE)
    end_lo = (ln - SAFETY * eln - half) * (1.0 - 4.0 * U)
    end_hi = (ln + SAFETY * eln - half) * (1.0 + 4.0 * U)
    hi_ok = YES if t_hi < end_lo else (NO if t_lo > end_hi else MAYBE)
    return and3(lo_ok, hi_ok)


@inline
def sphere_hit(a, d, ed, t_max, et_max, c, r2):  # pragma: no cover - compiled
    """``first_hit``'s sphere test of the ray ``a + t d`` (``d`` within ``ed`` per axis):
    ``ray_sphere``'s roots, the nearer one past ``SHADOW_EPS`` else the farther, in range.
    Vectors are 3-tuples, as in every test here."""
    o0, o1, o2 = a[0] - c[0], a[1] - c[1], a[2] - c[2]
    b = o0 * d[0] + o1 * d[1] + o2 * d[2]
    eb = abs(o0) * ed[0] + abs(o1) * ed[1] + abs(o2) * ed[2] + 4.0 * U * (
        abs(o0 * d[0]) + abs(o1 * d[1]) + abs(o2 * d[2]))
    s2 = o0 * o0 + o1 * o1 + o2 * o2
    cc = s2 - r2
    ecc = 4.0 * U * s2 + U * abs(cc)
    disc = b * b - cc
    edisc = (2.0 * abs(b) + eb) * eb + ecc + 2.0 * U * (b * b + abs(cc))
    real = less(0.0, 0.0, disc, edisc)  # else sqrt(NaN): no root
    if real != YES:
        return real
    sq = np.sqrt(disc)
    et = eb + edisc / sq + U * sq + U * (abs(b) + sq)
    near = less(SHADOW_EPS, 0.0, -b - sq, et)
    if near == MAYBE:
        return MAYBE
    return in_range(-b - sq if near == YES else -b + sq, et, t_max, et_max)


@inline
def box_hit(a, d, ed, t_max, et_max, lo, hi):  # pragma: no cover - compiled
    """``first_hit``'s box test (``ray_box``'s slabs; entry past ``SHADOW_EPS`` else exit,
    in range), on intervals that hold numpy's value of each slab distance."""
    te_lo = te_hi = -np.inf
    tx_lo = tx_hi = np.inf
    for k in range(3):
        dk = d[k]
        par = less(abs(dk), ed[k], PARALLEL_EPS, 0.0)
        if par == MAYBE:
            return MAYBE
        inv = 1.0 / (PARALLEL_EPS if par == YES else dk)
        rel = 2.0 * U if par == YES else ed[k] / abs(dk) + 3.0 * U
        p, q = (lo[k] - a[k]) * inv, (hi[k] - a[k]) * inv
        rp, rq = SAFETY * rel * abs(p) + TINY, SAFETY * rel * abs(q) + TINY
        te_lo, te_hi = max(te_lo, min(p - rp, q - rq)), max(te_hi, min(p + rp, q + rq))
        tx_lo, tx_hi = min(tx_lo, max(p - rp, q - rq)), min(tx_hi, max(p + rp, q + rq))
    if not te_lo < tx_hi:
        return NO  # te' >= tx': a miss
    if not te_hi < tx_lo:
        return MAYBE
    if te_lo > SHADOW_EPS:
        t_lo, t_hi = te_lo, te_hi
    elif te_hi < SHADOW_EPS:
        t_lo, t_hi = tx_lo, tx_hi
    else:
        return MAYBE
    return in_range(0.5 * (t_lo + t_hi), 0.5 * (t_hi - t_lo) / SAFETY, t_max, et_max)


@inline
def quad_hit(a, d, ed, t_max, et_max, corner, n, eu, ev, m):  # pragma: no cover - compiled
    """``first_hit``'s parallelogram test (``ray_parallelogram``): ``|d . n| >
    PARALLEL_EPS``, ``t = (corner - a) . n / d . n`` in range, and ``(u, v) = (p . eu,
    p . ev) m`` in ``[0, 1]^2`` for ``p = a + t d - corner``."""
    den = d[0] * n[0] + d[1] * n[1] + d[2] * n[2]
    eden = (abs(n[0]) * ed[0] + abs(n[1]) * ed[1] + abs(n[2]) * ed[2]
            + 4.0 * U * (abs(d[0] * n[0]) + abs(d[1] * n[1]) + abs(d[2] * n[2])))
    res = less(PARALLEL_EPS, 0.0, abs(den), eden)
    if res == NO:
        return NO
    if not abs(den) > 4.0 * SAFETY * eden:
        return MAYBE
    c0, c1, c2 = corner[0] - a[0], corner[1] - a[1], corner[2] - a[2]
    num = c0 * n[0] + c1 * n[1] + c2 * n[2]
    enum = 4.0 * U * (abs(c0 * n[0]) + abs(c1 * n[1]) + abs(c2 * n[2]))
    t = num / den
    if not np.isfinite(t):
        return MAYBE
    et = (enum + abs(t) * eden) / (abs(den) - SAFETY * eden) + U * abs(t)
    res = and3(res, in_range(t, et, t_max, et_max))
    if res == NO:
        return NO
    p0 = a[0] + t * d[0] - corner[0]
    p1 = a[1] + t * d[1] - corner[1]
    p2 = a[2] + t * d[2] - corner[2]
    ep0 = abs(d[0]) * et + abs(t) * ed[0] + 3.0 * U * (abs(a[0]) + abs(t * d[0]) + abs(corner[0]))
    ep1 = abs(d[1]) * et + abs(t) * ed[1] + 3.0 * U * (abs(a[1]) + abs(t * d[1]) + abs(corner[1]))
    ep2 = abs(d[2]) * et + abs(t) * ed[2] + 3.0 * U * (abs(a[2]) + abs(t * d[2]) + abs(corner[2]))
    r0 = p0 * eu[0] + p1 * eu[1] + p2 * eu[2]
    r1 = p0 * ev[0] + p1 * ev[1] + p2 * ev[2]
    er0 = (abs(eu[0]) * ep0 + abs(eu[1]) * ep1 + abs(eu[2]) * ep2
           + 4.0 * U * (abs(p0 * eu[0]) + abs(p1 * eu[1]) + abs(p2 * eu[2])))
    er1 = (abs(ev[0]) * ep0 + abs(ev[1]) * ep1 + abs(ev[2]) * ep2
           + 4.0 * U * (abs(p0 * ev[0]) + abs(p1 * ev[1]) + abs(p2 * ev[2])))
    for m0j, m1j in ((m[0], m[1]), (m[2], m[3])):  # (u, v) = (r0, r1) @ inv(Gram).T
        uv = r0 * m0j + r1 * m1j
        euv = abs(m0j) * er0 + abs(m1j) * er1 + 3.0 * U * (abs(r0 * m0j) + abs(r1 * m1j))
        res = and3(res, and3(less(0.0, 0.0, uv, euv), less(uv, euv, 1.0, 0.0)))
    return res


@inline
def blocker_hit(a, d, ed, t_max, et_max, bl):  # pragma: no cover - compiled
    """The exact test against one blocker ``bl`` (a :class:`BlockerRow`)."""
    if bl.kind == SPHERE:
        return sphere_hit(a, d, ed, t_max, et_max, bl.p, bl.e1[0] * bl.e1[0])
    if bl.kind == BOX:
        return box_hit(a, d, ed, t_max, et_max, bl.p, bl.e1)
    if bl.kind == QUAD:
        return quad_hit(a, d, ed, t_max, et_max, bl.p, bl.n, bl.e1, bl.e2, bl.gram)
    return MAYBE  # triangles: Blockers.occluded decides them (kernels.mesh_bvh)


def shade(nn, a, b, inside, rows, test_all, ok, photon, verdict, threads: int = 1) -> bool:
    """What ``Blockers.occluded`` answers for each near segment ``a[i] -> b[i]`` (one whose
    box meets a blocker's padded box): whether ``occluded`` tests it exactly (it meets a
    non-planar blocker's box, or crosses a planar one's plane: :func:`crosses_plane`), then
    ``Blockers.first_hit`` between ``SHADOW_EPS`` and ``|b - a| - SHADOW_EPS`` against every
    blocker (:func:`blocker_hit`).

    Parameters
    ----------
    nn : int
        Segments (the first ``nn`` rows).
    a, b : (>= nn, 3) float
        Segment ends (scene units).
    inside : (>= nn,) bool
        End inside the medium box.
    rows : (B, F) float
    test_all : bool
        :func:`table`'s.
    ok : (N,) bool
        ``prefix_ok`` of the end vertex: ``ok[photon[i]] = inside[i]`` and unoccluded,
        written for every decided segment.
    photon : (>= nn,) int64
    verdict : (>= nn,) int64
        ``CLEAR``, ``BLOCKED`` or ``DEFER``, written.
    threads : int
        Threads to run ranges of segments on (each segment is decided from its own row and
        writes its own ``verdict`` and photon's ``ok``: the result does not depend on it).

    Returns
    -------
    bool
        Some segment is ``DEFER``.
    """
    unsure = []

    def part(i0, i1):
        if shade_range(i0, i1, a, b, inside, rows, test_all, ok, photon, verdict):
            unsure.append(True)

    in_pieces(part, nn, threads, SHADE_MIN)
    return bool(unsure)


#: Near segments per thread below which :func:`shade` runs on one thread.
SHADE_MIN = 4096


@kernel(nogil=True)
def shade_range(i0, i1, a, b, inside, rows, test_all, ok, photon,
                verdict):  # pragma: no cover - compiled
    """:func:`shade` for the segments ``i0 .. i1 - 1``; returns whether one is ``DEFER``."""
    unsure = False
    # Loops over the blocker rows live here, not in the inlined tests: numba keeps a
    # reference count per segment for an array handed to an inlined loop.
    for i in range(i0, i1):
        ai, bi = (a[i, 0], a[i, 1], a[i, 2]), (b[i, 0], b[i, 1], b[i, 2])
        v0, v1, v2 = bi[0] - ai[0], bi[1] - ai[1], bi[2] - ai[2]
        ln = np.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
        eln = 4.0 * U * ln  # np.linalg.norm: three squares summed, a square root
        tested = MAYBE if test_all else NO  # kept by occluded for its exact test
        for k in range(rows.shape[0]):
            bl = load(rows, k, BlockerRow)
            if tested != YES and meets(ai, bi, bl):
                if bl.kind != QUAD:  # planar: the quads (Blockers.planes not NaN)
                    tested = YES
                else:
                    pl = (bl.normal[0], bl.normal[1], bl.normal[2], bl.offset)
                    tested = or3(tested, crosses_plane(ai, bi, ln, eln, pl))
        res = tested
        if tested != NO and not test_all:
            hit = NO
            if ln >= 1.9999 * SHADOW_EPS:  # else t_max <= t_min: nothing is kept
                d = (v0 / ln, v1 / ln, v2 / ln)
                ed = (6.0 * U * abs(d[0]), 6.0 * U * abs(d[1]), 6.0 * U * abs(d[2]))
                t_max, et_max = ln - SHADOW_EPS, eln + U * ln
                for k in range(rows.shape[0]):
                    if hit != YES:
                        hit = or3(hit, blocker_hit(ai, d, ed, t_max, et_max,
                                                   load(rows, k, BlockerRow)))
            res = and3(tested, hit)
        v = CLEAR if res == NO else BLOCKED if res == YES else DEFER
        verdict[i] = v
        if v == DEFER:
            unsure = True
        else:
            ok[photon[i]] = inside[i] and v == CLEAR
    return unsure


def resolve(photon, a, b, inside, blockers: Blockers, ok: np.ndarray) -> None:
    """``ok[photon] = inside & ~blockers.occluded(a, b)`` for the near segments of an unsure
    depth (every near segment, decided or not: the rows ``occluded`` keeps for its exact
    test, so its arrays and rounding are the reference's).

    Parameters
    ----------
    photon : (nn,) int64
    a, b : (nn, 3) float
        Segment ends (scene units).
    inside : (nn,) bool
        End vertex inside the medium box.
    blockers : Blockers
    ok : (N,) bool
        ``prefix_ok`` of the new vertex, written at ``photon``.
    """
    ok[photon] = inside & ~blockers.occluded(a, b)
