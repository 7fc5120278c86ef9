"""Single-scattering photon surfaces (``ss-*``, spec 3.2): the exact, per-hit checks.

* Every scaled normal against a central-difference Jacobian of ``x0(xi1, xi2)``.
* Evaluate against the closed forms of the 3.2 table, hit by hit, in a scene with a point,
  a parallelogram and a mesh light (so ``1/P_L`` is included); reconstructed records are
  consistent paths on the light.
* MIS weights sum to one on reconstructed paths, and only techniques that can produce a
  path's light kind have density on it.

The statistical checks are in ``test_photon_surfaces_single_unbiased.py``, the grazing ones in
``test_photon_surfaces_single_grazing.py``. Fixed seeds only.
"""

from __future__ import annotations

import numpy as np
import pytest
from photon_surfaces_single_support import (
    ICO,
    MESH,
    MESH_CENTER,
    MIXED,
    PLANES,
    QUAD,
    SINGLE,
    hits_of,
    unit,
)
from small_scenes import TOP_AREA

from psurf_core.estimators import parse_estimator
from psurf_core.mis import member_densities, weights_from_densities
from psurf_core.path_record import KIND_CODE, PathRecord
from psurf_core.sampling import direction_about, phase_value
from psurf_core.techniques import get_technique
from psurf_core.techniques.base import dot


def test_mesh_lights_face_as_intended():
    tri = MESH.triangles
    assert tri.shape == (80, 3, 3) and ICO.is_watertight
    assert np.all(dot(MESH.normals, tri.mean(axis=1) - MESH_CENTER) > 0)
    np.testing.assert_allclose(QUAD.normals, np.tile(TOP_AREA.normal, (2, 1)))
    assert np.isclose(QUAD.area, TOP_AREA.area)


# ------------------------------------------------------------------------- normals
def _record(x1, w1, t1, axis, eu, ev, uv, kind):
    n = x1.shape[0]
    nan3, nan = np.full((n, 3), np.nan), np.full(n, np.nan)
    psi = np.tile([0.0, 0.0, 1.0], (n, 1))
    return PathRecord(K=np.ones(n, np.int64), light=np.zeros(n, np.int64),
                      kind=np.full(n, KIND_CODE[kind]), tri=np.full(n, -1), uv=uv, axis=axis,
                      eu=eu, ev=ev, x3=nan3, x2=nan3, x1=x1, x0=x1 + t1[:, None] * w1,
                      w3=nan3, w2=nan3, w1=w1, t3=nan, t2=nan, t1=t1, psi=psi, s=nan)


@pytest.mark.parametrize("name", ["ss-sphere", "ss-cone", "ss-disk", "ss-plane-uv",
                                  "ss-plane-ut", "ss-plane-vt"])
def test_scaled_normal_matches_finite_differences(name, n=300):
    rng = np.random.default_rng(3)
    axis = unit(rng.normal(size=(n, 3)))
    eu, ev = rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
    corner = rng.normal(size=(n, 3))
    c0 = rng.uniform(-0.95, 0.95, n)
    ph0 = rng.uniform(0.0, 2.0 * np.pi, n)
    t0, u0, v0 = rng.uniform(0.2, 3.0, n), rng.uniform(0.0, 1.0, n), rng.uniform(0.0, 1.0, n)
    # x0 as a function of the technique's two integrated dimensions (the others fixed).
    light = lambda u, v: corner + u[:, None] * eu + v[:, None] * ev  # noqa: E731
    ray = lambda x, c, ph, t: x + t[:, None] * direction_about(axis, c, ph)  # noqa: E731
    w_of = lambda c, ph: direction_about(axis, c, ph)  # noqa: E731
    wp = w_of(c0, ph0)
    f, p0 = {
        "ss-sphere": (lambda a, b: ray(corner, a, b, t0), (c0, ph0)),
        "ss-cone": (lambda a, b: ray(corner, c0, b, a), (t0, ph0)),
        "ss-disk": (lambda a, b: ray(corner, b, ph0, a), (t0, c0)),
        "ss-plane-uv": (lambda a, b: light(a, b) + t0[:, None] * wp, (u0, v0)),
        "ss-plane-ut": (lambda a, b: light(a, v0) + b[:, None] * wp, (u0, t0)),
        "ss-plane-vt": (lambda a, b: light(u0, a) + b[:, None] * wp, (v0, t0)),
    }[name]
    h = 1e-6
    a, b = p0
    da = (f(a + h, b) - f(a - h, b)) / (2 * h)
    db = (f(a, b + h) - f(a, b - h)) / (2 * h)
    n_fd = np.cross(da, db)
    rec = _record(light(u0, v0) if "plane" in name else corner, wp, t0, axis, eu, ev,
                  np.stack([u0, v0], 1), "area")
    n_code = get_technique(name).scaled_normal(rec)
    err = np.minimum(np.linalg.norm(n_fd - n_code, axis=1), np.linalg.norm(n_fd + n_code, axis=1))
    assert np.max(err / np.linalg.norm(n_code, axis=1)) < 1e-5


