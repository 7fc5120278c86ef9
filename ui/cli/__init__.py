"""The command-line half of the UI: the ``python app.py`` subcommands, one module each.

=====================  ==================================================================
module                 owns
=====================  ==================================================================
:mod:`.common`         one-line errors (``CliError``), flag types, atomic output writes,
                       progress bar, scene/estimator/scatter checks (imports no command)
:mod:`.render`         ``render``: its flags, defaults and the ``.npz`` it writes
:mod:`.checkpoint`     ``render --checkpoint/--resume``: snapshots, resume checks, Ctrl-C
:mod:`.parallel`       ``--dask``/``--workers``/``--jobs`` (render, compare)
:mod:`.compare`        ``compare``: the equal-time study
:mod:`.record`         ``record`` (GIF/MP4 of the panels) and ``breakdown`` (MIS PNGs)
:mod:`.screenshot`     ``screenshot``: one stage of the window, off-screen
:mod:`.lecture`        ``lecture``: the tutorials' key states
:mod:`.progressive`    the background-render worker the window and ``record`` poll
=====================  ==================================================================

``app.py`` builds the parser from the ``add_*_parser`` functions and owns ``demo``. Nothing
here imports pyvista at module level; the commands that draw (``screenshot``, ``record``,
``breakdown``, ``lecture``) import :mod:`ui.views` only once their inputs are checked.
"""
