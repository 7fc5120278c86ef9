"""What every ``python app.py`` command shares: the one-line error, the flag types, atomic
output writes (files and animations; the window's recorder uses :class:`Animation` too), the
progress bar and the small checks of scene, estimator and scatter range.

It imports none of the commands (they import it), no pyvista and nothing of
:mod:`psurf_core` at module level (``app.py --help`` stays quick). Every bad input raises
:class:`CliError` (``app.main`` prints it as one ``psurf: error: ...`` line, exit code 2),
or a command prints :func:`fail`'s line itself, before anything is written.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import sys

import numpy as np

from psurf_core.interrupt import held

from .suggest import (  # noqa: F401 - the command line's shared names live here
    CliError,
    Parser,
    did_you_mean,
    estimator_names,
    explain_estimator_error,
    join_negative_values,
)

PROG = "psurf"

#: Exit code after Ctrl-C (128 + SIGINT, as shells report it).
EXIT_INTERRUPTED = 130


def fail(message: str) -> int:
    """Print ``psurf: error: <message>`` (on one line) to stderr; returns the exit code 2."""
    print(f"{PROG}: error: {' '.join(str(message).split())}", file=sys.stderr)
    return 2


# --------------------------------------------------------------------------- flag types


def _int_flag(text: str, ok, what: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be {what}, got {text!r}") from None
    if not ok(v):
        raise argparse.ArgumentTypeError(f"must be {what}, got {text!r}")
    return v


def positive_int(text: str) -> int:
    """Flag type: an integer > 0."""
    return _int_flag(text, lambda v: v > 0, "an integer > 0")


def nonneg_int(text: str) -> int:
    """Flag type: an integer >= 0."""
    return _int_flag(text, lambda v: v >= 0, "an integer >= 0")


def scatter_int(text: str) -> int:
    """Flag type: a scatter count, an integer >= 1 or -1 (unlimited)."""
    return _int_flag(text, lambda v: v >= 1 or v == -1, "an integer >= 1 or -1")


def positive_float(text: str) -> float:
    """Flag type: a finite number > 0."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number > 0, got {text!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text!r}")
    return v


def nonneg_float(text: str) -> float:
    """Flag type: a finite number >= 0."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number >= 0, got {text!r}") from None
    if not (math.isfinite(v) and v >= 0):
        raise argparse.ArgumentTypeError(f"must be a finite number >= 0, got {text!r}")
    return v


def shrink(text: str) -> float:
    """Flag type: a progressive radius reduction alpha in (0, 1]."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number in (0, 1], got {text!r}") from None
    if not 0.0 < v <= 1.0:
        raise argparse.ArgumentTypeError(f"must be a number in (0, 1], got {text!r}")
    return v


def nonempty_path(text: str) -> str:
    """Flag type: a path that is not empty."""
    if not text.strip():
        raise argparse.ArgumentTypeError("must be a path, got an empty string")
    return text


