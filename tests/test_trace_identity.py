"""Trace's output is frozen: every ``PhotonPaths`` field, and the random numbers it consumes.

The screenshot baselines and the statistical tests depend on ``trace`` returning the same
arrays for the same scene, photon count and generator, so its speed work must not change
them. ``tests/data/trace_expected.npz`` holds the full output of small runs, written by the
implementation of 2026-11-22 before the speed work (commit 293fc23), and
``tests/data/trace_expected.json`` what is kept of larger ones (deep roulette paths, the
benchmark's batch size). Each case also records the next draws of the generator after the
trace: the same numbers must have been consumed. Both implementations are held to it: the
compiled path ``trace`` runs and the numpy reference (``reference=True``); that they are
equal to each other bit for bit on every bundled scene is ``tests/test_trace_reference.py``.

Integer and boolean fields and the generator's draws must match bit for bit. Floating-point
fields must match to ``FLOAT_RTOL``: the last bit of ``log`` (free-flight distances) is not
the same on every machine (glibc and numpy choose code paths by CPU; on 2026-12-03 an AMD
EPYC differed from the machine that froze the data in ``t``, ``x`` and ``clip`` only, by at
most 3.3e-14 relative), while any change a code edit makes is many orders larger. The large
runs keep exact SHA-256 digests of their integer fields and, of each floating-point field,
sums that a tolerance can compare (:func:`_summary`), written on 2026-12-03 from the output
whose integer fields matched the 2026-11-22 digests exactly. On 2026-12-04 the azimuths'
``cos``/``sin`` and the flights' logarithm became ``psurf_core.variates``' polynomials (in
both implementations): the floating-point fields moved by rounding only, inside the
tolerance, and the integer fields and draws did not change.

Regenerate (only for an intended change of Trace's output):
``.venv/bin/python tests/test_trace_identity.py --write``.
"""

from __future__ import annotations

import hashlib
import json
import sys
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
if __name__ == "__main__":  # pragma: no cover - fixture writer
    sys.path.insert(0, str(ROOT))

from trace_scenes import scene as _scene  # noqa: E402

from psurf_core.geometry import blockers_of  # noqa: E402
from psurf_core.trace import PhotonPaths, trace  # noqa: E402

DATA = Path(__file__).resolve().parent / "data"
NPZ = DATA / "trace_expected.npz"
DIGESTS = DATA / "trace_expected.json"
BUNDLED = ("area", "area_occluder", "hg", "mesh_light", "point", "study_area", "study_medium",
           "study_occluder")


#: name -> (scene, photons, seed, max_scatter override or None, max_depth or None)
SMALL = {
    **{f"{s}": (s, 32, 10 + i, None, None) for i, s in enumerate(BUNDLED)},
    "mixed_occluders": ("mixed_occluders", 32, 30, None, None),
    "area_k2": ("area", 40, 31, 2, None),
    "hg_k3": ("hg", 40, 32, 3, None),
    "mesh_light_k1": ("mesh_light", 40, 33, 1, None),
    "point_depth1": ("point", 30, 34, None, 1),
    "area_one": ("area", 1, 35, None, None),
    "area_none": ("area", 0, 36, None, None),
    "multi_light": ("multi_light", 60, 37, None, None),
    "near_isotropic": ("near_isotropic", 40, 38, None, None),
}
LARGE = {
    "area_batch": ("area", 1 << 15, 40, None, None),
    "hg_deep": ("hg", 20_000, 41, None, None),
    "area_occluder_deep": ("area_occluder", 20_000, 42, None, None),
    "mesh_light_deep": ("mesh_light", 8_000, 43, None, None),
    "mixed_occluders_deep": ("mixed_occluders", 12_000, 44, None, None),
    "study_occluder_k4": ("study_occluder", 10_000, 45, 4, None),
    "multi_light_deep": ("multi_light", 12_000, 46, None, None),
}

FIELDS = [f.name for f in fields(PhotonPaths)]


def _run(case, reference: bool = False) -> dict[str, np.ndarray]:
    """Trace one case; every field plus the generator's next four draws (``rng_next``)."""
    name, n, seed, k, depth = case
    scene = _scene(name)
    if k is not None:
        scene = scene.with_scatter(max_scatter=k)
    rng = np.random.default_rng(seed)
    paths = trace(scene, n, rng, blockers=blockers_of(scene), max_depth=depth,
                  reference=reference)
    out = {f: np.asarray(getattr(paths, f)) for f in FIELDS}
    out["rng_next"] = rng.random(4)
    return out


#: Relative tolerance of floating-point fields (see the module docstring).
FLOAT_RTOL = 1e-12


