"""Measured peak memory of one run per size against :mod:`psurf_core.budget`'s model.

Usage: ``python benchmarks/memory_model.py [--quick] [--json OUT.json]`` prints one row per
configuration: the peak RSS growth of a fresh process rendering it (``VmHWM``,
:func:`psurf_core.peak_memory.peak_rss_bytes`, after a
warm-up render of the same estimator at 32x24, so imports and compiled kernels do not count)
and what :func:`psurf_core.budget.render_need` says. The model is meant to be above every
measurement (``ratio`` = model / measured >= 1), by up to ~2-3x. ``--one JSON`` measures one
configuration (what each subprocess runs; ``tests/test_budget_measured.py`` uses it).

A configuration: ``est``, ``res`` [W, H], ``photons``, ``spp``, ``budget`` (MiB),
``max_scatter``, ``scene`` (default ``scenes/area.toml``), ``passes``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

#: The configurations of a full run: one size large at a time.
CONFIGS = [
    {"est": "planes", "res": [1024, 1024], "photons": 100},
    {"est": "planes", "res": [512, 512], "photons": 100, "spp": 4},
    {"est": "reference", "res": [512, 512], "spp": 4},
    {"est": "planes", "photons": 32768},
    {"est": "planes", "photons": 32768, "max_scatter": 3},
    {"est": "beams", "photons": 16384, "budget": 16},
    {"est": "planes", "photons": 32768, "max_scatter": 3, "budget": 2048},
    {"est": "cone", "photons": 16384, "budget": 16},
    {"est": "paper-multi", "photons": 16384, "budget": 16},
    {"est": "planes", "photons": 2000, "mesh": "ico6"},
]
QUICK = [CONFIGS[0], CONFIGS[3], CONFIGS[4]]


def _scene(cfg: dict, tmp: str):
    """The configuration's scene (a mesh light of ``icoN`` is written and loaded here)."""
    from dataclasses import replace

    from psurf_core import load_scene

    path = cfg.get("scene", str(ROOT / "scenes" / "area.toml"))
    if cfg.get("mesh"):
        import trimesh

        mesh = os.path.join(tmp, f"{cfg['mesh']}.stl")
        trimesh.creation.icosphere(subdivisions=int(cfg["mesh"][3:]), radius=0.3).export(mesh)
        text = (ROOT / "scenes" / "mesh_light.toml").read_text()
        path = os.path.join(tmp, "mesh.toml")
        Path(path).write_text(text.replace("meshes/blob.obj", mesh))
    sc = load_scene(path)
    if cfg.get("max_scatter") is not None:
        sc = sc.with_scatter(None, int(cfg["max_scatter"]))
    w, h = cfg.get("res", (64, 48))
    return replace(sc, camera=replace(sc.camera, width=int(w), height=int(h)))


def measure_one(cfg: dict) -> dict:
    """Run ``cfg`` in this (fresh) process: the peak RSS growth of loading its scene and
    rendering it, after a warm-up render, and the modelled need."""
    import tempfile

    from psurf_core import budget, parse_estimator
    from psurf_core.peak_memory import peak_rss_bytes
    from psurf_core.render import RenderSettings, render

    with tempfile.TemporaryDirectory() as tmp:
        warm = _scene({"res": (32, 24)}, tmp)
        render(warm, parse_estimator(cfg["est"], warm), RenderSettings(photons=300), passes=2)
        before = peak_rss_bytes()
        scene = _scene(cfg, tmp)
        est = parse_estimator(cfg["est"], scene)
        st = RenderSettings(photons=int(cfg.get("photons", 1000)), spp=int(cfg.get("spp", 1)),
                            memory_budget_mib=int(cfg.get("budget", 512)))
        render(scene, est, st, passes=int(cfg.get("passes", 2)))
        after = peak_rss_bytes()
    need = budget.render_need(scene, est, st)
    # Loading a mesh needs more than rendering with it (trimesh's parsing).
    load = budget.scene_triangles(scene) * (budget.TRIANGLE_LOAD_BYTES - budget.TRIANGLE_BYTES)
    measured = after - before
    model = need.total + max(load, 0)
    return {**cfg, "measured_mib": round(measured / 2**20, 1),
            "model_mib": round(model / 2**20, 1), "ratio": round(model / max(measured, 1), 2)}


def measure(cfg: dict) -> dict:
    """``cfg`` measured in a fresh subprocess."""
    r = subprocess.run([sys.executable, __file__, "--one", json.dumps(cfg)], cwd=ROOT,
                       capture_output=True, text=True, timeout=1800)
    if r.returncode != 0:
        raise RuntimeError(f"{cfg}: {r.stderr.strip()[-2000:]}")
    return json.loads(r.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="three configurations")
    p.add_argument("--json", default=None, metavar="OUT.json")
    p.add_argument("--one", default=None, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.one is not None:
        sys.path.insert(0, str(ROOT))
        print(json.dumps(measure_one(json.loads(args.one))))
        return 0
    rows = []
    for cfg in QUICK if args.quick else CONFIGS:
        row = measure(cfg)
        rows.append(row)
        print(f"{json.dumps(cfg):80s} measured {row['measured_mib']:8.1f} MiB  model "
              f"{row['model_mib']:8.1f} MiB  ratio {row['ratio']:.2f}", flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps({"argv": sys.argv, "rows": rows}, indent=1))
    return 0 if all(r["ratio"] >= 1 for r in rows) else 1


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    sys.exit(main())
