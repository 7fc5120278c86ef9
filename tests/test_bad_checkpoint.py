"""Bad checkpoint flags of ``python app.py render`` (``--checkpoint``, ``--checkpoint-every``,
``--resume``: bad values, missing or wrong directories, a corrupt checkpoint): one clear line
naming the flag, exit code 2, nothing written (the check: ``bad_input_support.py``). What a
valid checkpoint refuses to resume into is in ``test_checkpoint_resume.py``."""

from __future__ import annotations

from pathlib import Path

import pytest
from bad_input_support import (
    assert_rejected,
    assert_rejected_by_subprocess,
    render_argv,
)


def _ck_with(tmp: Path, content: bytes) -> str:
    (tmp / "ck").mkdir()
    (tmp / "ck" / "checkpoint.npz").write_bytes(content)
    return "ck"


def _file(tmp: Path, name: str) -> str:
    (tmp / name).write_text("x")
    return name


#: name -> (extra argv (list, or tmp -> list), needles), as in ``test_bad_flags.py``.
CHECKPOINTS = {
    "checkpoint-every negative": (["--estimator", "planes", "--checkpoint", "ck",
                                   "--checkpoint-every", "-5"], ["--checkpoint-every", ">= 0"]),
    "checkpoint-every alone": (["--estimator", "planes", "--checkpoint-every", "5"],
                               ["--checkpoint-every", "needs --checkpoint"]),
    "checkpoint is a file": (lambda t: ["--estimator", "planes", "--checkpoint",
                                        _file(t, "notadir")],
                             ["--checkpoint", "notadir", "not a directory"]),
    "checkpoint parent missing": (["--estimator", "planes", "--checkpoint", "a/b/ck"],
                                  ["--checkpoint", "a/b/ck", "parent directory does not exist"]),
    "checkpoint empty path": (["--estimator", "planes", "--checkpoint", ""], ["--checkpoint"]),
    "resume missing dir": (["--estimator", "planes", "--resume", "nock"],
                           ["--resume", "nock", "no such directory"]),
    "resume without checkpoint": (lambda t: ["--estimator", "planes", "--resume",
                                             (t / "ck").mkdir() or "ck"],
                                  ["--resume", "ck", "no checkpoint"]),
    "resume a corrupt checkpoint": (lambda t: ["--estimator", "planes", "--resume",
                                               _ck_with(t, b"PK\x03\x04 truncated")],
                                    ["--resume", "checkpoint.npz", "unreadable checkpoint"]),
}


@pytest.mark.parametrize("case", sorted(CHECKPOINTS))
def test_bad_checkpoint_flag(case, tmp_path, capsys):
    spec, needles = CHECKPOINTS[case]
    assert_rejected(render_argv(tmp_path, spec), needles, tmp_path, capsys)


def test_subprocess_exit_code_2_without_traceback(tmp_path):
    spec, needles = CHECKPOINTS["resume a corrupt checkpoint"]
    assert_rejected_by_subprocess(render_argv(tmp_path, spec), needles, tmp_path)
