"""Checkpoints of ``python app.py render`` (``--checkpoint DIR``, ``--checkpoint-every``,
``--resume DIR``): the snapshot kept after every pass, the checks that a resumed command line
is the one the checkpoint was made with, the pass/time budget of a resumed session, and what
Ctrl-C or a failure saves.

The file format and its atomic write are :mod:`psurf_core.checkpoint`'s; this module is the
command-line side (every bad input is one :class:`~ui.cli.common.CliError`). It imports only
:mod:`ui.cli.common` of the commands' modules; :mod:`ui.cli.render` imports it.
"""

from __future__ import annotations

import os
import sys
import time

from .common import (
    EXIT_INTERRUPTED,
    PROG,
    CliError,
    plural,
    sigint_deferred,
)

#: Identity keys (psurf_core.checkpoint.render_identity) -> the flag that sets them.
IDENTITY_FLAGS = {
    "estimator": "--estimator", "seed": "--seed", "photons": "--photons", "spp": "--spp",
    "min_scatter": "--min-scatter", "max_scatter": "--max-scatter",
    "memory_budget_mib": "--memory-budget", "radius": "--radius",
    "radius_shrink": "--radius-shrink", "pixel_sampler": "--pixel-sampler",
    "photon_sampler": "--photon-sampler",
}


def describe_difference(key: str, saved, current, scene_file: str) -> str:
    """One clause saying how the checkpoint's identity ``key`` differs from this command's."""
    if key == "scene_sha256":
        return (f"the scene file {scene_file} is not the one the checkpoint was made from "
                f"(SHA-256 {str(current)[:12]}..., checkpoint {str(saved)[:12]}...)")
    if key == "mesh_sha256":
        return f"a mesh file of {scene_file} changed since the checkpoint was made"
    if key == "resolution":
        return f"the checkpoint is a {saved} image, the scene renders {current}"
    if key == "reference_sampler":
        return (f"the checkpoint was rendered by another version of the reference path tracer "
                f"(sampler {saved or 'before issue 15'}, this psurf's is {current}); render "
                f"it again without --resume")
    flag = IDENTITY_FLAGS.get(key, key)

    def show(v):
        return "(not set)" if v is None else repr(v) if isinstance(v, str) else str(v)

    if key in ("pixel_sampler", "photon_sampler"):  # the identity leaves the default out
        saved, current = saved or "independent", current or "independent"
    return (f"the checkpoint was made with {flag} {show(saved)}, "
            f"the command line has {show(current)}")


class Checkpointer:
    """Keeps a consistent snapshot of the accumulator after every pass and writes it.

    The snapshot (a copy of the accumulator: ``n``, ``mean``, ``m2`` and, when it keeps them,
    the higher moments and peak) is replaced in one assignment, so a
    Ctrl-C that lands anywhere (even inside ``Welford.add`` of the next pass) leaves it
    consistent; the interrupt handler then saves it.
    """

    def __init__(self, directory: str, identity: dict, every: float, acc, seconds_before: float,
                 extra: dict, on_disk: int | None):
        self.directory = directory
        self.identity = identity
        self.every = every
        self.seconds_before = seconds_before
        self.extra = extra
        self.snapshot = (acc.copy(), seconds_before)
        self.on_disk = on_disk  # pass count of the checkpoint file now in DIR (None: none)
        self.last_write = time.monotonic()

    @property
    def passes(self) -> int:
        return self.snapshot[0].n

    def on_pass(self, i, acc, elapsed) -> None:
        self.snapshot = (acc.copy(), self.seconds_before + elapsed)
        if time.monotonic() - self.last_write >= self.every:
            self.write()

    def write(self) -> bool:
        """Save the snapshot unless the file already holds it (or it has no pass)."""
        from psurf_core import __version__
        from psurf_core.checkpoint import save_checkpoint

        acc, seconds = self.snapshot
        if acc.n == 0 or acc.n == self.on_disk:
            return False
        save_checkpoint(self.directory, acc, self.identity, seconds=seconds,
                        version=__version__, extra=self.extra)
        self.on_disk = acc.n
        self.last_write = time.monotonic()
        return True


class CheckpointWriteError(Exception):
    """Writing ``DIR/checkpoint.npz`` failed (``error``: the ``OSError``); the file in DIR is
    still the previous checkpoint (``ckpt.on_disk`` passes), or none."""

    def __init__(self, ckpt: Checkpointer, error: OSError):
        super().__init__(ckpt.directory, error)
        self.ckpt, self.error = ckpt, error

    def line(self, out: str | None = None) -> str:
        """The one line saying what failed, what is kept and how to go on."""
        from psurf_core.checkpoint import checkpoint_path

        d = self.ckpt.directory
        why = self.error.strerror or " ".join(str(self.error).split()) or "OSError"
        if not os.path.isdir(d):
            kept = f"the checkpoint directory {d} no longer exists"
        elif self.ckpt.on_disk:
            kept = (f"{d} still holds the previous checkpoint "
                    f"({plural(self.ckpt.on_disk, 'pass')}; continue with --resume {d} once it "
                    f"can be written)")
        else:
            kept = "no checkpoint was saved"
        tail = f"; {out} not written" if out else ""
        return f"cannot write the checkpoint {checkpoint_path(d)} ({why}); {kept}{tail}"


def write_checkpoint(ckpt: Checkpointer, write=None) -> bool:
    """``ckpt.write()`` (or ``write()``), an ``OSError`` raised as
    :class:`CheckpointWriteError`."""
    try:
        return (write or ckpt.write)()
    except OSError as e:
        raise CheckpointWriteError(ckpt, e) from e


