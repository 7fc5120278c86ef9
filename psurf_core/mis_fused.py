"""Compiled MIS weights: Reconstruct + every member's density + the heuristic, per hit.

:func:`psurf_core.mis.mis_weights` on the numpy path builds a full
:class:`~psurf_core.path_record.PathRecord` per chunk of hits (~40 floats per hit), then
every member's ``density`` allocates its own (H,) / (H, 3) temporaries, then a (J, H) array
of densities becomes the weights: ~1.1-1.3 us per hit for paper-multi's five members
(``benchmarks/run.py --quick``, before this module). Here one compiled loop does the same
with scalars, ~0.08 us per hit: per primitive (hits come ~100 per primitive) it reads the
photon's last three segments from :class:`~psurf_core.trace.PhotonPaths` and what they fix;
per hit it replaces the integrated dimensions by the hit's roots (the technique's
``reconstruct``), evaluates each member's relative density ``Q_j`` (the technique's
``density``) and returns ``Q_i^b / sum_j Q_j^b``.

Only what the densities read is rebuilt: directions, distances, the light coordinates
``uv`` and ``psi`` (no density reads a vertex, except the single-scattering sphere, cone and
disk, whose rebuilt ``w1`` is ``x0 - x1``). The arithmetic is written in the numpy path's
order (its ``einsum`` dots and ``np.cross`` included), so weights agree to rounding
(``tests/test_mis_fast.py``); the numpy ``density`` methods remain the reference, used for any
technique or hit layout this module does not know (:func:`fast_weights` returns ``None``).

Covered techniques (exact types, long and short): ``plane-t1t2``, ``plane-t1t3``,
``plane-t2t3``, ``cone``, ``cylinder``, ``sphere``, ``disk``, ``ss-sphere``, ``ss-cone``,
``ss-disk``, ``ss-plane-{uv,ut,vt}``: the members of ``paper-single``, ``paper-multi`` and
``paper-full``, and more; ``hyperboloid`` and ``torus`` (roots of quartics) are not.
The kernel is single-threaded and compiled once per clone (``cache=True``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .compiled import ctrl_c_kept
from .path_record import KIND_CODE, photon_table
from .records import flat
from .sampling import INV_4PI
from .techniques.cones import PhotonCone
from .techniques.cylinders import PhotonCylinder
from .techniques.disks import PhotonDisk
from .techniques.generalized_planes import GeneralizedPlane
from .techniques.planes import PhotonPlane
from .techniques.single import SingleCone, SingleDisk, SingleSphere
from .techniques.single_planes import SinglePlane
from .techniques.spheres import PhotonSphere

#: Technique codes of the kernel.
(_PLANE, _GP13, _GP23, _CONE, _CYL, _SS_SPHERE, _SS_CONE, _SS_DISK, _SS_UV, _SS_UT,
 _SS_VT, _SPHERE, _DISK) = range(13)
_N_CODES = 13

#: Hit data each reconstructing technique contributes: (``r0``, ``r1``, ``wv``) keys of
#: ``Hits.data`` (None: not read).
_HIT_KEYS = {
    _PLANE: ("t2", "t1", None), _GP13: ("t3", "tv", None), _GP23: ("t3", "tv", None),
    _CONE: ("t1", None, "w1"), _CYL: ("t2", None, "w1"),
    _SS_SPHERE: (None, None, None), _SS_CONE: (None, None, None),
    _SS_DISK: (None, None, None),
    _SS_UV: ("a", "b", None), _SS_UT: ("a", "b", None), _SS_VT: ("a", "b", None),
    _SPHERE: (None, None, "w1"), _DISK: ("t1", None, "w1"),
}

_POINT, _MESH = KIND_CODE["point"], KIND_CODE["mesh"]
_TWO_PI = 2.0 * np.pi
_INV_2PI = 1.0 / (2.0 * np.pi)


def technique_code(tech) -> int | None:
    """Kernel code of ``tech`` (exact type: a subclass may change its density), or None."""
    t = type(tech)
    if t is PhotonPlane:
        return _PLANE
    if t is GeneralizedPlane:
        return _GP13 if tech.which == "t1t3" else _GP23
    if t is PhotonCone:
        return _CONE
    if t is PhotonCylinder:
        return _CYL
    if t is PhotonSphere:
        return _SPHERE
    if t is PhotonDisk:
        return _DISK
    if t is SingleSphere:
        return _SS_SPHERE
    if t is SingleCone:
        return _SS_CONE
    if t is SingleDisk:
        return _SS_DISK
    if t is SinglePlane:
        return {"uv": _SS_UV, "ut": _SS_UT, "vt": _SS_VT}[tech.which]
    return None


def member_table(group) -> np.ndarray | None:
    """(J, 5) int64 rows ``code, short, min_k, max_k (-1: none), light-kind bit mask`` of an
    MIS group (``Technique.can_produce`` and ``density`` in numbers), or None when a member
    has no kernel code."""
    rows = []
    for m in group:
        code = technique_code(m)
        if code is None:
            return None
        mask = 0
        for k in m.lights:
            mask |= 1 << KIND_CODE[k]
        rows.append((code, int(bool(m.short)), int(m.min_k),
                     -1 if m.max_k is None else int(m.max_k), mask))
    return np.array(rows, dtype=np.int64).reshape(-1, 5)


# ------------------------------------------------------------------------- entry point
def fast_weights(tech, group, weighting, hits, prims, paths, rays, ctx,
                 member: int | None = None) -> np.ndarray | None:
    """(H,) MIS weights of ``tech``'s hits within ``group``, or None where not covered.

    Same parameters and result as :func:`psurf_core.mis.mis_weights` (to rounding); None
    when ``tech`` or a member has no kernel code or the hits lack the data its
    ``reconstruct`` reads (the caller then runs the numpy path). ``member`` (index into
    ``group``): the weight of that member on the paths of ``tech``'s hits instead of
    ``tech``'s own (weights of all members sum to one on every path).
    """
    code = technique_code(tech)
    mem = member_table(group) if code is not None else None
    if mem is None:
        return None
    me = [i for i, m in enumerate(group) if m is tech][0] if member is None else int(member)
    keys = _HIT_KEYS[code]
    if any(k is not None and k not in hits.data for k in keys):
        return None
    c = np.ascontiguousarray
    r0 = c(hits.data[keys[0]], float) if keys[0] else np.zeros(0)
    r1 = c(hits.data[keys[1]], float) if keys[1] else np.zeros(0)
    wv = c(hits.data[keys[2]], float) if keys[2] else np.zeros((0, 3))
    med = ctx.scene.medium
    g = float(med.phase.g)
    # phase_value's constants, computed as it computes them (same rounding).
    hg_a = (1.0 - g) ** 2 if g > 0.0 else (1.0 + g) ** 2
    hg_c = INV_4PI * ((1.0 - g) * (1.0 + g))
    par = np.array([float(med.sigma_t), g, 1.0 if weighting == "power" else 0.0, hg_a, hg_c])
    out = np.empty(len(hits))
    i64 = np.int64
    with ctrl_c_kept():
        _weights_kernel(code, me, c(hits.ray, i64), c(hits.prim, i64), c(hits.s, float),
                        r0, r1, wv, c(prims.photon, i64), c(prims.K, i64),
                        c(paths.x, float), c(paths.w, float), c(paths.t, float),
                        flat(photon_table(paths, ctx.scene)), c(rays.o, float), c(rays.d, float),
                        mem, par, out)
    return out


# ------------------------------------------------------------------------- kernel
@njit(cache=True, error_model="numpy", inline="always")
def _dot(a0, a1, a2, b0, b1, b2):  # pragma: no cover - compiled
    """``einsum('ij,ij->i')`` of one row: left to right, as numpy sums three terms."""
    return a0 * b0 + a1 * b1 + a2 * b2


@njit(cache=True, error_model="numpy", inline="always")
def _phase(mu, g, hg_a, hg_c):  # pragma: no cover - compiled
    """:func:`~psurf_core.sampling.phase_value` of one cosine (NaN stays NaN)."""
    if g == 0.0:
        return INV_4PI
    if mu < -1.0:
        mu = -1.0
    elif mu > 1.0:
        mu = 1.0
    if g > 0.0:
        den = hg_a + 2.0 * g * (1.0 - mu)
    else:
        den = hg_a - 2.0 * g * (1.0 + mu)
    return hg_c / (den * np.sqrt(den))


@njit(cache=True, error_model="numpy", inline="always")
def _emission(kind, cos):  # pragma: no cover - compiled
    """``path_record._emission_pdf``: ``1/4pi`` (point) or ``max(cos, 0) / pi`` (NaN stays)."""
    if kind == _POINT:
        return INV_4PI
    if cos < 0.0:
        cos = 0.0
    return cos / np.pi


@njit(cache=True, error_model="numpy")
def _weights_kernel(code, me, ray, prim, s, r0, r1, wv, photon, kk, x, w, t, ptab, ray_o,
                    ray_d, mem, par, out):  # pragma: no cover - compiled
    """Weights ``out[h] = Q_me^b / sum_j Q_j^b`` (0 where the sum is 0) of every hit ``h``.

    ``code``: the hits' technique; ``r0, r1, wv``: its hit data (``_HIT_KEYS``); ``mem``:
    :func:`member_table`; ``par``: ``sigma_t, g, power (0/1), phase constants``;
    ``ptab``: :func:`photon_table`. Mirrors ``reconstruct`` + ``Pdfs`` + each ``density``.

    Hits come grouped by primitive (~100 per primitive), so the photon's own record, its
    pdfs and which members can produce it are computed when the primitive changes; per hit
    only what the technique's roots replace is recomputed. Every ``exp`` is taken before
    the densities: a call inside them would make the compiler keep their values in memory.
    """
    st = par[0]
    g = par[1]
    power = par[2] != 0.0
    hg_a = par[3]
    hg_c = par[4]
    nan = np.nan
    nm = mem.shape[0]
    # What the hits' technique replaces.
    set_t1 = (code == _PLANE or code == _GP13 or code == _CONE or code == _SS_CONE
              or code == _SS_DISK or code == _SS_UT or code == _SS_VT or code == _DISK)
    set_t2 = code == _PLANE or code == _GP23 or code == _CYL
    set_t3 = code == _GP13 or code == _GP23
    set_w1 = (code == _CONE or code == _CYL or code == _SS_SPHERE or code == _SS_CONE
              or code == _SS_DISK or code == _SPHERE or code == _DISK)
    set_uv = code == _SS_UV or code == _SS_UT or code == _SS_VT
    ok = np.zeros(nm, np.bool_)
    has = np.zeros(_N_CODES, np.bool_)  # a member of this code can produce the current path
    short = np.zeros(_N_CODES, np.bool_)  # ... and one of them is short
    h_pl = h_13 = h_23 = h_co = h_cy = h_ss = h_sc = h_sd = h_uv = h_ut = h_vt = False
    h_sp = h_di = False
    s_t1 = s_t2 = s_12 = s_13 = s_23 = False
    qt = np.zeros(_N_CODES)  # long density of each technique code on the current hit
    sf = np.ones(_N_CODES)  # short factor of each code
    qb = np.zeros(nm)
    last = -1
    K = 0
    ph = 0
    kind = 0.0
    pk = bu = bv = ax = ay = az = 0.0
    bw1x = bw1y = bw1z = bt1 = bw2x = bw2y = bw2z = bt2 = bw3x = bw3y = bw3z = bt3 = 0.0
    bf1 = bf2 = bf3 = bpw1 = bpw2 = bqw2 = bpu = bpv = 0.0
    lx = ly = lz = 0.0
    bnpx = bnpy = bnpz = bn13x = bn13y = bn13z = n23x = n23y = n23z = bdd = 0.0
    bvcox = bvcoy = bvcoz = bvcyx = bvcyy = bvcyz = 0.0
    for h in range(ray.shape[0]):
        p = prim[h]
        if p != last:
            # ---- the photon's own record (photon_record): segment k is tracer index K - k.
            last = p
            ph = photon[p]
            K = kk[p]
            j = K - 1
            bw1x, bw1y, bw1z, bt1 = w[ph, j, 0], w[ph, j, 1], w[ph, j, 2], t[ph, j]
            if K >= 2:
                j = K - 2
                bw2x, bw2y, bw2z, bt2 = w[ph, j, 0], w[ph, j, 1], w[ph, j, 2], t[ph, j]
            else:
                bw2x, bw2y, bw2z, bt2 = nan, nan, nan, nan
            if K >= 3:
                j = K - 3
                bw3x, bw3y, bw3z, bt3 = w[ph, j, 0], w[ph, j, 1], w[ph, j, 2], t[ph, j]
            else:
                bw3x, bw3y, bw3z, bt3 = nan, nan, nan, nan
            lx, ly, lz = x[ph, K - 1, 0], x[ph, K - 1, 1], x[ph, K - 1, 2]
            kind = ptab[ph, 0]
            pk = ptab[ph, 1]
            bu = ptab[ph, 2]
            bv = ptab[ph, 3]
            ax, ay, az = ptab[ph, 4], ptab[ph, 5], ptab[ph, 6]
            # ---- its pdfs (Pdfs)
            bf1 = st * np.exp(-st * bt1)
            bf2 = st * np.exp(-st * bt2)
            bf3 = st * np.exp(-st * bt3)
            if K == 1:
                bpw1 = _emission(kind, _dot(ax, ay, az, bw1x, bw1y, bw1z))
            else:
                bpw1 = _phase(_dot(bw2x, bw2y, bw2z, bw1x, bw1y, bw1z), g, hg_a, hg_c)
            if K == 2:
                bpw2 = _emission(kind, _dot(ax, ay, az, bw2x, bw2y, bw2z))
            else:
                bpw2 = _phase(_dot(bw3x, bw3y, bw3z, bw2x, bw2y, bw2z), g, hg_a, hg_c)
            bqw2 = (bf3 if K >= 3 else 1.0) * bpw2  # surface_common.q_to_w2
            bpu = 2.0 * pk * (1.0 - bu) if kind == _MESH else 1.0
            bpv = 2.0 * pk * (1.0 - bv) if kind == _MESH else 1.0
            # ---- the directions' vectors of the multiple-scattering densities: w1 x w2
            # (plane, disk), w1 x w3, w2 x w3 (generalized planes), w2 - c1 w1 (cone),
            # c1 w2 - w1 (cylinder); per hit only where the hit replaces w1
            bnpx = bw1y * bw2z - bw1z * bw2y
            bnpy = bw1z * bw2x - bw1x * bw2z
            bnpz = bw1x * bw2y - bw1y * bw2x
            bdd = _dot(bnpx, bnpy, bnpz, bnpx, bnpy, bnpz)
            bn13x = bw1y * bw3z - bw1z * bw3y
            bn13y = bw1z * bw3x - bw1x * bw3z
            bn13z = bw1x * bw3y - bw1y * bw3x
            n23x = bw2y * bw3z - bw2z * bw3y
            n23y = bw2z * bw3x - bw2x * bw3z
            n23z = bw2x * bw3y - bw2y * bw3x
            c = _dot(bw1x, bw1y, bw1z, bw2x, bw2y, bw2z)
            bvcox, bvcoy, bvcoz = bw2x - c * bw1x, bw2y - c * bw1y, bw2z - c * bw1z
            bvcyx, bvcyy, bvcyz = c * bw2x - bw1x, c * bw2y - bw1y, c * bw2z - bw1z
            # ---- Technique.can_produce of every member; only their densities are needed
            ik = np.int64(kind)
            has[:] = False
            short[:] = False
            for jm in range(nm):
                ok[jm] = (K >= mem[jm, 2] and (mem[jm, 3] < 0 or K <= mem[jm, 3])
                          and ((mem[jm, 4] >> ik) & 1) == 1)
                if ok[jm]:
                    has[mem[jm, 0]] = True
                    if mem[jm, 1] != 0:
                        short[mem[jm, 0]] = True
            h_pl, h_13, h_23 = has[_PLANE], has[_GP13], has[_GP23]
            h_co, h_cy = has[_CONE], has[_CYL]
            h_ss, h_sc, h_sd = has[_SS_SPHERE], has[_SS_CONE], has[_SS_DISK]
            h_uv, h_ut, h_vt = has[_SS_UV], has[_SS_UT], has[_SS_VT]
            h_sp, h_di = has[_SPHERE], has[_DISK]
            s_t1 = (short[_CONE] or short[_SS_CONE] or short[_SS_DISK] or short[_SS_UT]
                    or short[_SS_VT] or short[_DISK])
            s_t2, s_12, s_13, s_23 = short[_CYL], short[_PLANE], short[_GP13], short[_GP23]
        # ---- reconstruct: the hit's integrated dimensions replace the photon's.
        w1x, w1y, w1z, t1 = bw1x, bw1y, bw1z, bt1
        w2x, w2y, w2z, t2 = bw2x, bw2y, bw2z, bt2
        w3x, w3y, w3z, t3 = bw3x, bw3y, bw3z, bt3
        u, v = bu, bv
        px, py, pz = ray_d[ray[h], 0], ray_d[ray[h], 1], ray_d[ray[h], 2]
        if code == _PLANE:
            t2 = r0[h]
            t1 = r1[h]
        elif code == _GP13:
            t3 = r0[h]
            t1 = r1[h]
        elif code == _GP23:
            t3 = r0[h]
            t2 = r1[h]
        elif code == _CONE or code == _DISK:
            t1 = r0[h]
            w1x, w1y, w1z = wv[h, 0], wv[h, 1], wv[h, 2]
        elif code == _SPHERE:
            w1x, w1y, w1z = wv[h, 0], wv[h, 1], wv[h, 2]
        elif code == _CYL:
            t2 = r0[h]
            w1x, w1y, w1z = wv[h, 0], wv[h, 1], wv[h, 2]
        elif code == _SS_SPHERE or code == _SS_CONE or code == _SS_DISK:
            # w1* = normalize(x0 - x1), x1 = the light point (K = 1), x0 = o + s psi.
            r = ray[h]
            sh = s[h]
            dx = (ray_o[r, 0] + sh * px) - lx
            dy = (ray_o[r, 1] + sh * py) - ly
            dz = (ray_o[r, 2] + sh * pz) - lz
            nl = np.sqrt(dx * dx + dy * dy + dz * dz)
            dv = nl if nl > 0.0 else 1.0
            w1x, w1y, w1z = dx / dv, dy / dv, dz / dv
            if code != _SS_SPHERE:
                t1 = nl
        elif code == _SS_UV:
            u = r0[h]
            v = r1[h]
        elif code == _SS_UT:
            u = r0[h]
            t1 = r1[h]
        elif code == _SS_VT:
            v = r0[h]
            t1 = r1[h]
        # ---- the pdfs that changed
        f1 = st * np.exp(-st * t1) if set_t1 else bf1
        f2 = st * np.exp(-st * t2) if set_t2 else bf2
        f3 = bf3
        qw2 = bqw2
        if set_t3:
            f3 = st * np.exp(-st * t3)
            qw2 = (f3 if K >= 3 else 1.0) * bpw2
        pw1 = bpw1
        if set_w1:
            if K == 1:
                pw1 = _emission(kind, _dot(ax, ay, az, w1x, w1y, w1z))
            else:
                pw1 = _phase(_dot(w2x, w2y, w2z, w1x, w1y, w1z), g, hg_a, hg_c)
        pw2 = bpw2
        pc1 = _TWO_PI * pw1
        pu, pv = bpu, bpv
        if set_uv and kind == _MESH:
            pu = 2.0 * pk * (1.0 - u)
            pv = 2.0 * pk * (1.0 - v)
        puv = 2.0 * pk if kind == _MESH else 1.0
        # ---- short factors (Q_short = Q_long E(integrated t)), applied last as density does
        if s_t1:
            e1 = np.exp(-st * t1)
            sf[_CONE] = sf[_SS_CONE] = sf[_SS_DISK] = sf[_SS_UT] = sf[_SS_VT] = e1
            sf[_DISK] = e1
        if s_t2:
            sf[_CYL] = np.exp(-st * t2)
        if s_12:
            sf[_PLANE] = np.exp(-st * (t1 + t2))
        if s_13:
            sf[_GP13] = np.exp(-st * (t1 + t3))
        if s_23:
            sf[_GP23] = np.exp(-st * (t2 + t3))
        # ---- the direction vectors (the primitive's, or rebuilt with the hit's w1)
        npx, npy, npz, dd = bnpx, bnpy, bnpz, bdd
        n13x, n13y, n13z = bn13x, bn13y, bn13z
        vcox, vcoy, vcoz = bvcox, bvcoy, bvcoz
        vcyx, vcyy, vcyz = bvcyx, bvcyy, bvcyz
        if set_w1:
            if h_pl or h_di:
                npx = w1y * w2z - w1z * w2y
                npy = w1z * w2x - w1x * w2z
                npz = w1x * w2y - w1y * w2x
                dd = _dot(npx, npy, npz, npx, npy, npz)
            if h_13:
                n13x = w1y * w3z - w1z * w3y
                n13y = w1z * w3x - w1x * w3z
                n13z = w1x * w3y - w1y * w3x
            if h_co or h_cy:
                c = _dot(w1x, w1y, w1z, w2x, w2y, w2z)
                vcox, vcoy, vcoz = w2x - c * w1x, w2y - c * w1y, w2z - c * w1z
                vcyx, vcyy, vcyz = c * w2x - w1x, c * w2y - w1y, c * w2z - w1z
        # ---- long densities (each technique's ``density``, same operation order)
        if h_pl:
            q = (f3 if K >= 3 else 1.0) * pw2 * pw1
            qt[_PLANE] = q * abs(_dot(npx, npy, npz, px, py, pz))
        if h_13:
            qt[_GP13] = f2 * pw2 * pw1 * abs(_dot(n13x, n13y, n13z, px, py, pz))
        if h_23:
            qt[_GP23] = f1 * pw2 * pw1 * abs(_dot(n23x, n23y, n23z, px, py, pz))
        if h_co:
            qt[_CONE] = qw2 * f2 * pc1 * abs(_dot(t1 * vcox, t1 * vcoy, t1 * vcoz, px, py, pz))
        if h_cy:
            qt[_CYL] = qw2 * pc1 * f1 * abs(_dot(t1 * vcyx, t1 * vcyy, t1 * vcyz, px, py, pz))
        if h_sp:  # spheres.py: q_{<=w2} p(t2) p(t1) t1^2 |w1 . psi|
            tt = t1 * t1
            qt[_SPHERE] = qw2 * f2 * f1 * abs(_dot(tt * w1x, tt * w1y, tt * w1z, px, py, pz))
        if h_di:  # disks.py: q_{<=w2} p(t2) (1/2pi) t1 |(w1 x w2) . psi| / s1^2
            kf = t1 / dd
            qt[_DISK] = qw2 * f2 * _INV_2PI * abs(_dot(kf * npx, kf * npy, kf * npz, px, py, pz))
        if h_ss:
            tt = t1 * t1
            qt[_SS_SPHERE] = puv * f1 * abs(_dot(tt * w1x, tt * w1y, tt * w1z, px, py, pz))
        if h_sc:
            c = _dot(w1x, w1y, w1z, ax, ay, az)
            nx = t1 * (ax - c * w1x)
            ny = t1 * (ay - c * w1y)
            nz = t1 * (az - c * w1z)
            qt[_SS_CONE] = puv * pc1 * abs(_dot(nx, ny, nz, px, py, pz))
        if h_sd:
            nx = w1y * az - w1z * ay
            ny = w1z * ax - w1x * az
            nz = w1x * ay - w1y * ax
            sin2 = _dot(nx, ny, nz, nx, ny, nz)
            kf = t1 / max(sin2, 1e-200) if sin2 > 1e-200 else 0.0
            qt[_SS_DISK] = puv * _INV_2PI * abs(_dot(kf * nx, kf * ny, kf * nz, px, py, pz))
        if h_uv or h_ut or h_vt:
            eux, euy, euz = ptab[ph, 7], ptab[ph, 8], ptab[ph, 9]
            evx, evy, evz = ptab[ph, 10], ptab[ph, 11], ptab[ph, 12]
            if h_uv:
                nx = euy * evz - euz * evy
                ny = euz * evx - eux * evz
                nz = eux * evy - euy * evx
                q = (0.5 * puv if kind == _MESH else 1.0) * pw1
                qt[_SS_UV] = q * abs(_dot(nx, ny, nz, px, py, pz)) * f1
            if h_ut:
                nx = euy * w1z - euz * w1y
                ny = euz * w1x - eux * w1z
                nz = eux * w1y - euy * w1x
                qt[_SS_UT] = pv * pw1 * abs(_dot(nx, ny, nz, px, py, pz))
            if h_vt:
                nx = evy * w1z - evz * w1y
                ny = evz * w1x - evx * w1z
                nz = evx * w1y - evy * w1x
                qt[_SS_VT] = pu * pw1 * abs(_dot(nx, ny, nz, px, py, pz))
        # ---- the heuristic over the members that can produce the path (member_densities:
        # nan_to_num(abs(Q)) with NaN and inf -> 0)
        den = 0.0
        for jm in range(nm):
            q = 0.0
            if ok[jm]:
                mc = mem[jm, 0]
                q = qt[mc] * sf[mc] if mem[jm, 1] != 0 else qt[mc]
                q = abs(q)
                if not (q < np.inf):
                    q = 0.0
            qb[jm] = q * q if power else q
            den += qb[jm]
        out[h] = qb[me] / den if den > 0.0 else 0.0
