"""Points to pixels in compiled code: the camera as a record (:class:`CameraRow`), the
projection of one point and the small helpers the screen footprints (:mod:`.spans`,
:mod:`.cloud_spans`) share."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..binning import _SPAN_MARGIN
from ..memo import memo
from ..records import Vec
from .jit import scalar


class CameraRow(NamedTuple):
    """What the compiled projection reads of a camera (:func:`camera_row`)."""

    position: Vec
    forward: Vec
    right: Vec
    image_up: Vec
    tan_half: float  # tan(fov_y / 2)
    aspect: float  # width / height
    width: float  # pixels
    height: float


@scalar
def _project(x, y, z, cam):
    """``camera.project`` of one point (``cam``: :class:`CameraRow`)."""
    vx, vy, vz = x - cam.position[0], y - cam.position[1], z - cam.position[2]
    depth = vx * cam.forward[0] + vy * cam.forward[1] + vz * cam.forward[2]
    u = ((vx * cam.right[0] + vy * cam.right[1] + vz * cam.right[2])
         / (depth * cam.tan_half * cam.aspect))
    w = (vx * cam.image_up[0] + vy * cam.image_up[1] + vz * cam.image_up[2]) / (
        depth * cam.tan_half)
    return (u + 1.0) * 0.5 * cam.width, (1.0 - w) * 0.5 * cam.height, depth


@scalar
def _row_range(ymin, ymax, y0, y1):
    """First row and number of rows of a polygon spanning ``[ymin, ymax]`` (with the span
    margin), within the image rows ``[y0, y1)``."""
    lo = max(np.floor(ymin - _SPAN_MARGIN), y0)
    hi = min(np.floor(ymax + _SPAN_MARGIN) + 1, y1)
    return int(lo), max(int(hi) - int(lo), 0)


@scalar
def _cross2(ox, oy, ax, ay, bx, by):
    """z of ``(a - o) x (b - o)``: > 0 where ``o, a, b`` turn counter-clockwise."""
    return (ax - ox) * (by - oy) - (ay - oy) * (bx - ox)


def camera_row(cam) -> CameraRow:
    """The :class:`CameraRow` of a :class:`~psurf_core.scene.Camera` (built once per
    camera)."""

    def build():
        def v(a):
            return tuple(float(x) for x in a)

        th = float(np.tan(np.radians(cam.fov_y) / 2.0))
        return CameraRow(v(cam.position), v(cam.forward), v(cam.right), v(cam.image_up), th,
                         cam.width / cam.height, float(cam.width), float(cam.height))

    return memo(cam, "row", build)
