"""Do two renders of one scene agree within their errors? (docs/study.md's reference checks)

Per pixel with variance, ``z = (a - b) / sqrt(var_a / n_a + var_b / n_b)`` from the two
``.npz`` files (``app.py render``'s ``mean``, per-pass ``var``, ``passes``): mean |z| (0.798
for two unbiased estimates), rms z (1), max |z|, the share over 3, the image sums' ratio and
each one's relMSE floor (``var / n / (mean^2 + 0.01 mean(mean)^2)``, pixel mean).

Usage::

    python benchmarks/reference_agreement.py A.npz B.npz
"""

from __future__ import annotations

import sys

import numpy as np


def main(a_path: str, b_path: str) -> None:
    a, b = np.load(a_path), np.load(b_path)
    ma, mb = a["mean"], b["mean"]
    va, vb = a["var"] / int(a["passes"]), b["var"] / int(b["passes"])
    m = (va + vb) > 0
    z = (ma - mb)[m] / np.sqrt((va + vb)[m])
    print(f"passes {int(a['passes'])} vs {int(b['passes'])}; "
          f"sum ratio B/A {mb.sum() / ma.sum():.5f}")
    print(f"mean |z| {np.abs(z).mean():.3f} (0.798 expected), "
          f"rms z {np.sqrt((z ** 2).mean()):.3f}, max |z| {np.abs(z).max():.2f}, "
          f"share |z| > 3 {(np.abs(z) > 3).mean():.4f}")
    for name, mean, var in (("A", ma, va), ("B", mb, vb)):
        floor = (var / (mean ** 2 + 0.01 * mean.mean() ** 2)).mean()
        print(f"relMSE floor {name} {floor:.2e}")


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2])