# ------------------------------------------------------------------------- records, MIS
def _closed_form(name, rec, scene, paths, prims, hits, rays):
    """The per-photon contributions of the table of spec 3.2 (closed forms), channel 0."""
    med = scene.medium
    st, ss = med.sigma_t, med.sigma_s
    light = rec.light
    pl = scene.light_pmf[light]
    lt = [scene.lights[i] for i in light]
    I = np.array([x.intensity[0] if x.kind == "point" else np.nan for x in lt])
    Le = np.array([np.nan if x.kind == "point" else x.radiance[0] for x in lt])
    area = np.array([np.nan if x.kind == "point" else x.area for x in lt])
    w, a, t = rec.w1, rec.axis, rec.t1
    psi = rec.psi
    c = dot(w, a)
    sin = np.sqrt(1.0 - c * c)
    eph = np.cross(a, w) / sin[:, None]
    rho0 = phase_value(-dot(w, psi), med.phase.g)
    cam = np.exp(-st * (rec.s - rays.s_min[hits.ray])) * ss * rho0
    e_t = 1.0 if name.endswith("short") else np.exp(-st * t)
    T = paths.t[prims.photon[hits.prim], 0]
    kind = rec.kind
    point, para = kind == KIND_CODE["point"], kind == KIND_CODE["area"]
    phi = np.where(point, 4 * np.pi * I, np.pi * area * Le)
    # |e_u x e_v| is A for the parallelogram and 2 A_k for a triangle (spec: A -> 2 A_k).
    a_patch = np.linalg.norm(np.cross(rec.eu, rec.ev), axis=1)
    p_uv = np.where(para, 1.0, a_patch / area)  # 1, or 2 P_k = 2 A_k / A_tot
    le_term = np.where(point, I, a_patch * Le * c)  # I, A Le cos, 2 A_k Le cos
    a_k = np.where(para, a_patch, 0.5 * a_patch)
    base = name.removesuffix("-short")
    out = {
        "ss-sphere": lambda: np.where(point, I, le_term / p_uv) / (st * T**2 * np.abs(dot(w, psi))),
        "ss-cone": lambda: np.where(point, 2 * I, area * Le / 2) * e_t
        / (t * np.abs(dot(a - c[:, None] * w, psi))),
        "ss-disk": lambda: 2 * np.pi * np.where(point, I, le_term / p_uv) * e_t * sin
        / (t * np.abs(dot(eph, psi))),
        "ss-plane-uv": lambda: phi / a_k / (st * np.abs(dot(a, psi))),
        "ss-plane-ut": lambda: phi / np.where(para, 1.0, 1.0 - rec.uv[:, 1]) * e_t
        / np.abs(dot(np.cross(rec.eu, w), psi)),
        "ss-plane-vt": lambda: phi / np.where(para, 1.0, 1.0 - rec.uv[:, 0]) * e_t
        / np.abs(dot(np.cross(rec.ev, w), psi)),
    }[base]()
    return out * cam / pl


@pytest.mark.parametrize("name", [*SINGLE, *PLANES])
def test_evaluate_matches_closed_forms_and_records(name):
    """Evaluate = the table's closed forms (incl. 1/P_L, three light kinds in one scene);
    the reconstructed record is a consistent path on the light."""
    tech, prims, hits, val, rec, paths, rays, ctx = hits_of(MIXED, name, n=4000)
    assert len(hits) > 50
    ok = val[:, 0] > 0
    assert ok.mean() > 0.8
    want = _closed_form(name, rec, MIXED, paths, prims, hits, rays)
    np.testing.assert_allclose(val[ok, 0], want[ok], rtol=1e-8)
    np.testing.assert_allclose(rec.x1 + rec.t1[:, None] * rec.w1, rec.x0, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(rec.w1, axis=1), 1.0, atol=1e-12)
    assert np.all(rec.K == 1) and np.all(np.isnan(rec.x2)) and np.all(np.isnan(rec.t2))
    emitter = rec.kind != KIND_CODE["point"]
    uv = rec.uv[emitter]
    corner = np.where((rec.kind[emitter] == KIND_CODE["area"])[:, None], TOP_AREA.corner,
                      MESH.triangles[np.maximum(rec.tri[emitter], 0), 0])
    np.testing.assert_allclose(corner + uv[:, :1] * rec.eu[emitter] + uv[:, 1:] * rec.ev[emitter],
                               rec.x1[emitter], atol=1e-9)
    tri = rec.kind[emitter] == KIND_CODE["mesh"]
    assert np.all(uv >= -1e-12) and np.all(np.where(tri, uv.sum(1), uv.max(1)) <= 1 + 1e-12)


def test_mis_weights_sum_to_one_on_reconstructed_paths():
    group = parse_estimator("paper-single", MIXED).groups[0]
    kinds = set()
    for tech in group:
        _, prims, hits, val, rec, paths, rays, ctx = hits_of(MIXED, tech, n=800)
        q = member_densities(rec, group, ctx)
        w = weights_from_densities(q, "balance")
        assert np.all(np.isfinite(q)) and np.all(np.isfinite(w)) and np.all(w >= 0)
        me = group.index(tech)
        ok = val[:, 0] > 0
        assert np.all(q[me, ok] > 0)  # the hit's own technique has density on its path
        np.testing.assert_allclose(w[:, ok].sum(axis=0), 1.0, rtol=1e-12)
        # Only techniques that can produce the path's light kind take part.
        for j, m in enumerate(group):
            assert np.all(q[j, ~m.can_produce(rec.K, rec.kind)] == 0)
        kinds |= set(np.unique(rec.kind[ok]).tolist())
    assert kinds == {0, 1, 2}
