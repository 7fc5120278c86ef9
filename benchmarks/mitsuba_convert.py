"""A psurf scene as a Mitsuba 3 scene dictionary.

The conversion (``SCENES.md`` on the psurf side; every convention is checked against psurf's
quadrature and reference in ``tests/test_vs_mitsuba.py``):

* **medium**: a ``cube`` over ``[bounds_min, bounds_max]`` with a ``null`` BSDF and a
  ``homogeneous`` interior (``sigma_t``, albedo ``sigma_s / sigma_t``, ``hg`` phase with psurf's
  ``g``; isotropic is ``g = 0``); vacuum outside. A camera inside the box gets the medium too.
* **point light**: ``point`` with ``intensity`` = psurf's radiant intensity (W/sr, RGB). The
  ``axis`` only parameterises psurf's single-scattering surfaces; the light is isotropic.
* **area and mesh lights**: triangle meshes (a parallelogram is two triangles, counter-clockwise
  seen from its front ``edge_u x edge_v``) with face normals, an ``area`` emitter of psurf's
  radiance (one-sided, on the face-normal side) and a black ``diffuse`` BSDF: opaque and black
  on both sides, as psurf's emitters.
* **occluders**: ``sphere``, ``cube`` (box) or a triangle mesh, all with a black ``diffuse``
  BSDF (they absorb; paths that meet them end).
* **camera**: ``perspective`` with ``fov_axis = 'y'`` (psurf's ``fov_y`` is vertical), its
  ``to_world`` built as Mitsuba's ``look_at`` (``left = up x forward``: Mitsuba's image runs
  from its local +x on the left to -x on the right, so image right is ``forward x up``, as in
  psurf), ``near_clip`` 1e-5 (rays start there: the default 0.01 would skip medium in front
  of a camera inside the box), an ``hdrfilm`` of psurf's resolution with a ``box`` filter (a
  pixel is the average over its area, row 0 at the top) and RGB float32 output (an RGB
  variant).
* **integrator**: ``volpath`` with ``hide_emitters`` (psurf counts no light seen directly) and
  ``max_depth = K + 1`` for at most ``K`` scattering events (volpath counts a depth per medium
  interaction and per non-null surface: ``max_depth = 1`` is light seen directly, 2 adds single
  scattering). Unlimited (``max_scatter = -1``) is ``MAX_TRACE_DEPTH + 1``: psurf's own cap,
  so both images hold the same paths. ``rr_depth`` keeps Mitsuba's default.
* **scatter windows**: volpath has no minimum depth, so ``[a, b]`` with ``a > 1`` is rendered as
  ``I(max_depth = b + 1) - I(max_depth = a)`` (:func:`depth_pair`); :mod:`mitsuba_scene`
  renders the two with the same sampler seed in each pass.

Mitsuba is imported lazily (:func:`mitsuba_variant.import_mitsuba`): a variant must be set
before :func:`scene_dict` is called. :mod:`mitsuba_scene` renders through this module's
attributes (``mitsuba_convert.scene_dict``, ``.integrator_dict``, ``.NEAR_CLIP``), so that
``benchmarks/mitsuba_conventions.py --mutations`` can replace them.
"""

from __future__ import annotations

import numpy as np
from mitsuba_variant import import_mitsuba

from psurf_core.constants import MAX_TRACE_DEPTH
from psurf_core.scene import (
    AreaLight,
    BoxOccluder,
    MeshLight,
    MeshOccluder,
    PointLight,
    Scene,
    SphereOccluder,
)

#: The sensor's near clip distance (scene units); Mitsuba's default is 0.01.
NEAR_CLIP = 1e-5


def _rgb(v) -> dict:
    return {"type": "rgb", "value": [float(x) for x in v]}


def look_at_matrix(position, look_at, up) -> np.ndarray:
    """(4, 4) camera-to-world matrix as Mitsuba's ``look_at``.

    Columns: ``left = normalize(up x forward)``, ``cross(forward, left)``, ``forward``,
    ``position``.
    """
    p, t, u = (np.asarray(x, dtype=float) for x in (position, look_at, up))
    f = (t - p) / np.linalg.norm(t - p)
    left = np.cross(u, f)
    left /= np.linalg.norm(left)
    new_up = np.cross(f, left)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = left, new_up, f, p
    return m


