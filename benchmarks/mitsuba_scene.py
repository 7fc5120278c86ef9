"""Equal-time Mitsuba 3 renders of a psurf scene's scatter window, and their command line.

The scene is converted by :mod:`mitsuba_convert` (every convention listed there; the renders
call its ``scene_dict`` and ``integrator_dict`` through the module, ``ms.convert``, which is
what ``benchmarks/mitsuba_conventions.py --mutations`` replaces); Mitsuba and its variant are
found by :mod:`mitsuba_variant`. The functions of both that ``benchmarks/vs_mitsuba.py`` and
``tests/test_vs_mitsuba.py`` use are importable from here too (``import mitsuba_scene as ms``).

**Scatter windows**: volpath has no minimum depth, so ``[a, b]`` with ``a > 1`` is rendered as
``I(max_depth = b + 1) - I(max_depth = a)``, both with the same sampler seed in each pass:
the paths of the two renders then share their first vertices, so the difference is (nearly)
the window's own paths and much less noisy than two independent renders (about 5x less
variance on ``study_occluder``, docs/vs_mitsuba.md). Each pass's difference is one unbiased
estimate; its variance across passes is what this module reports.

As a command, ``python benchmarks/mitsuba_scene.py SCENE.toml (--time S | --passes P)
[--spp N] [--min-scatter A] [--max-scatter B] [--seed S] [--jobs J] [--variant V] --out X.npz``
renders the converted scene and writes an ``app.py render``-style .npz (``mean``, ``var``,
``sum_var``, ``passes``, ``seconds``, ``spp``, ``seed``, ``min_scatter``, ``max_scatter``,
``estimator`` = ``mitsuba-volpath:<variant>``), which ``app.py compare --reference`` also
reads.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import dataclass

import mitsuba_convert as convert
import numpy as np
from mitsuba_convert import (  # noqa: F401 - also this module's names for its users
    depth_pair,
    look_at_matrix,
    parallelogram_triangles,
)
from mitsuba_variant import import_mitsuba, pick_variant

from psurf_core.scene import Scene


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
    sum_var : (3,) float64 or None
        Sample variance across passes of one pass's image sum (over the pixels), per channel
        (zeros after one pass), as ``app.py render`` writes it.
    """

    mean: np.ndarray
    var: np.ndarray
    passes: int
    spp: int
    seconds: float
    warmup_seconds: float
    variant: str
    sum_var: np.ndarray | None = None


def save_npz(path, render: MitsubaRender, scene: Scene, seed: int) -> None:
    """Write ``render`` as an ``app.py render``-style .npz (module docstring), atomically."""
    path = os.fspath(path)
    tmp = path + ".tmp.npz"
    sums = {} if render.sum_var is None else {"sum_var": np.asarray(render.sum_var, np.float64)}
    np.savez(tmp, mean=render.mean.astype(np.float32), var=render.var.astype(np.float32),
             passes=render.passes, spp=render.spp, seconds=render.seconds, seed=int(seed),
             min_scatter=scene.min_scatter, max_scatter=scene.max_scatter,
             estimator=f"mitsuba-volpath:{render.variant}",
             warmup_seconds=render.warmup_seconds, **sums)
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
        self.mi_scene = mi.load_dict(convert.scene_dict(scene, spp=self.spp))
        hi, lo = depth_pair(scene)
        self.hi = mi.load_dict(convert.integrator_dict(hi))
        self.lo = None if lo is None else mi.load_dict(convert.integrator_dict(lo))

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
        sum_m2 = np.zeros(3)  # the same for the image sums (their deviations: delta's sums)
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
                ds = delta.sum(axis=(0, 1))
                sum_m2 += ds * ds * ((n - 1) / n)
            spent = time.perf_counter() - start
            if (passes is not None and n >= passes) or (seconds is not None and spent >= seconds):
                break
        var = m2 / (n - 1) if n > 1 else np.zeros_like(mean)
        return MitsubaRender(mean, np.maximum(var, 0.0), n, self.spp, spent, t_warm,
                             self.variant, sum_m2 / (n - 1) if n > 1 else sum_m2)


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
