"""Every numpy function with a compiled twin (``kernels.jit.twin``) against that twin.

The numpy function runs on arrays of hits; the twin (what compiled code gets when it calls
the same name) on one hit at a time, through a small compiled trampoline. They are written
with the same operations in the same order, so on real data from a pass they agree to
1e-13 (most fields bit for bit).
"""

from __future__ import annotations

from functools import cache
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pytest
from numba import njit
from scene_support import COVERED_SCENES, SLOW_SCENES, scene_params

from psurf_core.binning import candidate_pairs
from psurf_core.camera import camera_rays
from psurf_core.estimators import parse_estimator
from psurf_core.geometry import blockers_of, inside_box
from psurf_core.kernels.shadow import BLOCKED, shadow_args
from psurf_core.path_record import at_hit, photon_record, photon_row, photon_table, row_of
from psurf_core.pdfs import direction_pdf, emission_pdf, flight_pdf, position_pdfs
from psurf_core.records import flat, load
from psurf_core.sampling import phase_value
from psurf_core.scene import medium_row
from psurf_core.scene_io import load_scene
from psurf_core.techniques import get_technique
from psurf_core.techniques.base import PassContext, cross, dot
from psurf_core.techniques.surface_common import (
    cached_solve,
    camera_term,
    plane_solver,
    quadratic_roots,
    solve_columns,
    unit,
)
from psurf_core.trace import trace

SCENES = sorted((Path(__file__).resolve().parent.parent / "scenes").glob("*.toml"))
TECHS = ["plane-t1t2", "planes", "plane-t1t3", "plane-t2t3-short", "cone", "cone-short",
         "cylinder", "cylinder-short", "sphere", "disk", "disk-short", "hyperboloid",
         "hyperboloid-short", "torus", "ss-sphere", "ss-cone", "ss-cone-short", "ss-disk",
         "ss-disk-short", "ss-plane-uv", "ss-plane-ut", "ss-plane-ut-short", "ss-plane-vt",
         "ss-plane-vt-short", "plane-ut", "plane-ut-short", "plane-vt-short"]
RTOL = 1e-13


class _Cache(NamedTuple):
    """The geometry columns :func:`cached_solve` reads (``solve_columns``)."""

    eye: tuple
    m0: tuple
    m1: tuple
    m2: tuple
    sdet: float


@cache
def compiled(f, n: int):
    """A compiled function of ``n`` arguments that calls ``f`` (its twin, in compiled code)."""
    args = ", ".join(f"a{i}" for i in range(n))
    ns = {"f": f}
    exec(f"def call({args}):\n    return f({args})\n", ns)  # noqa: S102 - test trampoline
    return njit(ns["call"])


def rows(a):
    return [tuple(float(x) for x in r) for r in np.atleast_2d(a)]


def close(a, b, what):
    np.testing.assert_allclose(np.asarray(a, float), np.asarray(b, float), rtol=RTOL,
                               atol=1e-300, equal_nan=True, err_msg=what)


