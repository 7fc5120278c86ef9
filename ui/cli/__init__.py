"""The command-line half of the UI: the ``python app.py`` subcommands, one module each.

=====================  ==================================================================
module                 owns
=====================  ==================================================================
:mod:`.common`         one-line errors (``CliError``), flag types, atomic output writes,
                       progress bar, scene/estimator/scatter checks (imports no command)
:mod:`.render`         ``render``: its flags, defaults and input checks
:mod:`.render_run`     ``render``'s run: passes, checkpoints, one-line failures, outputs
:mod:`.render_npz`     the ``.npz`` ``render`` writes (also the web page's download)
:mod:`.checkpoint`     ``render --checkpoint/--resume``: snapshots, resume checks, Ctrl-C
:mod:`.parallel`       ``--dask``/``--workers``/``--jobs`` (render, compare)
:mod:`.compare`        ``compare``: the equal-time study
:mod:`.record`         ``record`` (GIF/MP4 of the panels) and ``breakdown`` (MIS PNGs)
:mod:`.screenshot`     ``screenshot``: one stage of the window, off-screen
:mod:`.lecture`        ``lecture``: the tutorials' key states
:mod:`.limits`         sizes against the memory limit, outputs against the disk
:mod:`.demo`           ``demo``: the window on the showcase comparison, or its pictures
:mod:`.serve`          ``serve``: the web page's flags (the server is :mod:`ui.web`)
:mod:`.progressive`    the panels' progressive render the window and ``record`` poll;
                       its background process is :mod:`.progressive_worker`
:mod:`.inspector`      the stages' inspections, off the window's thread
:mod:`.background`     what the background processes share (spawn, pipes, restart)
:mod:`.suggest`        "did you mean" for mistyped estimator, technique and flag names
:mod:`.equal_time`     the equal-time rows (Var ratio, relMSE) compare and the panels show
=====================  ==================================================================

``app.py`` builds the parser from the ``add_*_parser`` functions. Nothing
here imports pyvista at module level; the commands that draw (``screenshot``, ``record``,
``breakdown``, ``lecture``) import :mod:`ui.views` only once their inputs are checked.
"""
