"""The one module of :mod:`ui.web` that touches VTK: the session's off-screen plotters and
the trame view that streams the 3D one (trame-pyvista's ``PyVistaRemoteView``, rendered on
the server, so the page needs no WebGL and the server no display).

pyvista comes from :mod:`ui.views._vtk` (which sets up headless rendering first), as in every
view; trame-pyvista / trame-vtk are imported here only.
"""

from __future__ import annotations

import asyncio

from ui.views import scene_view
from ui.views._vtk import pv, rendered_image

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

    view = PyVistaRemoteView(plotter, interactive_ratio=1, still_ratio=1, **kwargs)
    # trame-pyvista streams a frame (render, JPEG, send) from every ``plotter.render()``, and
    # pyvista calls it for each actor a stage adds, even while rendering is held: 15 frames
    # per step, seconds with ten sessions on two cores. The page pushes one frame per change
    # (``view.update()`` once the stage is composed); the mouse's frames are trame-vtk's own.
    plotter.clear_on_render_callbacks()
    return view


#: Seconds to wait for the encoder before leaving a frame to trame-vtk's own retry.
ENCODE_WAIT = 2.0


async def deliver_frame(server, plotter: pv.Plotter) -> None:
    """Send the 3D view's newest frame as soon as it is encoded.

    ``view.update()`` renders the frame and hands it to VTK's encoder threads; its reply
    holds the previous JPEG, marked stale, and trame-vtk asks again only 0.5 s later. Here
    the view is asked every few milliseconds (no new render: the encoder's output is looked
    up) and the frame goes out once it is encoded, typically 10-50 ms later.
    """
    from trame_vtk.modules.vtk.protocols import vtkWebPublishImageDelivery

    root = server.protocol
    delivery = next((p for p in (root.getLinkProtocols() if root else ())
                     if isinstance(p, vtkWebPublishImageDelivery)), None)
    if delivery is None:
        return
    window = plotter.render_window
    vid = str(delivery.get_global_id(window))
    loop = asyncio.get_running_loop()
    t0 = loop.time()
    while loop.time() - t0 < ENCODE_WAIT:
        await asyncio.sleep(0.005)
        if vid not in delivery.tracking_views:
            return  # no page watches the view (yet)
        delivery.push_render(vid)  # sent when encoded; the stale flag is refreshed here
        if not delivery.app.GetHasImagesBeingProcessed(window):
            return


def screenshot(plotter: pv.Plotter):
    """(H, W, 3) uint8 of what ``plotter`` shows now, rendered first (the views' one way to
    take a picture, :func:`ui.views._vtk.rendered_image`)."""
    return rendered_image(plotter)
