"""Running a technique's walker over a pass: spans, chunks, threads and buffers.

:func:`fused_pass` is what :func:`psurf_core.render.photon_pass` calls for a technique with a
compiled declaration (``Technique.compiled``). It

1. computes the candidate pixel spans binning would walk (hull polygons clipped and
   projected, :func:`.spans.hull_spans`, or the screen rectangles), and the ray table;
2. cuts them into chunks within the memory budget (what the walk's rows take,
   :meth:`_Run.chunk_pairs`) and a large chunk into a fixed number of pieces for threads
   (:mod:`.threads`, :data:`CHUNK_PIECES`) whose hits are put back in span order and whose
   weighted values go to an image per piece, added in piece order (or to compact rows added
   in order), so hits, their order and the image do not depend on the thread count;
3. runs the walker (:mod:`.walk`) with the MIS weight of the technique's set composed in
   (:mod:`.mis`) where every member has a compiled density, and its shadow tests against
   every blocker, triangle meshes included (:mod:`.shadow`, :mod:`.mesh_bvh`).

With ``emit`` it yields every hit (:class:`~psurf_core.techniques.base.Hits` with the
technique's hit records, per-photon values and, where compiled, MIS weights: what the UI,
breakdowns and the numpy MIS fallback read); without, it adds the weighted values to the
per-ray sums directly and materializes no hits.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from ..binning import _spans, chunk_bounds_cum, screen_rects
from ..constants import BYTES_PER_PAIR
from ..interrupt import check
from ..memo import memo
from ..records import dtype_of, flat, widths
from ..scene import medium_row
from ..techniques.base import Hits
from .buffers import HitBuffers
from .jit import ctrl_c_kept, kernel
from .mis import member_params, weight_of
from .rays import ray_table
from .shadow import shadow_args
from .spans import _pairs_of, counted_spans
from .threads import guided_fractions, on_threads, thread_count
from .walk import accumulate, walker

#: Candidate pairs from which a chunk is shared among threads (below, handing the work out
#: costs more than it saves: ~20k pairs are ~2 ms of work).
THREADED_MIN_PAIRS = 20_000

#: Most bytes of output rows a chunk of a walk may take. A walk needs at most ``n_roots`` full
#: rows (:meth:`_Run.full_fields`, ~100 bytes) a candidate pair, not the numpy stages'
#: ``BYTES_PER_PAIR`` (1200) that ``max_pairs`` counts, so it is chunked by what its rows
#: take, within the memory budget and this cap (emitting or not: a chunk's cut decides the
#: bits of its image, see :data:`CHUNK_PIECES`): a ``planes`` pass at 64x48 with 5000
#: photons is one chunk instead of two (docs/study.md, "Each piece its own image").
CHUNK_BYTES = 128 << 20

#: Pieces a chunk of at least ``THREADED_MIN_PAIRS`` candidate pairs is cut into (by
#: candidate pairs, at :data:`CHUNK_CUT`: large pieces first), handed to whichever thread is
#: free. Where the image is small beside the chunk (:meth:`_Run.walk_chunk`), each piece
#: adds its hits to an image of its own (the first piece to the pass's), and those are added
#: to the pass's in piece order: the image's bits depend on the cut, so the cut is fixed,
#: never the thread count, and a pass that emits its hits adds them the same way
#: (:meth:`_Run.finish`).
CHUNK_PIECES = 12
#: Where the pieces of a chunk end, as fractions of its candidate pairs
#: (:func:`~.threads.guided_fractions`; fixed, so that the image's bits are).
CHUNK_CUT = guided_fractions(CHUNK_PIECES)

_BUFFERS = HitBuffers()


@dataclass
class MisSet:
    """The MIS set a technique's hits are weighted in.

    Attributes
    ----------
    group : tuple of Technique
        The members that are on.
    full_group : tuple of Technique
        The set the kernels are compiled for (``group`` is a subset: ``SPEC~A`` runs
        ``SPEC``'s kernels with ``A`` switched off).
    weighting : str or None
        ``"balance"`` or ``"power"``.
    shares : (J,) float, optional
        Per member of ``full_group``: the share of the batch's photons it swept (0: off);
        default 1 for the members of ``group``.
    """

    group: tuple
    full_group: tuple
    weighting: str | None
    shares: np.ndarray | None = None

    def share_array(self) -> np.ndarray:
        if self.shares is not None:
            return np.ascontiguousarray(self.shares, dtype=float)
        on = {id(m) for m in self.group}
        return np.array([1.0 if id(m) in on else 0.0 for m in self.full_group])


def fused_pass(tech, prims, paths, rays, ctx, mis: MisSet | None = None, emit: bool = True,
               out: np.ndarray | None = None, stats: dict | None = None,
               add_emitted: bool = False):
    """Find, evaluate and weight every hit of ``prims`` (``tech``'s primitives) with
    ``rays`` in compiled code, or return None where it does not apply (the technique has no
    compiled declaration; 64 or fewer pixels see medium, binning's per-pixel branch; the
    blockers carry no bounds): the caller then runs the stages.

    Parameters
    ----------
    mis : MisSet, optional
        The technique's MIS set; None for a technique alone.
    emit : bool
        Yield the hits (see below). Without it, ``out`` (R, 3) receives the weighted
        per-photon sums per ray.
    add_emitted : bool
        With ``emit`` and ``out``: also add the emitted hits' final values (weighted, or a
        technique alone) to ``out``, in the order the walker adds them without ``emit``, so
        that a pass that reads its hits gives the bits of one that does not.
    stats : dict, optional
        Receives ``candidates`` (ray-primitive pairs walked) and ``hits`` (hits evaluated,
        blocked ones included), added to what it holds (``benchmarks/``).

    Returns
    -------
    iterator of (Hits, (H, 3) values, (H,) weights or None), or None
        ``emit``: the hits of every chunk with their per-photon values before the MIS weight
        and the weights (None where the set has no compiled weight: the caller computes
        them). Without ``emit``: an iterator yielding nothing, to be exhausted.
    """
    fam = getattr(tech, "compiled", None)
    if fam is None:
        return None
    blk = shadow_args(ctx.blockers)
    if blk is None:
        return None
    cs, rt, rid = ray_table(rays, ctx.scene.camera.n_pixels)
    if memo(rays, "pixels with medium", lambda: np.count_nonzero(np.diff(cs))) <= 64:
        return None
    w, key, shares = None, None, np.ones((1, 2))
    if mis is not None:
        me = next(j for j, m in enumerate(mis.full_group) if m is tech)
        w, key = weight_of(mis.full_group, me, mis.weighting)
        shares = member_params(mis.full_group, mis.share_array())
    # One origin for the walk where the family gains from it (``Compiled.one_origin``).
    origin = common_origin(rays) if fam.one_origin else None
    run = _Run(tech, fam, walker(fam, w, key, origin is not None), prims, paths, rays, ctx,
               blk, cs, rt, rid, origin, shares, weighted=w is not None,
               emit=emit or (w is None and mis is not None))
    run.stats = stats
    run.add_emitted = add_emitted and (w is not None or mis is None)
    return _kept(run.chunks(out))


def common_origin(rays):
    """(3,) float: the origin every ray starts at (``Rays.origin``, a pinhole camera's
    position, checked against the rays' own), or None when they differ (each walker then
    reads every ray's own: :func:`.walk.walker`'s ``one_origin``)."""
    if rays.origin is None:
        return None
    origin = np.ascontiguousarray(rays.origin, dtype=float)
    same = memo(rays, "one origin", lambda: bool(np.all(rays.o == origin)))
    return origin if same else None


def _kept(it):
    """``it`` with Ctrl-C kept a KeyboardInterrupt (a SIGINT handled while numba boxes a
    result surfaces as a SystemError caused by it; ``render --checkpoint`` must see it)."""
    with ctrl_c_kept():
        yield from it


class _Run:
    """One technique's walk over one batch of primitives (see :func:`fused_pass`)."""

    def __init__(self, tech, fam, walk, prims, paths, rays, ctx, blk, cs, rt, rid, origin,
                 shares, weighted, emit):
        self.tech, self.fam, self.walk = tech, fam, walk
        self.prims, self.paths, self.rays, self.ctx = prims, paths, rays, ctx
        self.cs, self.rid, self.emit = cs, rid, emit
        self.weighted = weighted  # the walker computes the MIS weights
        self.add_emitted = False  # see fused_pass
        c = np.ascontiguousarray
        # The photons' light records are read by the MIS weight alone (``photon_row``): a
        # technique alone, or a set weighted by the caller, gets none (building the table
        # took ~0.24 ms of a 17 ms ``planes`` pass at 64x48).
        lights = _photon_lights(paths, ctx.scene) if weighted else _NO_LIGHTS
        # The walker's constant arguments after the span range (its signature, in order).
        origin = np.zeros(3) if origin is None else origin  # (unread: rays' own origins)
        self.const = (int(ctx.scene.camera.width), cs, flat(rt), rid, origin,
                      flat(prims.data), bool(tech.short), medium_row(ctx.scene.medium), blk,
                      c(prims.photon, np.int64), c(prims.K, np.int64), c(paths.x, float),
                      c(paths.w, float), c(paths.t, float), lights, shares, emit)

    def spans(self):
        """The candidate spans ``(prim, row, c0, c1)`` (None: none), the candidate pairs
        before each (None where not counted with them: :func:`.spans.counted_spans`) and
        their columns."""
        cam, med = self.ctx.scene.camera, self.ctx.scene.medium
        box = (med.bounds_min, med.bounds_max)
        prims, width = self.prims, int(cam.width)
        if prims.hull is not None:
            return counted_spans(cam, prims.lo, prims.hi, prims.hull,
                                 prims.clip_box(self.ctx.scene), self.cs, width)
        if prims.cloud is not None:
            return counted_spans(cam, prims.lo, prims.hi, prims.cloud, box, self.cs, width,
                                 cloud=True)
        x0, x1, y0, y1 = screen_rects(cam, prims.lo, prims.hi)
        return _spans(cam, x0, x1, y0, y1, None, box, self.ctx.max_pairs), None, 0

    def chunks(self, out):
        if len(self.prims) == 0:
            return
        spans, before, columns = self.spans()
        if spans is None or spans[0].size == 0:
            return
        spans = tuple(np.ascontiguousarray(a, np.int64) for a in spans)
        s_prim, s_row, s_c0, s_c1 = spans
        # Chunks as binning's (pixels x the most rays in a pixel, within the chunk's pairs).
        per_pix = memo(self.rays, "most rays in a pixel",
                       lambda: max(int(np.diff(self.cs).max()), 1))
        most = self.chunk_pairs()
        if before is None:
            before, slots = spans_before(self.cs, s_row, s_c0, s_c1,
                                         int(self.ctx.scene.camera.width), per_pix)
            bounds = chunk_bounds_cum(slots[1:], most)
        elif columns * per_pix <= most:
            bounds = [0, s_row.size]
        else:
            bounds = chunk_bounds_cum(np.cumsum((s_c1 - s_c0) * per_pix), most)
        threads = thread_count()
        for a, b in zip(bounds[:-1], bounds[1:], strict=True):
            check()  # a held Ctrl-C (interrupt.held): between chunks
            n_cand = int(before[b] - before[a])
            th = threads if n_cand >= THREADED_MIN_PAIRS else 1
            res = self.walk_chunk(spans, before, a, b, th, out)
            if self.stats is not None:
                st = self.stats
                st["candidates"] = st.get("candidates", 0) + n_cand
                st["hits"] = st.get("hits", 0) + res["n_hits"]
            if res["compact_rows"]:
                accumulate(out, *res["compact"])
            if res["n_full"]:
                yield from self.finish(res, out)

    def chunk_pairs(self) -> int:
        """Candidate pairs a chunk may hold: what the memory budget and :data:`CHUNK_BYTES`
        hold of the walk's full rows (the same whether it emits them or not), at least
        binning's ``max_pairs``."""
        row = self.fam.n_roots * sum(np.dtype(t).itemsize * k for t, k in self.full_fields())
        budget = min(self.ctx.max_pairs * BYTES_PER_PAIR, CHUNK_BYTES)
        return max(self.ctx.max_pairs, budget // row)

    def walk_chunk(self, spans, before, a, b, threads, out=None):
        """Run the walker over spans ``a .. b - 1`` on ``threads`` threads: in
        :data:`CHUNK_PIECES` pieces, large first, cut at :data:`CHUNK_CUT` of its candidate
        pairs (one below ``THREADED_MIN_PAIRS``), each writing its own region of the
        outputs. Without ``emit``, where the pieces' images hold fewer cells than the
        chunk's compact rows would (``to_img``; so on all but large images), each piece adds
        its hits to its own image (the first to ``out``), added to ``out`` in order; else to
        compact rows.
        ``before``: (S + 1,) the candidate pairs before each span (:func:`spans_before`)."""
        # Candidate pairs before each span of the chunk: the pieces' cut and their row ranges.
        base = int(before[a])
        total = int(before[b]) - base
        if total < THREADED_MIN_PAIRS:
            cut = [a, b]
        else:
            # As integers (the first span whose pairs before reach the float cut: the same):
            # numpy's search of int64 for float keys converts the array, ~60 us a pass.
            at = np.ceil(base + total * CHUNK_CUT[1:-1]).astype(np.int64)
            cut = np.unique(np.concatenate(
                [[a], a + np.searchsorted(before[a + 1:b + 1], at), [b]])).tolist()
        off = ((before[np.asarray(cut)] - base) * self.fam.n_roots).astype(np.int64)
        pieces = len(cut) - 1
        n_rays = len(self.rays)
        to_img = (pieces - 1) * n_rays <= int(off[-1])
        use_img = to_img and not self.emit and out is not None
        rows = 0 if self.emit or use_img else int(off[-1])
        full = _BUFFERS.take("full", self.full_fields(), int(off[-1]) if self.emit else 0)
        compact = _BUFFERS.take("compact", _COMPACT, rows)
        own = pieces - 1 if use_img else 0
        images = _BUFFERS.take("images", _IMAGE, own * n_rays)[0].reshape(-1, n_rays, 3)
        ends = np.zeros((pieces, 3), np.int64)
        nowhere = np.zeros((0, 3))

        def piece(j):
            n0 = off[j] if self.emit else 0
            na0 = off[j] if rows else 0
            lim = off[j + 1] if self.emit else 0
            img = nowhere
            if use_img:
                img = out if j == 0 else images[j - 1]
                if j:
                    img.fill(0.0)
            ends[j] = self.walk(cut[j], cut[j + 1], *spans, *self.const, *full, n0, lim,
                                *compact, na0, img, use_img)

        on_threads(piece, pieces, threads)
        add_images(out, images)
        n_full = int((ends[:, 0] - (off[:-1] if self.emit else 0)).sum())
        return dict(full=full, compact=(compact[0], compact[1], off[:-1].copy(), ends[:, 1]),
                    full_ranges=(off[:-1] if self.emit else np.zeros(pieces, np.int64),
                                 ends[:, 0]), n_full=n_full, n_hits=int(ends[:, 2].sum()),
                    to_img=to_img, n_rays=n_rays, compact_rows=bool(rows) and out is not None)

    def full_fields(self):
        """The full rows' fields (:data:`_FULL_HEAD`, the hit record, :data:`_FULL_TAIL`),
        built once a family: every chunk asks (``records.widths`` reads the record's fields
        in Python: ~0.07 ms of a 17 ms ``planes`` pass when built each time)."""
        return _full_fields(self.fam.hit)

    def finish(self, res, out):
        """The full rows of a chunk (``emit``) as Hits, pieces closed up in order; with
        ``add_emitted``, their weighted values also go to ``out``."""
        starts, ends = res["full_ranges"]
        cols = [np.concatenate([f[s:e] for s, e in zip(starts, ends, strict=True)])
                if len(starts) > 1 else f[starts[0]:ends[0]] for f in res["full"]]
        ray, prim, s, hit, val, wts, st = cols
        hits = Hits(ray, prim, s, hit.view(np.float64).view(
            dtype_of(self.fam.hit)).reshape(-1).view(np.recarray))
        yield hits, val, wts if self.weighted else None
        if out is not None and self.add_emitted:
            # As the walk without emit adds them (np.add.at adds one row after another, as
            # the walker and accumulate do): each piece to its own image where the walk
            # would (the first to ``out``), those to ``out`` in order; so the image does not
            # depend on emit.
            v = val * (wts[:, None] if self.weighted else 1.0)
            if not res["to_img"]:
                np.add.at(out, ray, v)
                return
            at = np.concatenate([[0], np.cumsum(ends - starts)])
            np.add.at(out, ray[at[0]:at[1]], v[at[0]:at[1]])
            for j in range(1, len(starts)):
                img = np.zeros((res["n_rays"], 3))
                np.add.at(img, ray[at[j]:at[j + 1]], v[at[j]:at[j + 1]])
                out += img


def add_images(out, images) -> None:
    """``out += images[j]`` for every piece's own image ``j`` ((P, R, 3)), in order: the
    image's bits depend on the cut alone (:data:`CHUNK_PIECES`). One core; 7 images of a
    64x48 image are ~50 us, a chunk's compact rows ~1 ms (docs/study.md, "Each piece its own
    image")."""
    for img in images:
        out += img


@kernel
def spans_before(cs, s_row, s_c0, s_c1, width, per_pix):  # pragma: no cover - compiled
    """What comes before each span, in one loop over them (the per-span gathers, then numpy's
    sums, products and concatenations of them, took ~0.5 ms of a 17 ms ``planes`` pass at
    64x48 on one core, between its spans and its walk: docs/study.md, "Where a ``planes``
    pass goes"):

    Returns
    -------
    before : (S + 1,) int64
        Candidate ray-primitive pairs of spans ``0 .. i - 1``, a span's the rays of its
        pixels ``cs[row * width + c1] - cs[row * width + c0]``.
    slots : (S + 1,) int64
        The same of binning's chunk sizes, ``(c1 - c0) * per_pix``.
    """
    n = s_row.shape[0]
    before = np.empty(n + 1, np.int64)
    slots = np.empty(n + 1, np.int64)
    before[0] = 0
    slots[0] = 0
    for i in range(n):
        before[i + 1] = before[i] + _pairs_of(cs, width, s_row[i], s_c0[i], s_c1[i])
        slots[i + 1] = slots[i] + (s_c1[i] - s_c0[i]) * per_pix
    return before, slots


@functools.cache
def _full_fields(hit) -> tuple:
    """:meth:`_Run.full_fields` of a family whose hit record is ``hit``."""
    return (*_FULL_HEAD, (np.float64, sum(widths(hit))), *_FULL_TAIL)


#: Full rows: ray, prim (int64), s; [the hit record]; value (3), weight, statuses (3 int8).
_FULL_HEAD = ((np.int64, 1), (np.int64, 1), (np.float64, 1))
_FULL_TAIL = ((np.float64, 3), (np.float64, 1), (np.int8, 3))
#: Compact rows: ray (int64), weighted value (3).
_COMPACT = ((np.int64, 1), (np.float64, 3))
#: A piece's own image: per ray, the weighted values' sum (3).
_IMAGE = ((np.float64, 3),)


#: The photon table of a walk that reads none (:class:`_Run`).
_NO_LIGHTS = np.zeros((0, 1))


def _photon_lights(paths, scene):
    from ..path_record import photon_table

    return flat(photon_table(paths, scene))


