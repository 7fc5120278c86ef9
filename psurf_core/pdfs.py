"""The elementary sampling pdfs on a reconstructed path: :class:`Pdfs` (numpy, H hits) and
its compiled twin :class:`PdfsRow` (one hit), built from the same functions.

Every technique's effective density ``Q`` (spec section 2) is a product of these and its
scaled normal: ``p(t_k) = st exp(-st t_k)`` (:func:`flight_pdf`), the direction pdfs (the
phase function about the previous direction, or the emission pdf at the light:
:func:`emission_pdf`), ``p(cos th_1) = 2 pi p(w_1)``, and the light-position pdfs (1 on a
parallelogram; ``2 P_k`` jointly and ``2 P_k (1 - v)``, ``2 P_k (1 - u)`` as marginals on a
mesh triangle ``k``). See :mod:`psurf_core.path_record` for which factors are dropped as
shared.
"""

from __future__ import annotations

import weakref
from functools import cached_property
from typing import NamedTuple

import numpy as np

from .kernels.jit import twin
from .sampling import INV_4PI, phase_value
from .scene import MeshLight, Scene

#: Light kind codes of records and photon tables.
KIND_CODE = {"point": 0, "area": 1, "mesh": 2}
POINT, AREA, MESH = KIND_CODE["point"], KIND_CODE["area"], KIND_CODE["mesh"]


# ------------------------------------------------------------------------- the pdfs
def flight_pdf(t, st):
    """``(E(t), st E(t))``: the transmittance and the free-flight pdf (1 / scene units) of
    distance ``t``, ``E(t) = exp(-st t)``."""
    with np.errstate(invalid="ignore", over="ignore"):
        e = np.exp(-st * t)
    return e, st * e


@twin(flight_pdf)
def _flight_pdf(t, st):
    e = np.exp(-st * t)
    return e, st * e


def emission_pdf(kind, axis, w):
    """Solid-angle emission pdf (1/sr) of direction ``w`` (H, 3) at lights of kind code
    ``kind`` (H,) with axis / normal ``axis`` (H, 3): ``1/(4 pi)`` for an isotropic point
    light, ``max(cos, 0) / pi`` (cosine-weighted) for area and mesh lights."""
    with np.errstate(invalid="ignore"):
        cos = np.einsum("ij,ij->i", axis, w)
    return np.where(kind == POINT, INV_4PI, np.clip(cos, 0.0, None) / np.pi)


@twin(emission_pdf)
def _emission_pdf(kind, axis, w):
    if kind == POINT:
        return INV_4PI
    cos = (axis[0] * w[0] + axis[2] * w[2]) + axis[1] * w[1]
    if cos < 0.0:  # NaN stays NaN, as np.clip keeps it
        cos = 0.0
    return cos / np.pi


def direction_pdf(K, k, kind, axis, w_prev, w, g):
    """Pdf of ``w_k`` (``k`` = 1 or 2): the emission pdf where ``x_k`` is the light
    (``K == k``), else the phase function about ``w_{k+1}`` (``w_prev``)."""
    return np.where(K == k, emission_pdf(kind, axis, w),
                    phase_value(np.einsum("ij,ij->i", w_prev, w), g))


@twin(direction_pdf)
def _direction_pdf(K, k, kind, axis, w_prev, w, g):
    if K == k:
        return emission_pdf(kind, axis, w)
    return phase_value((w_prev[0] * w[0] + w_prev[2] * w[2]) + w_prev[1] * w[1], g)


def position_pdfs(kind, pk, u, v):
    """``(p(u,v), p(u), p(v))``: 1 on parallelograms and point lights; ``2 P_k``,
    ``2 P_k (1 - u)``, ``2 P_k (1 - v)`` on mesh triangle ``k`` (``pk = P_k``)."""
    mesh = kind == MESH
    return (np.where(mesh, 2.0 * pk, 1.0), np.where(mesh, 2.0 * pk * (1.0 - u), 1.0),
            np.where(mesh, 2.0 * pk * (1.0 - v), 1.0))


