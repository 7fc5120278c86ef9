"""The technique registry: every estimator name maps to a factory, so adding a technique is
adding one module and one :func:`register` call.

Names follow the CLI contract (issues 2 and 3): baselines ``points``, ``bre``, ``beams``,
``beams-long``, ``planes``; photon-surface techniques such as ``plane-t1t2`` with an optional
``-short`` suffix where the technique has a short variant.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from .base import Hits, PassContext, Primitives, Technique


@dataclass(frozen=True)
class Entry:
    """How to build a registered technique.

    Attributes
    ----------
    factory : callable(short: bool) -> Technique
    has_short : bool
        Whether ``NAME-short`` is a valid name.
    baseline : bool
        Kernel baselines and ``planes`` (they cannot take ``-short`` and cannot join MIS
        unless ``mis_ok``).
    mis_ok : bool
        Whether the technique has an MIS density.
    summary : str
        One line for ``--help``.
    """

    factory: Callable[[bool], Technique]
    has_short: bool = False
    baseline: bool = False
    mis_ok: bool = True
    summary: str = ""


REGISTRY: dict[str, Entry] = {}


def register(name: str, factory, *, has_short=False, baseline=False, mis_ok=True, summary=""):
    """Register a technique under ``name`` (``factory(short) -> Technique``)."""
    REGISTRY[name] = Entry(factory, has_short, baseline, mis_ok, summary)


class UnknownTechnique(ValueError):
    """A technique name that is not registered or takes no ``-short`` suffix."""


def get_technique(name: str) -> Technique:
    """Build the technique called ``name`` (with an optional ``-short`` suffix)."""
    if name in REGISTRY:
        return REGISTRY[name].factory(False)
    if name.endswith("-short"):
        base = name[: -len("-short")]
        if base in REGISTRY:
            if not REGISTRY[base].has_short:
                raise UnknownTechnique(f"'{base}' has no short variant (no '-short' on it)")
            return REGISTRY[base].factory(True)
    raise UnknownTechnique(f"unknown estimator '{name}'")


def _lazy(module: str):
    """A module of this package, imported when a technique is first built (keeps import
    cheap and free of cycles)."""
    import importlib

    return importlib.import_module(f"{__name__}.{module}")


def _register_builtin() -> None:
    planes = _lazy("planes")

    register("planes", lambda short: planes.PhotonPlane(short=True), baseline=True,
             summary="photon planes [t1,t2], short (Bitterli & Jarosz 17); unbiased, K>=2")
    register("plane-t1t2", lambda short: planes.PhotonPlane(short=short), has_short=True,
             summary="photon plane [t1,t2], long (explicit transmittance); K>=2")
    kernel = dict(baseline=True, mis_ok=False)
    register("points", lambda short: _lazy("points").PhotonPoints(), **kernel,
             summary="photon points, 3D kernel along the ray (Jensen & Christensen 98)")
    register("bre", lambda short: _lazy("points").BeamRadianceEstimate(), **kernel,
             summary="beam radiance estimate, points vs camera beam, 2D kernel (Jarosz 08)")
    register("beams", lambda short: _lazy("beams").PhotonBeams(short=True), **kernel,
             summary="short photon beams, 1D kernel (Jarosz 11, as in Tungsten)")
    register("beams-long", lambda short: _lazy("beams").PhotonBeams(short=False), **kernel,
             summary="long photon beams, 1D kernel, explicit transmittance")

    # Photon surfaces (issue 3): multiple scattering.
    def multi(module, cls, **kw):
        return lambda short: getattr(_lazy(module), cls)(short=short, **kw)

    register("plane-t1t3", multi("generalized_planes", "GeneralizedPlane", which="t1t3"),
             has_short=True, summary="generalized plane [t1,t3] through x3 + T2 w2; K>=3")
    register("plane-t2t3", multi("generalized_planes", "GeneralizedPlane", which="t2t3"),
             has_short=True, summary="generalized plane [t2,t3] through x3 + T1 w1; K>=3")
    register("plane-ut", multi("light_planes", "LightPlane", which="ut"), has_short=True,
             summary="light strip [u, t_K]: light edge e_u and emission flight, the rest of "
                     "the path carried along; K=2..3, area and mesh lights")
    register("plane-vt", multi("light_planes", "LightPlane", which="vt"), has_short=True,
             summary="light strip [v, t_K] (edge e_v); K=2..3, area and mesh lights")
    register("sphere", multi("spheres", "PhotonSphere"),
             summary="photon sphere [cos th1, ph1] about x1, radius T1; K>=2")
    register("cone", multi("cones", "PhotonCone"), has_short=True,
             summary="photon cone [t1, ph1], apex x1, axis w2; K>=2")
    register("cylinder", multi("cylinders", "PhotonCylinder"), has_short=True,
             summary="photon cylinder [t2, ph1], axis x2 + h w2; K>=2")
    register("disk", multi("disks", "PhotonDisk"), has_short=True,
             summary="photon disk [t1, cos th1], half-plane through x1; K>=2")
    register("hyperboloid", multi("hyperboloids", "Hyperboloid"), has_short=True,
             summary="hyperboloid [t1, ph2]: ray x1 + t w1 revolved about (x2, A3); K>=2")
    register("torus", multi("tori", "Torus"),
             summary="torus [cos th1, ph2]: meridian circle revolved about (x2, A3); K>=2")
    # Single scattering (K = 1).
    register("ss-sphere", multi("single_spheres", "SingleSphere"),
             summary="single scattering: sphere [cos th, ph] about the light point; K=1")
    register("ss-cone", multi("single_cones", "SingleCone"), has_short=True,
             summary="single scattering: cone [t, ph] about the light axis / normal; K=1")
    register("ss-disk", multi("single_disks", "SingleDisk"), has_short=True,
             summary="single scattering: disk [t, cos th] (half-plane through the axis); K=1")
    register("ss-plane-uv", multi("single_planes", "SinglePlane", which="uv"),
             summary="single scattering: the area/mesh light translated by T w; K=1")
    register("ss-plane-ut", multi("single_planes", "SinglePlane", which="ut"), has_short=True,
             summary="single scattering: strip [u, t] swept from the light; K=1")
    register("ss-plane-vt", multi("single_planes", "SinglePlane", which="vt"), has_short=True,
             summary="single scattering: strip [v, t] swept from the light; K=1")


_register_builtin()

__all__ = ["REGISTRY", "Entry", "Hits", "PassContext", "Primitives", "Technique",
           "UnknownTechnique", "get_technique", "register"]
