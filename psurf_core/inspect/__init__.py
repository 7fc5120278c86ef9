"""Everything the UI shows for one pixel and one pass, as plain records (numpy only).

* :mod:`.pixel`: :func:`inspect_pixel` replays one pass for one pixel and flattens what
  happened into a :class:`HitTable` (one row per camera-ray/primitive hit, summing to the
  pixel's value in that pass), kept in a :class:`PixelInspection`;
* :mod:`.path`: the Reconstruct stage of one hit, :func:`reconstruct_hit` (the full path and
  every MIS member's density on it) and :func:`member_primitives` (each member's surface
  through that path);
* :mod:`.coverage`: :func:`primitive_pixels`, the pixels one primitive reaches.

Every formula these show (a scaled normal, a density) is the family's own, called through
the :class:`~psurf_core.techniques.base.Technique` interface.
"""

from .coverage import primitive_pixels
from .path import member_primitives, reconstruct_hit
from .pixel import SUM_RTOL, HitTable, PixelInspection, inspect_pixel

__all__ = [
    "SUM_RTOL",
    "HitTable",
    "PixelInspection",
    "inspect_pixel",
    "member_primitives",
    "primitive_pixels",
    "reconstruct_hit",
]
