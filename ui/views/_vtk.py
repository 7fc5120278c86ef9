"""The one module that imports pyvista and VTK (as pyvista does with ``plotting/_vtk.py``).

Every view, and the commands that draw off-screen, import them from here::

    from ._vtk import pv, vtkTextActor            # inside ui.views
    from ui.views._vtk import pv                  # ui.cli, app.py

so that what VTK needs before its first render window is set once, here, before ``pyvista``
is imported: without a display, VTK 9.4+ tries X first, prints "bad X server connection",
then falls back to EGL/OSMesa; choosing EGL up front (unless the user chose) keeps stderr to
one clear line. The OpenGL rendering module is loaded so that ``vtkRenderWindow()`` is an
OpenGL window (pyvista loads it with its first plotter anyway).
"""

import os

if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")

import pyvista as pv  # noqa: E402
import vtkmodules.vtkRenderingOpenGL2  # noqa: E402, F401 - the OpenGL vtkRenderWindow
from vtkmodules.vtkCommonCore import vtkPoints  # noqa: E402
from vtkmodules.vtkCommonDataModel import vtkCellArray, vtkImageData, vtkPolyData  # noqa: E402
from vtkmodules.vtkInteractionWidgets import (  # noqa: E402
    vtkSliderRepresentation2D,
    vtkSliderWidget,
)
from vtkmodules.vtkRenderingCore import (  # noqa: E402
    vtkActor2D,
    vtkCellPicker,
    vtkCoordinate,
    vtkPolyDataMapper2D,
    vtkRenderer,
    vtkRenderWindow,
    vtkTextActor,
    vtkTextProperty,
    vtkTextRenderer,
)

__all__ = [
    "pv",
    "register_text_backends",
    "vtkActor2D",
    "vtkCellArray",
    "vtkCellPicker",
    "vtkCoordinate",
    "vtkImageData",
    "vtkPoints",
    "vtkPolyData",
    "vtkPolyDataMapper2D",
    "vtkRenderWindow",
    "vtkRenderer",
    "vtkSliderRepresentation2D",
    "vtkSliderWidget",
    "vtkTextActor",
    "vtkTextProperty",
    "vtkTextRenderer",
]


def register_text_backends() -> None:
    """Load VTK's FreeType and MathText (matplotlib) text backends, if this VTK has them.

    Their object-factory overrides must be registered before the ``vtkTextRenderer``
    singleton is made (:func:`ui.views.scene_view.plain_text` then picks FreeType).
    """
    try:
        import vtkmodules.vtkRenderingFreeType  # noqa: F401
        import vtkmodules.vtkRenderingMatplotlib  # noqa: F401
    except ImportError:
        pass
