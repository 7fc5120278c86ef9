"""Every tutorial runs headless with its small budget, and its own checks pass.

A tutorial (``tutorials/NN_*.py``, ``# %%`` cells) ends with explicit ``assert`` checks of what
it claims, so running it *is* the test. Each runs as a subprocess with
``PSURF_TUTORIAL_BUDGET=test`` (seconds, not minutes), ``MPLBACKEND=Agg`` and its figures
redirected to a temporary folder (``PSURF_TUTORIAL_OUT``), so ``make test`` never overwrites
the lecture-quality figures in ``out/tutorials/``.

The budgets are sized so that all eight together take well under four minutes on two busy
cores; ``pytest --durations=0`` shows each one's time.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TUTORIALS = sorted((ROOT / "tutorials").glob("[0-9][0-9]_*.py"))
#: A tutorial that takes longer than this in test mode is a budget bug (or a hung renderer).
TIMEOUT = 240


def _env(out: Path, budget: str = "test") -> dict:
    env = dict(os.environ)
    env.update(PSURF_TUTORIAL_BUDGET=budget, MPLBACKEND="Agg", PSURF_TUTORIAL_OUT=str(out),
               PYTHONPATH=str(ROOT) + os.pathsep + env.get("PYTHONPATH", ""))
    return env


def test_there_are_eight_numbered_tutorials():
    numbers = [int(p.name[:2]) for p in TUTORIALS]
    assert numbers == list(range(1, 9)), [p.name for p in TUTORIALS]


@pytest.mark.parametrize("path", TUTORIALS, ids=[p.stem for p in TUTORIALS])
def test_tutorial_runs_and_its_checks_pass(path, tmp_path):
    proc = subprocess.run([sys.executable, str(path)], cwd=ROOT, env=_env(tmp_path),
                          capture_output=True, text=True, timeout=TIMEOUT)
    tail = "\n".join((proc.stdout + proc.stderr).splitlines()[-30:])
    assert proc.returncode == 0, f"{path.name} failed:\n{tail}"
    assert f"{path.name[:2]}: all checks passed" in proc.stdout, tail
    figures = sorted(tmp_path.glob(f"{path.name[:2]}_*.png"))
    assert figures, f"{path.name} wrote no figure into PSURF_TUTORIAL_OUT"


@pytest.mark.parametrize("path", TUTORIALS, ids=[p.stem for p in TUTORIALS])
def test_tutorial_shape(path):
    """Percent format, a title and a learning goal, the budget switch, checks at the end,
    figures named after the tutorial, public API only."""
    text = path.read_text()
    assert text.count("# %%") >= 6, "cells: '# %%' code and '# %% [markdown]' text"
    assert re.search(rf"^# # {int(path.name[:2])} · ", text, re.M), "title: '# # N · ...'"
    assert "**Learning goal.**" in text
    assert 'os.environ.get("PSURF_TUTORIAL_BUDGET", "lecture")' in text
    assert "## What this tutorial claims, checked" in text
    last_cell = text.rsplit("# %%", 1)[1]
    assert last_cell.count("assert ") >= 3 and "all checks passed" in last_cell
    for name in re.findall(r'"(\d\d_[a-z0-9_]+\.png)"', text):
        assert name.startswith(path.name[:2]), name
    # Public API only: no private helpers of psurf_core or ui.
    assert not re.search(r"\b(psurf_core|ui)[\w.]*\._\w", text)
    assert not re.search(r"from (psurf_core|ui)[\w.]* import [^\n]*\b_\w", text)


def test_budget_switch_rejects_unknown_values(tmp_path):
    proc = subprocess.run([sys.executable, str(TUTORIALS[0])], cwd=ROOT,
                          env=_env(tmp_path, budget="huge"), capture_output=True, text=True,
                          timeout=TIMEOUT)
    assert proc.returncode != 0
    assert "PSURF_TUTORIAL_BUDGET must be 'test' or 'lecture'" in proc.stderr


def test_readme_lists_the_tutorials_in_order():
    readme = (ROOT / "tutorials" / "README.md").read_text()
    positions = [readme.find(f"({p.name})") for p in TUTORIALS]
    assert all(pos >= 0 for pos in positions), "every tutorial is linked from tutorials/README.md"
    assert positions == sorted(positions), "in order"
