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

``rec.pdf`` (:class:`~psurf_core.pdfs.Pdfs`) gives the elementary pdfs on a record so that
every technique's ``Q`` is one line from the spec's tables.

The compiled twin of a record is :class:`PathRow` (one hit, vectors as 3-tuples, its pdfs
kept with it in ``row.pdf``): :func:`photon_row` is :func:`photon_record` for one photon,
and the ``with_*`` setters are :meth:`PathRecord.with_` for the fields a technique
replaces, updating the pdfs that depend on them.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass, field, fields, replace
from typing import NamedTuple

import numpy as np

from .kernels.jit import ctrl_c_kept, inline, kernel, scalar, twin
from .kernels.vec import vec
from .pdfs import (
    KIND_CODE,
    Pdfs,
    PdfsRow,
    direction_pdf,
    flight_pdf,
    position_pdfs,
    triangle_pmf,
)
from .records import Vec, flat, load, table
from .records import replace as set_field
from .scene import AreaLight, MeshLight, PointLight, Scene

__all__ = ["KIND_CODE", "PathRecord", "PathRow", "Pdfs", "PhotonLight", "light_kinds",
           "photon_record", "photon_row", "photon_table", "revolution_axis"]

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
    scene: Scene | None = field(default=None, repr=False, compare=False)

    def __len__(self) -> int:
        return self.K.shape[0]

    def with_(self, **changes) -> PathRecord:
        return replace(self, **changes)

    def select(self, idx) -> PathRecord:
        return PathRecord(**{f.name: getattr(self, f.name)[idx] for f in fields(self)
                             if f.name != "scene"}, scene=self.scene)

    @property
    def pdf(self) -> Pdfs:
        """The elementary pdfs on this record (computed on first use, then kept)."""
        return Pdfs(self, self.scene)

    @property
    def st(self) -> float:
        """``sigma_t`` of the scene's medium (1 / scene units)."""
        return self.scene.medium.sigma_t

    @property
    def A3(self) -> np.ndarray:
        """(H, 3) the revolution axis of section 3.3 (:func:`revolution_axis`)."""
        return revolution_axis(self)


def revolution_axis(rec):
    """(H, 3) the revolution axis ``A3`` of section 3.3 on records ``rec``: ``w3``, or the
    light's axis / normal when ``x2`` is the light (``K = 2``)."""
    return np.where((rec.K == 2)[:, None], rec.axis, rec.w3)


@twin(revolution_axis)
def _revolution_axis(rec):
    return rec.axis if rec.K == 2 else rec.w3


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
                c(paths.t, float), flat(photon_table(paths, scene)), c(rays.o, float),
                c(rays.d, float), vec, sca, uv, kind)
    return PathRecord(
        K=K, light=paths.light[photon], kind=kind, tri=paths.tri[photon], uv=uv,
        axis=vec[8], eu=vec[9], ev=vec[10], x3=vec[0], x2=vec[1], x1=vec[2], x0=vec[3],
        w3=vec[4], w2=vec[5], w1=vec[6], t3=sca[0], t2=sca[1], t1=sca[2], psi=vec[7],
        s=s, scene=scene,
    )


class PhotonLight(NamedTuple):
    """What a photon's light puts into every record of it (a row of :func:`photon_table`).

    Attributes
    ----------
    kind : float
        Light kind code (:data:`KIND_CODE`).
    pk : float
        Triangle pmf ``P_k = A_k / A_tot`` (0 unless a mesh light's triangle).
    u, v : float
        The photon's light coordinates (parallelogram, or barycentric on its triangle).
    axis : Vec
        The point light's axis, or the normal ``n_L`` / ``n_k``.
    eu, ev : Vec
        Parallelogram edges, or the triangle's ``v1 - v0, v2 - v0``; zeros for point lights.
    """

    kind: float
    pk: float
    u: float
    v: float
    axis: Vec
    eu: Vec
    ev: Vec


_PHOTON_CACHE: list = []  # [(weakref to paths, scene, table)]: the last paths seen


