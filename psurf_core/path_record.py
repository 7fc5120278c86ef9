"""Reconstructed paths: the record every technique builds for a hit, and the pdfs MIS needs.

A hit of any technique implies one full photon path (spec section 2: the sampled dimensions
are the photon's, the integrated ones the hit's roots). :class:`PathRecord` holds the last
(up to) three segments of that path in the spec's notation, ``x_3 -> x_2 -> x_1 -> x_0``
with ``x_{k-1} = x_k + t_k w_k`` and ``x_0 = y(s)`` on the camera ray. Everything earlier is
sampled identically by every technique, so its pdf cancels in MIS weights.

Densities are *relative*: each technique's ``density(rec)`` returns ``Q`` without the factors
every technique of that scatter count shares:

* ``K >= 3``: ``q_{<= w3}`` (dims up to and including ``w3``) is dropped;
* ``K = 2``: the light-position pdf is dropped (``x2`` is on the light);
* ``K = 1``: nothing is dropped (the single-scattering table of section 3.2 as written).

:class:`Pdfs` gives the elementary pdfs on a record so that every technique's ``Q`` is one
line from the spec's tables.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass, fields, replace
from functools import cached_property

import numpy as np
from numba import njit

from .compiled import ctrl_c_kept
from .sampling import INV_4PI, phase_value
from .scene import AreaLight, MeshLight, PointLight, Scene

KIND_CODE = {"point": 0, "area": 1, "mesh": 2}


@dataclass
class PathRecord:
    """The last segments of the full path a hit implies (H hits, leading axis H).

    Attributes
    ----------
    K : (H,) int
        Scatter count.
    light, kind, tri : (H,) int
        Light index, light kind code (:data:`KIND_CODE`), mesh triangle (-1 otherwise).
    uv : (H, 2) float
        Light-surface coordinates of the light vertex (parallelogram or barycentric).
    axis : (H, 3) float
        ``a`` (point light) or ``n_L``/``n_k`` at the light vertex.
    eu, ev : (H, 3) float
        Parallelogram edges / triangle edges ``v1 - v0, v2 - v0`` (zeros for point lights).
    x3, x2, x1, x0 : (H, 3) float
        Vertices; ``x_K`` is the light, vertices beyond it are NaN.
    w3, w2, w1 : (H, 3) float
        Unit directions (NaN beyond the light).
    t3, t2, t1 : (H,) float
        Segment lengths (NaN beyond the light).
    psi : (H, 3) float
        Camera-ray direction.
    s : (H,) float
        Distance of ``x0`` along the camera ray.
    """

    K: np.ndarray
    light: np.ndarray
    kind: np.ndarray
    tri: np.ndarray
    uv: np.ndarray
    axis: np.ndarray
    eu: np.ndarray
    ev: np.ndarray
    x3: np.ndarray
    x2: np.ndarray
    x1: np.ndarray
    x0: np.ndarray
    w3: np.ndarray
    w2: np.ndarray
    w1: np.ndarray
    t3: np.ndarray
    t2: np.ndarray
    t1: np.ndarray
    psi: np.ndarray
    s: np.ndarray

    def __len__(self) -> int:
        return self.K.shape[0]

    def with_(self, **changes) -> PathRecord:
        return replace(self, **changes)

    def select(self, idx) -> PathRecord:
        return PathRecord(**{f.name: getattr(self, f.name)[idx] for f in fields(self)})

    @property
    def A3(self) -> np.ndarray:
        """(H, 3) the revolution axis of section 3.3: ``w3``, or the light axis when ``K = 2``."""
        return np.where((self.K == 2)[:, None], self.axis, self.w3)


def photon_record(paths, photon: np.ndarray, K: np.ndarray, scene: Scene, rays,
                  ray: np.ndarray, s: np.ndarray) -> PathRecord:
    """A record filled with the photon's own sampled path (tracer vertex ``j`` is ``x_{K-j}``).

    Techniques then replace the integrated dimensions (and what they rebuild) with the
    hit's values via :meth:`PathRecord.with_`. One compiled gather (:func:`_gather`) fills
    every field: the same values as numpy's fancy indexing, without its ~20 temporaries.
    """
    h = photon.shape[0]
    c = np.ascontiguousarray
    photon = c(photon, np.int64)
    K = c(K, np.int64)
    ray = c(ray, np.int64)
    vec = np.empty((11, h, 3))  # x3 x2 x1 x0 w3 w2 w1 psi axis eu ev
    sca = np.empty((3, h))  # t3 t2 t1
    uv = np.empty((h, 2))
    kind = np.empty(h, np.int64)
    with ctrl_c_kept():
        _gather(photon, K, ray, c(s, float), c(paths.x, float), c(paths.w, float),
                c(paths.t, float), photon_table(paths, scene), c(rays.o, float),
                c(rays.d, float), vec, sca, uv, kind)
    return PathRecord(
        K=K, light=paths.light[photon], kind=kind, tri=paths.tri[photon], uv=uv,
        axis=vec[8], eu=vec[9], ev=vec[10], x3=vec[0], x2=vec[1], x1=vec[2], x0=vec[3],
        w3=vec[4], w2=vec[5], w1=vec[6], t3=sca[0], t2=sca[1], t1=sca[2], psi=vec[7],
        s=s,
    )


_PHOTON_CACHE: list = []  # [(weakref to paths, scene, table)]: the last paths seen


def photon_table(paths, scene: Scene) -> np.ndarray:
    """(P, 13) float per photon: light kind code (:data:`KIND_CODE`), triangle pmf
    ``P_k = A_k / A_tot`` (0 unless a mesh light's triangle), ``uv`` (2), light ``axis`` (3),
    patch edges ``eu``, ``ev`` (3 + 3: parallelogram edges or ``v1 - v0, v2 - v0``, zeros
    for point lights).

    Kept for the last ``paths`` seen: every chunk of every technique of a batch reads the
    same photons.
    """
    if _PHOTON_CACHE:
        ref, sc, tab = _PHOTON_CACHE[0]
        if ref() is paths and sc is scene:
            return tab
    tab = np.zeros((len(paths), 13))
    tab[:, 2:4] = paths.light_uv
    tab[:, 4:7] = paths.light_normal
    for li, lt in enumerate(scene.lights):
        sel = np.flatnonzero(paths.light == li)
        tab[sel, 0] = KIND_CODE[lt.kind]
        if isinstance(lt, AreaLight):
            tab[sel, 7:10], tab[sel, 10:13] = lt.edge_u, lt.edge_v
        elif isinstance(lt, MeshLight):
            tri = paths.tri[sel]
            tr = lt.triangles[tri]
            tab[sel, 7:10], tab[sel, 10:13] = tr[:, 1] - tr[:, 0], tr[:, 2] - tr[:, 0]
            ok = tri >= 0
            tab[sel[ok], 1] = lt.areas[tri[ok]] / lt.area
    _PHOTON_CACHE[:] = [(weakref.ref(paths), scene, tab)]
    return tab


@njit(cache=True, error_model="numpy")
def _gather(photon, K, ray, s, x, w, t, ptab, ray_o, ray_d, vec, sca, uv,
            kind):  # pragma: no cover - compiled
    """Fill :func:`photon_record`'s arrays: ``vec`` (11, H, 3), ``sca`` (3, H), ``uv``
    (H, 2), ``kind`` (H,). Segment ``k`` (``x_k``, ``w_k``, ``t_k``) is tracer index
    ``K - k``; NaN where that is negative (beyond the light)."""
    nan = np.nan
    for h in range(photon.shape[0]):
        ph = photon[h]
        for m in range(3):  # x3, x2, x1 / w3, w2, w1 / t3, t2, t1
            j = K[h] - 3 + m
            if j >= 0:
                for a in range(3):
                    vec[m, h, a] = x[ph, j, a]
                    vec[4 + m, h, a] = w[ph, j, a]
                sca[m, h] = t[ph, j]
            else:
                for a in range(3):
                    vec[m, h, a] = nan
                    vec[4 + m, h, a] = nan
                sca[m, h] = nan
        r = ray[h]
        for a in range(3):
            vec[7, h, a] = ray_d[r, a]
            vec[3, h, a] = ray_o[r, a] + s[h] * ray_d[r, a]
            vec[8, h, a] = ptab[ph, 4 + a]
            vec[9, h, a] = ptab[ph, 7 + a]
            vec[10, h, a] = ptab[ph, 10 + a]
        uv[h, 0] = ptab[ph, 2]
        uv[h, 1] = ptab[ph, 3]
        kind[h] = np.int64(ptab[ph, 0])


class Pdfs:
    """Elementary sampling pdfs evaluated on a record (all (H,) float).

    Computed on first use and kept with the record: every member of an MIS set evaluates
    its density on the same record, so each pdf is computed once per record, not per member.

    Attributes
    ----------
    t1, t2, t3 : free-flight pdfs ``st exp(-st t_k)``.
    w1, w2 : solid-angle pdfs of ``w_k``: the phase function about ``w_{k+1}``, or the
        emission pdf when ``x_k`` is the light (``1/(4 pi)`` point, ``cos/pi`` area/mesh).
    c1, c2 : pdfs of ``cos th_k`` (``2 pi`` times the direction pdf: azimuthal symmetry).
    ph : ``1 / (2 pi)``, the pdf of any azimuth.
    uv : joint light-position pdf on the unit square (1) or a triangle (``2 P_k``).
    u, v : marginal pdfs of ``u`` and ``v`` (1, or ``2 P_k (1 - u)``, ``2 P_k (1 - v)``).
    """

    def __new__(cls, rec: PathRecord, scene: Scene):
        cached = rec.__dict__.get("_pdfs")
        if cached is not None and cached.scene is scene:
            return cached
        self = super().__new__(cls)
        # A weak reference back: a strong one would make a record <-> pdfs cycle, which only
        # the cyclic garbage collector frees, so every chunk's arrays would pile up.
        self._rec, self.scene = weakref.ref(rec), scene
        rec.__dict__["_pdfs"] = self
        return self

    @property
    def rec(self) -> PathRecord:
        return self._rec()

    def _flight(self, t):
        st = self.scene.medium.sigma_t
        with np.errstate(invalid="ignore", over="ignore"):
            return st * np.exp(-st * t)

    @cached_property
    def t1(self):
        return self._flight(self.rec.t1)

    @cached_property
    def t2(self):
        return self._flight(self.rec.t2)

    @cached_property
    def t3(self):
        return self._flight(self.rec.t3)

    @cached_property
    def w1(self):
        rec = self.rec
        return np.where(rec.K == 1, _emission_pdf(rec, rec.w1),
                        phase_value(_dot(rec.w2, rec.w1), self.scene.medium.phase.g))

    @cached_property
    def w2(self):
        rec = self.rec
        return np.where(rec.K == 2, _emission_pdf(rec, rec.w2),
                        phase_value(_dot(rec.w3, rec.w2), self.scene.medium.phase.g))

    @cached_property
    def c1(self):
        return 2.0 * np.pi * self.w1

    @cached_property
    def c2(self):
        return 2.0 * np.pi * self.w2

    @cached_property
    def ph(self):
        return np.full(len(self.rec), 1.0 / (2.0 * np.pi))

    @cached_property
    def _mesh_pk(self):
        return self.rec.kind == KIND_CODE["mesh"], _triangle_pmf(self.rec, self.scene)

    @cached_property
    def uv(self):
        mesh, pk = self._mesh_pk
        return np.where(mesh, 2.0 * pk, 1.0)

    @cached_property
    def u(self):
        mesh, pk = self._mesh_pk
        return np.where(mesh, 2.0 * pk * (1.0 - self.rec.uv[:, 0]), 1.0)

    @cached_property
    def v(self):
        mesh, pk = self._mesh_pk
        return np.where(mesh, 2.0 * pk * (1.0 - self.rec.uv[:, 1]), 1.0)


def _dot(a, b):
    return np.einsum("ij,ij->i", a, b)


def _emission_pdf(rec: PathRecord, w: np.ndarray) -> np.ndarray:
    """Solid-angle emission pdf of direction ``w`` at the light vertex of each record."""
    with np.errstate(invalid="ignore"):
        cos = _dot(rec.axis, w)
    return np.where(rec.kind == KIND_CODE["point"], INV_4PI, np.clip(cos, 0.0, None) / np.pi)


def _triangle_pmf(rec: PathRecord, scene: Scene) -> np.ndarray:
    """``P_k = A_k / A_tot`` of each record's emitting triangle (0 for other lights)."""
    out = np.zeros(len(rec))
    for li, lt in enumerate(scene.lights):
        if isinstance(lt, MeshLight):
            sel = (rec.light == li) & (rec.tri >= 0)
            out[sel] = lt.areas[rec.tri[sel]] / lt.area
    return out


def light_kinds(scene: Scene) -> set[str]:
    """The kinds of light present in ``scene``."""
    return {lt.kind for lt in scene.lights if isinstance(lt, PointLight | AreaLight | MeshLight)}
