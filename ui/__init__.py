"""psurf's user interface, in two halves.

* :mod:`ui.cli`: the ``python app.py`` commands (render, compare, record/breakdown, screenshot
  and lecture command lines, checkpoints) and the progressive background-render worker. No
  pyvista at module level: ``app.py render`` never loads VTK.
* :mod:`ui.views`: the PyVista views of every stage, the window and lecture mode.
  :mod:`ui.views._vtk` is the only module that imports pyvista/vtk (and sets up headless
  rendering before it does).

The core (:mod:`psurf_core`) never imports either.
"""
