"""Trace's output is frozen: every ``PhotonPaths`` field, and the random numbers it consumes.

The screenshot baselines and the statistical tests depend on ``trace`` returning exactly the
same arrays for the same scene, photon count and generator, so its speed work must not change
a single bit. ``tests/data/trace_expected.npz`` holds the full output of small runs and
``tests/data/trace_expected.json`` the SHA-256 of every field of larger ones (deep roulette
paths, the benchmark's batch size), both written by the implementation of 2026-11-22 before
the speed work (commit 293fc23). Each case also records the next draws of the generator after
the trace: the same numbers must have been consumed.

Regenerate (only for an intended change of Trace's output):
``.venv/bin/python tests/test_trace_identity.py --write``.
"""

from __future__ import annotations

import hashlib
import json
import sys
from dataclasses import fields, replace
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
if __name__ == "__main__":  # pragma: no cover - fixture writer
    sys.path.insert(0, str(ROOT))

from psurf_core.geometry import blockers_of  # noqa: E402
from psurf_core.scene import BoxOccluder, MeshOccluder, Phase, SphereOccluder  # noqa: E402
from psurf_core.scene_io import load_scene  # noqa: E402
from psurf_core.trace import PhotonPaths, trace  # noqa: E402

DATA = Path(__file__).resolve().parent / "data"
NPZ = DATA / "trace_expected.npz"
DIGESTS = DATA / "trace_expected.json"
BUNDLED = ("area", "area_occluder", "hg", "mesh_light", "point", "study_area", "study_medium",
           "study_occluder")


def _mixed_occluders():
    """``point.toml`` with a sphere, a box and a triangle-mesh occluder (no bundled scene has a
    mesh occluder; the mesh is the mesh light's blob, shrunk and moved off the light)."""
    base = load_scene(ROOT / "scenes/point.toml")
    blob = load_scene(ROOT / "scenes/mesh_light.toml").lights[0].triangles
    tris = 0.5 * blob + np.array([0.35, -0.4, 0.2])
    occ = (SphereOccluder(center=np.array([-0.4, 0.3, 0.0]), radius=0.25),
           BoxOccluder(min=np.array([0.1, 0.2, -0.5]), max=np.array([0.5, 0.45, -0.2])),
           MeshOccluder(triangles=tris, source="blob, scaled"))
    return replace(base, occluders=occ)


def _multi_light():
    """Point, area and mesh lights in one scene (photons split between them by power), the
    mixed occluders, a backward-scattering medium with a strong albedo."""
    base = _mixed_occluders()
    point = replace(base.lights[0], intensity=base.lights[0].intensity / 12)  # power ~ the others
    lights = (point, load_scene(ROOT / "scenes/area.toml").lights[0],
              load_scene(ROOT / "scenes/mesh_light.toml").lights[0])
    med = replace(base.medium, sigma_s=1.6, sigma_a=0.1, phase=Phase("hg", -0.4))
    return replace(base, lights=lights, medium=med)


def _scene(name: str):
    if name == "mixed_occluders":
        return _mixed_occluders()
    if name == "multi_light":
        return _multi_light()
    if name == "near_isotropic":  # |g| below HG_ISOTROPIC_G: sampled as isotropic
        s = load_scene(ROOT / "scenes/hg.toml")
        return replace(s, medium=replace(s.medium, phase=Phase("hg", 5e-4)))
    return load_scene(ROOT / f"scenes/{name}.toml")


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


def _run(case) -> dict[str, np.ndarray]:
    """Trace one case; every field plus the generator's next four draws (``rng_next``)."""
    name, n, seed, k, depth = case
    scene = _scene(name)
    if k is not None:
        scene = scene.with_scatter(max_scatter=k)
    rng = np.random.default_rng(seed)
    paths = trace(scene, n, rng, blockers=blockers_of(scene), max_depth=depth)
    out = {f: np.asarray(getattr(paths, f)) for f in FIELDS}
    out["rng_next"] = rng.random(4)
    return out


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


@pytest.mark.parametrize("name", sorted(SMALL))
def test_trace_arrays_frozen(name, expected_small):
    got = _run(SMALL[name])
    for key, a in got.items():
        want = expected_small[f"{name}/{key}"]
        assert a.dtype == want.dtype and a.shape == want.shape, _mismatch(name, key, a, want)
        assert np.array_equal(a, want), _mismatch(name, key, a, want)
        # array_equal calls -0.0 and 0.0 equal: the bytes must match too.
        assert a.tobytes() == want.tobytes(), f"{name}.{key}: bytes differ (signed zeros?)"