def lock_checkpoint_dir(flag: str, directory: str):
    """Hold an exclusive lock on ``directory`` for this process (an open descriptor, released
    when the process ends, even by ``kill -9``), then remove temporary files that a killed
    writer left there. Returns the descriptor (keep it), or None where locks do not exist."""
    from psurf_core.checkpoint import CHECKPOINT_FILE

    try:
        import fcntl
    except ImportError:  # not POSIX
        return None
    fd = os.open(directory, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(fd)
        raise CliError(f"{flag} {directory}: another psurf render is writing checkpoints "
                       f"there") from None
    for name in os.listdir(directory):
        if name.startswith(f".{CHECKPOINT_FILE}.") and name.endswith(".tmp"):
            try:
                os.remove(os.path.join(directory, name))
            except OSError:
                pass
    return fd


def checkpoint_dir_ok(flag: str, directory: str, must_be_empty: bool) -> None:
    """``directory`` can hold a checkpoint: it is (or can be made) a writable directory."""
    from psurf_core.checkpoint import CHECKPOINT_FILE, checkpoint_path

    if os.path.exists(directory) and not os.path.isdir(directory):
        raise CliError(f"{flag} {directory}: exists and is not a directory")
    if os.path.isdir(directory):
        if must_be_empty and os.path.exists(checkpoint_path(directory)):
            raise CliError(f"{flag} {directory}: already holds a checkpoint ({CHECKPOINT_FILE}); "
                           f"continue it with --resume {directory}, or choose another directory")
        if not os.access(directory, os.W_OK):
            raise CliError(f"{flag} {directory}: directory is not writable")
        return
    parent = os.path.dirname(os.path.abspath(directory))
    if not os.path.isdir(parent):
        raise CliError(f"{flag} {directory}: parent directory does not exist: "
                       f"{os.path.dirname(directory) or '.'}")
    if not os.access(parent, os.W_OK):
        raise CliError(f"{flag} {directory}: cannot create it (parent not writable)")


def same_dir(a: str, b: str) -> bool:
    """Whether the paths ``a`` and ``b`` name the same directory."""
    return os.path.abspath(a) == os.path.abspath(b) or (
        os.path.exists(a) and os.path.exists(b) and os.path.samefile(a, b))


def load_resume(args, identity: dict):
    """The checkpoint of ``--resume``, checked against this command line."""
    from psurf_core import __version__
    from psurf_core.checkpoint import CheckpointError, identity_differences, load_checkpoint

    try:
        ck = load_checkpoint(args.resume)
    except CheckpointError as e:
        raise CliError(f"--resume {args.resume}: {e}") from None
    if ck.meta.get("version") != __version__:
        raise CliError(f"--resume {args.resume}: the checkpoint was written by psurf "
                       f"{ck.meta.get('version')}, this is psurf {__version__}")
    diffs = identity_differences(ck.identity, identity)
    if diffs:
        more = f" (and {plural(len(diffs) - 1, 'other difference')})" if len(diffs) > 1 else ""
        raise CliError(f"--resume {args.resume}: "
                       f"{describe_difference(*diffs[0], args.scene)}{more}; a resumed render "
                       f"must use the same scene file, estimator, seed and settings")
    return ck


def session_budget(args, ck, default_passes: int):
    """``(passes, time_budget)`` of this session (see the ``render`` help on resuming).

    ``default_passes`` is ``render``'s ``--passes`` default: the budget of a fresh render
    without ``--passes``/``--time``, and of a resumed one whose checkpoint saved none.
    """
    if args.passes is not None or args.time is not None:
        if ck is not None and args.passes is not None and ck.accumulator.n > args.passes:
            raise CliError(f"--passes {args.passes}: the checkpoint in {args.resume} already "
                           f"holds {ck.accumulator.n} passes")
        return args.passes, args.time
    if ck is None:
        return default_passes, None
    saved = ck.meta.get("budget") or {}
    if saved.get("time") is not None:
        left = float(saved["time"]) - ck.seconds
        return (None, left) if left > 0 else (ck.accumulator.n, None)
    return max(int(saved.get("passes") or default_passes), ck.accumulator.n), None


def report_interrupt(ckpt: Checkpointer | None, args) -> int:
    """Ctrl-C: save the completed passes (if checkpointing), print one line, exit 130."""
    if ckpt is None:
        print(f"{PROG}: interrupted; nothing written", file=sys.stderr)
        return EXIT_INTERRUPTED
    try:
        with sigint_deferred():
            ckpt.write()
    except OSError as e:
        print(f"{PROG}: interrupted; could not save the checkpoint in {ckpt.directory} "
              f"({e.strerror or e}); nothing written", file=sys.stderr)
        return EXIT_INTERRUPTED
    if not ckpt.on_disk:
        print(f"{PROG}: interrupted before the first pass finished; nothing written",
              file=sys.stderr)
    else:
        print(f"{PROG}: interrupted; {ckpt.directory} holds {plural(ckpt.on_disk, 'pass')} "
              f"(continue with --resume {ckpt.directory}); {args.out} not written",
              file=sys.stderr)
    return EXIT_INTERRUPTED


def save_on_failure(ckpt: Checkpointer | None) -> str:
    """Save the completed passes after a failure; the clause the error line adds (or "")."""
    if ckpt is None:
        return ""
    try:
        with sigint_deferred():
            ckpt.write()
    except OSError:
        return ""
    if ckpt.on_disk:
        return f"; {ckpt.directory} holds the {plural(ckpt.on_disk, 'completed pass')}"
    return ""
