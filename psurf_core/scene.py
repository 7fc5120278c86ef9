"""The scene: camera, homogeneous medium box, lights and black occluders (``SCENES.md``).

Plain frozen dataclasses holding numpy arrays; ``load_scene`` (in :mod:`psurf_core.scene_io`)
builds them from a TOML file and validates every rule of the scene contract.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from .memo import frozen, memo


class SceneError(ValueError):
    """A scene (or command line) that cannot be used; the message names file, key and problem."""


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


@dataclass(frozen=True)
class Camera:
    """Pinhole camera.

    Attributes
    ----------
    position, look_at, up : (3,) float
    fov_y : float
        Vertical field of view in degrees.
    width, height : int
        Resolution in pixels.
    """

    position: np.ndarray
    look_at: np.ndarray
    up: np.ndarray
    fov_y: float
    width: int
    height: int

    @property
    def forward(self) -> np.ndarray:
        """(3,) unit view direction (read-only: computed once per camera)."""
        return memo(self, "forward", lambda: frozen(_unit(self.look_at - self.position)))

    @property
    def right(self) -> np.ndarray:
        """(3,) unit image-right direction, ``normalize(forward x up)`` (read-only)."""
        return memo(self, "right", lambda: frozen(_unit(np.cross(self.forward, self.up))))

    @property
    def image_up(self) -> np.ndarray:
        """(3,) unit image-up direction (``up`` projected orthogonal to ``forward``;
        read-only)."""
        return memo(self, "image_up", lambda: frozen(np.cross(self.right, self.forward)))

    @property
    def n_pixels(self) -> int:
        return self.width * self.height


@dataclass(frozen=True)
class Phase:
    """Henyey-Greenstein phase function; ``g = 0`` with ``kind='isotropic'`` is isotropic."""

    kind: str = "isotropic"
    g: float = 0.0


class MediumRow(NamedTuple):
    """:class:`Medium` in compiled code (its attribute names; :func:`medium_row`)."""

    sigma_t: float
    sigma_s: float
    g: float
    bounds_min: tuple[float, float, float]
    bounds_max: tuple[float, float, float]


def medium_row(medium: Medium) -> MediumRow:
    """The compiled code's :class:`MediumRow` of ``medium`` (built once per medium)."""
    return memo(medium, "row", lambda: MediumRow(
        float(medium.sigma_t), float(medium.sigma_s), float(medium.g),
        tuple(float(x) for x in medium.bounds_min), tuple(float(x) for x in medium.bounds_max)))


@dataclass(frozen=True)
class Medium:
    """Axis-aligned box of homogeneous medium (vacuum outside).

    Attributes
    ----------
    bounds_min, bounds_max : (3,) float
    sigma_s, sigma_a : float
        Scattering and absorption coefficients (1/scene unit), grey.
    phase : Phase
    """

    bounds_min: np.ndarray
    bounds_max: np.ndarray
    sigma_s: float
    sigma_a: float
    phase: Phase = field(default_factory=Phase)

    @property
    def sigma_t(self) -> float:
        return self.sigma_s + self.sigma_a

    @property
    def albedo(self) -> float:
        return self.sigma_s / self.sigma_t

    @property
    def g(self) -> float:
        """The phase function's ``g`` (0: isotropic)."""
        return self.phase.g

    @property
    def diagonal(self) -> float:
        return float(np.linalg.norm(self.bounds_max - self.bounds_min))


@dataclass(frozen=True)
class PointLight:
    """Isotropic point light of radiant intensity ``intensity`` (W/sr, RGB)."""

    position: np.ndarray
    intensity: np.ndarray
    axis: np.ndarray  # (3,) unit; the fixed axis `a` of single-scattering cone/disk

    kind = "point"

    @property
    def power(self) -> float:
        """Mean-over-RGB emitted power ``4 pi I`` (chooses lights during Trace)."""
        return float(4.0 * np.pi * np.mean(self.intensity))

    @property
    def power_rgb(self) -> np.ndarray:
        return 4.0 * np.pi * self.intensity


