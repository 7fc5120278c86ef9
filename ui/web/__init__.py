"""psurf in the browser: ``python app.py serve`` (trame), the window's content as a web page.

=====================  ==================================================================
module                 owns
=====================  ==================================================================
:mod:`.launcher`       the front server: one session process per browser tab, the proxy
                       to it, the "server busy" page, reaping closed tabs
:mod:`.session`        one session's process: its trame server, download routes
:mod:`.page`           one session's page: state keys and callbacks
:mod:`.layout`         the page's layout (Vuetify 3), bound to state keys by name
:mod:`.model`          the session's app (plain Python): the window's state and actions
:mod:`.tables`         the Evaluate / Reconstruct tables from the core's records
:mod:`.scenes`         bundled scenes by name, upload checks (size, TOML, no file refs)
:mod:`._view3d`        the session's off-screen plotters and the streamed 3D view (the
                       only import of trame-pyvista / trame-vtk)
=====================  ==================================================================

Importing this package loads neither trame nor VTK.
"""
