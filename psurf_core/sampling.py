"""Samplers paired with their pdfs (as Nori's warps): phase functions, emission, distances.

Every sampler is vectorized: it takes uniform variates of shape ``(N,)`` (or draws them from
a ``numpy.random.Generator``) and returns ``(N, ...)`` arrays. Directions are unit vectors.
The phase convention is the spec's: ``mu`` is the cosine between the propagation directions
before and after scattering.
"""

from __future__ import annotations

import numpy as np

from .constants import HG_ISOTROPIC_G
from .kernels.jit import twin

INV_4PI = 1.0 / (4.0 * np.pi)


# --------------------------------------------------------------------------- frames
def orthonormal_basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors completing ``n`` to a right-handed frame (Duff et al. 2017).

    Parameters
    ----------
    n : (N, 3) float
        Unit vectors.

    Returns
    -------
    b1, b2 : (N, 3) float
        ``b1 x b2 = n``.
    """
    n = np.asarray(n, dtype=float)
    sign = np.where(n[..., 2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + n[..., 2])
    b = n[..., 0] * n[..., 1] * a
    b1 = np.stack([1.0 + sign * n[..., 0] ** 2 * a, sign * b, -sign * n[..., 0]], axis=-1)
    b2 = np.stack([b, sign + n[..., 1] ** 2 * a, -n[..., 1]], axis=-1)
    return b1, b2


def direction_about(axis: np.ndarray, cos_theta: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Unit direction at polar cosine ``cos_theta`` and azimuth ``phi`` about ``axis``.

    Parameters
    ----------
    axis : (N, 3) float
        Unit axes.
    cos_theta, phi : (N,) float

    Returns
    -------
    (N, 3) float
    """
    b1, b2 = orthonormal_basis(axis)
    sin_theta = np.sqrt(np.clip(1.0 - cos_theta**2, 0.0, None))
    return (
        (sin_theta * np.cos(phi))[:, None] * b1
        + (sin_theta * np.sin(phi))[:, None] * b2
        + cos_theta[:, None] * axis
    )


# --------------------------------------------------------------------------- phase
def phase_value(mu: np.ndarray, g: float) -> np.ndarray:
    """Henyey-Greenstein ``rho(mu)`` (1/sr); isotropic ``1/(4 pi)`` when ``g = 0``."""
    mu = np.asarray(mu, dtype=float)
    if g == 0.0:
        return np.full(mu.shape, INV_4PI)
    mu = np.clip(mu, -1.0, 1.0)
    # 1 + g^2 - 2 g mu written as a sum of non-negative terms: the textbook form cancels to
    # 0 (an infinite rho, then NaN) at mu = +-1 when |g| is within ~1e-8 of 1.
    if g > 0.0:
        denom = (1.0 - g) ** 2 + 2.0 * g * (1.0 - mu)
    else:
        denom = (1.0 + g) ** 2 - 2.0 * g * (1.0 + mu)
    return INV_4PI * ((1.0 - g) * (1.0 + g)) / (denom * np.sqrt(denom))


@twin(phase_value)
def _phase_value(mu, g):
    """``phase_value`` of one cosine (NaN stays NaN)."""
    if g == 0.0:
        return INV_4PI
    mu = min(max(mu, -1.0), 1.0) if mu == mu else mu
    if g > 0.0:
        denom = (1.0 - g) ** 2 + 2.0 * g * (1.0 - mu)
    else:
        denom = (1.0 + g) ** 2 - 2.0 * g * (1.0 + mu)
    return INV_4PI * ((1.0 - g) * (1.0 + g)) / (denom * np.sqrt(denom))


def sample_phase_cos(g: float, u: np.ndarray) -> np.ndarray:
    """Sample ``mu`` with density ``2 pi rho(mu)`` on [-1, 1] (spec section 1)."""
    u = np.asarray(u, dtype=float)
    if abs(g) < HG_ISOTROPIC_G:
        return 1.0 - 2.0 * u
    sq = (1.0 - g * g) / (1.0 - g + 2.0 * g * u)
    return np.clip((1.0 + g * g - sq * sq) / (2.0 * g), -1.0, 1.0)


def sample_phase(w_in: np.ndarray, g: float, rng: np.random.Generator) -> np.ndarray:
    """Scatter propagation directions ``w_in`` (N, 3); pdf ``rho(w_in . w_out)`` per sr."""
    n = w_in.shape[0]
    mu = sample_phase_cos(g, rng.random(n))
    return direction_about(w_in, mu, 2.0 * np.pi * rng.random(n))


# --------------------------------------------------------------------------- sphere/hemisphere
def sample_uniform_sphere(rng: np.random.Generator, n: int) -> np.ndarray:
    """Uniform unit directions, pdf ``1/(4 pi)``."""
    z = 1.0 - 2.0 * rng.random(n)
    phi = 2.0 * np.pi * rng.random(n)
    r = np.sqrt(np.clip(1.0 - z * z, 0.0, None))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1)


def sample_cosine_hemisphere(normal: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Cosine-weighted directions about ``normal`` (N, 3); pdf ``cos / pi``."""
    n = normal.shape[0]
    cos_theta = np.sqrt(rng.random(n))  # p(cos) = 2 cos
    return direction_about(normal, cos_theta, 2.0 * np.pi * rng.random(n))


def cosine_hemisphere_pdf(cos_theta: np.ndarray) -> np.ndarray:
    """Solid-angle pdf ``max(cos, 0) / pi``."""
    return np.clip(cos_theta, 0.0, None) / np.pi


# --------------------------------------------------------------------------- distances
def sample_free_flight(sigma_t: float, rng: np.random.Generator, n: int) -> np.ndarray:
    """Distances with pdf ``sigma_t exp(-sigma_t t)``."""
    return -np.log1p(-rng.random(n)) / sigma_t


def free_flight_pdf(sigma_t: float, t: np.ndarray) -> np.ndarray:
    return sigma_t * np.exp(-sigma_t * np.asarray(t, dtype=float))


# --------------------------------------------------------------------------- surfaces
def sample_triangle_barycentric(rng: np.random.Generator, n: int) -> np.ndarray:
    """Uniform barycentric ``(u, v)`` with ``u, v >= 0, u + v <= 1``; pdf 2 on that triangle.

    Returns
    -------
    (N, 2) float
    """
    su = np.sqrt(rng.random(n))
    r2 = rng.random(n)
    return np.stack([1.0 - su, r2 * su], axis=-1)


def sample_discrete(pmf: np.ndarray, rng: np.random.Generator, n: int) -> np.ndarray:
    """Indices drawn with probabilities ``pmf`` (K,).

    Returns
    -------
    (n,) intp
        One variate consumed per index, also when ``K = 1`` (always index 0: the search
        below would return ``0`` or be clamped to it), so the generator's stream is the same.
    """
    if len(pmf) == 1:
        rng.random(n)
        return np.zeros(n, dtype=np.intp)
    cdf = np.cumsum(pmf)
    cdf /= cdf[-1]
    return np.minimum(np.searchsorted(cdf, rng.random(n), side="right"), len(pmf) - 1)
