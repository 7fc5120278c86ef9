"""Sum what a test run compiled (``PSURF_COMPILE_LOG=<dir>``, see ``tests/conftest.py``).

Usage::

    git clone -q /work/main /tmp/fc && cd /tmp/fc && PSURF_COMPILE_LOG=/tmp/fc_cl make test
    python benchmarks/compile_log.py /tmp/fc_cl [--top 10]

Prints the seconds of numba compilation per worker, per test file and per kernel, and the
kernels two workers compiled twice (the same cache key and argument types in two workers'
files: the on-disk cache did not have them yet when the second one needed them).
"""

from __future__ import annotations

import argparse
import collections
from pathlib import Path


def read(folder: Path) -> list[tuple[str, str, str, str, float, str]]:
    """Rows ``(worker, test, kernel, key, seconds, argument-types digest)`` (the columns
    ``tests/compile_log_support.py`` writes, after the worker its file is named by)."""
    rows = []
    for f in sorted(folder.glob("*.tsv")):
        for line in f.read_text().splitlines():
            test, name, key, sec, args = line.split("\t")
            rows.append((f.stem, test, name, key, float(sec), args))
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", type=Path)
    ap.add_argument("--top", type=int, default=10)
    a = ap.parse_args(argv)
    rows = read(a.folder)
    if not rows:
        ap.error(f"{a.folder}: no <worker>.tsv files")

    def table(title, key):
        tot, n = collections.Counter(), collections.Counter()
        for r in rows:
            tot[key(r)] += r[4]
            n[key(r)] += 1
        print(f"\n{title}: seconds (compilations)")
        for k, s in tot.most_common(a.top):
            print(f"  {s:8.1f} ({n[k]:3d})  {k}")

    print(f"{len(rows)} compilations, {sum(r[4] for r in rows):.1f} s")
    table("per worker", lambda r: r[0])
    table("per test file", lambda r: r[1].split("::")[0])
    table("per kernel", lambda r: r[2])
    seen = collections.defaultdict(list)
    for r in rows:
        seen[(r[3], r[5])].append(r)
    twice = [v for v in seen.values() if len({r[0] for r in v}) > 1]
    extra = sum(sum(r[4] for r in v) - max(r[4] for r in v) for v in twice)
    print(f"\ncompiled in more than one worker: {len(twice)} kernels, {extra:.1f} s beyond "
          "the first")
    for v in sorted(twice, key=lambda v: -sum(r[4] for r in v))[:a.top]:
        print(f"  {sum(r[4] for r in v):6.1f} s  {v[0][2]}  ({', '.join(r[0] for r in v)})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
