"""The PyVista half of the UI: the views of every stage, the window and lecture mode.

=========================  ==============================================================
module                     owns
=========================  ==============================================================
:mod:`._vtk`               the only import of pyvista/vtk (and the headless set-up)
:mod:`.scene_view`         medium box, lights, occluders, camera; the palette and fonts
:mod:`.primitives_view`    photon subpaths and the primitives of each family
:mod:`.hits_view`          the query ray, its hits and the reconstructed paths
:mod:`.image_panels`       render / variance / techniques / bounces image panels
:mod:`.window`             what the window shows at each stage; :func:`~.window.screenshot`
:mod:`.interactive`        the on-screen window: keys, mouse, timer
:mod:`.controls`           picking, buttons, sliders (pure parts testable without VTK)
:mod:`.stepper`            the stage machine and the window's defaults (plain Python)
:mod:`.lecture_states`     the lecture's pinned states (plain data)
:mod:`.lecture`            lecture mode in the window
=========================  ==============================================================

Importing this package (or :mod:`.stepper`, :mod:`.lecture_states`) loads no VTK, so the
command line (:mod:`ui.cli`) can take stage names, defaults and states from here.
"""
