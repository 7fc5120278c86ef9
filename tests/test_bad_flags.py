"""Bad flags of ``python app.py render`` (estimator names, ``-short`` misuse, MIS specs,
budgets, scatter counts, kernel radii, memory, outputs, unknown or abbreviated flags): one
clear line naming the flag, exit code 2, nothing written (the check: ``bad_input_support.py``).
Checkpoint flags have their own corpus (``test_bad_checkpoint.py``)."""

from __future__ import annotations

import pytest
from bad_input_support import (
    POINT,
    assert_rejected,
    assert_rejected_by_subprocess,
    render_argv,
)

#: name -> (extra argv (list, or tmp -> list), needles). The scene is scenes/area.toml unless
#: the argv names another; ``--out out.npz --png out.png`` are always added (unless given).
FLAGS = {
    "unknown estimator": (["--estimator", "nosuch"], ["--estimator", "unknown estimator",
                                                      "nosuch"]),
    "empty estimator": (["--estimator", ""], ["--estimator", "unknown estimator"]),
    "-short on planes": (["--estimator", "planes-short"], ["--estimator", "'planes'",
                                                           "no short variant"]),
    "-short on sphere": (["--estimator", "sphere-short"], ["--estimator", "'sphere'",
                                                           "no short variant"]),
    "-short on a kernel baseline": (["--estimator", "points-short"],
                                    ["--estimator", "'points'", "no short variant"]),
    "-short on the reference": (["--estimator", "reference-short"],
                                ["--estimator", "reference-short"]),
    "-short on a preset": (["--estimator", "paper-full-short"],
                           ["--estimator", "paper-full", "no short variant"]),
    "MIS without members": (["--estimator", "mis:"], ["--estimator", "malformed MIS spec"]),
    "MIS trailing plus": (["--estimator", "mis:cone+"], ["--estimator", "malformed MIS spec"]),
    "MIS member twice": (["--estimator", "mis:cone+cone"], ["--estimator", "listed twice"]),
    "MIS of a kernel baseline": (["--estimator", "mis:points+cone"],
                                 ["--estimator", "'points'", "kernel baseline"]),
    "MIS of a preset": (["--estimator", "mis:paper-single+cone"], ["--estimator", "preset"]),
    "MIS unknown member": (["--estimator", "mis:cone+nosuch"], ["--estimator", "nosuch"]),
    "MIS bad -short member": (["--estimator", "mis:cone+sphere-short"],
                              ["--estimator", "'sphere'", "no short variant"]),
    "MIS unknown weighting": (["--estimator", "mis-pow:cone+disk"],
                              ["--estimator", "unknown estimator"]),
    "estimator for no light": (["--estimator", "ss-plane-uv", POINT],
                               ["point.toml", "ss-plane-uv", "applies to no light"]),
    "missing estimator": (["--out", "out.npz"], ["--estimator", "required"]),
    "missing out": (["--estimator", "planes", "--png", "out.png", "--out"], ["--out"]),
    "negative time": (["--estimator", "planes", "--time", "-1"], ["--time", "> 0", "-1"]),
    "zero time": (["--estimator", "planes", "--time", "0"], ["--time", "> 0"]),
    "NaN time": (["--estimator", "planes", "--time", "nan"], ["--time", "finite"]),
    "negative photons": (["--estimator", "planes", "--photons", "-5"], ["--photons", "> 0"]),
    "zero photons": (["--estimator", "planes", "--photons", "0"], ["--photons", "> 0"]),
    "photons not a number": (["--estimator", "planes", "--photons", "lots"],
                             ["--photons", "integer", "lots"]),
    "zero spp": (["--estimator", "planes", "--spp", "0"], ["--spp", "> 0"]),
    "zero passes": (["--estimator", "planes", "--passes", "0"], ["--passes", "> 0"]),
    "fractional passes": (["--estimator", "planes", "--passes", "2.5"], ["--passes", "integer"]),
    "negative seed": (["--estimator", "planes", "--seed", "-1"], ["--seed", ">= 0"]),
    "passes and time": (["--estimator", "planes", "--passes", "2", "--time", "1"],
                        ["--time", "not allowed with"]),
    "negative radius": (["--estimator", "points", "--radius", "-1"], ["--radius", "> 0"]),
    "radius shrink 0": (["--estimator", "points", "--radius-shrink", "0"],
                        ["--radius-shrink", "(0, 1]"]),
    "radius shrink 1.5": (["--estimator", "points", "--radius-shrink", "1.5"],
                          ["--radius-shrink", "(0, 1]"]),
    "zero memory budget": (["--estimator", "planes", "--memory-budget", "0"],
                           ["--memory-budget", "> 0"]),
    "min-scatter 0": (["--estimator", "planes", "--min-scatter", "0"], ["--min-scatter", ">= 1"]),
    "max-scatter -2": (["--estimator", "planes", "--max-scatter", "-2"], ["--max-scatter"]),
    "inverted scatter range": (["--estimator", "planes", "--min-scatter", "3", "--max-scatter",
                                "2"], ["--max-scatter", ">= min_scatter (3)"]),
    "unknown flag": (["--estimator", "planes", "--bogus"], ["--bogus", "unrecognized"]),
    "abbreviated flag": (["--estimator", "planes", "--phot", "10"], ["--phot"]),
    "out dir missing": (["--estimator", "planes", "--out", "nodir/x.npz"],
                        ["--out", "nodir", "does not exist"]),
    "out is a directory": (lambda t: ["--estimator", "planes", "--out", str(t)],
                           ["--out", "is a directory"]),
    "png dir missing": (["--estimator", "planes", "--png", "nodir/x.png"],
                        ["--png", "does not exist"]),
}


@pytest.mark.parametrize("case", sorted(FLAGS))
def test_bad_flag(case, tmp_path, capsys):
    spec, needles = FLAGS[case]
    assert_rejected(render_argv(tmp_path, spec), needles, tmp_path, capsys)


@pytest.mark.parametrize("case", ["-short on sphere", "MIS of a kernel baseline",
                                  "negative time"])
def test_subprocess_exit_code_2_without_traceback(case, tmp_path):
    spec, needles = FLAGS[case]
    assert_rejected_by_subprocess(render_argv(tmp_path, spec), needles, tmp_path)
