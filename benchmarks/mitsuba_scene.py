"""A psurf scene as a Mitsuba 3 scene, and equal-time Mitsuba renders of its scatter window.

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
  scattering). Unlimited
  (``max_scatter = -1``) is ``MAX_TRACE_DEPTH + 1``: psurf's own cap, so both images hold the
  same paths. ``rr_depth`` keeps Mitsuba's default.
* **scatter windows**: volpath has no minimum depth, so ``[a, b]`` with ``a > 1`` is rendered as
  ``I(max_depth = b + 1) - I(max_depth = a)``, both with the same sampler seed in each pass:
  the paths of the two renders then share their first vertices, so the difference is (nearly)
  the window's own paths and much less noisy than two independent renders (about 5x less
  variance on ``study_occluder``, docs/vs_mitsuba.md). Each pass's
  difference is one unbiased estimate; its variance across passes is what this module reports.

Mitsuba is imported lazily (:func:`import_mitsuba`): it is an optional extra (``bench``).

As a command, ``python benchmarks/mitsuba_scene.py SCENE.toml (--time S | --passes P)
[--spp N] [--min-scatter A] [--max-scatter B] [--seed S] [--jobs J] [--variant V] --out X.npz``
renders the converted scene and writes an ``app.py render``-style .npz (``mean``, ``var``,
``passes``, ``seconds``, ``spp``, ``seed``, ``min_scatter``, ``max_scatter``, ``estimator`` =
``mitsuba-volpath:<variant>``), which ``app.py compare --reference`` also reads.
"""

from __future__ import annotations

import argparse
import glob
import os
import re
import subprocess
import sys
import time
from dataclasses import dataclass

import numpy as np

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

#: Variants tried in order: LLVM (vectorised, JIT-compiled) first, the scalar one as fallback.
VARIANTS = ("llvm_ad_rgb", "scalar_rgb")

_PROBE = """
import mitsuba as mi
mi.set_variant({variant!r})
s = mi.load_dict({{'type': 'scene', 'integrator': {{'type': 'volpath', 'max_depth': 3}},
    'sensor': {{'type': 'perspective', 'film': {{'type': 'hdrfilm', 'width': 4, 'height': 3}}}},
    'm': {{'type': 'sphere', 'interior': {{'type': 'homogeneous', 'sigma_t': 1.0,
           'albedo': 0.5}}, 'bsdf': {{'type': 'null'}}, 'to_world':
           mi.ScalarTransform4f().translate([0, 0, 3])}},
    'l': {{'type': 'point', 'position': [0, 0, 3], 'intensity': {{'type': 'rgb',
           'value': [1, 1, 1]}}}}}})
mi.render(s, spp=4)
print('ok')
"""


#: Oldest LLVM tried for drjit 1.5's LLVM backend: 15 and 16 abort ("Cannot select:
#: fminimum"), 19 works; 17 and 18 (not in Debian 12) are untested.
MIN_LLVM = 17


def newest_llvm(min_version: int = MIN_LLVM) -> str | None:
    """Path of the newest ``libLLVM`` shared library of at least ``min_version``, or ``None``."""
    best, best_v = None, -1
    paths = glob.glob("/usr/lib/*/libLLVM*.so*") + glob.glob("/usr/lib/llvm-*/lib/libLLVM*.so*")
    for path in paths:
        m = re.search(r"libLLVM(?:-|\.so\.)(\d+)", os.path.basename(path))
        if m and int(m.group(1)) >= min_version and int(m.group(1)) > best_v:
            best, best_v = path, int(m.group(1))
    return best


def import_mitsuba():
    """The ``mitsuba`` module, or ``None`` when it is not installed (the ``bench`` extra).

    Points drjit at :func:`newest_llvm` (``DRJIT_LIBLLVM_PATH``) unless that is already set:
    drjit may otherwise load an older LLVM that cannot compile its kernels.
    """
    if "DRJIT_LIBLLVM_PATH" not in os.environ and (lib := newest_llvm()) is not None:
        os.environ["DRJIT_LIBLLVM_PATH"] = lib
    try:
        import mitsuba
    except ImportError:
        return None
    return mitsuba


