"""Where a point-light scene's single-scattering image sum differs: the light's own pixels or
the rest, against a deterministic pixel quadrature.

At K = 1 a point light's image has a 1/r^2 peak in the pixels about the light's projection:
every estimator is heavy-tailed there (next-event estimation to a point has no variance
bound), so an image-sum z there says little. This splits the image sum of each given render
(.npz of ``app.py render``, ``compare`` or ``benchmarks/vs_mitsuba.py``'s references) into
the light's 3x3 pixels and the rest, against

* the rest: the Gauss-Legendre pixel quadrature (``reference_quadrature.pixel_quadrature``)
  with ``--sub`` and half as many points a side (their difference: its error);
* the light's pixels: jittered sub-pixel points (``--light-sub`` strata a side, two
  independent jitters: a product rule converges erratically about the peak), ``--nodes``
  a ray;

and, with ``--estimator``, renders psurf on the light's nine pixels alone for ``--passes``
passes (``render_pass(pixels=)``: the same estimate those pixels get in a full render) and
prints its mean and standard error.

Usage::

    python benchmarks/point_light_pixels.py scenes/hg.toml RENDER.npz [...] \\
        [--sub 8] [--light-sub 128] [--nodes 2048] [--estimator fast-single --passes 1500]

docs/vs_mitsuba.md ("`hg`'s image-sum z") has a run. The scene is taken at K = 1; one point
light.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from psurf_core.camera import project  # noqa: E402
from psurf_core.estimators import parse_estimator  # noqa: E402
from psurf_core.geometry import blockers_of  # noqa: E402
from psurf_core.reference_quadrature import pixel_quadrature  # noqa: E402
from psurf_core.render import RenderSettings, render_pass  # noqa: E402
from psurf_core.scene_io import load_scene  # noqa: E402


def light_pixels(scene) -> tuple[slice, slice, np.ndarray]:
    """Rows and columns of the 3x3 pixels about the (one) point light's projection, and their
    flat indices."""
    px, py, _ = project(scene.camera, scene.lights[0].position[None])
    r, c = int(py[0]), int(px[0])
    rows, cols = slice(max(r - 1, 0), r + 2), slice(max(c - 1, 0), c + 2)
    w = scene.camera.width
    idx = np.array([i * w + j for i in range(rows.start, rows.stop)
                    for j in range(cols.start, cols.stop)])
    return rows, cols, idx


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scene")
    ap.add_argument("renders", nargs="*")
    ap.add_argument("--sub", type=int, default=8, help="0: no quadrature")
    ap.add_argument("--light-sub", type=int, default=128)
    ap.add_argument("--nodes", type=int, default=2048)
    ap.add_argument("--estimator", default=None)
    ap.add_argument("--passes", type=int, default=1500)
    ap.add_argument("--photons", type=int, default=1000)
    ap.add_argument("--spp", type=int, default=16)
    args = ap.parse_args(argv)

    scene = load_scene(args.scene).with_scatter(1, 1)
    cam = scene.camera
    rows, cols, idx = light_pixels(scene)
    mask = np.ones((cam.height, cam.width), bool)
    mask[rows, cols] = False
    if args.sub > 0:
        quadrature(scene, args, rows, cols, idx, mask)
    if args.estimator:
        rendered(scene, args, rows, cols, idx)
    return 0


def quadrature(scene, args, rows, cols, idx, mask) -> None:
    """The quadrature's two parts, and each given render's against them."""
    t = time.perf_counter()
    fine = pixel_quadrature(scene, args.sub, args.nodes)[..., 0]
    coarse = pixel_quadrature(scene, args.sub // 2, args.nodes)[..., 0]
    rest, rest_err = fine[mask].sum(), abs(fine - coarse)[mask].sum()
    light = [pixel_quadrature(scene, args.light_sub, args.nodes, pixels=idx,
                              rng=np.random.default_rng(s))[rows, cols, 0].sum()
             for s in (1, 2)]
    print(f"# {' '.join(sys.argv)}\n# quadrature ({time.perf_counter() - t:.0f} s): away from "
          f"the light {rest:.4f} (+- {rest_err:.4f}: {args.sub} vs {args.sub // 2} points a "
          f"side), the light's 3x3 pixels {light[0]:.4f}, {light[1]:.4f} (two jitters of "
          f"{args.light_sub}^2 a pixel), {args.nodes} nodes a ray; channel 0")
    for f in args.renders:
        with np.load(f) as z:
            m, passes = z["mean"][..., 0], int(z["passes"])
            se = np.sqrt(z["var"][..., 0][rows, cols].sum() / passes)
        print(f"{f}: away {m[mask].sum():.4f} ({m[mask].sum() / rest - 1:+.3%}), light's pixels "
              f"{m[rows, cols].sum():.4f} (+- {se:.3f}, per-pixel errors), "
              f"{passes} passes")


def rendered(scene, args, rows, cols, idx) -> None:
    """psurf's estimator on the light's nine pixels alone."""
    est = parse_estimator(args.estimator, scene)
    st = RenderSettings(photons=args.photons, spp=args.spp)
    bl = blockers_of(scene)
    t = time.perf_counter()
    sums = np.array([render_pass(scene, est, i, 77, st, blockers=bl, pixels=idx)[
        rows, cols, 0].sum() for i in range(args.passes)])
    print(f"{args.estimator} on the light's pixels alone: {sums.mean():.4f} +- "
          f"{sums.std(ddof=1) / np.sqrt(sums.size):.4f} ({args.passes} passes x "
          f"{args.photons} photons, {args.spp} rays a pixel, {time.perf_counter() - t:.0f} "
          f"s; median pass {np.median(sums):.2f}, largest {sums.max():.1f})")


if __name__ == "__main__":
    sys.exit(main())
