"""psurf UI: PyVista views of every stage (the only package that imports pyvista/vtk).

Without a display, VTK 9.4+ tries X first, prints "bad X server connection", then falls back
to EGL/OSMesa. Choosing EGL up front (unless the user chose) keeps stderr to one clear line.
"""

import os

if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
