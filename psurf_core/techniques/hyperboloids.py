"""Hyperboloid ``[t1, ph2]`` (spec 3.3, first row; K >= 2).

The photon keeps everything up to ``x2`` (tracer vertex ``K-2``), its flight ``T2`` and its
last direction ``w1``; it integrates the azimuth ``ph2`` of ``w2`` about ``A3`` and the
distance ``t1``. ``x0 = x2 + R(ph2) (T2 w2 + t1 w1)`` sweeps the ray ``x1 + t w1`` revolved
about the axis ``(x2, A3)``: a one-sheet hyperboloid (a cone if the ray meets the axis). With
``p = y(s) - x2``, ``q0 = T2 w2``: equal heights ``p . A3 = (q0 + t w1) . A3`` (linear) and
equal radii about the axis (quadratic) give at most two roots; the photon's subpath is then
revolved onto the hit (:mod:`.revolutions`). The scaled normal is ``n = w1* x (A3 x d2)``,
``d2 = x0 - x2``.

``X = beta_1^- (1/2pi) E(t1*) ss rho0 E(s*) / |n . psi|`` (the spec's
``beta_2 (1/2pi)(ss/st) ...``: ``p(ph2)`` is not in ``q`` and ``E(T2)/p(T2) ss`` makes
``beta_1^-``); short: ``t1* < T1``, drop ``E(t1*)``.

``Q = q_{<=w2} 2pi p(t2) p(w1) |n . psi|`` (``p(c2) = 2pi p(w2)``: the azimuth ``ph2`` is
integrated); short: ``* E(t1)``.

Each numpy function has its compiled twin (``@twin``) beneath it; see :mod:`.cones`. The
hit record, shadow segments and Reconstruct are the revolutions' (:mod:`.revolutions`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..kernels.jit import twin
from ..kernels.vec import madd, scale, sub
from ..path_record import revolution_axis
from ..records import Vec, table
from . import grids
from .base import Compiled, Primitives, Technique, clip_bounds, cross, dot
from .cones import contribution  # the same X: (1/2pi) [E(t1*)] ss rho0 E(s*) / |n . psi|
from .revolutions import RevolutionHit, reconstruct, revolved, segments, visibility
from .surface_common import (
    NDP_MIN,
    beta1,
    gather,
    q_to_w2,
    quadratic_roots,
    select_photons,
)


class HyperboloidGeometry(NamedTuple):
    """One hyperboloid (a row of its ``Primitives.data``)."""

    x2: Vec  # a point of the axis: the photon's vertex x2
    A3: Vec  # the axis direction (w3, or the light's axis / normal)
    w2: Vec  # the photon's w2 (before revolving)
    w1: Vec  # the photon's w1: the revolved ray's direction
    T2: float  # the photon's flight from x2
    T1: float  # the photon's flight from x1 (the short hyperboloid's extent)
    beta: Vec  # beta_1^- (W)


# ------------------------------------------------------------------------- geometry
def scaled_normal(w1, A3, d2):
    """(H, 3) ``dx0/dt1 x dx0/dph2 = w1 x (A3 x d2)`` (up to sign), ``d2 = x0 - x2``."""
    return cross(w1, cross(A3, d2))


@twin(scaled_normal)
def _scaled_normal(w1, A3, d2):
    return cross(w1, cross(A3, d2))


# ------------------------------------------------------------------------- Intersect
def solve(G, o, psi):
    """``(s, t)``, each (2, N): the ray distances and ray parameters ``t1`` of the candidate
    roots (NaN: none), in ``u = s - sc`` about the ray point closest to ``x2``.

    Equal heights fix one unknown linearly in the other and equal radii then give a
    quadratic; it is solved in the unknown whose height rate is the larger (``t(u)`` if
    ``|w1 . A| >= |psi . A|``, else ``u(t)``: spec 3.3, better conditioned).
    """
    A, w1 = G.A3, G.w1
    q = G.T2[:, None] * G.w2
    sc = dot(G.x2 - o, psi)
    b = o + sc[:, None] * psi - G.x2  # P(u) = b + u psi

    def perp(v):
        return v - dot(v, A)[:, None] * A

    bA, pA, qA, dA = dot(b, A), dot(psi, A), dot(q, A), dot(w1, A)
    bp, pp, qp, dp = perp(b), perp(psi), perp(q), perp(w1)
    by_u = np.abs(dA) >= np.abs(pA)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        al, ga = (bA - qA) / dA, pA / dA  # t = al + ga u
        m, n = qp + al[:, None] * dp, ga[:, None] * dp
        r_u = quadratic_roots(dot(pp, pp) - dot(n, n), dot(bp, pp) - dot(m, n),
                              dot(bp, bp) - dot(m, m))
        al2, ga2 = (qA - bA) / pA, dA / pA  # u = al2 + ga2 t
        m2, n2 = bp + al2[:, None] * pp, ga2[:, None] * pp
        r_t = quadratic_roots(dot(n2, n2) - dot(dp, dp), dot(m2, n2) - dot(qp, dp),
                              dot(m2, m2) - dot(qp, qp))
        u = np.where(by_u, r_u, al2 + ga2 * r_t)
        t = np.where(by_u, al + ga * r_u, r_t)
    return sc + u, t


@twin(solve)
def _solve(G, o, psi):
    A, w1 = G.A3, G.w1
    q = scale(G.T2, G.w2)
    sc = dot(sub(G.x2, o), psi)
    b = sub(madd(o, sc, psi), G.x2)
    bA, pA, qA, dA = dot(b, A), dot(psi, A), dot(q, A), dot(w1, A)
    bp, pp = sub(b, scale(bA, A)), sub(psi, scale(pA, A))
    qp, dp = sub(q, scale(qA, A)), sub(w1, scale(dA, A))
    if abs(dA) >= abs(pA):
        al, ga = (bA - qA) / dA, pA / dA
        m, n = madd(qp, al, dp), scale(ga, dp)
        r0, r1 = quadratic_roots(dot(pp, pp) - dot(n, n), dot(bp, pp) - dot(m, n),
                                 dot(bp, bp) - dot(m, m))
        return (sc + r0, sc + r1), (al + ga * r0, al + ga * r1)
    al2, ga2 = (qA - bA) / pA, dA / pA
    m2, n2 = madd(bp, al2, pp), scale(ga2, pp)
    r0, r1 = quadratic_roots(dot(n2, n2) - dot(dp, dp), dot(m2, n2) - dot(qp, dp),
                             dot(m2, m2) - dot(qp, qp))
    return (sc + (al2 + ga2 * r0), sc + (al2 + ga2 * r1)), (r0, r1)


def roots(G, o, psi):
    """(2, N) ray distances of the candidate roots (:func:`solve`)."""
    return solve(G, o, psi)[0]


@twin(roots)
def _roots(G, o, psi):
    return solve(G, o, psi)[0]


def accept(G, o, psi, s, short):
    """Hits: ``t1* > 0`` (``< T1`` if short), the photon's subpath revolved onto ``y(s)``
    (:func:`~.revolutions.revolved`), not grazing; their records (:class:`RevolutionHit`).

    ``t1*`` is the solve's own value at the root ``s`` (the slot whose ``s`` is nearest):
    recomputing it from ``s`` would lose the conditioning :func:`solve` chose.
    """
    ss, ts = solve(G, o, psi)
    d0, d1 = np.abs(ss[0] - s), np.abs(ss[1] - s)
    t = np.where((d1 < d0) | np.isnan(d0), ts[1], ts[0])
    with np.errstate(invalid="ignore"):
        ok = (t > 0) & (t < np.inf)
        if short:
            ok &= t < G.T1
    P = o + s[:, None] * psi - G.x2
    with np.errstate(invalid="ignore", over="ignore"):  # rows already rejected: t = NaN
        landed, w2, w1 = revolved(G.A3, G.T2, G.w2, G.w1, t, P)
        ndp = np.abs(dot(scaled_normal(w1, G.A3, P), psi))
        ok &= landed & (ndp > NDP_MIN) & np.isfinite(ndp)
    return ok, table(RevolutionHit, t1=t, w2=w2, w1=w1, n_dot_psi=ndp)


@twin(accept)
def _accept(G, o, psi, s, short):
    ss, ts = solve(G, o, psi)
    d0, d1 = abs(ss[0] - s), abs(ss[1] - s)
    t = ts[1] if (d1 < d0 or np.isnan(d0)) else ts[0]
    ok = t > 0.0 and t < np.inf and (not short or t < G.T1)
    P = sub(madd(o, s, psi), G.x2)
    landed, w2, w1 = revolved(G.A3, G.T2, G.w2, G.w1, t, P)
    ndp = abs(dot(scaled_normal(w1, G.A3, P), psi))
    return ok and landed and ndp > NDP_MIN and np.isfinite(ndp), RevolutionHit(t, w2, w1, ndp)


# ------------------------------------------------------------------------- Evaluate
# segments and visibility: the surfaces of revolution's (.revolutions); contribution: the
# cone's (.cones), the same X.


# ------------------------------------------------------------------------- MIS
def density(rec, short):
    """Relative ``Q = q_{<=w2} 2pi p(t2) p(w1) |n . psi|`` (short: ``* E(t1)``)."""
    n = scaled_normal(rec.w1, revolution_axis(rec), rec.x0 - rec.x2)
    q = q_to_w2(rec) * 2.0 * np.pi * rec.pdf.t2 * rec.pdf.w1 * np.abs(dot(n, rec.psi))
    return q * rec.pdf.e1 if short else q


@twin(density, weight=True)
def _density(rec, short):
    n = scaled_normal(rec.w1, revolution_axis(rec), sub(rec.x0, rec.x2))
    q = q_to_w2(rec) * 2.0 * np.pi * rec.pdf.t2 * rec.pdf.w1 * abs(dot(n, rec.psi))
    return q * rec.pdf.e1 if short else q


# ------------------------------------------------------------------------- drawing
def surface_grid(G, short, far):
    """(M, 2, 36, 3) the generator ``x2 + T2 w2 + t w1``, ``t <= T1`` (short) or ``far``,
    revolved about ``(x2, A3)``: the drawing's sweep grid (:mod:`.grids`)."""
    t1 = grids.lengths(G.T1 if short else None, len(G), far)
    v0 = G.T2[:, None] * G.w2
    v1 = v0 + t1[:, None] * G.w1
    return grids.revolve(G.x2, G.A3, np.stack([v0, v1], axis=1))


