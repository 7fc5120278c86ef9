"""Records numba's compilations during a test run (``PSURF_COMPILE_LOG``, see conftest).

Only the outermost compilation of a nest is written (a kernel's callees compile inside it
and their time is part of it); the key is the kernel's source digest and argument types,
the same key the on-disk cache uses, so two rows with one key in two workers' files are a
kernel compiled twice.
"""

from __future__ import annotations

import hashlib
import os
import time

import numba.core.event as ev


class _Recorder(ev.Listener):
    def __init__(self, path: str):
        self.path = path
        self.depth = 0
        self.t0 = 0.0
        self.test = "(collection)"

    def on_start(self, event):
        if self.depth == 0:
            self.t0 = time.perf_counter()
        self.depth += 1

    def on_end(self, event):
        self.depth -= 1
        if self.depth:
            return
        from psurf_core.kernels.cache import source_digest

        d = event.data["dispatcher"]
        try:
            key = source_digest(d.py_func)[:16]
        except Exception:  # noqa: BLE001 - a diagnostic: never fail the run
            key = "?"
        name = f"{d.py_func.__module__}.{d.py_func.__qualname__}"
        args = ",".join(str(a) for a in event.data["args"])
        with open(self.path, "a") as f:
            f.write(f"{self.test}\t{name}\t{key}\t{time.perf_counter() - self.t0:.3f}"
                    f"\t{hashlib.sha1(args.encode()).hexdigest()[:8]}\n")


def install(config, out: str) -> None:
    """Register the recorder for this process (a worker or the only process)."""
    os.makedirs(out, exist_ok=True)
    worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
    rec = _Recorder(os.path.join(out, f"{worker}.tsv"))
    ev.register("numba:compile", rec)

    class _Plugin:
        def pytest_runtest_setup(self, item):
            rec.test = item.nodeid

    config.pluginmanager.register(_Plugin(), "psurf-compile-log")
