"""The one module that imports pyvista and VTK (as pyvista does with ``plotting/_vtk.py``).

Every view, and the commands that draw off-screen, import them from here::

    from ._vtk import pv, vtkTextActor            # inside ui.views
    from ui.views._vtk import pv                  # ui.cli, app.py

so that what VTK needs before its first render window is set once, here, before ``pyvista``
is imported: without a display, VTK 9.4+ tries X first, prints "bad X server connection",
then falls back to EGL/OSMesa; choosing EGL up front (unless the user chose) keeps stderr to
one clear line. The OpenGL rendering module is loaded so that ``vtkRenderWindow()`` is an
OpenGL window (pyvista loads it with its first plotter anyway).

pyvista's plotting package imports ``matplotlib.pyplot`` and ``pooch`` (a downloader) when it
loads, for a chart type and remote files that psurf never uses: ~0.2 s of the ~1.45 s of
CPU that importing the window and making its plotter took (1.22-1.32 s with the stand-ins,
1.40-1.52 s without, 3 runs each at load 5-6). Here they are stand-ins (:class:`_Deferred`) that
import the real module the first time one of its attributes is read, so a program that
uses them (a figure of the breakdowns, a tutorial's plot) gets them unchanged.

Pictures of a plotter (screenshots, figures, the pages' PNGs) are taken by
:func:`rendered_image`, which renders first: pyvista's off-screen ``screenshot`` may return the
last rendered picture. (The window's ``s`` key and a script's ``shot`` render the whole window
just before their screenshot, and a recording keeps each frame as it was just rendered.)
"""

import importlib
import importlib.util
import os
import sys
import types

import numpy as np

if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")


class _Deferred(types.ModuleType):
    """A module imported the first time one of its attributes is read (then it forwards:
    whoever bound the stand-in reads the real module's attributes through it). Dunder names
    (``__file__``, ``__warningregistry__``: what tools scanning ``sys.modules`` look for)
    are not attributes of the stand-in and import nothing."""

    def __getattr__(self, attr):
        if attr.startswith("__") and attr.endswith("__"):
            raise AttributeError(attr)
        name = self.__name__
        if sys.modules.get(name) is self:
            del sys.modules[name]  # the real import replaces the stand-in
        return getattr(importlib.import_module(name), attr)


def _defer(name: str) -> None:
    """Put a stand-in for module ``name`` where ``import name`` finds it (unless it is
    imported already or absent)."""
    if name in sys.modules or importlib.util.find_spec(name.partition(".")[0]) is None:
        return
    stand_in = _Deferred(name)
    parent, _, child = name.rpartition(".")
    sys.modules[name] = stand_in
    if parent:
        setattr(importlib.import_module(parent), child, stand_in)


#: Imported by pyvista's plotting package but never used by psurf's views (see above).
DEFERRED_MODULES = ("matplotlib.pyplot", "pooch")
for _name in DEFERRED_MODULES:
    _defer(_name)

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
    "rendered_image",
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


def rendered_image(plotter: pv.Plotter) -> np.ndarray:
    """The picture of ``plotter`` rendered now (a screenshot to compare or save).

    pyvista's ``Plotter.screenshot`` renders only before the plotter's first render: after
    that its ``vtkWindowToImageFilter`` (``ShouldRerenderOff``) reads the pixels of the last
    render, so a change made since (a colour, a turned camera, a new stage) would be missing
    from the picture. And ``Plotter.render`` renders nothing while ``suppress_rendering`` is
    held (as the views hold it while they add actors): it is lifted for this one render.
    (A fresh plotter's first picture differs from its later ones where a colour bar's tick
    labels are: VTK places them anew after its first render; SSIM 0.998 on a window.)

    Parameters
    ----------
    plotter : pyvista.Plotter
        An open plotter, off-screen or shown.

    Returns
    -------
    (H, W, 3) uint8 ndarray
        RGB, a copy (pyvista may reuse its buffer for the next picture).
    """
    held = plotter.suppress_rendering
    plotter.suppress_rendering = False
    try:
        plotter.render()  # (before the first render this does nothing; screenshot renders)
        img = plotter.screenshot(None, return_img=True)
    finally:
        plotter.suppress_rendering = held
    return np.array(img[..., :3])
