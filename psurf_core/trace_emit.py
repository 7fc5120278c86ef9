"""Trace's emission, numpy reference: where photons start and which way they leave.

The samplers of :mod:`psurf_core.sampling` written from their variates (the caller draws the
random numbers, computes ``cos``/``sin`` of the azimuths with
:func:`psurf_core.variates.cos_sin_turn`, and passes them), so that each has a
compiled scalar twin of the same name in :mod:`psurf_core.trace_emit_compiled` with the same
operations in the same order; and :func:`emit`, which draws the variates of a batch and
applies them. ``direction_about`` also scatters photons at every later vertex
(:mod:`psurf_core.trace`).
"""

from __future__ import annotations

import numpy as np

from . import sampling
from .photon_sampler import uniforms
from .scene import AreaLight, MeshLight, PointLight, Scene
from .variates import cos_sin_turn


def direction_about(axis, cos_theta, cos_phi, sin_phi):
    """Unit directions at polar cosine ``cos_theta`` about unit ``axis``, azimuth given by
    its cosine and sine, in ``sampling.orthonormal_basis``'s frame (as
    ``sampling.direction_about``).

    Parameters
    ----------
    axis : (M, 3) float
    cos_theta, cos_phi, sin_phi : (M,) float

    Returns
    -------
    (M, 3) float
    """
    b1, b2 = sampling.orthonormal_basis(axis)
    sin_theta = np.sqrt(np.clip(1.0 - cos_theta * cos_theta, 0.0, None))
    return ((sin_theta * cos_phi)[:, None] * b1 + (sin_theta * sin_phi)[:, None] * b2
            + cos_theta[:, None] * axis)


def uniform_direction(u_z, cos_phi, sin_phi):
    """Uniform unit directions (pdf ``1/(4 pi)``, ``sampling.sample_uniform_sphere``):
    ``z = 1 - 2 u_z``, ``(r cos phi, r sin phi, z)`` with ``r = sqrt(1 - z^2)``.

    Parameters
    ----------
    u_z, cos_phi, sin_phi : (M,) float

    Returns
    -------
    (M, 3) float
    """
    z = 1.0 - 2.0 * u_z
    r = np.sqrt(np.clip(1.0 - z * z, 0.0, None))
    return np.stack([r * cos_phi, r * sin_phi, z], axis=-1)


def cosine_direction(normal, u_c, cos_phi, sin_phi):
    """Cosine-weighted directions about unit ``normal`` (pdf ``cos / pi``,
    ``sampling.sample_cosine_hemisphere``: ``cos_theta = sqrt(u_c)``).

    Parameters
    ----------
    normal : (M, 3) float
    u_c, cos_phi, sin_phi : (M,) float

    Returns
    -------
    (M, 3) float
    """
    return direction_about(normal, np.sqrt(u_c), cos_phi, sin_phi)


def parallelogram_point(corner, edge_u, edge_v, u):
    """Points ``corner + u0 edge_u + u1 edge_v`` (scene units).

    Parameters
    ----------
    corner, edge_u, edge_v : (3,) float
    u : (M, 2) float

    Returns
    -------
    (M, 3) float
    """
    return corner + u[:, :1] * edge_u + u[:, 1:] * edge_v


def triangle_point(tri, u_s, u_r):
    """Uniform points on triangles (``sampling.sample_triangle_barycentric``): barycentric
    ``(1 - sqrt(u_s), u_r sqrt(u_s))`` and ``v0 + b0 (v1 - v0) + b1 (v2 - v0)``.

    Parameters
    ----------
    tri : (M, 3, 3) float
        Vertices ``v0, v1, v2`` of each photon's triangle.
    u_s, u_r : (M,) float

    Returns
    -------
    bary : (M, 2) float
    x : (M, 3) float
    """
    su = np.sqrt(u_s)
    bary = np.stack([1.0 - su, u_r * su], axis=-1)
    v0 = tri[:, 0]
    return bary, v0 + bary[:, :1] * (tri[:, 1] - v0) + bary[:, 1:] * (tri[:, 2] - v0)


def search_right(cdf, u):
    """``numpy.searchsorted(cdf, u, side="right")``: the first index whose entry exceeds ``u``.

    Parameters
    ----------
    cdf : (K,) float
        Non-decreasing.
    u : (M,) float

    Returns
    -------
    (M,) intp
    """
    return np.searchsorted(cdf, u, side="right")


def emit(scene: Scene, rng: np.random.Generator, n: int) -> dict:
    """Sample ``n`` photon emissions (light chosen proportional to power).

    Draws, in this order: one variate per photon for the light; then per light in scene
    order, for its ``m`` photons: point ``2m`` (cosine, azimuth), area ``4m`` (``u, v`` per
    photon, cosine^2, azimuth), mesh ``m`` (triangle) then ``4m`` (two barycentric,
    cosine^2, azimuth).

    Returns
    -------
    dict of (n, ...) arrays
        ``light, light_pmf, light_uv, tri, light_normal, x0, w1, beta`` (``PhotonPaths``'
        fields; ``x0`` the light points, ``w1`` the first directions, ``beta`` the emitted
        weights, W).
    """
    pmf = scene.light_pmf
    light = _discrete(pmf, rng, n)
    x0, w1, normal, beta = (np.zeros((n, 3)) for _ in range(4))
    uv = np.zeros((n, 2))
    tri = np.full(n, -1, dtype=np.int64)
    for li, lt in enumerate(scene.lights):
        sel = np.flatnonzero(light == li)
        m = sel.size
        if m == 0:
            continue
        beta[sel] = lt.power_rgb / pmf[li]
        if isinstance(lt, PointLight):
            r = uniforms(rng, 2, m, rows=sel)
            x0[sel], normal[sel] = lt.position, lt.axis
            w1[sel] = uniform_direction(r[:m], *cos_sin_turn(r[m:]))
        elif isinstance(lt, AreaLight):
            r = uniforms(rng, 4, m, pairs=True, rows=sel)
            nl = np.broadcast_to(lt.normal, (m, 3))
            uv[sel] = r[: 2 * m].reshape(m, 2)
            x0[sel] = parallelogram_point(lt.corner, lt.edge_u, lt.edge_v, uv[sel])
            normal[sel] = nl
            w1[sel] = cosine_direction(nl, r[2 * m : 3 * m], *cos_sin_turn(r[3 * m :]))
        elif isinstance(lt, MeshLight):
            k = _discrete(lt.areas / lt.area, rng, m, sel)
            r = uniforms(rng, 4, m, rows=sel)
            tri[sel] = k
            uv[sel], x0[sel] = triangle_point(lt.triangles[k], r[:m], r[m : 2 * m])
            normal[sel] = lt.normals[k]
            w1[sel] = cosine_direction(normal[sel], r[2 * m : 3 * m],
                                       *cos_sin_turn(r[3 * m :]))
        else:  # pragma: no cover - the scene loader admits no other light
            raise TypeError(f"unknown light {lt!r}")
    return dict(light=light, light_pmf=pmf[light], light_uv=uv, tri=tri, light_normal=normal,
                x0=x0, w1=w1, beta=beta)


def _discrete(pmf, rng, n, rows=None):
    """``sampling.sample_discrete``: one variate per index, the index :func:`search_right`
    finds in the normalised cdf (clamped to the last; no search for one entry). (n,) intp."""
    u = uniforms(rng, 1, n, rows=rows, spare=len(pmf) == 1)
    if len(pmf) == 1:
        return np.zeros(n, dtype=np.intp)
    cdf = np.cumsum(pmf)
    cdf /= cdf[-1]
    return np.minimum(search_right(cdf, u), len(pmf) - 1)
