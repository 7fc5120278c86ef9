"""``fast-full@S`` and the pilot that chooses ``S`` per scene (``psurf_core/share_pilot.py``):
the grammar, the cost model's optimum, the pilot on a small scene, and ``compare``'s use of
it (``--photons auto``)."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import pytest

import psurf_core.share_pilot as sp
from psurf_core.estimators import AREA_DISK_SHARE, AREA_SPHERE_SHARE, parse_estimator
from psurf_core.render import RenderSettings
from psurf_core.scene_io import load_scene
from psurf_core.study import compare
from psurf_core.study_report import to_json
from psurf_core.techniques import UnknownTechnique

SCENES = Path(__file__).resolve().parent.parent / "scenes"


def _small(name: str, w: int = 16, h: int = 12):
    scene = load_scene(SCENES / f"{name}.toml")
    return replace(scene, camera=replace(scene.camera, width=w, height=h))


def test_fast_full_takes_a_share_for_its_single_scattering_set():
    """``fast-full@S``: every light kind's single-scattering members on ``S`` (an area
    light's disk and sphere scaled as in ``fast-full``), the multiple-scattering set as in
    ``fast-full``; ``~`` leaves members out as for any preset."""
    mesh = load_scene(SCENES / "mesh_light.toml")
    est = parse_estimator("fast-full@0.04", mesh)
    assert est.spec == "fast-full@0.04"
    assert [t.label for t in est.groups[0]] == [
        "ss-sphere@0.04", "ss-cone@0.04", "ss-disk-short@0.04"]
    assert [t.label for t in est.groups[1]] == [
        t.label for t in parse_estimator("fast-full", mesh).groups[1]]
    area = parse_estimator("fast-full@0.5", load_scene(SCENES / "area.toml"))
    assert [t.label for t in area.groups[0]] == [
        "ss-plane-uv@0.5", "ss-plane-ut-short@0.5", "ss-plane-vt-short@0.5",
        f"ss-sphere@{AREA_SPHERE_SHARE * 0.5:g}", f"ss-disk@{AREA_DISK_SHARE * 0.5:g}"]
    assert [t.label for t in parse_estimator("fast-full@1~ss-cone", mesh).groups[0]] == [
        "ss-sphere", "ss-disk-short"]
    for bad in ("fast-full@0", "fast-full@1.5", "fast-full@x", "fast-full@"):
        with pytest.raises(UnknownTechnique, match="share after '@'"):
            parse_estimator(bad)
    with pytest.raises(UnknownTechnique, match="takes no share"):
        parse_estimator("fast-multi@0.5")


def test_best_share_minimises_the_model():
    """``s* = sqrt(v1 c2 / (v2 c1))`` beats its neighbours in ``(v1/s + v2)(s c1 + c2)``;
    kept within SHARE_RANGE; the top of it when the second set shows no variance."""
    v, c = (20.0, 600.0), (1.4e-4, 2.1e-5)
    s = sp.best_share(v, c)
    assert sp.SHARE_RANGE[0] < s < sp.SHARE_RANGE[1]
    assert s == pytest.approx(math.sqrt(v[0] * c[1] / (v[1] * c[0])))
    assert sp.model(v, c, (s, 1.0)) < min(sp.model(v, c, (s / 1.5, 1.0)),
                                       sp.model(v, c, (s * 1.5, 1.0)))
    assert sp.best_share((1e-9, 600.0), c) == sp.SHARE_RANGE[0]
    assert sp.best_share((5e4, 1.0), c) == sp.SHARE_RANGE[1]
    assert sp.best_share((0.5, 0.0), c) == sp.SHARE_RANGE[1]


def test_an_area_light_keeps_at_least_the_presets_share():
    """With an area light the pilot may raise the share, not lower it (its planes' heavy
    tails are read low by a short pilot); without one, SHARE_RANGE's floor holds."""
    area, point = load_scene(SCENES / "area.toml"), load_scene(SCENES / "point.toml")
    assert sp.share_floor(area, 0.3) == 0.3
    assert sp.share_floor(point, 0.15) == sp.SHARE_RANGE[0]
    v, c = (1e-6, 600.0), (1.4e-4, 2.1e-5)  # a misread: the single set all but noiseless
    assert sp.best_share(v, c, sp.share_floor(area, 0.3)) == 0.3
    assert sp.best_share(v, c, sp.share_floor(point, 0.15)) == sp.SHARE_RANGE[0]


