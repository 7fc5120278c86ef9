"""The path tracer on ``scenes/dense_mesh_light.toml`` (issue 15): the measurements behind the
diagnosis in ``psurf_core/reference.py`` and ``docs/reference.md``.

Subcommands (every render is deterministic: same arguments, same numbers)::

    python benchmarks/reference_dense.py oracle --res 32x24 --passes 197 --out pf.npz
        paper-full, 5000 photons per pass, seed 1000: the independent estimate
    python benchmarks/reference_dense.py runs --res 32x24 --strategy mis-free-flight \\
        --passes 800 --seeds 0,1,2,3 --out DIR
        reference runs of one sampler strategy (psurf_core.reference.STRATEGIES), each
        DIR/<strategy>_<seed>.npz with mean, m2, m3, m4, peak, passes and the CPU seconds
    python benchmarks/reference_dense.py report pf.npz DIR
        per strategy: per-pixel z against the oracle (mean |z|, share |z| > 3), the median
        pixel and the image sum over the oracle's, the share of pixels the reliability
        check flags (psurf_core.reliability)
    python benchmarks/reference_dense.py samples --res 64x48 --spp 256 --strategy S
        one pass of SPP rays per pixel broken down by scatter count and direct-light
        technique (reference_pass's tally): shares of the image, of the dark half's second
        moment, and of the largest 0.1 % contributions
    python benchmarks/reference_dense.py flags --passes 200 scenes/area.toml ...
        the share of pixels psurf_core.reliability flags after PASSES reference passes
        (seed 0) of each scene, as compare would check a reference it renders
"""

from __future__ import annotations

import argparse
import functools
import glob
import os
import sys
import time
from dataclasses import replace

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from psurf_core import reference as ref_mod  # noqa: E402
from psurf_core import reliability as rl  # noqa: E402
from psurf_core.camera import camera_rays  # noqa: E402
from psurf_core.estimators import parse_estimator  # noqa: E402
from psurf_core.geometry import blockers_of  # noqa: E402
from psurf_core.render import RenderSettings, render  # noqa: E402
from psurf_core.scene_io import load_scene  # noqa: E402

SCENE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "scenes",
                     "dense_mesh_light.toml")


def _scene(res: str):
    w, h = (int(v) for v in res.split("x"))
    s = load_scene(SCENE)
    return replace(s, camera=replace(s.camera, width=w, height=h))


def oracle(args) -> None:
    s = _scene(args.res)
    c0 = time.process_time()
    r = render(s, parse_estimator("paper-full", s), RenderSettings(photons=5000),
               passes=args.passes, seed=1000)
    np.savez(args.out, mean=r.mean, var=r.var, passes=r.passes,
             cpu=time.process_time() - c0)
    print(f"paper-full {args.res}: {r.passes} passes x 5000 photons, "
          f"{time.process_time() - c0:.0f} s CPU -> {args.out}")


def runs(args) -> None:
    s = _scene(args.res)
    # The estimator registry knows the default sampler only: the others by a partial.
    orig = ref_mod.reference_pass
    ref_mod.reference_pass = functools.partial(orig, strategy=args.strategy)
    try:
        est = parse_estimator("reference", s)
        os.makedirs(args.out, exist_ok=True)
        for seed in (int(v) for v in args.seeds.split(",")):
            c0 = time.process_time()
            acc = render(s, est, RenderSettings(spp=args.spp), passes=args.passes,
                         seed=seed).accumulator
            cpu = time.process_time() - c0
            path = os.path.join(args.out, f"{args.strategy}_{seed}.npz")
            np.savez(path, mean=acc.mean, m2=acc.m2, m3=acc.m3, m4=acc.m4, peak=acc.peak,
                     passes=acc.n, cpu=cpu)
            print(f"{args.strategy} seed {seed}: {acc.n} passes, {cpu:.1f} s CPU "
                  f"({cpu / acc.n:.4f} s/pass) -> {path}", flush=True)
    finally:
        ref_mod.reference_pass = orig


