"""Trace's emission, compiled: the twin of each formula of :mod:`psurf_core.trace_emit`
(same name, same IEEE operations in the same order; a (3,) vector is a 3-tuple), the
per-photon emission loops, and :func:`emit`, which draws exactly what ``trace_emit.emit``
draws (the azimuths' ``cos``/``sin`` by ``variates.cos_sin_turn``'s twin, in the loops).
"""

from __future__ import annotations

import numpy as np

from . import trace_buffers as buffers
from . import trace_emit as ref_emit
from . import (
    variates,
    variates_compiled,  # noqa: F401 - registers the twins the loops call
)
from .kernels.jit import kernel, twin
from .photon_sampler import uniforms
from .scene import AreaLight, MeshLight, PointLight


# --------------------------------------------------------------------------- twins
# Each is documented by the numpy function it twins (trace_emit.py), operation for operation.
@twin(ref_emit.direction_about)
def direction_about(axis, cos_theta, cos_phi, sin_phi):  # pragma: no cover - compiled
    a0, a1, a2 = axis
    sign = 1.0 if a2 >= 0.0 else -1.0  # sampling.orthonormal_basis (Duff et al.)
    a = -1.0 / (sign + a2)
    b = a0 * a1 * a
    b10, b11, b12 = 1.0 + sign * (a0 * a0) * a, sign * b, -sign * a0
    b20, b21, b22 = b, sign + (a1 * a1) * a, -a1
    s2 = 1.0 - cos_theta * cos_theta
    sin_theta = np.sqrt(s2 if s2 > 0.0 else 0.0)
    p = sin_theta * cos_phi
    q = sin_theta * sin_phi
    return (p * b10 + q * b20 + cos_theta * a0,
            p * b11 + q * b21 + cos_theta * a1,
            p * b12 + q * b22 + cos_theta * a2)


@twin(ref_emit.uniform_direction)
def uniform_direction(u_z, cos_phi, sin_phi):  # pragma: no cover - compiled
    z = 1.0 - 2.0 * u_z
    s2 = 1.0 - z * z
    r = np.sqrt(s2 if s2 > 0.0 else 0.0)
    return r * cos_phi, r * sin_phi, z


@twin(ref_emit.cosine_direction)
def cosine_direction(normal, u_c, cos_phi, sin_phi):  # pragma: no cover - compiled
    return ref_emit.direction_about(normal, np.sqrt(u_c), cos_phi, sin_phi)


@twin(ref_emit.parallelogram_point)
def parallelogram_point(corner, edge_u, edge_v, u):  # pragma: no cover - compiled
    return (corner[0] + u[0] * edge_u[0] + u[1] * edge_v[0],
            corner[1] + u[0] * edge_u[1] + u[1] * edge_v[1],
            corner[2] + u[0] * edge_u[2] + u[1] * edge_v[2])


@twin(ref_emit.triangle_point)
def triangle_point(tri, u_s, u_r):  # pragma: no cover - compiled
    v0, v1, v2 = tri  # 3-tuples
    su = np.sqrt(u_s)
    b0, b1 = 1.0 - su, u_r * su
    x = (v0[0] + b0 * (v1[0] - v0[0]) + b1 * (v2[0] - v0[0]),
         v0[1] + b0 * (v1[1] - v0[1]) + b1 * (v2[1] - v0[1]),
         v0[2] + b0 * (v1[2] - v0[2]) + b1 * (v2[2] - v0[2]))
    return (b0, b1), x


@twin(ref_emit.search_right)
def search_right(cdf, u):  # pragma: no cover - compiled
    # Bisection in numpy's order (NaN after every number); numpy's own search took ~170 ns
    # per random key here.
    lo, hi = 0, cdf.shape[0]
    while lo < hi:
        mid = (lo + hi) >> 1
        c = cdf[mid]
        if u < c or (c != c and u == u):
            hi = mid
        else:
            lo = mid + 1
    return lo