def test_the_pilot_measures_both_sets_and_chooses_a_share():
    """A real pilot on a small point-light scene: both sets measured alone (their own
    members, positive costs and variances), a share within range that the spec replays,
    and the model's verdict on it against the preset's share."""
    scene = _small("point")
    choice = sp.choose_share(scene, "fast-full", RenderSettings())
    assert sp.SHARE_RANGE[0] <= choice["share"] <= sp.SHARE_RANGE[1]
    assert choice["spec"] == f"fast-full@{choice['share']:g}"
    assert choice["preset_share"] == 0.15
    single, multi = choice["sets"]
    assert single["members"] == ["ss-sphere", "ss-cone-short", "ss-disk"]
    assert multi["members"] == ["plane-t1t2-short", "plane-t2t3-short@0.3", "cone-short@0.2"]
    for row in choice["sets"]:
        assert row["c1"] > 0.0 and row["v"] > 0.0
    v, c = (single["v"], multi["v"]), (single["c1"], multi["c1"])
    assert choice["model_vs_preset"] == pytest.approx(
        sp.model(v, c, (choice["share"], 1.0)) / sp.model(v, c, (0.15, 1.0)))
    est = parse_estimator(choice["spec"], scene)
    assert {t.share for t in est.groups[0]} == {min(choice["share"], 1.0)} or \
        choice["share"] == 1.0


def test_only_the_bare_shared_preset_is_piloted():
    assert sp.shared_preset("fast-full") == "fast-full"
    for spec in ("fast-full@0.2", "fast-full~ss-sphere", "fast-multi", "planes",
                 "mis:planes+cone@0.5"):
        assert sp.shared_preset(spec) is None


def test_compare_runs_the_chosen_share_and_says_so(monkeypatch):
    """``compare`` with ``--photons auto``: ``fast-full`` is run as the spec its share pilot
    chose (sized by the photon pilot for that share), the row names it and notes where it
    came from, ``on_pilot`` and the JSON keep the pilot's record; an estimator given a
    count runs as given."""
    import psurf_core.pass_size as ps

    chosen = {"spec": "fast-full@0.05", "share": 0.05, "preset_share": 0.15,
              "sets": [], "model_vs_preset": 0.8, "pilot_seconds": 0.0}
    asked = []
    monkeypatch.setattr(sp, "choose_share",
                        lambda scene, spec, st: asked.append(spec) or dict(chosen))
    monkeypatch.setattr(ps, "pilot", lambda *a: (0.01, 5e-5, 4e-6, 3e-4))
    scene = _small("point", 8, 6).with_scatter(1, 2)
    seen = []
    s = compare(scene, ["fast-full", "fast-full"], 0.2, runs=1, seed=3,
                photons=["auto", 150], reference_seconds=0.2,
                on_pilot=lambda spec, m: seen.append((spec, m)))
    auto, given = s["results"]
    assert asked == ["fast-full"]
    assert auto["estimator"] == "fast-full@0.05" and given["estimator"] == "fast-full"
    assert auto["pass_model"]["share_model"] == chosen
    assert seen == [("fast-full", None), ("fast-full@0.05", auto["pass_model"])]
    assert any("chosen by the pilot" in n and "--estimators fast-full@0.05 --photons "
               f"{auto['photons_per_pass']} " in n for n in auto["notes"])
    assert not any("chosen by the pilot" in n for n in given["notes"])
    assert json.loads(json.dumps(to_json(s), allow_nan=False))["results"][0][
        "pass_model"]["share_model"]["spec"] == "fast-full@0.05"


def test_the_cli_pilot_line_names_the_share_and_how_to_repeat_it(capsys):
    """``app.py compare``'s pilot line: the share chosen, the preset's, and the flags that
    repeat both choices."""
    from ui.cli.compare import _on_pilot

    share = {"spec": "fast-full@0.05", "share": 0.05, "preset_share": 0.15,
             "pilot_seconds": 6.7}
    _on_pilot("fast-full", None)
    _on_pilot("fast-full@0.05", {"photons": 122, "pilot_seconds": 1.0, "c0": 0.01,
                                 "c1": 5e-5, "vj": 4e-6, "vp": 3e-4, "share_model": share})
    out = capsys.readouterr().out
    assert out.startswith("fast-full: sizing its passes")
    assert "single scattering on 0.05 of the photons (the preset's 0.15" in out
    assert "--estimators fast-full@0.05 --photons 122 repeat both" in out
    assert out.count("\n") == 1  # one line