def _box_matrix(lo, hi) -> np.ndarray:
    """(4, 4) map of Mitsuba's cube ``[-1, 1]^3`` onto the box ``[lo, hi]``."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    m = np.diag([*(0.5 * (hi - lo)), 1.0])
    m[:3, 3] = 0.5 * (hi + lo)
    return m


def parallelogram_triangles(light: AreaLight) -> np.ndarray:
    """(2, 3, 3) triangles of a psurf parallelogram, counter-clockwise about its normal."""
    c, u, v = light.corner, light.edge_u, light.edge_v
    return np.array([[c, c + u, c + u + v], [c, c + u + v, c + v]], dtype=float)


def _black(mi):
    return mi.load_dict({"type": "diffuse", "reflectance": _rgb([0.0, 0.0, 0.0])})


def _mesh(mi, name: str, tris: np.ndarray, radiance=None):
    """A Mitsuba triangle soup with face normals, black, emitting ``radiance`` if given."""
    props = mi.Properties()
    props["bsdf"] = _black(mi)
    if radiance is not None:
        props["emitter"] = mi.load_dict({"type": "area", "radiance": _rgb(radiance)})
    tris = np.asarray(tris, dtype=np.float32).reshape(-1, 3, 3)
    f = tris.shape[0]
    mesh = mi.Mesh(name, 3 * f, f, props=props, has_vertex_normals=False)
    params = mi.traverse(mesh)
    # The buffers' own types: dynamic arrays in every variant (mi.Float is a plain float in
    # the scalar ones).
    params["vertex_positions"] = type(params["vertex_positions"])(tris.reshape(-1))
    params["faces"] = type(params["faces"])(np.arange(3 * f, dtype=np.uint32))
    params.update()
    return mesh


def max_depth_for(max_scatter: int) -> int:
    """volpath's ``max_depth`` that holds paths of at most ``max_scatter`` events (-1:
    psurf's unlimited, which is capped at ``MAX_TRACE_DEPTH``)."""
    k = MAX_TRACE_DEPTH if max_scatter < 0 else int(max_scatter)
    return k + 1


def depth_pair(scene: Scene) -> tuple[int, int | None]:
    """``(max_depth, subtract_depth)`` of the scene's window ``[min_scatter, max_scatter]``:
    the image is ``I(max_depth) - I(subtract_depth)``, ``None`` when nothing is subtracted."""
    hi = max_depth_for(scene.max_scatter)
    lo = scene.min_scatter if scene.min_scatter > 1 else None
    return hi, lo


def integrator_dict(max_depth: int) -> dict:
    """``volpath`` with ``hide_emitters`` and this ``max_depth`` (module docstring)."""
    return {"type": "volpath", "max_depth": int(max_depth), "hide_emitters": True}


def scene_dict(scene: Scene, spp: int = 16) -> dict:
    """The Mitsuba scene dictionary of ``scene`` (module docstring); needs a variant set.

    Parameters
    ----------
    scene : Scene
    spp : int
        Samples per pixel of one ``mi.render`` call (the ``independent`` sampler).

    Returns
    -------
    dict
        For ``mitsuba.load_dict``; its integrator renders ``[1, max_scatter]``.
    """
    mi = import_mitsuba()
    cam, med = scene.camera, scene.medium
    medium = {
        "type": "homogeneous",
        "sigma_t": float(med.sigma_t),
        "albedo": float(med.albedo),
        "phase": {"type": "hg", "g": float(med.phase.g)},
    }
    inside = bool(np.all(cam.position > med.bounds_min) and np.all(cam.position < med.bounds_max))
    d = {
        "type": "scene",
        "integrator": integrator_dict(max_depth_for(scene.max_scatter)),
        "medium": medium,
        "sensor": {
            "type": "perspective",
            "fov": float(cam.fov_y),
            "fov_axis": "y",
            # Mitsuba starts camera rays at the near clip plane: with the camera inside the
            # medium the default 0.01 skips that much medium (1 % brighter at sigma_t = 1).
            "near_clip": NEAR_CLIP,
            "to_world": mi.ScalarTransform4f(
                look_at_matrix(cam.position, cam.look_at, cam.up).tolist()),
            "film": {"type": "hdrfilm", "width": int(cam.width), "height": int(cam.height),
                     "rfilter": {"type": "box"}, "pixel_format": "rgb",
                     "component_format": "float32"},
            "sampler": {"type": "independent", "sample_count": int(spp)},
        },
        "box": {"type": "cube", "bsdf": {"type": "null"},
                "to_world": mi.ScalarTransform4f(
                    _box_matrix(med.bounds_min, med.bounds_max).tolist()),
                "interior": {"type": "ref", "id": "medium"}},
    }
    if inside:
        d["sensor"]["medium"] = {"type": "ref", "id": "medium"}
    for i, lt in enumerate(scene.lights):
        key = f"light{i}"
        if isinstance(lt, PointLight):
            d[key] = {"type": "point", "position": [float(x) for x in lt.position],
                      "intensity": _rgb(lt.intensity)}
        elif isinstance(lt, AreaLight):
            d[key] = _mesh(mi, key, parallelogram_triangles(lt), lt.radiance)
        elif isinstance(lt, MeshLight):
            d[key] = _mesh(mi, key, lt.triangles, lt.radiance)
        else:  # pragma: no cover - the scene loader admits no other light
            raise TypeError(f"unknown light {lt!r}")
    for i, oc in enumerate(scene.occluders):
        key = f"occluder{i}"
        if isinstance(oc, SphereOccluder):
            d[key] = {"type": "sphere", "center": [float(x) for x in oc.center],
                      "radius": float(oc.radius), "bsdf": _black(mi)}
        elif isinstance(oc, BoxOccluder):
            d[key] = {"type": "cube", "bsdf": _black(mi),
                      "to_world": mi.ScalarTransform4f(_box_matrix(oc.min, oc.max).tolist())}
        elif isinstance(oc, MeshOccluder):
            d[key] = _mesh(mi, key, oc.triangles)
        else:  # pragma: no cover
            raise TypeError(f"unknown occluder {oc!r}")
    return d
