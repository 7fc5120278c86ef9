"""``python app.py ...`` in a child process, as a user runs it: the one helper of every test
that checks the command line end to end (exit status, stderr, files written).

The child gets no display (``DISPLAY``/``WAYLAND_DISPLAY`` removed: the window never opens in
a test), matplotlib's off-screen backend, and the project root on ``PYTHONPATH`` (a child in
a temporary directory imports ``psurf_core`` and ``benchmarks`` from this checkout).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
APP = ROOT / "app.py"


def app_env() -> dict[str, str]:
    """The child's environment (module docstring)."""
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    env["MPLBACKEND"] = "Agg"
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")])
    return env


def run_app(*args, cwd: Path = ROOT, timeout: float = 120.0,
            check: bool = False) -> subprocess.CompletedProcess:
    """Run ``python app.py *args`` (each argument ``str()``-ed) in ``cwd``; stdout and
    stderr captured as text. ``check``: raise when it exits non-zero."""
    return subprocess.run([sys.executable, str(APP), *map(str, args)], cwd=cwd, env=app_env(),
                          capture_output=True, text=True, timeout=timeout, check=check)
