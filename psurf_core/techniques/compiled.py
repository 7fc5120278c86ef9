"""What a technique family declares to the compiled machinery (:mod:`psurf_core.kernels`):
:class:`Compiled`, its records and the compiled twins of its numpy functions."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Compiled:
    """What a technique family gives the compiled machinery (:mod:`psurf_core.kernels`):
    its records and the compiled twins of its numpy functions (each twin has the name of
    the numpy function it mirrors and sits beside it in the family's module).

    Attributes
    ----------
    geometry, hit : type
        ``NamedTuple`` classes (:mod:`psurf_core.records`) of a row of ``Primitives.data``
        (with a ``beta`` field: the photon weight the contribution multiplies) and of
        ``Hits.data``.
    n_roots : int
        Candidate roots per ray and primitive.
    roots, accept, visibility, contribution : callable
        The family's numpy functions of Intersect and Evaluate, each with a compiled twin
        (see :mod:`psurf_core.kernels.walk` for what each returns).
    segments : callable
        ``segments(G, x0, hit) -> [(a, b), ...]``: the shadow segments of hits (numpy), in
        the order ``visibility`` tests them (for the exact mesh tests it defers).
    reconstruct, density : callable or None
        The full path of a hit and the family's MIS density, with compiled twins; None:
        its hits cannot be weighted in compiled code.
    short_ratio : callable or None
        ``short_ratio(rec)``: the short variant's density over the path's pdfs, which every
        member shares (its Jacobian and constants only; compiled twin); where every member
        of an MIS set has one and is short, the compiled weights use these
        (:mod:`psurf_core.kernels.mis`). None: the set weighs densities.
    one_origin : bool
        The walker reads the rays' common origin, not each ray's (a plane's cached camera
        solve gains; other families do not: :func:`psurf_core.kernels.walk.walker`).
    staged : bool
        The walker finds the roots of a block of rays first, keeps those inside their ray's
        medium interval without a branch, then accepts and shades the kept ones
        (:data:`psurf_core.kernels.walk.STAGE_BLOCK`). Where a pair's roots are a long
        chain (a square root and divisions), the interval test's branch, unpredictable
        (a quarter of the cones' and cylinders' pairs miss), kept the next pairs' roots waiting:
        staged, the cone and cylinder walks take 0.87x the CPU (``ss-cone`` 0.91x), the
        spheres' 0.76x and 0.90x (``ss-sphere``), the disks' 0.92x, the hyperboloids'
        0.97x, the tori's 0.99x. The plane families, whose roots are one cached division
        and whose pairs end mostly in ``accept``, took 1.05-1.13x staged and are not
        (docs/study.md, "Roots first").
    """

    geometry: type
    hit: type
    n_roots: int
    roots: object
    accept: object
    visibility: object
    contribution: object
    segments: object
    reconstruct: object = None
    density: object = None
    short_ratio: object = None
    one_origin: bool = False
    staged: bool = False
