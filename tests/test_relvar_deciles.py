"""The relMSE's noise part per pixel (metrics.var_relmse_map) averages to its scalar, and
benchmarks/relvar_deciles.py's deciles split the lit pixels into ten parts of (nearly) equal
size."""

import numpy as np

from benchmarks.relvar_deciles import DECILES, decile_masks
from psurf_core.metrics import var_relmse, var_relmse_map


def test_map_is_the_relmse_noise_part_per_pixel():
    rng = np.random.default_rng(3)
    ref = rng.random((12, 16, 3))
    ref[:2] = 0.0  # black rows: EPS mean(R)^2 keeps their weight finite
    var = rng.random((12, 16, 3)) * 1e-3
    assert np.isclose(var_relmse_map(var, ref).mean(), var_relmse(var, ref), rtol=1e-12)


def test_deciles_partition_the_lit_pixels():
    rng = np.random.default_rng(4)
    ref = rng.random((20, 30, 3))
    ref[:5] = 0.0
    masks, edges = decile_masks(ref)
    lit = ref.mean(axis=-1) > 0
    counts = np.array([m.sum() for m in masks])
    assert len(masks) == DECILES and len(edges) == DECILES + 1
    assert counts.sum() == lit.sum()                      # every lit pixel once
    assert not np.any(np.sum(masks, axis=0)[~lit])        # no unlit pixel
    assert counts.max() - counts.min() <= 1