# ------------------------------------------------------------------------- shared helpers
def test_shared_helpers_equal_their_twins():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(200, 3)) * 3, rng.normal(size=(200, 3))
    for i in range(len(a)):
        A, B = tuple(a[i]), tuple(b[i])
        assert compiled(dot, 2)(A, B) == dot(a, b)[i]
        assert compiled(cross, 2)(A, B) == tuple(cross(a, b)[i])
        u, n = compiled(unit, 1)(A)
        uu, nn = unit(a)
        assert u == tuple(uu[i]) and n == nn[i]
    mu = np.concatenate([np.linspace(-1.2, 1.2, 41), [np.nan]])
    for g in (0.0, 0.6, -0.35, 0.99999):
        want = phase_value(mu, g)
        got = [compiled(phase_value, 2)(m, g) for m in mu]
        close(got, want, f"phase_value g={g}")
    t = np.concatenate([rng.exponential(size=50), [0.0, np.nan]])
    close(np.array([compiled(flight_pdf, 2)(x, 0.8) for x in t]).T, np.array(flight_pdf(t, 0.8)),
          "flight_pdf")
    for kind in (0, 1, 2):
        k = np.full(len(a), kind)
        w = unit(b)[0]
        ax = unit(a)[0]
        close([compiled(emission_pdf, 3)(kind, tuple(ax[i]), tuple(w[i])) for i in range(len(a))],
              emission_pdf(k, ax, w), f"emission_pdf {kind}")
        for K, j in ((1, 1), (2, 1), (2, 2), (3, 2)):
            Kk = np.full(len(a), K)
            want = direction_pdf(Kk, j, k, ax, w[::-1].copy(), w, 0.4)
            got = [compiled(direction_pdf, 7)(K, j, kind, tuple(ax[i]), tuple(w[::-1][i]),
                                              tuple(w[i]), 0.4) for i in range(len(a))]
            close(got, want, f"direction_pdf {K} {j} {kind}")
        uu, vv = rng.random(len(a)), rng.random(len(a))
        want = position_pdfs(k, 0.3, uu, vv)
        got = [compiled(position_pdfs, 4)(kind, 0.3, uu[i], vv[i]) for i in range(len(a))]
        close(np.array(got).T, np.array(want), f"position_pdfs {kind}")
    qa, qh, qc = rng.normal(size=(3, 300))
    qa[:20] = 0.0
    want = quadratic_roots(qa, qh, qc)
    got = [compiled(quadratic_roots, 3)(qa[i], qh[i], qc[i]) for i in range(300)]
    close(np.array(got).T, want, "quadratic_roots")
    x, u, v, o, psi = (rng.normal(size=(100, 3)) for _ in range(5))
    want = plane_solver(x, u, v, o)
    got = [compiled(plane_solver, 4)(*(tuple(a[i]) for a in (x, u, v, o))) for i in range(100)]
    for j, name in enumerate(("m0", "m1", "m2")):
        close([g[j] for g in got], want[j], f"plane_solver {name}")
    close([g[3] for g in got], want[3], "plane_solver sdet")
    # cached_solve: rays from the camera read the stored vectors, others solve afresh; both
    # give numpy's (which always solves afresh).
    scene = load_scene(SCENES[0])
    cols = solve_columns(scene, x, u, v)
    eye = np.broadcast_to(scene.camera.position, x.shape)
    for origin, what in ((eye, "cached"), (o, "fresh")):
        want = cached_solve(x, u, v, None, origin, psi)
        got = [compiled(cached_solve, 6)(tuple(x[i]), tuple(u[i]), tuple(v[i]), _Cache(
            tuple(cols["eye"][i]), tuple(cols["m0"][i]), tuple(cols["m1"][i]),
            tuple(cols["m2"][i]), float(cols["sdet"][i])), tuple(origin[i]), tuple(psi[i]))
            for i in range(100)]
        close(np.array(got).T, np.array(want), f"cached_solve {what}")
    scene = load_scene(SCENES[0])
    med, mr = scene.medium, medium_row(scene.medium)
    mus, ds, ex = rng.uniform(-1, 1, 100), rng.random(100), rng.random(100)
    close([compiled(camera_term, 4)(mus[i], ds[i], ex[i], mr) for i in range(100)],
          camera_term(mus, ds, ex, med), "camera_term")
    x = rng.uniform(-1.3, 1.3, (300, 3))
    want = inside_box(x, med.bounds_min, med.bounds_max)
    got = [compiled(inside_box, 3)(tuple(x[i]), mr.bounds_min, mr.bounds_max)
           for i in range(len(x))]
    np.testing.assert_array_equal(got, want)


