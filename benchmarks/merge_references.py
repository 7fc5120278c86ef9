"""Merge reference renders of one scene into one ``.npz``: their passes pooled exactly.

A reference's noise floor falls with its pass count, and a render is bounded by one
machine's time: two renders of the same scene, estimator and pass size with *different*
seeds are independent sets of passes, and together they are the reference of all their
passes. The mean, the per-pass variance, the higher moment sums ``compare --reference``
checks tails with, the peak and the image sum's variance merge exactly
(:meth:`psurf_core.accumulate.Welford.merge`; a file's ``mean`` is float32, so the merged
mean is as exact as the files are).

Usage::

    python benchmarks/merge_references.py A.npz B.npz [C.npz ...] --out MERGED.npz

Refused (exit 2, one line naming the files and the field): a different scene file (its
SHA-256), estimator, scatter range, resolution, photons or rays per pass, a kernel radius,
or the same seed twice (the same passes again: not independent). The output keeps the first
file's provenance, with ``passes`` and ``seconds`` the totals, ``seed`` the first's and
``seeds`` all of them.
"""

from __future__ import annotations

import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from psurf_core.accumulate import Welford  # noqa: E402
from psurf_core.reliability import npz_fields  # noqa: E402
from ui.cli.common import OutputWriteError, npz_writer, write_all  # noqa: E402

#: Fields that must agree for passes to be pooled.
SAME = ("scene_sha256", "estimator", "min_scatter", "max_scatter", "photons_per_pass", "spp",
        "radius")
#: What a file needs to be merged exactly.
NEEDED = ("mean", "passes", "m2", "m3", "m4", "peak", "seed")


class MergeError(ValueError):
    """Files that cannot be pooled (the message names them and the field)."""


def accumulator(data) -> Welford:
    """The :class:`Welford` of a reference ``.npz``'s arrays."""
    n = int(data["passes"])
    sum_m2 = (np.asarray(data["sum_var"], np.float64) * max(n - 1, 0)
              if "sum_var" in data else None)
    return Welford(n, np.asarray(data["mean"], np.float64), np.array(data["m2"], np.float64),
                   np.array(data["m3"], np.float64), np.array(data["m4"], np.float64),
                   np.array(data["peak"], np.float64), sum_m2)


def merge(paths: list[str]) -> dict:
    """The merged ``.npz`` arrays of the references ``paths`` (:class:`MergeError` when
    they cannot be pooled)."""
    files = [dict(np.load(p)) for p in paths]
    first = files[0]
    for p, f in zip(paths, files, strict=True):
        missing = [k for k in NEEDED if k not in f]
        if missing:
            raise MergeError(f"{p}: no {', '.join(missing)} (written before the pass moments "
                             "were kept: cannot be merged exactly)")
        if f["mean"].shape != first["mean"].shape:
            raise MergeError(f"{p}: image {f['mean'].shape[1]}x{f['mean'].shape[0]}, "
                             f"{paths[0]} {first['mean'].shape[1]}x{first['mean'].shape[0]}")
        for k in SAME:
            if (k in f) != (k in first) or (k in f and str(f[k]) != str(first[k])):
                raise MergeError(f"{p}: {k} {f.get(k, 'missing')!s}, {paths[0]} "
                                 f"{first.get(k, 'missing')!s}")
    seeds = [int(f["seed"]) for f in files]
    if len(set(seeds)) < len(seeds):
        raise MergeError(f"seed {max(set(seeds), key=seeds.count)} twice: the same passes "
                         "again are not independent")
    acc = accumulator(first)
    for f in files[1:]:
        acc.merge(accumulator(f))
    out = dict(first)
    out.update({"mean": acc.mean.astype(np.float32),
                "var": acc.variance.astype(np.float32),
                "passes": np.int64(acc.n),
                "seconds": np.float64(sum(float(f["seconds"]) for f in files)),
                "seeds": np.array(seeds, dtype=np.int64),
                "argv": np.array(sys.argv, dtype=str)})
    out.update(npz_fields(acc))
    if acc.sum_variance is not None:
        out["sum_var"] = np.asarray(acc.sum_variance, np.float64)
    else:
        out.pop("sum_var", None)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("references", nargs="+", help="reference .npz files (app.py render)")
    ap.add_argument("--out", required=True, help="the merged .npz")
    args = ap.parse_args(argv)
    if len(args.references) < 2:
        print("merge_references: give two references or more", file=sys.stderr)
        return 2
    for p in args.references:
        if not os.path.isfile(p):
            print(f"merge_references: {p}: no such file", file=sys.stderr)
            return 2
    try:
        data = merge(args.references)
    except MergeError as e:
        print(f"merge_references: {e}", file=sys.stderr)
        return 2
    try:
        write_all([(args.out, npz_writer(data))])  # a reader never sees half a file
    except OutputWriteError as e:
        print(f"merge_references: {e}", file=sys.stderr)
        return 2
    print(f"{args.out}: {int(data['passes'])} passes of {int(data['photons_per_pass'])} "
          f"photons, {float(data['seconds']):.0f} s, seeds {', '.join(map(str, data['seeds']))}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
