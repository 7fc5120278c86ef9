"""``render``'s run, once its inputs are checked (:func:`run_session`, called by
:func:`ui.cli.render.cmd_render`): render the passes (resuming a checkpoint; in this process or
with ``--dask``/``--workers``/``--jobs``), checkpoint them every
:data:`DEFAULT_CHECKPOINT_EVERY` seconds, turn every failure into one line and an exit code
(Ctrl-C 130; a checkpoint, memory, the workers or an output lost 1), and write the outputs
together (``.npz`` from :mod:`ui.cli.render_npz`, ``.png``, ``.exr``) or none of them.
"""

from __future__ import annotations

import os
import sys

import numpy as np

from .checkpoint import (
    Checkpointer,
    CheckpointWriteError,
    report_interrupt,
    same_dir,
    save_on_failure,
    write_checkpoint,
)
from .common import (
    PROG,
    CliError,
    OutputWriteError,
    npz_writer,
    plural,
    png_writer,
    progress,
    sigint_deferred,
    write_all,
)
from .parallel import WorkersLost, maybe_distributed
from .render_npz import npz_payload

#: Seconds between checkpoints of ``render --checkpoint`` without ``--checkpoint-every``.
DEFAULT_CHECKPOINT_EVERY = 60.0


def run_session(args, scene, est, settings, radius, ck, ck_dir, identity, passes, time_budget,
                need) -> int:
    """Render (resuming ``ck``), checkpoint into ``ck_dir``, write the outputs; the exit code.

    Every failure is one line: Ctrl-C (130, the passes saved), a checkpoint that cannot be
    written (1, the previous one kept), memory or workers lost (1, the passes saved), an
    output that cannot be written (1, none of them written).
    """
    from psurf_core.render import RenderResult, render

    acc = ck.accumulator if ck is not None else None
    seconds_before = ck.seconds if ck is not None else 0.0
    ckpt = None
    if ck_dir is not None:
        every = DEFAULT_CHECKPOINT_EVERY if args.checkpoint_every is None else args.checkpoint_every
        budget = ({"passes": passes} if passes is not None else
                  {"time": seconds_before + time_budget})
        extra = {"scene": os.path.abspath(args.scene), "argv": list(sys.argv), "budget": budget}
        start = acc if acc is not None else _empty_acc(scene)
        on_disk = start.n if ck is not None and same_dir(ck_dir, args.resume) else None
        ckpt = Checkpointer(ck_dir, identity, every, start, seconds_before, extra, on_disk)

    start_n = acc.n if acc is not None else 0
    bar, close = progress(args.estimator, passes, time_budget, start_n)

    def on_pass(i, a, elapsed):
        if ckpt is not None:
            write_checkpoint(ckpt, lambda: ckpt.on_pass(i, a, elapsed))
        if bar is not None:
            bar(i, a, elapsed)

    try:
        if acc is not None and passes is not None and acc.n >= passes:
            result = RenderResult(acc.mean.copy(), acc.variance, acc.n, settings.photons,
                                  settings.spp, 0.0, est.spec, args.seed, acc)
        else:
            kw = dict(passes=passes, time_budget=time_budget, seed=args.seed, accumulator=acc,
                      on_pass=on_pass)
            result = (maybe_distributed(args, scene, est, settings, error=CliError, **kw)
                      or render(scene, est, settings, **kw))
    except KeyboardInterrupt:
        close()
        return report_interrupt(ckpt, args)
    except CheckpointWriteError as e:  # disk full, read-only, the directory vanished
        close()
        print(f"{PROG}: error: {e.line(args.out)}", file=sys.stderr)
        return 1
    except MemoryError:
        close()
        saved = save_on_failure(ckpt)
        print(f"{PROG}: error: out of memory while rendering (the run was estimated at "
              f"{_fmt(need.total)}; lower the resolution, --spp or --photons, or give a "
              f"--memory-budget below the memory free){saved}", file=sys.stderr)
        return 1
    except WorkersLost as e:  # every worker gone, or a pass lost with its worker
        close()
        saved = save_on_failure(ckpt)
        print(f"{PROG}: error: {e}{saved}", file=sys.stderr)
        return 1
    except FloatingPointError as e:  # Welford.add refused a non-finite pixel: a bug
        close()
        saved = save_on_failure(ckpt)
        print(f"{PROG}: error: internal: {e} (estimator '{est.spec}'; please report it)"
              f"{saved}", file=sys.stderr)
        return 1
    finally:
        close()
    result.seconds += seconds_before

    jobs = [(args.out, npz_writer(npz_payload(result, radius, scene, {
        "radius_shrink": np.float64(args.radius_shrink),
        "memory_budget_mib": np.int64(settings.memory_budget_mib)})))]
    if args.png is not None:
        jobs.append((args.png, png_writer(result.mean)))
    if args.exr is not None:
        from psurf_core.images import write_exr

        jobs.append((args.exr, lambda tmp: write_exr(tmp, result.mean)))
    try:
        with sigint_deferred():
            if ckpt is not None:
                write_checkpoint(ckpt)
            write_all(jobs)
    except CheckpointWriteError as e:
        print(f"{PROG}: error: {e.line(args.out)}", file=sys.stderr)
        return 1
    except OutputWriteError as e:
        kept = (f"; {ckpt.directory} holds all {plural(ckpt.on_disk, 'pass')}: --resume "
                f"{ckpt.directory} (without --time) writes them without rendering again"
                if ckpt is not None and ckpt.on_disk else "")
        print(f"{PROG}: error: {e}; nothing of {written_list(jobs)} written{kept}",
              file=sys.stderr)
        return 1
    written = written_list(jobs)
    budget_text = "" if est.reference else f" x {result.photons_per_pass} photons"
    resumed = f" (continued from {plural(start_n, 'pass')})" if ck is not None else ""
    print(f"{args.estimator}: {plural(result.passes, 'pass')}{budget_text}, spp {result.spp}, "
          f"{result.seconds:.2f} s{resumed} -> {written}")
    return 0


def written_list(jobs) -> str:
    """``"a.npz, a.png"``: the outputs of ``jobs``."""
    return ", ".join(p for p, _ in jobs)


def _fmt(nbytes: float) -> str:
    from psurf_core.budget import format_bytes

    return format_bytes(nbytes)


def _empty_acc(scene):
    from psurf_core.accumulate import Welford

    return Welford.empty((scene.camera.height, scene.camera.width, 3))
