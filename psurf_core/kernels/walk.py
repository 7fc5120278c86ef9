"""The walker: one compiled loop over a technique's candidate pixel spans that finds, shades
and MIS-weights its hits, composed from the family's compiled twins.

For every span ``(prim, row, c0, c1)`` (primitive-major), every pixel of it and every ray of
that pixel, the walker calls the family's twins in the order its numpy Intersect and
Evaluate do:

``roots(G, o, psi)``
    the ray distances ``s`` of the candidate roots (NaN: none), then ``s_min < s < s_max``;
``accept(G, o, psi, s, short)``
    whether a root is a hit, and the hit's record (the technique's ``Hits.data`` row);
``visibility(G, x0, hit, medium, blockers)``
    the shadow status of the reconstructed path's segments (``kernels.shadow``);
``contribution(G, psi, s, s_min, hit, short, medium)``
    ``f / (q |n . psi|)`` without the photon weight ``G.beta``;
``reconstruct(row, G, hit)`` and every MIS member's ``density(row, short)``
    the hit's full path and the balance / power weight (:mod:`.mis`), where the technique is
    in an MIS set.

A *staged* family (:attr:`~psurf_core.techniques.compiled.Compiled.staged`) has its walker
call ``roots`` for a block of a span's rays first (up to :data:`STAGE_BLOCK`), keep the roots
inside their ray's interval without a branch, then go on from ``accept`` for those: the same
roots in the same order, so the same hits, in the same order, and the same image bits.

``G`` is the primitive's geometry record, read once per span. Hits go to one of three
outputs: *full rows* (ray, primitive, ``s``, the hit record, value, weight, shadow statuses:
what ``Hits`` and the UI need) when ``emit`` is set, else the weighted values added to a
per-ray image of the walker's piece, or *compact rows* (ray, weighted value) that the caller
adds to the image in order (:mod:`.fused` chooses). A walker is built per (family, MIS set,
member) by :func:`walker` and compiled once per clone (the on-disk cache is keyed by every
source it inlines, :mod:`.cache`).
"""

from __future__ import annotations

import numpy as np

from ..path_record import at_hit, photon_row
from ..records import load, store
from .jit import inline, kernel
from .rays import RayRow
from .shadow import BLOCKED
from .vec import madd
from .views import borrowed

_WALKERS: dict = {}

#: Rays whose roots a staged walker finds before it shades any (:attr:`Compiled.staged`): a
#: span's rays (one image row's pixels) in blocks of this many. Blocks of 16 took 1.015x the
#: cone and cylinder walks' CPU of 64 at 64x48 (one ray a pixel: a span is at most 64 rays);
#: 256 and 1024 read as 64 there (0.98-1.00x) and keep the spans of larger images whole
#: (docs/study.md, "Roots first").
STAGE_BLOCK = 256


@inline
def _no_shares(row, params):
    return 0.0


@inline
def _unweighted(row, params, shares):
    return 1.0


def walker(fam, weight=None, key=None, one_origin=True):
    """The compiled walker of family ``fam`` (a technique's ``compiled`` declaration,
    :class:`~psurf_core.techniques.base.Compiled`) with the MIS weight ``weight`` (a
    :class:`.mis.Weight` from :func:`.mis.weight_of`; None: no MIS). ``key``
    names ``weight`` (equal keys: the same function), so each walker is built once per
    process. ``one_origin``: every ray starts at the walker's ``origin`` argument (a pinhole
    camera's rays, ``Rays.origin``); else each ray's own origin is read."""
    k = (id(fam), key, one_origin)
    if k not in _WALKERS:
        # ``fam`` is kept with its walker: while it lives, no other record can take its id
        # (a record built on the fly, then freed, would otherwise hand its id and walker on).
        _WALKERS[k] = (fam, _build(fam, weight, one_origin))
    return _WALKERS[k][1]


