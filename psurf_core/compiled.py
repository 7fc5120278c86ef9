"""Moved to :mod:`psurf_core.kernels.jit` (kept until every caller imports it from there)."""

from .kernels.jit import ctrl_c_kept, interrupted  # noqa: F401
