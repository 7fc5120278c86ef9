"""Memory: the rays x primitives work is chunked by ``--memory-budget`` (RenderSettings.max_pairs).

One render whose full rays x primitives arrays would need more than 4 GiB (64x48 pixels x
4 spp = 12288 camera rays against ~15000 long photon planes, every pair a binning candidate
because a long plane spans the whole box: 12288 x 15000 pairs x 8 bytes x 3 coordinates =
4.4 GiB) runs with ``--memory-budget 1024`` and its peak resident memory grows by less than
1 GiB. It runs through ``app.main`` in a fresh subprocess that measures its own peak RSS
(:func:`psurf_core.peak_memory.peak_rss_bytes`: ``VmHWM``, not ``ru_maxrss``, which a child
inherits from its parent, this pytest process) after a warm-up render, so imports and caches do
not count.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from psurf_core.geometry import blockers_of
from psurf_core.render import PHOTON_BATCH, RenderSettings, kernel_radius, pass_generators
from psurf_core.scene_io import load_scene
from psurf_core.techniques import get_technique
from psurf_core.techniques.base import PassContext
from psurf_core.trace import trace

ROOT = Path(__file__).resolve().parent.parent
PHOTONS = 15000
SPP = 4
BUDGET_MIB = 1024

#: A point light (no emitter surface to shadow-test against, which keeps the test fast), two
#: scattering events only (one long plane per photon), and a field of view the box fills, so
#: that every camera ray sees the medium and meets every plane's screen rectangle.
SCENE = """\
[camera]
position   = [0.0, 0.0, -4.0]
look_at    = [0.0, 0.0, 0.0]
up         = [0.0, 1.0, 0.0]
fov_y      = 25.0
resolution = [64, 48]

[medium]
bounds_min = [-1.0, -1.0, -1.0]
bounds_max = [ 1.0,  1.0,  1.0]
sigma_s = 0.8
sigma_a = 0.2
phase   = { type = "isotropic" }

[[lights]]
type = "point"
position  = [0.3, 0.4, 0.1]
intensity = [4.0, 4.0, 4.0]

[render]
min_scatter = 2
max_scatter = 2
"""

CHILD = textwrap.dedent("""\
    import json, sys, time
    import app
    from psurf_core.peak_memory import peak_rss_bytes

    scene, out = sys.argv[1], sys.argv[2]
    common = ["render", scene, "--estimator", "plane-t1t2", "--spp", "{spp}", "--passes", "1",
              "--memory-budget", "{budget}"]
    assert app.main([*common, "--photons", "50", "--out", out]) == 0  # warm-up
    base = peak_rss_bytes()
    t = time.perf_counter()
    code = app.main([*common, "--photons", "{photons}", "--out", out])
    seconds = time.perf_counter() - t
    peak = peak_rss_bytes()
    print(json.dumps({{"code": code, "base_bytes": base, "peak_bytes": peak, "seconds": seconds}}))
""").format(spp=SPP, budget=BUDGET_MIB, photons=PHOTONS)


def _full_array_bytes(scene_path: Path) -> tuple[int, int, int]:
    """(rays, primitives, bytes of one float64 (rays x prims x 3) array) of pass 0."""
    scene = load_scene(scene_path)
    tech = get_technique("plane-t1t2")
    settings = RenderSettings(photons=PHOTONS, spp=SPP, memory_budget_mib=BUDGET_MIB)
    _, photon_ss = pass_generators(0, 0)
    assert PHOTONS <= PHOTON_BATCH  # one batch: the pass traces exactly these photons
    blockers = blockers_of(scene)
    paths = trace(scene, PHOTONS, np.random.default_rng(photon_ss.spawn(1)[0]),
                  blockers=blockers)
    ctx = PassContext(scene, blockers, kernel_radius(tech, scene, settings, 0), 0,
                      settings.max_pairs)
    prims = len(tech.create(paths, ctx))
    rays = scene.camera.n_pixels * SPP
    return rays, prims, rays * prims * 8 * 3


@pytest.mark.skipif(sys.platform == "win32", reason="resource.getrusage is POSIX")
def test_render_needing_4_gib_of_pairs_runs_in_a_1_gib_budget(tmp_path):
    scene = tmp_path / "planes.toml"
    scene.write_text(SCENE)
    rays, prims, full = _full_array_bytes(scene)
    assert full > 4 * 2**30, (rays, prims, full)
    r = subprocess.run([sys.executable, "-c", CHILD, str(scene), str(tmp_path / "out.npz")],
                       cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    m = json.loads(r.stdout.strip().splitlines()[-1])
    assert m["code"] == 0
    grown_mib = (m["peak_bytes"] - m["base_bytes"]) / 2**20
    print(f"\n{rays} rays x {prims} planes: full arrays {full / 2**30:.2f} GiB; peak RSS grew "
          f"{grown_mib:.0f} MiB (budget {BUDGET_MIB} MiB) in {m['seconds']:.1f} s")
    assert grown_mib < BUDGET_MIB
    with np.load(tmp_path / "out.npz") as d:
        assert np.all(np.isfinite(d["mean"])) and d["mean"].mean() > 0
        assert int(d["memory_budget_mib"]) == BUDGET_MIB