def photon_table(paths, scene: Scene) -> np.recarray:
    """(P,) :class:`PhotonLight` records, one per photon.

    Kept for the last ``paths`` seen: every chunk of every technique of a batch reads the
    same photons.
    """
    if _PHOTON_CACHE:
        ref, sc, tab = _PHOTON_CACHE[0]
        if ref() is paths and sc is scene:
            return tab
    tab = table(PhotonLight, len(paths))
    # (fields are written by item: a recarray's attribute assignment of a (3,) field fails)
    tab["u"], tab["v"] = paths.light_uv[:, 0], paths.light_uv[:, 1]
    tab["axis"] = paths.light_normal
    for li, lt in enumerate(scene.lights):
        sel = np.flatnonzero(paths.light == li)
        tab["kind"][sel] = KIND_CODE[lt.kind]
        if isinstance(lt, AreaLight):
            tab["eu"][sel], tab["ev"][sel] = lt.edge_u, lt.edge_v
        elif isinstance(lt, MeshLight):
            tri = paths.tri[sel]
            tr = lt.triangles[tri]
            tab["eu"][sel], tab["ev"][sel] = tr[:, 1] - tr[:, 0], tr[:, 2] - tr[:, 0]
            ok = tri >= 0
            tab["pk"][sel[ok]] = lt.areas[tri[ok]] / lt.area
    _PHOTON_CACHE[:] = [(weakref.ref(paths), scene, tab)]
    return tab


