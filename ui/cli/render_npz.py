"""The ``.npz`` a ``render`` writes: :func:`npz_payload` (mean, variance, counts, the kernel
radius, provenance and the scene file's SHA-256, the pass moments for ``compare
--reference``) and :func:`initial_radius`, the radius it records. Also used by the web page's
download (:mod:`ui.web.model`). Only numpy and :mod:`psurf_core`; writing the file atomically
is :mod:`ui.cli.common`'s.
"""

from __future__ import annotations

import os
import sys

import numpy as np


def initial_radius(estimator, scene, settings) -> float:
    """The largest pass-0 kernel radius of the estimator's techniques (0.0: no kernel)."""
    from psurf_core.render import kernel_radius

    radii = [kernel_radius(t, scene, settings, 0) for t in estimator.techniques
             if t.kernel_dim > 0]
    return float(max(radii)) if radii else 0.0


def npz_payload(result, radius: float, scene, extra: dict | None = None) -> dict:
    """The arrays of a render ``.npz`` (``mean``, ``var``, counts, ``radius``, provenance;
    ``sum_var``, the (3,) per-pass variance of the image sum, when ``result`` knows it),
    updated with ``extra``."""
    from psurf_core import __version__

    data = {
        "mean": result.mean.astype(np.float32),
        "var": result.var.astype(np.float32),
        "passes": np.int64(result.passes),
        "photons_per_pass": np.int64(result.photons_per_pass),
        "spp": np.int64(result.spp),
        "seconds": np.float64(result.seconds),
        "estimator": np.str_(result.estimator),
        "seed": np.int64(result.seed),
        "radius": np.float64(radius),
        "version": np.str_(__version__),
        "argv": np.array(sys.argv, dtype=str),
        "scene": np.str_(scene.path),
        "min_scatter": np.int64(scene.min_scatter),
        "max_scatter": np.int64(scene.max_scatter),
    }
    if os.path.isfile(scene.path):  # which scene file, exactly (a bundled reference is checked)
        from psurf_core.checkpoint import file_sha256

        data["scene_sha256"] = np.str_(file_sha256(scene.path))
    # Pass moments for the reliability check of compare --reference (psurf_core.reliability).
    from psurf_core.reliability import npz_fields

    data.update(npz_fields(getattr(result, "accumulator", None)))
    sum_var = getattr(result, "sum_var", None)  # not var summed: photon passes' pixels correlate
    if sum_var is not None:
        data["sum_var"] = np.asarray(sum_var, dtype=np.float64)
    data.update(extra or {})
    return data