# ------------------------------------------------------------------------- the families
def _pass(path, photons=120, width=24, height=18):
    from dataclasses import replace

    scene = load_scene(path)
    # From K = 1 whatever the scene renders (the showcase starts at 2): every family has paths.
    scene = replace(scene, min_scatter=1,
                    camera=replace(scene.camera, width=width, height=height))
    blockers = blockers_of(scene)
    rays = camera_rays(scene, 1, np.random.default_rng(3), blockers=blockers)
    paths = trace(scene, photons, np.random.default_rng(4), blockers=blockers)
    return scene, blockers, rays, paths


def _hit_pairs(tech, prims, rays, ray, prim):
    """Indices of the candidate pairs ``(ray, prim)`` with a hit (numpy)."""
    fam, G = tech.compiled, prims.data[prim]
    r = fam.roots(G, rays.o[ray], rays.d[ray])
    with np.errstate(invalid="ignore"):
        slot, k = np.nonzero((r > rays.s_min[ray]) & (r < rays.s_max[ray]))
    ok, _ = fam.accept(G[k], rays.o[ray[k]], rays.d[ray[k]], r[slot, k], tech.short)
    return np.unique(k[ok])


def _candidates(tech, path):
    """A pass and ~4000 of its candidate pairs for ``tech`` (from the first chunk, at random).
    Where those hold few hits (a mesh triangle translated by ``ss-plane-uv`` is hit by few
    of the pairs its bounds cover), a pass with more photons, and its hits among the pairs.

    Returns ``(scene, blockers, rays, paths, ctx, prims, ray, prim)``.
    """
    for photons in (120, 4000):
        scene, blockers, rays, paths = _pass(path, photons)
        ctx = PassContext(scene, blockers)
        prims = tech.create(paths, ctx)
        med = scene.medium
        ray, prim = next(iter(candidate_pairs(scene.camera, rays, prims.lo, prims.hi, 1 << 22,
                                              prims.hull, (med.bounds_min, med.bounds_max))),
                         (np.zeros(0, int), np.zeros(0, int)))
        take = np.random.default_rng(0).permutation(len(ray))[:4000]
        if len(_hit_pairs(tech, prims, rays, ray[take], prim[take])) >= 50:
            break
    else:
        hit = _hit_pairs(tech, prims, rays, ray, prim)
        take = np.union1d(take[:2000], np.random.default_rng(1).permutation(hit)[:2000])
    return scene, blockers, rays, paths, ctx, prims, ray[take], prim[take]


