"""The benchmarks' shared scene arguments (benchmarks/scene_args.py): the scatter range and
``--resolution`` reach the scene, and a bad resolution is refused like the command line's."""

import argparse

import pytest

from benchmarks.scene_args import add_scene_args, scene_of


def _parser():
    ap = argparse.ArgumentParser()
    add_scene_args(ap)
    return ap


def test_scatter_range_and_resolution_reach_the_scene():
    scene = scene_of(_parser().parse_args(
        ["scenes/study_medium.toml", "2", "3", "--resolution", "256,192"]))
    assert (scene.camera.width, scene.camera.height) == (256, 192)
    assert (scene.min_scatter, scene.max_scatter) == (2, 3)


def test_without_resolution_the_scene_keeps_its_own():
    scene = scene_of(_parser().parse_args(["scenes/study_medium.toml", "1", "1"]))
    assert (scene.camera.width, scene.camera.height) == (64, 48)
    assert (scene.min_scatter, scene.max_scatter) == (1, 1)


def test_bad_resolution_is_refused(capsys):
    with pytest.raises(SystemExit) as e:
        _parser().parse_args(["scenes/study_medium.toml", "1", "1", "--resolution", "4,x"])
    assert e.value.code == 2
    assert "--resolution" in capsys.readouterr().err
