"""Benchmark scripts under test: ``benchmarks/`` is not a package, so its scripts are loaded
from their files (:func:`load_benchmark`) or run in a child process (:func:`run_benchmark`,
for the scripts that patch modules or clock whole renders)."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path
from types import ModuleType

ROOT = Path(__file__).resolve().parent.parent


def load_benchmark(name: str) -> ModuleType:
    """The module of ``benchmarks/<name>.py``, executed (its ``main`` not run)."""
    spec = importlib.util.spec_from_file_location(name, ROOT / "benchmarks" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def run_benchmark(name: str, *args, check: bool = True,
                  timeout: float = 600.0) -> subprocess.CompletedProcess:
    """``python benchmarks/<name>.py ARGS`` from the project root; text output captured.
    ``check`` raises on a non-zero exit (the tests of exit codes pass ``check=False``)."""
    return subprocess.run([sys.executable, str(ROOT / "benchmarks" / f"{name}.py"),
                           *map(str, args)], capture_output=True, text=True, check=check,
                          cwd=ROOT, timeout=timeout)
