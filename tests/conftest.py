"""Fixtures that more than one test module uses; pytest hands them to the tests by name.

Why this file: a fixture imported from a ``*_support.py`` module into a test module is
redefined by every test taking it as a parameter (ruff F811), and defining it again in each
module repeats it. Plain helpers (functions, constants) stay in the ``*_support.py`` modules;
only fixtures shared by several modules belong here. A test module that defines its own
fixture of the same name uses its own (pytest looks in the module first).
"""

from __future__ import annotations

import os

import pytest


@pytest.fixture()
def app(tmp_path, monkeypatch):
    """The window off-screen with three passes merged in this process
    (:func:`window_frames_support.window_app`), for the window's frame tests
    (``test_window_frames.py``, ``test_window_steps.py``, ``test_window_baked_light.py``).
    Function scope: each test gets a new window, closed after it."""
    # Imported here, not at the top: every test module loads this file, and only the
    # window's tests (which first skip without pyvista) should load the window's helpers.
    from window_frames_support import window_app

    with window_app(tmp_path, monkeypatch) as a:
        yield a


#: Test files that take longest on a fresh clone (numba compiling their kernels), longest
#: first (``--durations`` of a cold ``make test``, 2026-12-04: ``test_walkers.py`` ~9 min
#: of one worker, the window's screenshots 100 s in their first fixture, ...).
#: ``make test`` runs files on two workers (``--dist loadfile``), each taking the next file
#: when free; started last, a long file is the run's tail while the other worker idles.
#: xdist's default order (most tests first) is not the longest first: the Makefile passes
#: ``--no-loadscope-reorder`` so that this order holds.
LONGEST_FIRST = ("test_walkers.py", "test_ui_screenshots.py", "test_lecture.py",
                 "test_photon_surfaces_multi_unbiased.py", "test_multi_mesh_light.py",
                 "test_twins.py", "test_tutorials.py", "test_web.py",
                 "test_panel_screenshots.py", "test_window_controls.py", "test_cli.py")


def pytest_collection_modifyitems(config, items):
    """The files of :data:`LONGEST_FIRST` first, in that order; the rest after, in their
    order (a stable sort: the tests of a file keep theirs)."""
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))


def pytest_configure(config):
    """With ``PSURF_COMPILE_LOG=<dir>``, record every top-level numba compilation (kernel,
    argument types, seconds, test, worker) into ``<dir>/<worker>.tsv``: what a cold
    ``make test`` spends compiling, and what two workers compile twice
    (``benchmarks/compile_log.py`` sums it)."""
    out = os.environ.get("PSURF_COMPILE_LOG")
    if out:
        from compile_log_support import install

        install(config, out)