@twin(position_pdfs)
def _position_pdfs(kind, pk, u, v):
    if kind == MESH:
        return 2.0 * pk, 2.0 * pk * (1.0 - u), 2.0 * pk * (1.0 - v)
    return 1.0, 1.0, 1.0


# ------------------------------------------------------------------------- numpy: H hits
class Pdfs:
    """Elementary sampling pdfs evaluated on a record (all (H,) float).

    Computed on first use and kept with the record: every member of an MIS set evaluates
    its density on the same record, so each pdf is computed once per record, not per member.

    Attributes
    ----------
    e1, e2, e3 : transmittances ``E(t_k) = exp(-st t_k)`` (the short variants' density
        factors, one exponential each, shared by every member).
    t1, t2, t3 : free-flight pdfs ``st E(t_k)``.
    w1, w2 : solid-angle pdfs of ``w_k``: the phase function about ``w_{k+1}``, or the
        emission pdf when ``x_k`` is the light (``1/(4 pi)`` point, ``cos/pi`` area/mesh).
    c1, c2 : pdfs of ``cos th_k`` (``2 pi`` times the direction pdf: azimuthal symmetry).
    ph : ``1 / (2 pi)``, the pdf of any azimuth.
    uv : joint light-position pdf on the unit square (1) or a triangle (``2 P_k``).
    u, v : marginal pdfs of ``u`` and ``v`` (1, or ``2 P_k (1 - u)``, ``2 P_k (1 - v)``).
    """

    def __new__(cls, rec, scene: Scene):
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
    def rec(self):
        return self._rec()

    @property
    def _st(self) -> float:
        return self.scene.medium.sigma_t

    def _e(self, t):
        with np.errstate(invalid="ignore", over="ignore"):
            return np.exp(-self._st * t)

    @cached_property
    def e1(self):
        return self._e(self.rec.t1)

    @cached_property
    def e2(self):
        return self._e(self.rec.t2)

    @cached_property
    def e3(self):
        return self._e(self.rec.t3)

    @cached_property
    def t1(self):
        return self._st * self.e1

    @cached_property
    def t2(self):
        return self._st * self.e2

    @cached_property
    def t3(self):
        return self._st * self.e3

    @cached_property
    def w1(self):
        r = self.rec
        return direction_pdf(r.K, 1, r.kind, r.axis, r.w2, r.w1, self.scene.medium.phase.g)

    @cached_property
    def w2(self):
        r = self.rec
        return direction_pdf(r.K, 2, r.kind, r.axis, r.w3, r.w2, self.scene.medium.phase.g)

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
    def _position(self):
        r = self.rec
        return position_pdfs(r.kind, triangle_pmf(r, self.scene), r.uv[:, 0], r.uv[:, 1])

    @cached_property
    def uv(self):
        return self._position[0]

    @cached_property
    def u(self):
        return self._position[1]

    @cached_property
    def v(self):
        return self._position[2]


def triangle_pmf(rec, scene: Scene) -> np.ndarray:
    """``P_k = A_k / A_tot`` of each record's emitting triangle (0 for other lights)."""
    out = np.zeros(len(rec))
    for li, lt in enumerate(scene.lights):
        if isinstance(lt, MeshLight):
            sel = (rec.light == li) & (rec.tri >= 0)
            out[sel] = lt.areas[rec.tri[sel]] / lt.area
    return out


# ------------------------------------------------------------------------- compiled: one hit
class PdfsRow(NamedTuple):
    """:class:`Pdfs` of one hit (the compiled twin; same names, same formulas). ``ph`` is the
    constant ``1/(2 pi)`` and ``c2`` is not used by any compiled density."""

    e1: float
    e2: float
    e3: float
    t1: float
    t2: float
    t3: float
    w1: float
    w2: float
    c1: float
    uv: float
    u: float
    v: float
