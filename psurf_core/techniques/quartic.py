"""Real roots of quartics on ``[-1, 1]`` (the torus, spec 3.3), in numpy and compiled alike.

The roots are isolated, not eigen-solved: the roots of the second derivative (a quadratic,
closed form) cut ``[-1, 1]`` into pieces on which the first derivative is monotone; its root
in each piece (:func:`bracketed_root`) cuts ``[-1, 1]`` into at most four pieces on which the
quartic is monotone, and each piece where it changes sign holds exactly one root, found the
same way. :func:`bracketed_root` is Newton's method kept inside a shrinking bracket (a step
that would leave it bisects instead), for a fixed number of steps, so the numpy reference
(all pairs at once, ``numpy.where`` for the branches) and its compiled twin (one pair, early
exit only where the result is NaN anyway) do the same operations in the same order, with no
allocation per pair. Roots converge to the last bits (``u`` within a few ulps); a root of
even multiplicity (the ray tangent to the torus, measure zero) has no sign change and is
not reported.
"""

from __future__ import annotations

import numpy as np

from ..kernels.jit import twin
from .surface_common import quadratic_roots

#: Newton / bisection steps per root; Newton converges in ~6 from a bracket's midpoint, the
#: rest covers brackets where it starts far off and bisects (2^-40 of the interval).
ITERATIONS = 60

#: A root is done when its last step is below this (``u`` is in [-1, 1]: a few ulps).
TOL = 1e-14


def horner(c, x):
    """``c[0] x^n + ... + c[n]``: ``c`` the coefficients, highest degree first (rows of (N,)
    arrays broadcast against ``x``)."""
    v = c[0]
    for k in range(1, len(c)):
        v = v * x + c[k]
    return v


@twin(horner)
def _horner(c, x):
    v = c[0]
    for k in range(1, len(c)):
        v = v * x + c[k]
    return v


def bracketed_root(c, dc, a, b, iterations, tol=TOL):
    """The root in ``[a, b]`` of the polynomial ``c`` (derivative ``dc``), monotone there,
    where it changes sign; NaN where it does not. ``a, b`` broadcast against the
    coefficients (e.g. (P, N) pieces of N polynomials).

    Newton's steps kept in the shrinking bracket, bisecting where a step would leave it or
    would not halve the step before last (``rtsafe``); a root is done when it is exact or
    its last step is below ``tol``. Done roots leave the arrays (the twin stops there).
    """
    shape = np.broadcast_shapes(np.shape(a), np.shape(b), np.shape(c[0]))
    flat = [np.broadcast_to(v, shape).ravel() for v in (*c, *dc, a, b)]
    c, dc, (a, b) = flat[:len(c)], flat[len(c):-2], flat[-2:]
    fa, fb = horner(c, a), horner(c, b)
    neg = fa < 0
    out = np.full(a.size, np.nan)
    i = np.flatnonzero(neg != (fb < 0))  # a sign change: one root
    c, dc, a, b, neg = [v[i] for v in c], [v[i] for v in dc], a[i], b[i], neg[i]
    x = a - fa[i] * ((b - a) / (fb[i] - fa[i]))  # the secant's root: in [a, b]
    dx = dx_old = b - a
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for _ in range(iterations):
            fx, dfx = horner(c, x), horner(dc, x)
            left = (fx < 0) == neg  # the root lies right of x
            a, b = np.where(left, x, a), np.where(left, b, x)
            newton = x - fx / dfx
            bis = ~((newton > a) & (newton < b)) | (np.abs(2.0 * fx) > np.abs(dx_old * dfx))
            step = np.where(bis, 0.5 * (b - a), np.abs(fx / dfx))
            dx_old, dx = dx, step
            x = np.where(fx == 0, x, np.where(bis, 0.5 * (a + b), newton))
            done = (fx == 0) | (step < tol)
            out[i[done]] = x[done]
            k = ~done
            i, c, dc = i[k], [v[k] for v in c], [v[k] for v in dc]
            a, b, neg, x, dx, dx_old = a[k], b[k], neg[k], x[k], dx[k], dx_old[k]
            if not i.size:
                break
    out[i] = x  # (not done within ``iterations``)
    return out.reshape(shape)


