"""The PyVista half of the UI: the views of every stage, the window and lecture mode.

=========================  ==============================================================
module                     owns
=========================  ==============================================================
:mod:`._vtk`               the only import of pyvista/vtk (and the headless set-up)
:mod:`.palette`            the colours: one per technique, colour-blind safe (plain)
:mod:`.layout`             where each part of the window goes, for any size (plain)
:mod:`.stepper`            the stage machine and the window's defaults (plain)
:mod:`.stage_text`         the stage panel's text: tables of hits and weights (plain)
:mod:`.panel_modes`        what the image panels show per mode; the variance scale (plain)
:mod:`.controls`           picking and what the controls change (plain)
:mod:`.lecture_states`     the lecture's pinned states (plain data)
:mod:`.scene_view`         medium box, lights, occluders, camera; fonts, measured text
:mod:`.primitives_view`    photon subpaths and the primitives of each family
:mod:`.hits_view`          the query ray, its hits and the reconstructed paths
:mod:`.coverage_view`      the pixels a primitive reaches, tinted on the render tile
:mod:`.panel_view`         the image panels' tiles, drawn and updated in place
:mod:`.image_panels`       lecture mode's single panels; figures of the panel modes
:mod:`.view3d`             the 3D view of a stage, composed in steps (the window's ticks)
:mod:`.baked_light`        translucent surfaces shaded on the CPU (software OpenGL)
:mod:`.compose`            what each part of the window shows for a state
:mod:`.view_state`         the window's state; which estimators its image panels show
:mod:`.window`             the state built and changed; :func:`~.window.screenshot`
:mod:`.footer`             the window's chips, buttons, sliders and help (an overlay)
:mod:`.interactive`        the on-screen window: keys, stages, rendering
:mod:`.interactive_timer`  the window's timer: what a tick takes in and draws
:mod:`.interactive_draw`   a change drawn in parts: only the renderers it touched
:mod:`.interactive_params` what clicks, estimator chips, members, sliders change; recording
:mod:`.script`             scripted steps for the window (tests under Xvfb)
:mod:`.lecture`            lecture mode in the window
=========================  ==============================================================

Importing this package (or a plain module above) loads no VTK, so the command line
(:mod:`ui.cli`) and the browser version can take stage names, defaults, states, colours,
layouts and texts from here; composing a picture (:func:`ui.views.window.compose`) is apart
from handling events (:mod:`ui.views.interactive`).
"""