@pytest.mark.parametrize("path", scene_params(slow=SLOW_SCENES | COVERED_SCENES))
@pytest.mark.parametrize("name", TECHS)
def test_family_twins_agree_on_a_pass(name, path):
    tech = get_technique(name)
    if not any(tech.applies_to(lt) for lt in load_scene(path).lights):
        pytest.skip("no light this technique applies to")
    scene, blockers, rays, paths, ctx, prims, ray, prim = _candidates(tech, path)
    fam, med, mr = tech.compiled, scene.medium, medium_row(scene.medium)
    blk = shadow_args(blockers)
    Gf = flat(prims.data)
    G, o, psi = prims.data[prim], rays.o[ray], rays.d[ray]
    # roots
    want = fam.roots(G, o, psi)
    got = np.array([compiled(fam.roots, 3)(load(Gf, p, fam.geometry), tuple(o[i]),
                                           tuple(psi[i])) for i, p in enumerate(prim)]).T
    close(got, want, f"{name} roots")
    # accept, on the roots on the rays' valid intervals
    r = np.flatnonzero((want > rays.s_min[ray]) & (want < rays.s_max[ray]))
    slot, k = r // len(ray), r % len(ray)
    s = want[slot, k]
    ok, hit = fam.accept(G[k], o[k], psi[k], s, tech.short)
    # Each twin's values are gathered over the pairs and compared once (one assert_allclose a
    # pair cost more than the compiled calls themselves).
    ok_got, hit_got, hit_want = [], [], []
    for j, i in enumerate(k):
        ok_c, hit_c = compiled(fam.accept, 5)(load(Gf, prim[i], fam.geometry), tuple(o[i]),
                                              tuple(psi[i]), s[j], tech.short)
        ok_got.append(ok_c)
        if ok_c and ok[j]:
            hit_got.append(np.concatenate([np.ravel(x) for x in hit_c]))
            hit_want.append(np.concatenate([np.ravel(hit[f][j]) for f in hit.dtype.names]))
    np.testing.assert_array_equal(np.array(ok_got, bool), ok, err_msg=f"{name} accept")
    if hit_got:
        close(np.stack(hit_got), np.stack(hit_want), f"{name} hit")
    hits_k, hits_s, hit = k[ok], s[ok], hit[ok]
    assert len(hits_k) > 10, "too few hits to compare"
    Gh = G[hits_k]
    x0 = o[hits_k] + hits_s[:, None] * psi[hits_k]
    valid = fam.visibility(Gh, x0, hit, med, blockers)
    contrib = fam.contribution(Gh, psi[hits_k], hits_s, rays.s_min[ray[hits_k]], hit,
                               tech.short, med)
    Hf = flat(hit)
    valid_got, contrib_got = [], []
    for j, i in enumerate(hits_k):
        Gi, h = load(Gf, prim[i], fam.geometry), load(Hf, j, fam.hit)
        st = compiled(fam.visibility, 5)(Gi, tuple(x0[j]), h, mr, blk)
        valid_got.append(BLOCKED not in st)  # meshes too
        contrib_got.append(compiled(fam.contribution, 7)(Gi, tuple(psi[i]), hits_s[j],
                                                         rays.s_min[ray[i]], h, tech.short, mr))
    np.testing.assert_array_equal(np.array(valid_got, bool), valid, err_msg=f"{name} visibility")
    close(np.array(contrib_got), contrib, f"{name} contribution")
    # reconstruct + density: the photon's record, then the hit's
    rec = photon_record(paths, prims.photon[prim[hits_k]], prims.K[prim[hits_k]], scene, rays,
                        ray[hits_k], hits_s)
    rec = fam.reconstruct(rec, Gh, hit)
    q = fam.density(rec, tech.short)
    ratio = fam.short_ratio(rec) if fam.short_ratio is not None else None
    lights = flat(photon_table(paths, scene))
    fields = ("K", "kind", "w3", "w2", "w1", "t3", "t2", "t1", "psi", "pdf")
    got = {f: [] for f in (*fields, "density", "short_ratio")}
    want = {f: [] for f in fields}
    n_rows = min(300, len(hits_k))
    for j, i in enumerate(hits_k[:n_rows]):
        p = prim[i]
        base = compiled(photon_row, 8)(paths.x, paths.w, paths.t, lights, prims.photon[p],
                                       prims.K[p], med.sigma_t, med.g)
        row = compiled(at_hit, 4)(base, tuple(o[i]), tuple(psi[i]), hits_s[j])
        row = compiled(fam.reconstruct, 3)(row, load(Gf, p, fam.geometry), load(Hf, j, fam.hit))
        want_row = row_of(rec, j)
        for f in fields:
            got[f].append(np.ravel(getattr(row, f)))
            want[f].append(np.ravel(getattr(want_row, f)))
        got["density"].append(compiled(fam.density, 2)(row, tech.short))
        if ratio is not None:
            got["short_ratio"].append(compiled(fam.short_ratio, 1)(row))
    for f in fields:
        close(np.stack(got[f]), np.stack(want[f]), f"{name} row.{f}")
    close(np.array(got["density"]), q[:n_rows], f"{name} density")
    if ratio is not None:
        close(np.array(got["short_ratio"]), ratio[:n_rows], f"{name} short_ratio")


def test_mis_presets_only_use_compiled_members_where_declared():
    """Which techniques of the paper's presets are compiled (the rest run numpy stages and
    numpy MIS weights): the list the docs describe."""
    est = parse_estimator("paper-multi")
    assert all(t.compiled is not None for t in est.techniques)