def probe_variant(variant: str, timeout: float = 300.0) -> tuple[bool, str]:
    """Whether ``variant`` renders here, tried in a subprocess.

    An LLVM variant needs an LLVM shared library that drjit can compile with (LLVM 19 from
    Debian works with drjit 1.5; LLVM 15 and 16 abort the process with "Cannot select:
    fminimum"), so the probe must not run in this process.

    Returns
    -------
    ok : bool
    detail : str
        The probe's last line of output (the error, when it failed).
    """
    try:
        r = subprocess.run([sys.executable, "-c", _PROBE.format(variant=variant)],
                           capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return False, f"probe timed out after {timeout:g} s"
    out = (r.stdout + r.stderr).strip().splitlines()
    ok = r.returncode == 0 and bool(out) and out[-1] == "ok"
    return ok, (out[-1] if out else f"exit code {r.returncode}")[:200]


def pick_variant(requested: str | None = None) -> str:
    """Set and return the Mitsuba variant: ``requested``, or the first of :data:`VARIANTS`
    that passes :func:`probe_variant` (``PSURF_MITSUBA_VARIANT`` overrides the search)."""
    mi = import_mitsuba()
    if mi is None:
        raise RuntimeError("mitsuba is not installed: pip install -e '.[bench]'")
    want = requested or os.environ.get("PSURF_MITSUBA_VARIANT")
    if want:
        mi.set_variant(want)
        return want
    problems = []
    for v in VARIANTS:
        if v not in mi.variants():
            continue
        ok, detail = probe_variant(v)
        if ok:
            mi.set_variant(v)
            return v
        problems.append(f"{v}: {detail}")
    raise RuntimeError("no Mitsuba variant renders here: " + "; ".join(problems))


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


def pass_seed(seed: int, n: int, tag: int = 0) -> int:
    """32-bit sampler seed of pass ``n`` of a render with seed ``seed`` (``tag`` 0: counted
    passes, 1: warm-up, 2: calibration), from ``SeedSequence([seed, n, tag])`` as psurf's
    passes draw theirs: distinct for every pass and seed, and any ``seed >= 0`` fits."""
    return int(np.random.SeedSequence([int(seed), int(n), int(tag)]).generate_state(1)[0])


@dataclass
class MitsubaRender:
    """Accumulated Mitsuba passes of one scatter window (the psurf ``render`` .npz fields).

    Attributes
    ----------
    mean, var : (H, W, 3) float64
        Mean of the passes and the per-pixel sample variance of one pass across passes
        (zeros after one pass), as ``app.py render`` writes them.
    passes, spp : int
        Passes and samples per pixel per pass (per render of a window's difference).
    seconds : float
        Wall time of the passes (after the warm-up that compiles the kernels).
    warmup_seconds : float
    variant : str
    """

    mean: np.ndarray
    var: np.ndarray
    passes: int
    spp: int
    seconds: float
    warmup_seconds: float
    variant: str


def save_npz(path, render: MitsubaRender, scene: Scene, seed: int) -> None:
    """Write ``render`` as an ``app.py render``-style .npz (module docstring), atomically."""
    path = os.fspath(path)
    tmp = path + ".tmp.npz"
    np.savez(tmp, mean=render.mean.astype(np.float32), var=render.var.astype(np.float32),
             passes=render.passes, spp=render.spp, seconds=render.seconds, seed=int(seed),
             min_scatter=scene.min_scatter, max_scatter=scene.max_scatter,
             estimator=f"mitsuba-volpath:{render.variant}",
             warmup_seconds=render.warmup_seconds)
    os.replace(tmp, path)


class MitsubaRenderer:
    """Renders a psurf scene's scatter window with Mitsuba's ``volpath``, pass by pass.

    Parameters
    ----------
    scene : Scene
        Its ``[min_scatter, max_scatter]`` is the window (:func:`depth_pair`).
    spp : int
        Samples per pixel per pass.
    threads : int or None
        Dr.Jit's thread count (LLVM variants; ``None`` keeps its default, all cores).
    """

    def __init__(self, scene: Scene, spp: int = 16, threads: int | None = 2):
        mi = import_mitsuba()
        if mi is None:
            raise RuntimeError("mitsuba is not installed: pip install -e '.[bench]'")
        self.mi = mi
        self.variant = mi.variant()
        if self.variant is None:
            raise RuntimeError("set a Mitsuba variant first (pick_variant)")
        if threads is not None and self.variant.startswith("llvm"):
            import drjit as dr

            dr.set_thread_count(int(threads))
        self.scene = scene
        self.spp = int(spp)
        self.mi_scene = mi.load_dict(scene_dict(scene, spp=self.spp))
        hi, lo = depth_pair(scene)
        self.hi = mi.load_dict(integrator_dict(hi))
        self.lo = None if lo is None else mi.load_dict(integrator_dict(lo))

    def pass_image(self, seed: int) -> np.ndarray:
        """(H, W, 3) float64 estimate of the window from one pass with sampler seed ``seed``."""
        mi = self.mi
        img = np.array(mi.render(self.mi_scene, integrator=self.hi, seed=int(seed),
                                 spp=self.spp), dtype=np.float64)
        if self.lo is not None:
            img -= np.array(mi.render(self.mi_scene, integrator=self.lo, seed=int(seed),
                                      spp=self.spp), dtype=np.float64)
        return img[..., :3]

    def render(self, *, passes: int | None = None, seconds: float | None = None,
               seed: int = 0, warmup: bool = True) -> MitsubaRender:
        """Run passes ``i = 0, 1, ...`` with sampler seeds :func:`pass_seed` ``(seed, i)`` until
        ``passes`` are done or ``seconds`` of wall time are spent (the pass in flight finishes;
        at least one pass).

        The warm-up pass (a different seed, not counted) compiles the kernels outside the
        clock, as psurf's ``render --time`` compiles before its clock starts.
        """
        if (passes is None) == (seconds is None):
            raise ValueError("give exactly one of passes and seconds")
        t0 = time.perf_counter()
        if warmup:
            self.pass_image(seed=pass_seed(seed, 0, tag=1))
        t_warm = time.perf_counter() - t0
        mean = m2 = None  # Welford's running mean and sum of squared deviations
        n = 0
        start = time.perf_counter()
        while True:
            img = self.pass_image(seed=pass_seed(seed, n))
            n += 1
            if mean is None:
                mean, m2 = img.copy(), np.zeros_like(img)
            else:
                delta = img - mean
                mean += delta / n
                m2 += delta * (img - mean)
            spent = time.perf_counter() - start
            if (passes is not None and n >= passes) or (seconds is not None and spent >= seconds):
                break
        var = m2 / (n - 1) if n > 1 else np.zeros_like(mean)
        return MitsubaRender(mean, np.maximum(var, 0.0), n, self.spp, spent, t_warm,
                             self.variant)


def main(argv=None) -> int:
    """Command line (module docstring)."""
    from psurf_core.scene_io import load_scene

    ap = argparse.ArgumentParser(description="Render a psurf scene with Mitsuba's volpath.")
    ap.add_argument("scene", metavar="SCENE.toml")
    budget = ap.add_mutually_exclusive_group(required=True)
    budget.add_argument("--time", type=float, help="seconds of wall time (after a warm-up)")
    budget.add_argument("--passes", type=int)
    ap.add_argument("--spp", type=int, default=16, help="samples per pixel per pass")
    ap.add_argument("--min-scatter", type=int, default=None)
    ap.add_argument("--max-scatter", type=int, default=None)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--jobs", type=int, default=2, help="Dr.Jit threads")
    ap.add_argument("--variant", default=None)
    ap.add_argument("--out", required=True, metavar="OUT.npz")
    args = ap.parse_args(argv)
    variant = pick_variant(args.variant)
    scene = load_scene(args.scene).with_scatter(args.min_scatter, args.max_scatter)
    r = MitsubaRenderer(scene, spp=args.spp, threads=args.jobs).render(
        passes=args.passes, seconds=args.time, seed=args.seed)
    save_npz(args.out, r, scene, args.seed)
    print(f"mitsuba {variant}: {r.passes} passes x {r.spp} spp, {r.seconds:.2f} s "
          f"(warm-up {r.warmup_seconds:.2f} s) -> {args.out}")
    return 0


if __name__ == "__main__":
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    sys.exit(main())