def pair(text: str, what: str, minimum: int) -> tuple[int, int]:
    """Two integers ``A,B`` (or ``AxB``), each >= ``minimum``; ``what`` words the error."""
    parts = text.replace("x", ",").split(",")
    try:
        a, b = (int(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be {what}, got {text!r}") from None
    if a < minimum or b < minimum:
        raise argparse.ArgumentTypeError(f"must be {what}, got {text!r}")
    return a, b


def pixel(text: str) -> tuple[int, int]:
    """Flag type: a pixel ``X,Y`` (column from the left, row from the top)."""
    return pair(text, "X,Y (two integers >= 0: column from the left, row from the top)", 0)


def window_size(text: str) -> tuple[int, int]:
    """Flag type: a window or screenshot size ``W,H`` in pixels (each >= 64)."""
    return pair(text, "W,H (two integers >= 64)", 64)


def resolution(text: str) -> tuple[int, int]:
    """Flag type: an image resolution ``W,H`` in pixels (each >= 8), overriding the scene's."""
    return pair(text, "W,H (two integers >= 8: the image's width and height in pixels)", 8)


def add_resolution_flag(parser) -> None:
    """``--resolution W,H`` on ``parser`` (``args.resolution``: ``(W, H)`` or None), worded
    alike in every command that renders a scene; :func:`with_resolution` applies it."""
    parser.add_argument("--resolution", type=resolution, default=None, metavar="W,H",
                        help="render at W x H pixels instead of the scene's [camera] resolution")


def add_sampler_flags(parser, pixel: str = "independent", photon: str = "independent") -> None:
    """``--pixel-sampler`` and ``--photon-sampler`` on ``parser`` (``args.pixel_sampler``,
    ``args.photon_sampler``; defaults ``pixel`` and ``photon``), worded alike in every command
    that renders passes (:mod:`psurf_core.pixel_jitter`, :mod:`psurf_core.photon_sampler`)."""
    from psurf_core.photon_sampler import PHOTON_SAMPLERS
    from psurf_core.pixel_jitter import SAMPLERS

    parser.add_argument(
        "--pixel-sampler", choices=SAMPLERS, default=pixel,
        help="where each pass's camera rays go inside their pixels: 'independent' (a fresh "
             "uniform point every pass) or 'r2' (a low-discrepancy sequence over the passes, "
             "shifted at random per pixel and seed: the pixel-area noise falls much faster; "
             "passes are no longer independent, so per-pass variance overstates the "
             f"image's); default {pixel}")
    parser.add_argument(
        "--photon-sampler", choices=PHOTON_SAMPLERS, default=photon,
        help="where each batch's photons take their random numbers: 'independent', 'sobol' "
             "(each photon a point of a scrambled Sobol set drawn for the batch: each photon "
             "stays uniformly sampled, the batch covers its light points and directions "
             "evenly; passes stay independent) or 'sobol-seq' (one scrambled Sobol sequence "
             "over the passes, pass i taking its next points: the passes together cover "
             "them evenly; passes are no longer independent, so per-pass variance "
             f"overstates the image's); default {photon}")


# --------------------------------------------------------------------------- checks


def check_output(flag: str, path: str) -> None:
    """The directory of ``path`` must exist, and ``path`` must not be a directory."""
    if not path:
        raise CliError(f"{flag}: empty path")
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise CliError(f"{flag} {path}: output directory does not exist: "
                       f"{os.path.dirname(path) or '.'}")
    if os.path.isdir(path):
        raise CliError(f"{flag} {path}: is a directory")
    if not os.access(folder, os.W_OK):
        raise CliError(f"{flag} {path}: output directory is not writable")


def load_scene(path: str):
    """The scene file ``path`` (a ``SceneError`` propagates: one line naming file and key)."""
    from psurf_core import load_scene as _load

    return _load(path)


def with_resolution(scene, size):
    """``scene`` rendered at ``size = (W, H)`` pixels instead of its own (None: unchanged)."""
    if size is None:
        return scene
    from dataclasses import replace

    w, h = (int(v) for v in size)
    return replace(scene, camera=replace(scene.camera, width=w, height=h))


def parse_estimator_flag(spec: str, scene, flag: str = "--estimator"):
    """Parse ``--estimator`` (unknown names and inapplicable techniques become CliError)."""
    from psurf_core import SceneError, parse_estimator
    from psurf_core.techniques import UnknownTechnique

    try:
        return parse_estimator(spec, scene)
    except SceneError:
        raise
    except UnknownTechnique as e:
        raise CliError(f"{flag}: {explain_estimator_error(e)} (see 'python app.py --help')") \
            from None
    except ModuleNotFoundError as e:
        raise CliError(f"--estimator {spec!r}: not available in this build ({e})") from None
    except ValueError as e:  # e.g. a malformed mis: spec
        raise CliError(f"{flag} {spec!r}: {e}") from None


def load_reference(path: str, scene):
    """``psurf_core.study.load_reference`` with a clear line for a file that is no .npz
    render at all (a scene file given by mistake) instead of numpy's message.

    Raises
    ------
    SceneError
        Naming the file and what is wrong with it.
    """
    import zipfile

    from psurf_core import SceneError
    from psurf_core.study import load_reference as _load

    path = os.fspath(path)
    if os.path.isfile(path) and not zipfile.is_zipfile(path):
        kind = "a TOML scene file" if path.lower().endswith(".toml") else "not an .npz archive"
        raise SceneError(f"--reference {path}: {kind}, not a rendered image; make one with "
                         f"'python app.py render SCENE.toml --estimator reference --out "
                         f"ref.npz'")
    return _load(path, scene)


def with_scatter(scene, lo: int | None, hi: int | None):
    """Apply ``--min-scatter/--max-scatter`` and check the combined range."""
    if lo is not None and lo < 1:
        raise CliError(f"--min-scatter: must be >= 1, got {lo}")
    new_lo = scene.min_scatter if lo is None else lo
    new_hi = scene.max_scatter if hi is None else hi
    if new_hi != -1 and new_hi < new_lo:
        if hi is not None:
            raise CliError(f"--max-scatter: must be >= min_scatter ({new_lo}) or -1, got {hi}")
        raise CliError(f"--min-scatter: must be <= the scene's max_scatter ({new_hi}), got {lo}")
    return scene.with_scatter(lo, hi)


def note_scatter_range(est, scene) -> None:
    """Warn when the estimator covers none of the scatter range (a black image)."""
    if est.reference or not est.techniques or scene.max_scatter == -1:
        return
    if all(t.min_k > scene.max_scatter for t in est.techniques):
        k = min(t.min_k for t in est.techniques)
        note(f"estimator '{est.spec}' estimates K >= {k} scattering events only; the scatter "
             f"range [{scene.min_scatter}, {scene.max_scatter}] gives a black image")


# --------------------------------------------------------------------------- messages


def plural(n: int, word: str) -> str:
    """``"1 pass"``, ``"2 passes"``, ``"3 frames"``."""
    return f"{n} {word}" + ("" if n == 1 else "es" if word.endswith("s") else "s")


def note(text: str) -> None:
    """One ``psurf: note: ...`` line on stderr."""
    print(f"{PROG}: note: {text}", file=sys.stderr)


def progress(desc: str, passes: int | None, seconds: float | None, start: int = 0):
    """``(on_pass, close)`` showing a tqdm bar on stderr when it is a terminal."""
    if not sys.stderr.isatty():
        return None, lambda: None
    from tqdm import tqdm

    if passes is not None:
        bar = tqdm(total=passes, initial=start, desc=desc, unit="pass", file=sys.stderr,
                   leave=False)

        def on_pass(i, acc, elapsed):
            bar.update(1)

    else:
        bar = tqdm(total=seconds, desc=desc, file=sys.stderr, leave=False,
                   bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.1f}/{total:.1f} s{postfix}")

        def on_pass(i, acc, elapsed):
            bar.n = min(elapsed, seconds)
            bar.set_postfix_str(plural(acc.n, "pass"), refresh=False)
            bar.refresh()

    return on_pass, bar.close


# --------------------------------------------------------------------------- atomic writes


def _tmp_name(path: str) -> str:
    folder, base = os.path.split(os.path.abspath(path))
    stem, ext = os.path.splitext(base)
    return os.path.join(folder, f".{stem}.{os.getpid()}.tmp{ext}")


class OutputWriteError(Exception):
    """An output could not be written (disk full, read-only, a folder that vanished):
    ``path`` is the output, ``error`` the ``OSError``; ``str()`` is one line."""

    def __init__(self, path: str, error: OSError):
        super().__init__(path, error)
        self.path, self.error = path, error

    def __str__(self) -> str:
        why = self.error.strerror or " ".join(str(self.error).split()) or "OSError"
        return f"cannot write {self.path} ({why})"


def write_all(jobs: list) -> None:
    """Write every ``(path, writer)`` to a temporary name, then move all into place.

    A failure leaves none of the outputs (nor temporary files) behind and raises
    :class:`OutputWriteError` naming the output.
    """
    temps = []
    path = jobs[0][0] if jobs else ""
    try:
        for path, writer in jobs:
            tmp = _tmp_name(path)
            temps.append((tmp, path))
            writer(tmp)
        for tmp, path in temps:
            os.replace(tmp, path)
    except OSError as e:
        raise OutputWriteError(path, e) from e
    finally:
        for tmp, _ in temps:
            with contextlib.suppress(OSError):
                if os.path.exists(tmp):
                    os.remove(tmp)


def npz_writer(data: dict):
    """A :func:`write_all` writer of ``data`` as a compressed ``.npz``."""

    def write(tmp: str) -> None:
        with open(tmp, "wb") as f:  # a file object: savez adds no ".npz" suffix
            np.savez_compressed(f, **data)

    return write


def png_writer(linear_rgb):
    """A :func:`write_all` writer of a linear RGB image, tone-mapped to an 8-bit PNG."""
    from psurf_core import images

    def write(tmp: str) -> None:
        images.write_png(tmp, images.tone_map(linear_rgb), atomic=False)

    return write


def sigint_deferred():
    """No Ctrl-C while the last files are moved into place: the run is ending (saved after an
    interrupt or a failure, or done), so a SIGINT meanwhile is dropped. Main thread only; else
    a no-op."""
    return held(second_raises=False, reraise=False)


def _pad16(frame):
    """Pad to a multiple of 16 pixels (white): H.264 wants even sizes, and imageio would
    otherwise resize with a warning."""
    h, w = frame.shape[:2]
    ph, pw = -h % 16, -w % 16
    if not (ph or pw):
        return frame
    return np.pad(frame, ((0, ph), (0, pw), (0, 0)), constant_values=255)


class Animation:
    """A GIF or MP4 written atomically: frames stream to a temporary file in the target's
    folder, :meth:`commit` moves it into place, :meth:`abort` removes it (``record`` and the
    window's ``v`` key).

    Parameters
    ----------
    out : str
        The animation to write.
    ext : str
        ``".gif"``, or ``".mp4"`` (H.264 through imageio-ffmpeg; frames padded to 16 px).
    fps : float
        Frames per second.
    """

    def __init__(self, out: str, ext: str, fps: float):
        import imageio.v2 as iio2

        folder, base = os.path.split(os.path.abspath(out))
        self.out = out
        self.tmp = os.path.join(folder, f".{base}.{os.getpid()}.tmp{ext}")
        self.frames = 0
        if ext == ".gif":
            self.w = iio2.get_writer(self.tmp, mode="I", duration=1000.0 / fps, loop=0)
            self.pad = False
        else:
            self.w = iio2.get_writer(self.tmp, format="FFMPEG", fps=fps, codec="libx264",
                                     pixelformat="yuv420p", quality=8, macro_block_size=16)
            self.pad = True

    def add(self, frame) -> None:
        self.w.append_data(_pad16(frame) if self.pad else frame)
        self.frames += 1

    def commit(self) -> None:
        self.w.close()
        os.replace(self.tmp, self.out)

    def abort(self) -> None:
        try:
            self.w.close()
        except Exception:
            pass
        if os.path.exists(self.tmp):
            os.remove(self.tmp)
