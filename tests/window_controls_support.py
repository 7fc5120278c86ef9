"""What the window's controls tests (``test_window_controls.py``,
``test_window_controls_clicks.py``, ``test_window_controls_progressive.py``) share: the scene
they load. Their module-scoped ``window`` fixture stays in ``test_window_controls_clicks.py``,
the only module that uses it."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: The point-light scene (64 x 48 pixels) the controls tests load.
POINT = str(ROOT / "scenes" / "point.toml")
