"""Fixtures that more than one test module uses; pytest hands them to the tests by name.

Why this file: a fixture imported from a ``*_support.py`` module into a test module is
redefined by every test taking it as a parameter (ruff F811), and defining it again in each
module repeats it. Plain helpers (functions, constants) stay in the ``*_support.py`` modules;
only fixtures shared by several modules belong here. A test module that defines its own
fixture of the same name uses its own (pytest looks in the module first).
"""

from __future__ import annotations

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
