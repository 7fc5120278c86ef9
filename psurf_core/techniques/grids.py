"""Sweep grids: points sampling the surface a primitive sweeps, for drawing it (numpy only).

Every family with a surface provides ``Technique.surface_grid(prims, idx, far)``: an
``(M, nu, nv, 3)`` grid per primitive ``idx`` (a parametric patch, unclipped; a long
primitive's unbounded extent stops at ``far``), built in its own module from the helpers
here. The UI meshes the grids (``ui.views.primitives_view``); it knows no family.
"""

from __future__ import annotations

import numpy as np


def lengths(T: np.ndarray | None, m: int, far: float) -> np.ndarray:
    """(M,) extents: ``T`` (a short primitive's sampled flight), or ``far`` (``T`` None)."""
    return np.full(m, far) if T is None else np.asarray(T, float)


def frame(axis: np.ndarray):
    """(M, 3) unit vectors ``e1, e2`` completing unit ``axis`` to an orthonormal frame."""
    a = axis / np.linalg.norm(axis, axis=1, keepdims=True)
    helper = np.where(np.abs(a[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
    e1 = np.cross(a, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    return e1, np.cross(a, e1)


def ring(e1: np.ndarray, e2: np.ndarray, n: int) -> np.ndarray:
    """(M, n, 3) ``cos ph e1 + sin ph e2`` for ``n`` angles ``ph`` from 0 to 2 pi."""
    ph = np.linspace(0, 2 * np.pi, n)
    return np.cos(ph)[None, :, None] * e1[:, None] + np.sin(ph)[None, :, None] * e2[:, None]


def rotate(v: np.ndarray, axis: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Rodrigues: rotate (M, 3) ``v`` about unit (M, 3) ``axis`` by every angle of ``phi``.

    Returns (M, len(phi), 3).
    """
    c, s = np.cos(phi)[None, :, None], np.sin(phi)[None, :, None]
    v_, a = v[:, None, :], axis[:, None, :]
    return (v_ * c + np.cross(a, v_) * s
            + a * np.sum(a * v_, axis=-1, keepdims=True) * (1.0 - c))


def revolve(x2: np.ndarray, A3: np.ndarray, curve: np.ndarray, n: int = 36) -> np.ndarray:
    """(M, K, n, 3) the curve ``x2 + curve[:, k]`` (M, K, 3) revolved about the axis
    ``(x2, A3)``."""
    ph = np.linspace(0, 2 * np.pi, n)
    A = A3 / np.linalg.norm(A3, axis=1, keepdims=True)
    P = np.stack([rotate(curve[:, i], A, ph) for i in range(curve.shape[1])], axis=1)
    return x2[:, None, None, :] + P


def ruled(origin, dirs, length) -> np.ndarray:
    """(M, 2, nb, 3) grid ``origin + t dirs`` for ``t`` in ``{0, length}`` (straight
    generators along ``dirs`` (M, nb, 3))."""
    o = origin[:, None, None, :]
    t = np.stack([np.zeros_like(length), length], axis=1)[:, :, None, None]
    return o + t * dirs[:, None, :, :]


def parallelograms(origin, u, v, tu, tv) -> np.ndarray:
    """(M, 2, 2, 3) corners ``origin + a tu u + b tv v``, ``a, b`` in ``{0, 1}``."""
    a = np.array([0.0, 1.0])
    return (origin[:, None, None, :] + (a[None, :, None, None] * tu[:, None, None, None])
            * u[:, None, None, :] + (a[None, None, :, None] * tv[:, None, None, None])
            * v[:, None, None, :])


def sphere(centre, radius, axis=None, theta_max=None, nt=14, nph=28) -> np.ndarray:
    """(M, nt, nph, 3) the sphere (or the cap ``theta <= theta_max`` about ``axis``)."""
    m = centre.shape[0]
    axis = np.tile([0.0, 0.0, 1.0], (m, 1)) if axis is None else axis
    e1, e2 = frame(axis)
    tmax = np.full(m, np.pi) if theta_max is None else theta_max
    th = np.linspace(0, 1, nt)[None, :] * tmax[:, None]  # (M, nt)
    ph = np.linspace(0, 2 * np.pi, nph)
    around = (np.cos(ph)[None, None, :, None] * e1[:, None, None]
              + np.sin(ph)[None, None, :, None] * e2[:, None, None])
    dirs = (np.cos(th)[:, :, None, None] * axis[:, None, None, :]
            + np.sin(th)[:, :, None, None] * around)
    return centre[:, None, None, :] + radius[:, None, None, None] * dirs


def cone(apex, axis, c, length, nph=36) -> np.ndarray:
    """(M, 2, nph, 3) the nappe of half-angle ``acos c`` about ``axis``, out to ``length``."""
    e1, e2 = frame(axis)
    s = np.sqrt(np.clip(1.0 - c * c, 0.0, None))
    ph = np.linspace(0, 2 * np.pi, nph)
    dirs = (c[:, None, None] * axis[:, None, :]
            + s[:, None, None] * (np.cos(ph)[None, :, None] * e1[:, None]
                                  + np.sin(ph)[None, :, None] * e2[:, None]))
    return ruled(apex, dirs, length)


def half_disk(apex, axis, er, length, theta_max, nth=20) -> np.ndarray:
    """(M, 2, nth, 3) the sector ``theta <= theta_max`` from ``axis`` towards ``er``, out to
    ``length``."""
    th = np.linspace(0, 1, nth)[None, :] * theta_max[:, None]
    dirs = np.cos(th)[:, :, None] * axis[:, None, :] + np.sin(th)[:, :, None] * er[:, None, :]
    return ruled(apex, dirs, length)
