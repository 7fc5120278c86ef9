"""psurf core: unbiased volumetric photon density estimation (Deng et al. 2019, "Photon Surfaces").

The core is numpy only (no UI, no pyvista); ``app.py`` and ``ui/`` build on it.

Public API
----------
Scenes (``SCENES.md``)
    :func:`load_scene` (path -> :class:`Scene`), :class:`Scene`, :class:`SceneError` (one-line
    message ``"<file>: <key>: <problem>"``; also used for command-line problems).
Estimators
    :func:`parse_estimator` (``"planes"``, ``"reference"``, ``"mis:A+B"``, ... -> ``Estimator``;
    raises :class:`~psurf_core.techniques.UnknownTechnique` or :class:`SceneError`).
Rendering
    :func:`psurf_core.render.render` (progressive: whole passes until a pass count or a time
    budget), :func:`render_pass` (one pass's image), :class:`RenderSettings` (photons, spp, kernel
    radius, memory budget), :class:`RenderResult` (mean, per-pass variance, provenance).
Building blocks
    :func:`psurf_core.trace.trace` (photon paths), :func:`camera_rays` (jittered camera rays),
    :class:`Welford` (mean and variance across passes, exact merge).

``__version__`` is the package version (``pyproject.toml``). Image helpers (tone mapping,
false colour) live in :mod:`psurf_core.images`.

Notes
-----
``render`` and ``trace`` are submodules (the stages); their functions of the same name are
reached as ``psurf_core.render.render`` and ``psurf_core.trace.trace`` so that the package
attribute is never a function shadowing its module.
"""

from __future__ import annotations

__version__ = "0.1.0"

from .memory_release import keep_freed_memory  # noqa: E402

# Before any pass allocates: a pass's arrays are reused from the heap instead of faulted in
# again from the system every pass (memory_release).
keep_freed_memory()

from .accumulate import Welford  # noqa: E402
from .camera import camera_rays  # noqa: E402
from .estimators import parse_estimator  # noqa: E402
from .render import RenderResult, RenderSettings, render_pass  # noqa: E402
from .scene import Scene, SceneError  # noqa: E402
from .scene_io import load_scene  # noqa: E402

__all__ = [
    "RenderResult",
    "RenderSettings",
    "Scene",
    "SceneError",
    "Welford",
    "__version__",
    "camera_rays",
    "load_scene",
    "parse_estimator",
    "render_pass",
]