@kernel
def _gather(photon, K, ray, s, x, w, t, lights, ray_o, ray_d, vec, sca, uv,
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
        lt = load(lights, ph, PhotonLight)
        for a in range(3):
            vec[7, h, a] = ray_d[r, a]
            vec[3, h, a] = ray_o[r, a] + s[h] * ray_d[r, a]
            vec[8, h, a] = lt.axis[a]
            vec[9, h, a] = lt.eu[a]
            vec[10, h, a] = lt.ev[a]
        uv[h, 0] = lt.u
        uv[h, 1] = lt.v
        kind[h] = np.int64(lt.kind)


def light_kinds(scene: Scene) -> set[str]:
    """The kinds of light present in ``scene``."""
    return {lt.kind for lt in scene.lights if isinstance(lt, PointLight | AreaLight | MeshLight)}


# ------------------------------------------------------------------------- compiled: one hit
class PathRow(NamedTuple):
    """One hit's :class:`PathRecord` (the compiled twin; vectors as 3-tuples), with the
    fields its pdfs need and the pdfs themselves (``pdf``: :class:`~psurf_core.pdfs.PdfsRow`,
    :attr:`PathRecord.pdf`'s twin). Fields beyond the light (``K < 3`` for ``w3, t3``) are
    NaN, as in :class:`PathRecord`."""

    K: int
    kind: int
    st: float  # sigma_t (PathRecord.st)
    g: float  # the phase function's g (the pdfs of w1 and w2 need it)
    pk: float  # triangle pmf P_k (Pdfs reads it from the scene)
    uv: tuple[float, float]
    axis: Vec
    eu: Vec
    ev: Vec
    x2: Vec
    x1: Vec
    x0: Vec
    w3: Vec
    w2: Vec
    w1: Vec
    t3: float
    t2: float
    t1: float
    psi: Vec
    pdf: PdfsRow


@inline
def _segment(x, w, t, ph, j):
    """Tracer segment ``j`` of photon ``ph`` (``w``, ``t``), NaN where ``j < 0``."""
    if j < 0:
        return (np.nan, np.nan, np.nan), np.nan
    return vec(w[ph, j]), t[ph, j]


@inline
def _vertex(x, ph, j):
    """Tracer vertex ``j`` of photon ``ph``, NaN where ``j < 0`` (beyond the light)."""
    if j < 0:
        return (np.nan, np.nan, np.nan)
    return vec(x[ph, j])


@inline
def photon_row(x, w, t, lights, ph, K, st, g):
    """:func:`photon_record` of photon ``ph`` at scatter count ``K`` for one hit, before the
    hit is known (``psi``, ``x0`` zero: :func:`at_hit` sets them). ``x, w, t``:
    ``PhotonPaths`` arrays; ``lights``: flat :func:`photon_table`. The arrays are read here
    (inlined into the walker); the pdfs are computed by :func:`_row_of` from numbers and
    tuples (typed once per process instead of in every walker)."""
    lt = load(lights, ph, PhotonLight)
    w3, t3 = _segment(x, w, t, ph, K - 3)
    w2, t2 = _segment(x, w, t, ph, K - 2)
    w1, t1 = _segment(x, w, t, ph, K - 1)
    return _row_of(lt, (w3, w2, w1), (t3, t2, t1), _vertex(x, ph, K - 2), vec(x[ph, K - 1]),
                   K, st, g)


@scalar
def _row_of(lt, ws, ts, x2, x1, K, st, g):
    """The :class:`PathRow` of :func:`photon_row` from its photon's light row ``lt``, the
    directions ``ws = (w3, w2, w1)`` and lengths ``ts = (t3, t2, t1)`` of its last
    segments and its vertices ``x2, x1``."""
    w3, w2, w1 = ws
    t3, t2, t1 = ts
    kind = int(lt.kind)
    axis = lt.axis
    p1 = direction_pdf(K, 1, kind, axis, w2, w1, g)
    p2 = direction_pdf(K, 2, kind, axis, w3, w2, g)
    puv, pu, pv = position_pdfs(kind, lt.pk, lt.u, lt.v)
    e1, f1 = flight_pdf(t1, st)
    e2, f2 = flight_pdf(t2, st)
    e3, f3 = flight_pdf(t3, st)
    pdf = PdfsRow(e1, e2, e3, f1, f2, f3, p1, p2, 2.0 * np.pi * p1, puv, pu, pv)
    zero = (0.0, 0.0, 0.0)
    return PathRow(K, kind, st, g, lt.pk, (lt.u, lt.v), axis, lt.eu, lt.ev, x2, x1, zero,
                   w3, w2, w1, t3, t2, t1, zero, pdf)


@scalar
def at_hit(row, o, psi, s):
    """``row`` on the camera ray ``o + s psi``: ``psi`` and ``x0 = y(s)``."""
    x0 = (o[0] + s * psi[0], o[1] + s * psi[1], o[2] + s * psi[2])
    return set_field(set_field(row, "psi", psi), "x0", x0)


@scalar
def with_t1(row, t1):
    """``row.with_(t1=t1)`` with its pdf."""
    e, f = flight_pdf(t1, row.st)
    return set_field(set_field(row, "t1", t1), "pdf",
                     set_field(set_field(row.pdf, "e1", e), "t1", f))


@scalar
def with_t2(row, t2):
    e, f = flight_pdf(t2, row.st)
    return set_field(set_field(row, "t2", t2), "pdf",
                     set_field(set_field(row.pdf, "e2", e), "t2", f))


@scalar
def with_w2(row, w2):
    """``row.with_(w2=w2)`` with the pdf of ``w2`` (set ``w1`` after it: its pdf is about
    ``w2``)."""
    p2 = direction_pdf(row.K, 2, row.kind, row.axis, row.w3, w2, row.g)
    return set_field(set_field(row, "w2", w2), "pdf", set_field(row.pdf, "w2", p2))


@scalar
def with_t3(row, t3):
    e, f = flight_pdf(t3, row.st)
    return set_field(set_field(row, "t3", t3), "pdf",
                     set_field(set_field(row.pdf, "e3", e), "t3", f))


@scalar
def with_w1(row, w1):
    """``row.with_(w1=w1)`` with the pdfs of ``w1`` and ``cos th1``."""
    p1 = direction_pdf(row.K, 1, row.kind, row.axis, row.w2, w1, row.g)
    pdf = set_field(set_field(row.pdf, "w1", p1), "c1", 2.0 * np.pi * p1)
    return set_field(set_field(row, "w1", w1), "pdf", pdf)


@scalar
def with_light_point(row, x1, u, v):
    """``row.with_(x1=x1, uv=(u, v))``: the light vertex moved (single-scattering planes),
    with the light-position pdfs."""
    puv, pu, pv = position_pdfs(row.kind, row.pk, u, v)
    pdf = set_field(set_field(set_field(row.pdf, "uv", puv), "u", pu), "v", pv)
    return set_field(set_field(set_field(row, "x1", x1), "uv", (u, v)), "pdf", pdf)


def row_of(rec: PathRecord, i: int) -> PathRow:
    """Record ``i`` of ``rec`` (numpy) as its compiled twin's :class:`PathRow`, pdfs included
    (what the twin tests and the inspector compare against)."""

    def v(a):
        return tuple(float(x) for x in a[i])

    pdf = rec.pdf
    return PathRow(int(rec.K[i]), int(rec.kind[i]), float(rec.st), float(rec.scene.medium.g),
                   float(triangle_pmf(rec.select([i]), rec.scene)[0]), v(rec.uv), v(rec.axis),
                   v(rec.eu), v(rec.ev), v(rec.x2), v(rec.x1), v(rec.x0), v(rec.w3), v(rec.w2),
                   v(rec.w1), float(rec.t3[i]), float(rec.t2[i]), float(rec.t1[i]), v(rec.psi),
                   PdfsRow(*(float(getattr(pdf, f)[i]) for f in PdfsRow._fields)))
