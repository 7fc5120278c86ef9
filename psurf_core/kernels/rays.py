"""The camera rays as the walkers read them: the rays that see medium, in pixel order, one
:class:`RayRow` record each, and where each pixel's rays start."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..memo import memo
from ..records import Vec, table


class RayRow(NamedTuple):
    """One camera ray ``y(s) = o + s psi`` that sees medium for ``s_min < s < s_max``."""

    o: Vec
    psi: Vec
    s_min: float
    s_max: float


def ray_table(rays, n_pixels: int):
    """The rays with medium (``s_max > s_min``) in pixel order (built once per ``rays``:
    every technique of a pass walks the same table).

    Returns
    -------
    cs : (n_pixels + 1,) int64
        Pixel ``q``'s rays are rows ``cs[q] .. cs[q + 1] - 1`` (rays are pixel-major, so a
        span of pixels of one image row is one contiguous run of rows).
    rt : (U,) RayRow records
    rid : (U,) int64
        Index of each row in ``rays``.
    """
    return memo(rays, ("table", n_pixels), lambda: _ray_table(rays, n_pixels))


def _ray_table(rays, n_pixels):
    rid = np.flatnonzero(rays.s_max > rays.s_min)
    cs = np.zeros(n_pixels + 1, np.int64)
    np.cumsum(np.bincount(rays.pixel[rid], minlength=n_pixels), out=cs[1:])
    rt = table(RayRow, o=rays.o[rid], psi=rays.d[rid], s_min=rays.s_min[rid],
               s_max=rays.s_max[rid])
    return cs, rt, rid