def _summary(a: np.ndarray) -> dict:
    """What a tolerance can compare of a floating-point field: counts of NaN and +-inf, and
    over the finite entries their sum, the sum of their magnitudes and a sum weighted by
    fixed pseudo-random numbers (a change to one entry moves it)."""
    a = np.ascontiguousarray(a, float).ravel()
    fin = np.isfinite(a)
    wts = np.random.default_rng(12345).random(a.size)
    return {"nan": int(np.isnan(a).sum()), "posinf": int((a == np.inf).sum()),
            "neginf": int((a == -np.inf).sum()), "sum": float(a[fin].sum()),
            "abs": float(np.abs(a[fin]).sum()), "dot": float((a[fin] * wts[fin]).sum()),
            "shape": list(np.shape(a))}


def _keep(a: np.ndarray):
    """A large run's field as stored: a digest (exact fields) or a summary (floats)."""
    if np.asarray(a).dtype.kind == "f" and a.size:
        return _summary(a)
    return _digest(a)


def _digest(a: np.ndarray) -> str:
    a = np.ascontiguousarray(a)
    h = hashlib.sha256(f"{a.dtype.str}{a.shape}".encode())
    h.update(a.tobytes())
    return h.hexdigest()


def _mismatch(name, key, got, want) -> str:
    if got.shape != want.shape or got.dtype != want.dtype:
        return f"{name}.{key}: {got.dtype}{got.shape} != {want.dtype}{want.shape}"
    bad = np.argwhere(~((got == want) | (np.isnan(got) & np.isnan(want)) if got.dtype.kind == "f"
                        else got == want))
    return f"{name}.{key}: {len(bad)} elements differ, first at {tuple(bad[0])}"


@pytest.fixture(scope="module")
def expected_small():
    with np.load(NPZ) as z:
        return {k: z[k] for k in z.files}


IMPLEMENTATIONS = pytest.mark.parametrize("reference", [False, True],
                                          ids=["compiled", "reference"])


@IMPLEMENTATIONS
@pytest.mark.parametrize("name", sorted(SMALL))
def test_trace_arrays_frozen(name, reference, expected_small):
    got = _run(SMALL[name], reference)
    for key, a in got.items():
        want = expected_small[f"{name}/{key}"]
        assert a.dtype == want.dtype and a.shape == want.shape, _mismatch(name, key, a, want)
        if a.dtype.kind == "f" and key != "rng_next":
            np.testing.assert_allclose(a, want, rtol=FLOAT_RTOL, atol=0.0, equal_nan=True,
                                       err_msg=f"{name}.{key}")
            zero = want == 0.0
            assert np.array_equal(np.signbit(a[zero]), np.signbit(want[zero])), \
                f"{name}.{key}: signed zeros differ"
        else:
            # array_equal calls -0.0 and 0.0 equal: the bytes must match too.
            assert np.array_equal(a, want), _mismatch(name, key, a, want)
            assert a.tobytes() == want.tobytes(), f"{name}.{key}: bytes differ"


@IMPLEMENTATIONS
@pytest.mark.parametrize("name", sorted(LARGE))
def test_trace_digests_frozen(name, reference):
    want = json.loads(DIGESTS.read_text())[name]
    got = _run(LARGE[name], reference)
    bad = []
    for k, w in want.items():
        if isinstance(w, str):  # exact: a digest
            ok = _digest(got[k]) == w
        else:
            g = _summary(got[k])
            ok = all(g[c] == w[c] for c in ("nan", "posinf", "neginf", "shape")) and all(
                abs(g[c] - w[c]) <= 1e3 * FLOAT_RTOL * abs(w["abs"]) for c in ("sum", "dot")
            ) and abs(g["abs"] - w["abs"]) <= 1e3 * FLOAT_RTOL * abs(w["abs"])
        if not ok:
            bad.append(k)
    assert not bad, f"{name}: fields differ from the frozen output: {bad}"


def _write() -> None:  # pragma: no cover - fixture writer
    DATA.mkdir(exist_ok=True)
    arrays = {f"{name}/{k}": a for name, case in SMALL.items() for k, a in _run(case).items()}
    np.savez_compressed(NPZ, **arrays)
    digests = {name: {k: (_digest(a) if k == "rng_next" else _keep(a))
                      for k, a in _run(case).items()}
               for name, case in LARGE.items()}
    DIGESTS.write_text(json.dumps(digests, indent=1, sort_keys=True) + "\n")
    print(f"wrote {NPZ} ({NPZ.stat().st_size} bytes) and {DIGESTS}")


if __name__ == "__main__":  # pragma: no cover
    if sys.argv[1:] != ["--write"]:
        sys.exit(__doc__)
    _write()
