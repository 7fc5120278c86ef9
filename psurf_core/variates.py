"""The two transcendental maps of Trace's variates, in ``+ - * /`` only: the cosine and sine of
an azimuth ``2 pi u`` (:func:`cos_sin_turn`) and the exponential variate ``-log(1 - u)``
(:func:`neg_log_complement`).

Why not ``np.cos``, ``np.sin`` and ``np.log1p``: Trace's compiled path must return the numpy
reference's arrays bit for bit (``tests/test_trace_reference.py``), and numba's ``cos`` is not
numpy's (numpy picks SIMD code paths by CPU), so the compiled path used to leave these to
numpy, in three extra passes over every depth's variates handed out to threads: 28 % of a
Trace batch on 2026-12-04. Written as a range reduction and a polynomial, each map is a
sequence of exactly rounded operations that numpy (vectorized, here) and numba (the scalar
twins in :mod:`psurf_core.variates_compiled`, in the same order, no fused multiply-add)
round alike, so the compiled path computes them inside its per-photon loop.

Accuracy: within a few units in the last place of ``cos``/``sin``/``-log1p(-u)`` for
``u`` in ``[0, 1)`` (``tests/test_variates.py``); Monte Carlo needs far less, but directions
must stay unit vectors to rounding.
"""

from __future__ import annotations

import numpy as np

#: ``pi / 2`` rounded: the reduced argument is ``f * HALF_PI`` with ``|f| <= 1/2``.
HALF_PI = 1.5707963267948966
#: Minimax coefficients of ``sin x = x + x^3 (S1 + x^2 S2 + ...)`` and
#: ``cos x = 1 - x^2/2 + x^4 (C1 + x^2 C2 + ...)`` on ``|x| <= pi/4`` (fdlibm's ``k_sin.c``,
#: ``k_cos.c``): error below 1e-16 there.
SIN_COEFFS = (-1.66666666666666324348e-01, 8.33333333332248946124e-03,
              -1.98412698298579493134e-04, 2.75573137070700676789e-06,
              -2.50507602534068634195e-08, 1.58969099521155010221e-10)
COS_COEFFS = (4.16666666666666019037e-02, -1.38888888888741095749e-03,
              2.48015872894767294178e-05, -2.75573143513906633035e-07,
              2.08757232129817482790e-09, -1.13596475577881948265e-11)
#: ``log 2`` rounded, and ``sqrt(1/2)``, the lower end of the reduced mantissa.
LN2 = 0.6931471805599453
SQRT_HALF = 0.7071067811865476
#: Minimax coefficients of ``log m = 2 s + s z (L1 + z L2 + ...)``, ``s = (m-1)/(m+1)``,
#: ``z = s^2``, for ``m`` in ``[sqrt(1/2), sqrt 2)`` (fdlibm's ``e_log.c``, ``Lg1..Lg7``;
#: ``L_k`` is close to ``2 / (2k + 1)``).
LOG_COEFFS = (6.666666666666735130e-01, 3.999999999940941908e-01, 2.857142874366239149e-01,
              2.222219843214978396e-01, 1.818357216161805012e-01, 1.531383769920937332e-01,
              1.479819860511658591e-01)


def _estrin6(z, z2, z4, c):
    """``c0 + c1 z + ... + c5 z^5`` as ``(c0 + z c1) + z^2 (c2 + z c3) + z^4 (c4 + z c5)``:
    three independent pairs instead of Horner's chain of five (the twins' order)."""
    return (c[0] + z * c[1]) + z2 * (c[2] + z * c[3]) + z4 * (c[4] + z * c[5])


def cos_sin_turn(u):
    """Cosine and sine of the azimuth ``phi = 2 pi u``.

    ``4 u`` is split into the nearest quarter turn ``q`` and ``f = 4u - q`` in
    ``[-1/2, 1/2]`` (both exact); ``x = f pi/2``, ``cos x`` and ``sin x`` are polynomials,
    rotated by ``k = q mod 4`` quarter turns: swapped for odd ``k``, signs flipped by
    multiplying with ``+-1``. All of it in floating point (``k`` too, exactly) and without a
    branch, so that the twin's loop vectorizes.

    Parameters
    ----------
    u : (M,) float
        Turns (``[0, 1)``: a uniform variate).

    Returns
    -------
    cos_phi, sin_phi : (M,) float
    """
    v = 4.0 * np.asarray(u, dtype=float)
    q = np.floor(v + 0.5)
    x = (v - q) * HALF_PI
    z = x * x
    z2 = z * z
    z4 = z2 * z2
    s = x + x * (z * _estrin6(z, z2, z4, SIN_COEFFS))
    c = (1.0 - 0.5 * z) + z2 * _estrin6(z, z2, z4, COS_COEFFS)
    k = q - 4.0 * np.floor(q * 0.25)
    odd = (k == 1.0) | (k == 3.0)
    cos_sign = np.where((k == 1.0) | (k == 2.0), -1.0, 1.0)
    sin_sign = np.where(k >= 2.0, -1.0, 1.0)
    return np.where(odd, s, c) * cos_sign, np.where(odd, c, s) * sin_sign


def neg_log_complement(u):
    """``-log(1 - u)``: an exponential variate of rate 1 from a uniform ``u``.

    ``1 - u = m 2^e`` (``frexp``, the mantissa moved into ``[sqrt(1/2), sqrt 2)``), and
    ``log m`` from the series in ``s = (m - 1)/(m + 1)``. ``1 - u`` is exact for numpy's
    variates (multiples of ``2^-53``) and ``m - 1`` is exact, so small ``u`` keep their
    relative accuracy as with ``log1p``.

    Parameters
    ----------
    u : (M,) float
        ``[0, 1)``.

    Returns
    -------
    (M,) float
        ``>= 0``.
    """
    m, e = np.frexp(1.0 - np.asarray(u, dtype=float))
    low = m < SQRT_HALF
    m = np.where(low, m * 2.0, m)
    e = np.where(low, e - 1, e).astype(np.float64)
    s = (m - 1.0) / (m + 1.0)
    z = s * s
    z2 = z * z
    c = LOG_COEFFS
    p = (c[0] + z * c[1]) + z2 * (c[2] + z * c[3]) + (z2 * z2) * (c[4] + z * (c[5] + z * c[6]))
    log_m = 2.0 * s + s * (z * p)
    return 0.0 - (e * LN2 + log_m)  # 0 - (...): +0.0 at u = 0, as -log1p(-0.0)