# --------------------------------------------------------------------------- emission
# Each kernel writes every field of its light's photons (rows ``rows[i]``, or ``i`` when the
# light emits all of them): x0, w1, light_normal, beta (W), light_uv, tri.
@kernel
def emit_point(rows, whole, u_z, u_phi, position, axis, beta_l, x0, w1, normal, beta, uv,
               tri):  # pragma: no cover - compiled
    """A point light's photons: its position, ``uniform_direction``, its axis as the normal.

    Parameters
    ----------
    rows : (M,) int
    whole : bool
    u_z, u_phi : (M,) float
        Variates of the polar cosine and the azimuth (turns: ``variates.cos_sin_turn``).
    position, axis, beta_l : (3,) float
        ``beta_l``: the light's power over its pick probability (W).
    x0, w1, normal, beta : (N, 3) float
    uv : (N, 2) float
    tri : (N,) int
        Written at the light's rows (``uv`` 0, ``tri`` -1).
    """
    for i in range(u_z.shape[0]):
        p = i if whole else rows[i]
        cp, sp = variates.cos_sin_turn(u_phi[i])
        w1[p, 0], w1[p, 1], w1[p, 2] = ref_emit.uniform_direction(u_z[i], cp, sp)
        for c in range(3):
            x0[p, c], normal[p, c], beta[p, c] = position[c], axis[c], beta_l[c]
        uv[p, 0] = uv[p, 1] = 0.0
        tri[p] = -1


@kernel
def emit_area(rows, whole, u, u_c, u_phi, corner, edge_u, edge_v, nl, beta_l, x0, w1, normal,
              beta, uv, tri):  # pragma: no cover - compiled
    """An area light's photons: ``parallelogram_point`` at ``u``, ``cosine_direction``
    about its normal ``nl``. Parameters as :func:`emit_point`; ``u`` (M, 2) float."""
    c, eu, ev = ((corner[0], corner[1], corner[2]), (edge_u[0], edge_u[1], edge_u[2]),
                 (edge_v[0], edge_v[1], edge_v[2]))
    n = (nl[0], nl[1], nl[2])
    for i in range(u.shape[0]):
        p = i if whole else rows[i]
        x0[p, 0], x0[p, 1], x0[p, 2] = ref_emit.parallelogram_point(c, eu, ev, (u[i, 0], u[i, 1]))
        cp, sp = variates.cos_sin_turn(u_phi[i])
        w1[p, 0], w1[p, 1], w1[p, 2] = ref_emit.cosine_direction(n, u_c[i], cp, sp)
        for k in range(3):
            normal[p, k], beta[p, k] = n[k], beta_l[k]
        uv[p, 0], uv[p, 1] = u[i, 0], u[i, 1]
        tri[p] = -1


@kernel
def emit_mesh(rows, whole, k, u_s, u_r, u_c, u_phi, triangles, normals, beta_l, x0, w1,
              normal, beta, uv, tri):  # pragma: no cover - compiled
    """A mesh light's photons: ``triangle_point`` on triangle ``k[i]``, ``cosine_direction``
    about its normal. Parameters as :func:`emit_point`; ``k`` (M,) int, ``triangles``
    (F, 3, 3) and ``normals`` (F, 3) float."""
    for i in range(k.shape[0]):
        p, f = (i if whole else rows[i]), k[i]
        t = ((triangles[f, 0, 0], triangles[f, 0, 1], triangles[f, 0, 2]),
             (triangles[f, 1, 0], triangles[f, 1, 1], triangles[f, 1, 2]),
             (triangles[f, 2, 0], triangles[f, 2, 1], triangles[f, 2, 2]))
        (uv[p, 0], uv[p, 1]), (x0[p, 0], x0[p, 1], x0[p, 2]) = ref_emit.triangle_point(
            t, u_s[i], u_r[i])
        nk = (normals[f, 0], normals[f, 1], normals[f, 2])
        cp, sp = variates.cos_sin_turn(u_phi[i])
        w1[p, 0], w1[p, 1], w1[p, 2] = ref_emit.cosine_direction(nk, u_c[i], cp, sp)
        for c in range(3):
            normal[p, c], beta[p, c] = nk[c], beta_l[c]
        tri[p] = f


@kernel
def search(cdf, u, out):  # pragma: no cover - compiled
    """``out[i] = min(search_right(cdf, u[i]), K - 1)``: ``trace_emit._discrete``'s index."""
    last = cdf.shape[0] - 1
    for i in range(u.shape[0]):
        out[i] = min(ref_emit.search_right(cdf, u[i]), last)


