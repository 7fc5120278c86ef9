"""The compiled twins of :mod:`psurf_core.variates` (same names, the same IEEE operations in
the same order on scalars): compiled code calling ``variates.cos_sin_turn`` or
``variates.neg_log_complement`` runs these (:func:`psurf_core.kernels.jit.twin`)."""

from __future__ import annotations

import math

import numpy as np

from . import variates as ref
from .kernels.jit import twin

_S = ref.SIN_COEFFS
_C = ref.COS_COEFFS
_L = ref.LOG_COEFFS


@twin(ref.cos_sin_turn, inline=True)  # inlined: its callers' loops vectorize
def cos_sin_turn(u):  # pragma: no cover - compiled
    v = 4.0 * u
    q = np.floor(v + 0.5)
    x = (v - q) * ref.HALF_PI
    z = x * x
    z2 = z * z
    z4 = z2 * z2
    ps = (_S[0] + z * _S[1]) + z2 * (_S[2] + z * _S[3]) + z4 * (_S[4] + z * _S[5])
    pc = (_C[0] + z * _C[1]) + z2 * (_C[2] + z * _C[3]) + z4 * (_C[4] + z * _C[5])
    s = x + x * (z * ps)
    c = (1.0 - 0.5 * z) + z2 * pc
    k = q - 4.0 * np.floor(q * 0.25)
    odd = k == 1.0 or k == 3.0
    cos_sign = -1.0 if (k == 1.0 or k == 2.0) else 1.0
    sin_sign = -1.0 if k >= 2.0 else 1.0
    return (s if odd else c) * cos_sign, (c if odd else s) * sin_sign


@twin(ref.neg_log_complement, inline=True)
def neg_log_complement(u):  # pragma: no cover - compiled
    m, e = math.frexp(1.0 - u)
    if m < ref.SQRT_HALF:
        m, e = m * 2.0, e - 1
    s = (m - 1.0) / (m + 1.0)
    z = s * s
    z2 = z * z
    p = ((_L[0] + z * _L[1]) + z2 * (_L[2] + z * _L[3])
         + (z2 * z2) * (_L[4] + z * (_L[5] + z * _L[6])))
    log_m = 2.0 * s + s * (z * p)
    return 0.0 - (np.float64(e) * ref.LN2 + log_m)
