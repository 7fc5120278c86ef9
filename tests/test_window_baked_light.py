"""The primitives' shading on the CPU (``ui.views.baked_light``, for software OpenGL): the
picture of VTK's lighting for the view they were made for, made again for a turned view, and
in the window by the tick after the user turned the view."""

from __future__ import annotations

import numpy as np
import pytest

pv = pytest.importorskip("pyvista")
pv.OFF_SCREEN = True

from window_frames_support import POINT, drawn, settle_by_ticks  # noqa: E402


@pytest.mark.parametrize("stage", ["create", "intersect"])
def test_baked_light_draws_the_picture_the_shader_draws(stage):
    """The window in software OpenGL shades the translucent primitives on the CPU
    (``ui.views.baked_light``): for the view they were made for, the same picture as VTK's
    lighting (within 2/255 per channel), with the primitives drawn unlit."""
    from ui.views import baked_light
    from ui.views._vtk import rendered_image
    from ui.views.window import attach_progressive, build_state, compose, make_plotter

    state = build_state(POINT, "mis:plane-t1t2+planes", seed=3, pixel_xy=(30, 20),
                        photons=100, passes=1, stage=stage)
    attach_progressive(state, workers=0, breakdown=False)
    state.prog.run(passes=1)
    shots = []
    try:
        for on in (False, True):
            p = make_plotter((800, 450), off_screen=True)
            baked_light.enable(p, on)
            compose(p, state)
            meshes = [a for n, a in p.renderers[0].actors.items()
                      if n.startswith(("prims-", "context-", "hitprims-")) and n.endswith(":mesh")]
            assert meshes and all(a.GetProperty().GetLighting() != on for a in meshes)
            shots.append(np.asarray(rendered_image(p), dtype=int))
            p.close()
    finally:
        state.prog.close()
        state.inspector.close()
    diff = np.abs(shots[0] - shots[1])
    assert diff.max() <= 2, (diff.max(), (diff > 2).sum())


def test_baked_light_is_made_again_for_a_turned_view():
    """Turning the 3D view (the window makes the shading again when the turn ends): the
    colours are those of VTK's lighting for the new view, and nothing changes for the same
    view."""
    from ui.views import baked_light
    from ui.views._vtk import rendered_image
    from ui.views.window import attach_progressive, build_state, compose, make_plotter

    state = build_state(POINT, "mis:plane-t1t2+planes", seed=3, pixel_xy=(30, 20),
                        photons=100, passes=1, stage="create")
    attach_progressive(state, workers=0, breakdown=False)
    state.prog.run(passes=1)
    p = make_plotter((800, 450), off_screen=True)
    try:
        baked_light.enable(p)
        compose(p, state)
        ren = p.renderers[0]
        assert baked_light.relight(ren) == 0  # made for this view already
        rendered_image(p)  # shown (VTK's first render places the colour bar's labels apart)
        ren.GetActiveCamera().Azimuth(40.0)
        ren.ResetCameraClippingRange()
        assert baked_light.relight(ren) > 0
        turned = np.asarray(rendered_image(p), dtype=int)
        for name, actor in ren.actors.items():  # the shader's lighting for the same view
            if name.endswith(":mesh") and actor.GetMapper().GetInput().GetCellData() \
                    .GetArray(baked_light.SHADE) is not None:
                actor.GetMapper().ScalarVisibilityOff()
                actor.GetProperty().LightingOn()
                actor.GetProperty().SetColor(*pv.wrap(actor.GetMapper().GetInput())
                                             .field_data[baked_light.BASE])
        lit = np.asarray(rendered_image(p), dtype=int)
    finally:
        p.close()
        state.prog.close()
        state.inspector.close()
    assert np.abs(turned - lit).max() <= 2


def test_in_the_window_a_turned_view_is_shaded_again_by_the_next_tick(app):
    """The window with baked shading: after the user turned the 3D view, the next tick shades
    the primitives for the new view and draws the 3D view alone; then nothing more."""
    from ui.views import baked_light

    s = app.s
    s.prog.pause()
    app.defer = True
    baked_light.enable(app.p)
    app.next()  # create: translucent primitives
    settle_by_ticks(app)
    app.tick()  # (the view as composed: nothing to shade again)
    count = drawn(app)
    app.tick()
    assert sum(count.values()) == 0, count
    ren = app.p.renderers[0]
    ren.GetActiveCamera().Azimuth(30.0)  # what a drag with the mouse does
    app.tick()
    assert count["3d"] == 1 and count["render"] == count["panel"] == 0, count
    assert baked_light.relight(ren) == 0  # shaded for this view already
    app.tick()
    assert count["3d"] == 1