class _Lambertian:
    """The power of a one-sided Lambertian emitter of ``radiance`` and ``area``."""

    @property
    def power(self) -> float:
        return float(np.pi * self.area * np.mean(self.radiance))

    @property
    def power_rgb(self) -> np.ndarray:
        return np.pi * self.area * self.radiance


@dataclass(frozen=True)
class AreaLight(_Lambertian):
    """One-sided Lambertian parallelogram ``corner + u edge_u + v edge_v``, ``u, v`` in [0, 1]."""

    corner: np.ndarray
    edge_u: np.ndarray
    edge_v: np.ndarray
    radiance: np.ndarray

    kind = "area"

    @property
    def normal(self) -> np.ndarray:
        """(3,) unit emitting-side normal ``normalize(edge_u x edge_v)``."""
        return _unit(np.cross(self.edge_u, self.edge_v))

    @property
    def area(self) -> float:
        return float(np.linalg.norm(np.cross(self.edge_u, self.edge_v)))


@dataclass(frozen=True)
class MeshLight(_Lambertian):
    """Triangle mesh; every triangle emits ``radiance`` on its counter-clockwise front side.

    Attributes
    ----------
    triangles : (F, 3, 3) float
        Vertices ``v0, v1, v2`` of each triangle, world space.
    radiance : (3,) float
    source : str
        The mesh file it was loaded from (for messages and drawing).
    """

    triangles: np.ndarray
    radiance: np.ndarray
    source: str = ""

    kind = "mesh"

    @property
    def cross(self) -> np.ndarray:
        """(F, 3) ``(v1 - v0) x (v2 - v0) = 2 A_k n_k``."""
        t = self.triangles
        return np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])

    @property
    def areas(self) -> np.ndarray:
        """(F,) triangle areas ``A_k``."""
        return 0.5 * np.linalg.norm(self.cross, axis=1)

    @property
    def normals(self) -> np.ndarray:
        """(F, 3) unit front normals ``n_k``."""
        c = self.cross
        return c / np.linalg.norm(c, axis=1, keepdims=True)

    @property
    def area(self) -> float:
        return float(self.areas.sum())


@dataclass(frozen=True)
class SphereOccluder:
    center: np.ndarray
    radius: float
    kind = "sphere"


@dataclass(frozen=True)
class BoxOccluder:
    min: np.ndarray
    max: np.ndarray
    kind = "box"


@dataclass(frozen=True)
class MeshOccluder:
    triangles: np.ndarray  # (F, 3, 3)
    source: str = ""
    kind = "mesh"


Light = PointLight | AreaLight | MeshLight
Occluder = SphereOccluder | BoxOccluder | MeshOccluder


@dataclass(frozen=True)
class Scene:
    """A whole scene as loaded from one TOML file.

    ``max_scatter = -1`` means unlimited (Russian roulette past a depth; see ``trace``).
    """

    camera: Camera
    medium: Medium
    lights: tuple
    occluders: tuple = ()
    min_scatter: int = 1
    max_scatter: int = -1
    path: str = "<memory>"

    @property
    def light_powers(self) -> np.ndarray:
        """(L,) mean-over-RGB powers of the lights."""
        return np.array([lt.power for lt in self.lights], dtype=float)

    @property
    def light_pmf(self) -> np.ndarray:
        """(L,) probability ``P_L`` of choosing each light (proportional to power)."""
        p = self.light_powers
        return p / p.sum()

    def with_scatter(self, min_scatter: int | None = None, max_scatter: int | None = None) -> Scene:
        """A copy with ``[render]`` scatter bounds overridden (``None`` keeps the value)."""
        from dataclasses import replace

        return replace(
            self,
            min_scatter=self.min_scatter if min_scatter is None else int(min_scatter),
            max_scatter=self.max_scatter if max_scatter is None else int(max_scatter),
        )

    def with_medium(self, **changes) -> Scene:
        """A copy with medium fields replaced (``sigma_s``, ``sigma_a``, ``phase``)."""
        from dataclasses import replace

        return replace(self, medium=replace(self.medium, **changes))