def _cdf(pmf):
    """The normalised cdf ``trace_emit._discrete`` searches (``None`` for one entry)."""
    if len(pmf) == 1:
        return None
    cdf = np.cumsum(pmf)
    cdf /= cdf[-1]
    return cdf


def _discrete(cdf, rng, n, out, rows=None):
    """``trace_emit._discrete`` with the compiled search, into ``out`` ((n,) intp)."""
    u = uniforms(rng, 1, n, rows=rows, spare=cdf is None)
    if cdf is None:
        out[:] = 0
    else:
        search(cdf, u, out)
    return out


def lights(scene) -> tuple:
    """What emission computes from the scene alone: ``P_L`` (L,), its cdf, and per light
    the constant arguments of its kernel (its weight ``power / P_L``, W, last). Computed once
    per scene (``trace_buffers.constants``)."""
    pmf = scene.light_pmf
    per = []
    for li, lt in enumerate(scene.lights):
        beta_l = lt.power_rgb / pmf[li]
        if isinstance(lt, PointLight):
            per.append((lt.position, lt.axis, beta_l))
        elif isinstance(lt, AreaLight):
            per.append((lt.corner, lt.edge_u, lt.edge_v, lt.normal, beta_l))
        elif isinstance(lt, MeshLight):
            per.append((_cdf(lt.areas / lt.area), np.ascontiguousarray(lt.triangles, dtype=float),
                        np.ascontiguousarray(lt.normals, dtype=float), beta_l))
        else:  # pragma: no cover - the scene loader admits no other light
            raise TypeError(f"unknown light {lt!r}")
    return pmf, _cdf(pmf), per


#: ``emit``'s arrays: name -> (shape after the photon axis, dtype).
FIELDS = {"light": ((), np.intp), "light_pmf": ((), np.float64), "light_uv": ((2,), np.float64),
          "tri": ((), np.int64), "light_normal": ((3,), np.float64), "x0": ((3,), np.float64),
          "w1": ((3,), np.float64), "beta": ((3,), np.float64)}


def emit(scene, rng, n: int, out: dict | None = None) -> dict:
    """``trace_emit.emit`` (same draws, same values, same dict) with compiled per-photon loops.

    Parameters
    ----------
    scene : Scene
    rng : numpy.random.Generator
    n : int
    out : dict of arrays, optional
        The arrays to write (:data:`FIELDS`, ``n`` rows each); new ones when omitted.

    Returns
    -------
    dict of (n, ...) arrays
        ``out`` (or the new arrays), written entirely.
    """
    e = out if out is not None else {k: np.empty((n, *s), dtype=dt)
                                     for k, (s, dt) in FIELDS.items()}
    pmf, cdf, per = buffers.constants(lights, scene)
    light = _discrete(cdf, rng, n, e["light"])
    np.take(pmf, light, out=e["light_pmf"])
    fields = tuple(e[k] for k in ("x0", "w1", "light_normal", "beta", "light_uv", "tri"))
    one = len(scene.lights) == 1  # every photon from light 0: no rows to select
    for li, (lt, args) in enumerate(zip(scene.lights, per, strict=True)):
        rows = np.empty(0, dtype=np.intp) if one else np.flatnonzero(light == li)
        m = n if one else rows.size
        sel = None if one else rows
        if m == 0:
            continue
        if isinstance(lt, PointLight):
            r = uniforms(rng, 2, m, rows=sel)
            emit_point(rows, one, r[:m], r[m:], *args, *fields)
        elif isinstance(lt, AreaLight):
            r = uniforms(rng, 4, m, pairs=True, rows=sel)
            emit_area(rows, one, r[: 2 * m].reshape(m, 2), r[2 * m : 3 * m], r[3 * m :], *args,
                      *fields)
        else:
            k = _discrete(args[0], rng, m, np.empty(m, dtype=np.intp), sel)
            r = uniforms(rng, 4, m, rows=sel)
            emit_mesh(rows, one, k, r[:m], r[m : 2 * m], r[2 * m : 3 * m], r[3 * m :],
                      *args[1:], *fields)
    return e