# ------------------------------------------------------------------------- Create
class Hyperboloid(Technique):
    """The hyperboloid ``[t1, ph2]``; ``short`` restricts ``t1* < T1``."""

    family = "revolutions"
    min_k = 2
    compiled = Compiled(HyperboloidGeometry, RevolutionHit, 2, roots, accept, visibility,
                        contribution, segments, reconstruct, density, staged=True)

    names = ("hyperboloid", "hyperboloid-short")
    grid = staticmethod(surface_grid)

    def create(self, paths, ctx) -> Primitives:
        photon, K = select_photons(self, paths, ctx, back=2)
        g = gather(paths, photon, K)
        x2, q0 = g["x2"], g["T2"][:, None] * g["w2"]
        if self.short:  # every point is within max(|q0|, |q0 + T1 w1|) of x2 (convexity)
            r = np.maximum(g["T2"], np.linalg.norm(q0 + g["T1"][:, None] * g["w1"], axis=1))
            lo, hi = x2 - r[:, None], x2 + r[:, None]
        else:  # unbounded: the whole box
            lo, hi = np.full_like(x2, -np.inf), np.full_like(x2, np.inf)
        lo, hi = clip_bounds(ctx.scene, lo, hi)
        return Primitives(self.name, photon, K, lo, hi, table(
            HyperboloidGeometry, x2=x2, A3=g["A3"], w2=g["w2"], w1=g["w1"], T2=g["T2"],
            T1=g["T1"], beta=beta1(paths, photon, K)))

    def scaled_normal(self, rec):
        """(H, 3) scaled normal on records ``rec`` (the inspector's)."""
        return scaled_normal(rec.w1, rec.A3, rec.x0 - rec.x2)
