"""psurf's user interface: the command line, the PyVista views, and the web page.

* :mod:`ui.cli`: the ``python app.py`` commands (render, compare, record/breakdown, screenshot
  and lecture command lines, checkpoints) and the progressive background-render worker. No
  pyvista at module level: ``app.py render`` never loads VTK.
* :mod:`ui.views`: the PyVista views of every stage, the window and lecture mode.
  :mod:`ui.views._vtk` is the only module that imports pyvista/vtk (and sets up headless
  rendering before it does).
* :mod:`ui.web`: ``python app.py serve``, the window's content as a web page (trame): one
  session process per browser tab, over the window's own state and views.

The core (:mod:`psurf_core`) never imports any of them.
"""
