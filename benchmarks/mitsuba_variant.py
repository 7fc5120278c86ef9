"""Which Mitsuba 3 renders here: import it (an optional extra, ``bench``), point drjit at a
recent enough LLVM, and pick a variant that a subprocess probe shows rendering.

Used by :mod:`mitsuba_convert` (the scene dictionary needs the module) and
:mod:`mitsuba_scene` (the renders and the command line).
"""

from __future__ import annotations

import glob
import os
import re
import subprocess
import sys

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