@pytest.mark.parametrize("name", sorted(LARGE))
def test_trace_digests_frozen(name):
    want = json.loads(DIGESTS.read_text())[name]
    got = {k: _digest(a) for k, a in _run(LARGE[name]).items()}
    bad = sorted(k for k in want if got[k] != want[k])
    assert not bad, f"{name}: fields differ from the frozen output: {bad}"


def _write() -> None:  # pragma: no cover - fixture writer
    DATA.mkdir(exist_ok=True)
    arrays = {f"{name}/{k}": a for name, case in SMALL.items() for k, a in _run(case).items()}
    np.savez_compressed(NPZ, **arrays)
    digests = {name: {k: _digest(a) for k, a in _run(case).items()}
               for name, case in LARGE.items()}
    DIGESTS.write_text(json.dumps(digests, indent=1, sort_keys=True) + "\n")
    print(f"wrote {NPZ} ({NPZ.stat().st_size} bytes) and {DIGESTS}")


if __name__ == "__main__":  # pragma: no cover
    if sys.argv[1:] != ["--write"]:
        sys.exit(__doc__)
    _write()


def test_plane_skip_is_sound():
    """``trace_kernels._misses_plane`` (which lets Trace skip ``Blockers.occluded``) never
    says "misses" where ``geometry._crosses_plane`` says "crosses": segments leaving the
    plane (as from an area light), grazing it, ending on it, crossing it near either end."""
    from psurf_core.constants import SHADOW_EPS
    from psurf_core.geometry import _crosses_plane
    from psurf_core.trace_kernels import _misses_plane

    rng = np.random.default_rng(3)
    light = load_scene(ROOT / "scenes/area.toml").lights[0]
    nq = np.cross(light.edge_u, light.edge_v)
    plane = np.append(nq, nq @ light.corner)
    m = 20_000
    uv = rng.random((m, 2))
    on = light.corner + uv[:, :1] * light.edge_u + uv[:, 1:] * light.edge_v
    d = rng.normal(size=(m, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    k = m // 4  # grazing directions: normal component down to 1e-12
    d[:k, 1] = rng.choice([-1, 1], k) * 10.0 ** rng.uniform(-12, -3, k)
    length = 10.0 ** rng.uniform(-7, 0.5, m)
    cases = [
        (on, on + length[:, None] * d),  # leaving the plane
        (on + length[:, None] * d, on),  # arriving on it
        (on - SHADOW_EPS * d, on + length[:, None] * d),  # crossing just after the start
        (on - length[:, None] * d, on + 0.5 * SHADOW_EPS * rng.random((m, 1)) * d),  # near end
        (on + 0.3 * d, on + 0.7 * d),  # clear of it, either side
    ]
    half = 0.5 * SHADOW_EPS
    decided = []
    for a, b in cases:
        misses = np.array([_misses_plane(*a[i], *b[i], plane, half) for i in range(m)])
        # BLAS rounds a row's dot product by the array it is in: try several.
        for sub in (np.s_[:], np.s_[1:4099], np.s_[7:10], np.s_[::3]):
            assert not np.any(misses[sub] & _crosses_plane(a[sub], b[sub], plane))
        decided.append(misses.mean())
    # It decides the segments that leave the plane (but the most grazing) and those clear
    # of it; it leaves crossings near either end to the exact test.
    assert decided[0] > 0.7 and decided[4] == 1.0, decided


def test_search_right_is_searchsorted():
    """Emission's compiled search picks what ``numpy.searchsorted(side="right")`` picks:
    ties, repeated cdf values, NaN, keys outside [0, 1]."""
    from psurf_core.trace_kernels import search_right

    rng = np.random.default_rng(0)
    for k in (1, 2, 3, 7, 320):
        for cdf in (np.cumsum(rng.random(k)), np.sort(rng.integers(1, 4, k)).astype(float),
                    np.r_[np.cumsum(rng.random(k)), [np.nan] * 3]):
            u = np.r_[rng.random(2000), cdf[:50], [0.0, 1.0, np.nan, -1.0, 2.0, np.inf]]
            out = np.empty(u.size, dtype=np.intp)
            search_right(cdf, u, out)
            assert np.array_equal(out, np.searchsorted(cdf, u, side="right")), (k, cdf[:4])
