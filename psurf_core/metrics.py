"""Error metrics against a reference image: relative MSE per pixel and over the image.

``relMSE = mean over pixels and channels of (I - R)^2 / (R^2 + EPS mean(R)^2)``: the
``EPS`` term keeps near-black reference pixels from dominating (``psurf_core.study``).
"""

from __future__ import annotations

import numpy as np

#: Weight of the squared image mean in the relMSE denominator.
RELMSE_EPS = 1e-2


def _den(ref: np.ndarray, eps: float) -> np.ndarray:
    ref = np.asarray(ref, dtype=np.float64)
    m = float(np.mean(ref))
    return ref**2 + eps * m * m


def relmse_map(img: np.ndarray, ref: np.ndarray, eps: float = RELMSE_EPS) -> np.ndarray:
    """(H, W) per-pixel relative squared error, averaged over channels.

    ``(img - ref)^2 / (ref^2 + eps * mean(ref)^2)``; 0 where both the numerator and the
    denominator are 0 (an all-black reference and image).
    """
    img = np.asarray(img, dtype=np.float64)
    num = (img - np.asarray(ref, dtype=np.float64)) ** 2
    den = _den(ref, eps)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(den > 0, num / np.where(den > 0, den, 1.0), np.where(num > 0, np.inf, 0.0))
    return r.mean(axis=-1)


def relmse(img: np.ndarray, ref: np.ndarray, eps: float = RELMSE_EPS) -> float:
    """Scalar relMSE: the mean of :func:`relmse_map` (module docstring)."""
    return float(np.mean(relmse_map(img, ref, eps)))


def _var_ratio(var_of_mean: np.ndarray, ref: np.ndarray, eps: float) -> np.ndarray:
    den = _den(ref, eps)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den > 0, var_of_mean / np.where(den > 0, den, 1.0), 0.0)


def var_relmse(var_of_mean: np.ndarray, ref: np.ndarray, eps: float = RELMSE_EPS) -> float:
    """The relMSE's noise part: the mean of ``var / (R^2 + eps mean(R)^2)`` over pixels and
    channels (0 where the denominator is 0), for the variance ``var_of_mean`` of an image."""
    return float(np.mean(_var_ratio(var_of_mean, ref, eps)))


def relative_weight(ref: np.ndarray, eps: float = RELMSE_EPS) -> np.ndarray:
    """(H, W, 3): the weight a relMSE gives each pixel's and channel's squared error,
    ``1 / (R^2 + eps mean(R)^2)`` (0 where that is 0), for weighting variances alike
    (``pass_size.split_variances``)."""
    return _var_ratio(np.ones_like(np.asarray(ref, dtype=np.float64)), ref, eps)


def var_relmse_map(var_of_mean: np.ndarray, ref: np.ndarray,
                   eps: float = RELMSE_EPS) -> np.ndarray:
    """(H, W): :func:`var_relmse` per pixel, averaged over channels (where in the image the
    relMSE's noise sits; ``benchmarks/relvar_deciles.py``)."""
    return _var_ratio(var_of_mean, ref, eps).mean(axis=-1)
