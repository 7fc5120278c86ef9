"""What the numerics tests (``test_numerics_*.py``) share: the technique names, the extreme
scenes (a point, an area and a mesh light in the unit box, so every technique applies, with
media from nearly transparent to very dense and ``|g|`` up to ``1 - 1e-9``), their hypothesis
strategies and settings, and the pinned pool of hypothesis constants (import
:func:`fixed_constant_pool` into a test module: it is autouse)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

from psurf_core.scene import (
    AreaLight,
    Camera,
    Medium,
    MeshLight,
    Phase,
    PointLight,
    Scene,
    SphereOccluder,
)
from psurf_core.techniques import REGISTRY

NAMES = [n for name, e in REGISTRY.items()
         for n in ([name, f"{name}-short"] if e.has_short else [name])]
MIS_NAMES = [n for n in NAMES if REGISTRY[n.removesuffix("-short")].mis_ok]

BOX_MIN, BOX_MAX = -np.ones(3), np.ones(3)
DEPTH = 3

CRAFTED = settings(derandomize=True, max_examples=20, deadline=None, database=None,
                   suppress_health_check=list(HealthCheck))
TRACED = settings(derandomize=True, max_examples=8, deadline=None, database=None,
                  suppress_health_check=list(HealthCheck))


@pytest.fixture(autouse=True)
def fixed_constant_pool():
    """Pin hypothesis's pool of "interesting" constants.

    Hypothesis mixes literals harvested from every *loaded* local module (psurf_core, ui,
    app, ...) into its draws, so with ``derandomize`` alone the examples still depend on
    which modules happen to be imported (the test selection, lazily imported techniques).
    An empty local pool makes the examples a function of the test module's own code only.
    """
    from hypothesis.internal.conjecture import providers

    get = getattr(providers, "_get_local_constants", None)
    cache = getattr(providers, "CONSTANTS_CACHE", None)
    if get is None or cache is None:  # another hypothesis version: nothing to pin
        yield
        return
    empty = providers.Constants()
    providers._get_local_constants = lambda: empty
    cache.cache.clear()
    try:
        yield
    finally:
        providers._get_local_constants = get
        cache.cache.clear()


# ----------------------------------------------------------------------------- scenes
def unit(v) -> np.ndarray:
    """``v`` (3,) normalized, as a float array."""
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def build_scene(sigma_t: float, albedo: float, g: float, placement: str, camera: str,
                res=(6, 5), max_scatter: int = DEPTH) -> Scene:
    """A point, an area and a mesh light (so every technique applies) in the unit box.

    ``placement``: ``inside`` (lights well inside), ``boundary`` (point light on a face, the
    area light on the top face, the mesh light on a side face) or ``corner`` (point light
    at a box corner, area and mesh lights touching edges).
    """
    if placement == "inside":
        point = np.array([0.3, 0.4, 0.1])
        corner, eu, ev = np.array([-0.3, 0.5, -0.3]), np.array([0.6, 0, 0]), np.array([0, 0, 0.6])
        tri_o = np.array([-0.5, -0.5, 0.2])
    elif placement == "boundary":
        point = np.array([0.2, -1.0, 0.3])
        corner, eu, ev = np.array([-0.3, 1.0, -0.3]), np.array([0.6, 0, 0]), np.array([0, 0, 0.6])
        tri_o = np.array([-1.0, -0.3, -0.2])
    else:
        point = np.array([1.0, 1.0, -1.0])
        corner, eu, ev = np.array([-1.0, 1.0, -1.0]), np.array([0.5, 0, 0]), np.array([0, 0, 0.5])
        tri_o = np.array([-1.0, -1.0, -1.0])
    # area light faces down (cross(eu, ev) = -y); mesh: two triangles of a quad facing +x.
    a, b = np.array([0.0, 0.6, 0.0]), np.array([0.0, 0.0, 0.6])
    tris = np.array([[tri_o, tri_o + b, tri_o + a], [tri_o + b, tri_o + a + b, tri_o + a]])
    lights = (
        PointLight(point, np.array([4.0, 3.0, 2.0]), unit([0.0, 1.0, 0.0])),
        AreaLight(corner, eu, ev, np.array([3.0, 3.0, 1.0])),
        MeshLight(tris, np.array([2.0, 1.0, 2.0]), "<crafted>"),
    )
    positions = {"outside": [0.0, 0.0, -4.0], "inside": [0.1, -0.2, -0.4],
                 "face": [0.05, 0.1, -1.0]}
    cam = Camera(np.array(positions[camera]), np.array([0.0, 0.05, 0.0]),
                 np.array([0.0, 1.0, 0.0]), 60.0, *res)
    med = Medium(BOX_MIN.copy(), BOX_MAX.copy(), albedo * sigma_t, (1.0 - albedo) * sigma_t,
                 Phase("hg", g) if g != 0.0 else Phase())
    occ = (SphereOccluder(np.array([-0.5, 0.0, 0.5]), 0.2),)
    return Scene(cam, med, lights, occ, 1, max_scatter, "<numerics>")


# ----------------------------------------------------------------------------- strategies
def _media(sigma_t):
    return st.fixed_dictionaries({
        "sigma_t": sigma_t,
        "albedo": st.sampled_from([0.0, 1e-9, 0.5, 1.0]) | st.floats(0.0, 1.0),
        "g": st.sampled_from([0.0, 1 - 1e-9, -(1 - 1e-9), 0.999, -0.999, 1e-4])
        | st.floats(-0.99, 0.99),
        "placement": st.sampled_from(["inside", "boundary", "corner"]),
        "camera": st.sampled_from(["outside", "inside", "face"]),
    })


#: Media from nearly transparent to very dense, |g| up to 1 - 1e-9.
media = _media(st.sampled_from([1e-6, 1e-3, 0.05, 1.0, 7.0, 1e2, 1e4]) | st.floats(1e-6, 1e4))
#: The same extremes, but ordinary densities often enough that traced photons leave valid
#: multiple-scattering paths in the unit box (with st = 1e4 there are almost none).
traced_media = _media(st.sampled_from([1e-6, 1e-3, 1e2, 1e4]) | st.floats(0.2, 5.0))
