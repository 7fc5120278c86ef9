"""Reference counts and calls inside the walkers' compiled loops, read from their LLVM IR.

numba reference-counts an array at every call it is passed to (an atomic add before and
after), so a count inside a walker's loop is paid at every hit. For each walker an estimator
builds, this prints the ``NRT_incref`` calls of the walker's function outside its entry block
(where the arguments are counted once), the arrays they count, and the functions the walker
calls. It compiles in a fresh numba cache directory (inspection needs code compiled in this
process), so a run takes minutes.

Usage::

    python benchmarks/walk_ir.py [ESTIMATOR] [SCENE.toml]
    python benchmarks/walk_ir.py planes scenes/area.toml
    python benchmarks/walk_ir.py paper-multi

Not a test: it reads the IR of one numba version.
"""

from __future__ import annotations

import collections
import os
import re
import sys
import tempfile

# Before numba is imported: a cache directory of its own, so every kernel compiles here.
os.environ["NUMBA_CACHE_DIR"] = tempfile.mkdtemp(prefix="psurf-walk-ir-")
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from psurf_core.estimators import parse_estimator  # noqa: E402
from psurf_core.kernels import walk  # noqa: E402
from psurf_core.render import RenderSettings, render_pass  # noqa: E402
from psurf_core.scene_io import load_scene  # noqa: E402


def loop_counts(ir: str) -> tuple[list[str], set[str]]:
    """(arrays counted outside the entry block, call sites by function) of the walker in
    ``ir`` (LLVM intrinsics such as ``llvm.exp.f64`` included: an exponential per site)."""
    body = re.search(r"^define [^\n]*walk[^\n]*\{\n(.*?)^\}", ir, re.S | re.M).group(1)
    blocks = re.split(r"\n(?=[\w.]+:)", body)
    counted = [m for b in blocks[1:] for m in re.findall(r"NRT_incref\(ptr %([\w.]+)\)", b)]
    calls = collections.Counter(c.split("B4v")[0] for c in
                                re.findall(r"call [^@]*@([\w.$]+)", body))
    return counted, calls


def main(argv) -> int:
    spec = argv[0] if argv else "planes"
    scene = load_scene(argv[1] if len(argv) > 1 else "scenes/area.toml")
    render_pass(scene, parse_estimator(spec, scene), 0, 1, RenderSettings(photons=300))
    for fam, fn in walk._WALKERS.values():
        for ir in fn.inspect_llvm().values():
            counted, calls = loop_counts(ir)
            sites = ", ".join(f"{k} x{v}" for k, v in sorted(calls.items())
                              if not k.startswith("NRT_"))
            print(f"{fam.geometry.__name__:>20}: {len(counted)} increfs past the entry "
                  f"{sorted(set(counted))}; call sites: {sites}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