def report(args) -> None:
    pf = np.load(args.oracle)
    p = pf["mean"][..., 0]
    p_se = np.sqrt(pf["var"][..., 0] / int(pf["passes"]))
    lit = p > 0
    print(f"oracle: paper-full, {int(pf['passes'])} passes, {lit.sum()} lit pixels, median "
          f"relative standard error {np.median(p_se[lit] / p[lit]):.4f}")
    print("| strategy | passes | CPU s/run | mean abs z | abs z > 3 | median pixel / oracle | "
          "image sum / oracle | flagged | mean abs z flagged / not | pooled mean abs z | "
          "pooled median / oracle |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    by = {}
    for f in sorted(glob.glob(os.path.join(args.runs, "*_*.npz"))):
        by.setdefault(os.path.basename(f).rsplit("_", 1)[0], []).append(f)
    for strat, files in by.items():
        rows, means, ses = [], [], []
        for f in files:
            d = np.load(f)
            n = int(d["passes"])
            m, se = d["mean"][..., 0], np.sqrt(d["m2"][..., 0] / (n - 1) / n)
            with np.errstate(divide="ignore", invalid="ignore"):  # unlit pixels: 0 / 0
                z = (m - p) / np.sqrt(se**2 + p_se**2)
            rel = rl.pixel_reliability(n, d["mean"], d["m2"], d["m3"], d["m4"], d["peak"])
            flag = rel.unreliable & lit
            rows.append((n, float(d["cpu"]), np.abs(z[lit]).mean(), np.mean(np.abs(z[lit]) > 3),
                         np.median(m[lit] / p[lit]), m[lit].sum() / p[lit].sum(),
                         rel.unreliable[rel.varies].mean(),
                         np.abs(z[flag]).mean() if flag.any() else np.nan,
                         np.abs(z[lit & ~flag]).mean()))
            means.append(m)
            ses.append(se)
        r = np.array(rows)
        mm = np.mean(means, axis=0)
        ss = np.sqrt(np.mean(np.square(ses), axis=0) / len(ses))
        with np.errstate(divide="ignore", invalid="ignore"):
            zp = (mm - p) / np.sqrt(ss**2 + p_se**2)

        def rng(col, fmt, r=r):
            lo, hi, mid = r[:, col].min(), r[:, col].max(), r[:, col].mean()
            return f"{mid:{fmt}} ({lo:{fmt}}-{hi:{fmt}})" if len(r) > 1 else f"{mid:{fmt}}"

        print(f"| `{strat}` x{len(r)} | {int(r[0, 0])} | {r[:, 1].mean():.0f} | {rng(2, '.2f')} | "
              f"{100 * r[:, 3].mean():.1f} % | {rng(4, '.3f')} | {rng(5, '.4f')} | "
              f"{100 * r[:, 6].mean():.0f} % | {np.nanmean(r[:, 7]):.2f} / {r[:, 8].mean():.2f} | "
              f"{np.abs(zp[lit]).mean():.2f} | "
              f"{np.median(mm[lit] / p[lit]):.3f} |")


def samples(args) -> None:
    s = _scene(args.res)
    bl = blockers_of(s)
    rays = camera_rays(s, args.spp, np.random.default_rng(1), blockers=bl)
    parts: dict = {}

    def tally(k, tech, idx, val):
        parts.setdefault((k, tech), []).append((idx, val[:, 0]))

    est = ref_mod.reference_pass(s, rays, np.random.default_rng(2), bl,
                                 strategy=args.strategy, tally=tally)[:, 0]
    n = len(rays)
    m = est.reshape(-1, args.spp).mean(axis=1)
    dark = (m > 0) & (m <= np.median(m[m > 0]))  # the darker half of the lit pixels
    in_dark = dark[rays.pixel]
    every = np.concatenate([v for batch in parts.values() for _, v in batch])
    top = np.quantile(every[every > 0], 0.999)
    e = est.reshape(-1, args.spp)
    lit = m > 0
    relvar = e[lit].var(axis=1, ddof=1) / m[lit] ** 2
    print(f"{args.strategy}, {args.res}, {args.spp} rays per pixel: image mean {est.mean():.5f}, "
          f"relative variance per ray of the median lit pixel {np.median(relvar):.1f}; the "
          f"largest 0.1 % of the {np.count_nonzero(every)} non-zero contributions hold "
          f"{every[every >= top].sum() / every.sum():.1%} of the image")
    print("| K | technique | samples > 0 | share of the image | share of the dark half's "
          "second moment | in the top 0.1 % |")
    print("|---:|---|---:|---:|---:|---:|")
    second = (est[in_dark] ** 2).sum()
    for (k, tech) in sorted(parts):
        per_ray = np.zeros(n)
        for idx, v in parts[k, tech]:
            per_ray[idx] += v
        vals = np.concatenate([v for _, v in parts[k, tech]])
        print(f"| {k} | {tech} | {np.count_nonzero(vals)} | {per_ray.sum() / est.sum():.3f} | "
              f"{(per_ray[in_dark] ** 2).sum() / second:.3f} | {(vals >= top).sum()} |")


def flags(args) -> None:
    for f in args.scenes:
        s = load_scene(f)
        c0 = time.process_time()
        r = render(s, parse_estimator("reference", s), RenderSettings(), passes=args.passes,
                   seed=0)
        sm = rl.summarize(rl.of_accumulator(r.accumulator))
        print(f"{f}: {args.passes} passes, {time.process_time() - c0:.0f} s CPU, flagged "
              f"{sm['unreliable']} of {sm['pixels']} ({100 * sm['fraction']:.1f} %), largest "
              f"skewness of the mean {sm['worst_skew_of_mean']:.2f}, warn: {sm['warn']}",
              flush=True)


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    o = sub.add_parser("oracle")
    o.add_argument("--res", default="32x24")
    o.add_argument("--passes", type=int, default=197)
    o.add_argument("--out", required=True)
    r = sub.add_parser("runs")
    r.add_argument("--res", default="32x24")
    r.add_argument("--strategy", default="mis", choices=ref_mod.STRATEGIES)
    r.add_argument("--passes", type=int, required=True)
    r.add_argument("--spp", type=int, default=1)
    r.add_argument("--seeds", default="0,1,2,3")
    r.add_argument("--out", required=True)
    rp = sub.add_parser("report")
    rp.add_argument("oracle")
    rp.add_argument("runs")
    sp = sub.add_parser("samples")
    sp.add_argument("--res", default="64x48")
    sp.add_argument("--spp", type=int, default=256)
    sp.add_argument("--strategy", default="mis", choices=ref_mod.STRATEGIES)
    fl = sub.add_parser("flags")
    fl.add_argument("--passes", type=int, default=200)
    fl.add_argument("scenes", nargs="+")
    a = p.parse_args(argv)
    {"oracle": oracle, "runs": runs, "report": report, "samples": samples,
     "flags": flags}[a.cmd](a)


if __name__ == "__main__":
    main()
