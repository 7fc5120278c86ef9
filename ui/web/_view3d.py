"""The one module of :mod:`ui.web` that touches VTK: the session's off-screen plotters and
the trame view that streams the 3D one (trame-pyvista's ``PyVistaRemoteView``, rendered on
the server, so the page needs no WebGL and the server no display).

pyvista comes from :mod:`ui.views._vtk` (which sets up headless rendering first), as in every
view; trame-pyvista / trame-vtk are imported here only.
"""

from __future__ import annotations

from ui.views import scene_view
from ui.views._vtk import pv

#: The 3D view's plotter size before the browser reports its own (the remote view then
#: resizes the render window to the element's size).
VIEW_SIZE = (800, 560)


def view_plotter(size=VIEW_SIZE) -> pv.Plotter:
    """An off-screen one-renderer plotter for the 3D stage view (FreeType text, white)."""
    scene_view.plain_text()
    p = pv.Plotter(window_size=list(size), off_screen=True, border=False)
    p.set_background("white")
    # Software OpenGL (no GPU): multisampling triples the cost of every streamed frame.
    p.ren_win.SetMultiSamples(0)
    return p


def panel_plotter(size) -> pv.Plotter:
    """An off-screen plotter with the two image-panel cells side by side (render | maps)."""
    scene_view.plain_text()
    p = pv.Plotter(window_size=list(size), off_screen=True, shape=(1, 2), border=False)
    p.set_background("white", all_renderers=True)
    p.ren_win.SetMultiSamples(0)  # pixel-aligned tiles need none
    return p


def remote_view(plotter: pv.Plotter, **kwargs):
    """The trame widget streaming ``plotter`` (JPEG frames rendered here; mouse rotates and
    zooms on the server)."""
    from trame_pyvista import PyVistaRemoteView

    return PyVistaRemoteView(plotter, interactive_ratio=1, still_ratio=1, **kwargs)


def screenshot(plotter: pv.Plotter):
    """(H, W, 3) uint8 of what ``plotter`` shows now (rendered first)."""
    plotter.render()
    import numpy as np

    return np.array(plotter.screenshot(None, return_img=True)[..., :3])