def _build(fam, weight, one_origin):
    Geometry, n_roots, staged = fam.geometry, fam.n_roots, fam.staged
    block = STAGE_BLOCK  # captured: a cached walker is keyed by it (.cache)
    roots, accept, visibility = fam.roots, fam.accept, fam.visibility
    contribution, reconstruct = fam.contribution, fam.reconstruct
    mis = weight is not None
    shares_of, w_of = weight if mis else (_no_shares, _unweighted)

    @kernel(nogil=True)
    def walk(i0, i1, s_prim, s_row, s_c0, s_c1, width, cs, rt, rid, origin, geom, short,
             medium, blockers, photon, kk, px, pw, pt, lights, params, emit,
             o_ray, o_prim, o_s, o_hit, o_val, o_w, o_st, n, lim,
             a_ray, a_val, na, img, to_img):  # pragma: no cover - compiled
        """Hits of spans ``i0 .. i1 - 1`` (module docstring); full rows from ``n`` (up to
        ``lim``); without ``emit``, the weighted values added to ``img[ray]`` where
        ``to_img``, else compact rows from ``na``. Returns the next free full and compact
        rows and the number of hits (occluded ones included: every hit is shaded)."""
        n_hits = 0
        # Passed to the shadow test at every hit: without its reference count (.views).
        shadow = borrowed(blockers)
        # The photons' arrays, read by ``photon_row`` at every primitive of an MIS set:
        # passed there with their counts, they were 6 atomic increfs a primitive on the
        # arrays both threads share (``benchmarks/walk_ir.py paper-multi``).
        paths = borrowed((px, pw, pt))
        # With one origin for every ray, the origin the twins see is the same value at every
        # pair: LLVM then moves what depends on it alone out of the loop (a plane's check
        # that the ray starts where Create computed its solver vectors, ``cached_solve``)
        # and computes the solve that ``roots`` and ``accept`` share once (read from each
        # ray, the check's branch stays at every pair and the solve is done twice: with
        # ``cached_solve``'s ``m0`` read for any origin, the ``planes`` walker took 1.15x the
        # CPU time, docs/study.md, "One origin for the plane walkers").
        o0 = (origin[0], origin[1], origin[2])
        # A staged walk's roots of one block of rays, those inside their ray's interval.
        keep_k = np.empty(block * n_roots if staged else 0, np.int64)
        keep_s = np.empty(block * n_roots if staged else 0)
        i = i0
        while i < i1:
            # One primitive's spans are consecutive (one per image row): its geometry and,
            # for the MIS weight, the photon's path row are read once for all of them (one
            # call site of the inlined ``photon_row``: each site costs its typing again).
            p = s_prim[i]
            G = load(geom, p, Geometry)
            if mis:
                base = photon_row(paths[0], paths[1], paths[2], lights, photon[p], kk[p],
                                  medium.sigma_t, medium.g)
                # Which members can produce this photon's path, and their shares: the
                # same for all of the primitive's hits.
                shares = shares_of(base, params)
            else:  # (unread: typed as anything)
                base = shares = 0.0
            j_end = i + 1
            while j_end < i1 and s_prim[j_end] == p:
                j_end += 1
            for i_span in range(i, j_end):
                base_px = s_row[i_span] * width
                k, k1 = cs[base_px + s_c0[i_span]], cs[base_px + s_c1[i_span]]
                while k < k1:
                    if staged:
                        # The roots of a block of the span's rays first, those inside their
                        # ray's interval kept without a branch, then the kept ones shaded
                        # (:attr:`Compiled.staged`).
                        m = 0
                        k_end = min(k + block, k1)
                        for kr in range(k, k_end):
                            ray = load(rt, kr, RayRow)
                            rts = roots(G, o0 if one_origin else ray.o, ray.psi)
                            for j in range(n_roots):
                                s = rts[j]
                                keep_k[m] = kr
                                keep_s[m] = s
                                m += np.int64((s > ray.s_min) & (s < ray.s_max))
                        k = k_end
                    else:  # one ray's roots, tested below with a branch (the plane families)
                        m = n_roots
                        ray = load(rt, k, RayRow)
                        rts = roots(G, o0 if one_origin else ray.o, ray.psi)
                        k += 1
                    # One body for both ways: ``staged`` is a constant of the closure, so numba
                    # drops the other branch as it compiles. (The hit's work in an inline
                    # function called from two loops took 1.58x the CPU: numba counts the
                    # references of its array arguments at every call.)
                    for q in range(m):
                        if staged:
                            kr = keep_k[q]
                            s = keep_s[q]
                            ray = load(rt, kr, RayRow)
                        else:
                            kr = k - 1
                            s = rts[q]
                            if not (s > ray.s_min and s < ray.s_max):  # NaN: no root
                                continue
                        o = o0 if one_origin else ray.o
                        ok, hit = accept(G, o, ray.psi, s, short)
                        if not ok:
                            continue
                        n_hits += 1
                        x0 = madd(o, s, ray.psi)
                        st = visibility(G, x0, hit, medium, shadow)
                        if st[0] == BLOCKED or st[1] == BLOCKED or st[2] == BLOCKED:
                            scal = 0.0
                        else:
                            scal = contribution(G, ray.psi, s, ray.s_min, hit, short, medium)
                        w = 1.0
                        # A blocked hit added to the image adds nothing: its weight is needed
                        # only where the hit itself is kept (emit).
                        if mis and (emit or scal != 0.0):
                            row = at_hit(base, o, ray.psi, s)
                            w = w_of(reconstruct(row, G, hit), params, shares)
                        if emit:
                            if n >= lim:  # cannot happen: lim is the candidates x roots bound
                                raise RuntimeError("walker: output capacity exceeded")
                            o_ray[n] = rid[kr]
                            o_prim[n] = p
                            o_s[n] = s
                            store(o_hit, n, hit)
                            for c in range(3):
                                o_val[n, c] = G.beta[c] * scal
                                o_st[n, c] = st[c]
                            o_w[n] = w
                            n += 1
                        elif scal != 0.0 and to_img:
                            r = rid[kr]
                            for c in range(3):
                                img[r, c] += (G.beta[c] * scal) * w
                        elif scal != 0.0:
                            a_ray[na] = rid[kr]
                            for c in range(3):
                                a_val[na, c] = (G.beta[c] * scal) * w
                            na += 1
            i = j_end
        return n, na, n_hits

    return walk


@kernel
def accumulate(out, a_ray, a_val, starts, ends):  # pragma: no cover - compiled
    """``out[a_ray[h]] += a_val[h]`` for the compact rows ``starts[j] .. ends[j] - 1`` of
    every piece ``j``, in order (so the sums do not depend on the thread count)."""
    for j in range(starts.shape[0]):
        for h in range(starts[j], ends[j]):
            r = a_ray[h]
            for c in range(3):
                out[r, c] += a_val[h, c]