@twin(bracketed_root)
def _bracketed_root(c, dc, a, b, iterations, tol=TOL):
    fa, fb = horner(c, a), horner(c, b)
    neg = fa < 0.0
    if neg == (fb < 0.0):
        return np.nan
    x = a - fa * ((b - a) / (fb - fa))
    dx = dx_old = b - a
    for _ in range(iterations):
        fx, dfx = horner(c, x), horner(dc, x)
        if (fx < 0.0) == neg:
            a = x
        else:
            b = x
        newton = x - fx / dfx
        bis = not (newton > a and newton < b) or abs(2.0 * fx) > abs(dx_old * dfx)
        step = 0.5 * (b - a) if bis else abs(fx / dfx)
        dx_old, dx = dx, step
        if fx == 0.0:
            break
        x = 0.5 * (a + b) if bis else newton
        if step < tol:
            break
    return x


def quartic_real_roots(coef, iterations=ITERATIONS):
    """Real roots in ``[-1, 1]`` of quartics ``c4 u^4 + ... + c0`` (see the module docstring).

    Parameters
    ----------
    coef : (5, N) float
        Coefficients, highest degree first (any of them may vanish).

    Returns
    -------
    (4, N) float
        Slot ``j``: the root in the ``j``-th monotone piece of ``[-1, 1]``, NaN where that
        piece holds none (or the coefficients are not finite, or all zero).
    """
    scale = np.max(np.abs(coef), axis=0)
    ok = np.isfinite(scale) & (scale > 0)
    c = coef / np.where(ok, scale, 1.0)
    d1 = (4.0 * c[0], 3.0 * c[1], 2.0 * c[2], c[3])
    d2 = (12.0 * c[0], 6.0 * c[1], 2.0 * c[2])
    r = quadratic_roots(d2[0], 3.0 * c[1], d2[2])
    z = np.where(np.isnan(r), 1.0, np.clip(r, -1.0, 1.0))
    one = np.ones(c.shape[1])
    edges = np.stack([-one, np.minimum(z[0], z[1]), np.maximum(z[0], z[1]), one])
    crit = bracketed_root(d1, d2, edges[:-1], edges[1:], iterations)  # d1 monotone between
    crit = np.where(np.isnan(crit), edges[1:], crit)
    edges = np.concatenate([-one[None], crit, one[None]])
    u = bracketed_root(c, d1, edges[:-1], edges[1:], iterations)  # the quartic monotone
    return np.where(ok, u, np.nan)


@twin(quartic_real_roots)
def _quartic_real_roots(coef, iterations=ITERATIONS):
    scale, finite = 0.0, True
    for k in range(5):
        v = abs(coef[k])
        finite = finite and np.isfinite(v)
        scale = max(scale, v)
    if not (finite and scale > 0.0):
        return np.nan, np.nan, np.nan, np.nan
    c = (coef[0] / scale, coef[1] / scale, coef[2] / scale, coef[3] / scale, coef[4] / scale)
    d1 = (4.0 * c[0], 3.0 * c[1], 2.0 * c[2], c[3])
    d2 = (12.0 * c[0], 6.0 * c[1], 2.0 * c[2])
    r0, r1 = quadratic_roots(d2[0], 3.0 * c[1], d2[2])
    z0 = 1.0 if np.isnan(r0) else min(max(r0, -1.0), 1.0)
    z1 = 1.0 if np.isnan(r1) else min(max(r1, -1.0), 1.0)
    e0, e1, e2, e3 = -1.0, min(z0, z1), max(z0, z1), 1.0
    k0 = bracketed_root(d1, d2, e0, e1, iterations)
    k1 = bracketed_root(d1, d2, e1, e2, iterations)
    k2 = bracketed_root(d1, d2, e2, e3, iterations)
    k0 = e1 if np.isnan(k0) else k0
    k1 = e2 if np.isnan(k1) else k1
    k2 = e3 if np.isnan(k2) else k2
    return (bracketed_root(c, d1, -1.0, k0, iterations), bracketed_root(c, d1, k0, k1, iterations),
            bracketed_root(c, d1, k1, k2, iterations), bracketed_root(c, d1, k2, 1.0, iterations))


def square_quadratic(c):
    """(5, N) coefficients (highest first) of the square of (3, N) quadratics."""
    a, b, e = c
    return np.stack([a * a, 2 * a * b, b * b + 2 * a * e, 2 * b * e, e * e])


@twin(square_quadratic)
def _square_quadratic(c):
    a, b, e = c
    return a * a, 2.0 * a * b, b * b + 2.0 * a * e, 2.0 * b * e, e * e
