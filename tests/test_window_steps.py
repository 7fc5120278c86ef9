"""The 3D view drawn in steps (``ui.views.view3d``, ``ui.views.interactive_draw``): in the
window a key or a new inspection draws its text and the 3D view's first step at once and
the rest of the 3D view over the next timer ticks, one part per step; keys draw only the
parts they change; the picture at the end is that of a full redraw."""

from __future__ import annotations

import numpy as np
import pytest

pv = pytest.importorskip("pyvista")
pv.OFF_SCREEN = True

from window_frames_support import drawn, last_frame, settle_by_ticks  # noqa: E402


def test_in_the_window_a_key_draws_at_once_and_the_3d_view_over_the_next_ticks(app, monkeypatch):
    """The window (``App.defer``): ``n`` composes and draws the title, the stage text and the
    3D view's first step (the scene, "drawing...") at once; each later tick adds one part of
    the 3D view (with no time to spare, ``STEP_BUDGET`` 0) and the completed view is drawn;
    the picture is then that of a full redraw."""
    from ui.views import interactive_timer

    s = app.s
    s.prog.pause()  # no passes: only the stage changes
    app.defer = True
    monkeypatch.setattr(interactive_timer, "STEP_BUDGET", 0.0)
    count = drawn(app)
    app.next()  # trace -> create: paths and the primitives of several techniques
    ren = app.p.renderers[0]
    assert "drawing" in ren.actors
    assert not any(n.startswith("prims-") for n in ren.actors)
    assert count["3d"] == count["title"] == count["panel"] == 1, count
    ticks = settle_by_ticks(app)
    assert ticks >= 3  # the paths, then one technique per tick
    assert count["3d"] == 2 and count["title"] == 1, count  # drawn once more, when complete
    assert "drawing" not in ren.actors
    assert sum(n.startswith("prims-") and n.endswith(":mesh") for n in ren.actors) >= 2
    deferred = last_frame(app)
    app.defer = False
    app.redraw()
    assert np.array_equal(deferred, last_frame(app))


def test_in_the_window_a_new_inspection_is_drawn_in_steps(app):
    from ui.views.window import reinspect

    s = app.s
    s.prog.pause()
    app.defer = True
    s.stepper.go("intersect")
    app.redraw()
    settle_by_ticks(app)
    s.pixel_xy = (31, 20)
    reinspect(s)  # computed at once here (workers=0); the next tick takes it
    count = drawn(app)
    app.tick()  # the stage text and the 3D view's first step
    assert s.inspection is not None and s.inspection.pixel_xy == (31, 20)
    assert count["panel"] == 1 and count["3d"] == 1 and count["title"] == 0, count
    assert "drawing" in app.p.renderers[0].actors
    settle_by_ticks(app)
    assert count["3d"] == 2 and count["title"] == 0, count
    assert "hits" in app.p.renderers[0].actors and "drawing" not in app.p.renderers[0].actors
    app.tick()
    assert count["3d"] == 2  # nothing new: nothing drawn


def test_in_the_window_keys_that_change_no_3d_leave_it_alone(app):
    """``m`` (panel mode) and ``l`` (variance scale) redraw the panels, not the 3D view."""
    s = app.s
    s.prog.pause()
    app.defer = True
    app.redraw()
    settle_by_ticks(app)
    count = drawn(app)
    app.toggle_scale()
    app.next_mode()
    assert s.mode == "techniques"
    assert count["3d"] == 0 and count["render"] == 2 and count["panel"] == 2, count
    app.tick()
    assert count["3d"] == 0, count
    app.settle()  # a screenshot's render: everything
    assert count["3d"] == 1
