"""Checkpoints of a progressive render: save the accumulator atomically, load it, check it.

A checkpoint is one file ``DIR/checkpoint.npz`` (numpy only, no pickle) holding

* ``n``, ``mean``, ``m2``: the :class:`~psurf_core.accumulate.Welford` accumulator (float64,
  bit-exact), so that continuing at pass ``n`` gives exactly the image an uninterrupted
  render with the same seed gives (pass ``i`` draws from ``SeedSequence([seed, i])``);
* ``m3``, ``m4``, ``peak`` (format 2): the accumulator's higher moments and largest pass
  value, which :mod:`psurf_core.reliability` needs; a format-1 checkpoint (written before
  they were kept) still loads, its accumulator then does not know them
  (``Welford.has_tails`` is False) and the resumed render's image is the same;
* ``sum_m2`` (optional in format 2, when ``meta["sums"]``): the (C,) moment of the per-pass
  image sums (``Welford.sum_variance``). A checkpoint written before it was kept loads with
  it unknown (``None``); an older psurf reading a newer file ignores it, so the format
  number stays 2;
* ``meta``: a JSON document with the format number, the psurf version, the *identity* of
  the render (:func:`render_identity`: scene file hash, estimator spec, seed and every
  setting that changes the numbers) and bookkeeping (seconds spent, scene path, argv, time).

Writes go to a temporary file in the same directory, are flushed to disk, then renamed over
the old checkpoint (``os.replace`` is atomic on POSIX and Windows), so a reader, a crash or
a second Ctrl-C only ever sees the previous complete checkpoint or the new one.
"""

from __future__ import annotations

import hashlib
import json
import os
import time
from dataclasses import dataclass

import numpy as np

from .accumulate import Welford

__all__ = ["CHECKPOINT_FILE", "FORMAT", "READABLE_FORMATS", "Checkpoint", "CheckpointError",
           "checkpoint_path", "file_sha256", "identity_differences", "load_checkpoint",
           "render_identity", "save_checkpoint"]

#: File name inside the checkpoint directory.
CHECKPOINT_FILE = "checkpoint.npz"

#: Version of the checkpoint layout written (bumped when the fields change meaning).
FORMAT = 2

#: Layouts this psurf reads: 1 (``n``, ``mean``, ``m2``), 2 (also ``m3``, ``m4``, ``peak``).
READABLE_FORMATS = (1, 2)

#: Arrays of a format-2 checkpoint beside ``n``, ``mean``, ``m2`` (when ``meta["tails"]``).
_TAIL_KEYS = ("m3", "m4", "peak")

#: The image-sum moment's array (when ``meta["sums"]``; absent from older files).
_SUM_KEY = "sum_m2"


class CheckpointError(ValueError):
    """A checkpoint that cannot be read or used; the message is one line naming the file."""


@dataclass
class Checkpoint:
    """A loaded checkpoint.

    Attributes
    ----------
    path : str
        The ``checkpoint.npz`` it was read from.
    accumulator : Welford
        Passes ``0 .. n-1`` (float64, exactly as saved).
    meta : dict
        The JSON metadata; ``meta["identity"]`` is what a resumed render must match.
    """

    path: str
    accumulator: Welford
    meta: dict

    @property
    def identity(self) -> dict:
        return self.meta["identity"]

    @property
    def seconds(self) -> float:
        return float(self.meta.get("seconds", 0.0))


def checkpoint_path(directory: str | os.PathLike) -> str:
    """``DIR/checkpoint.npz``."""
    return os.path.join(os.fspath(directory), CHECKPOINT_FILE)


def file_sha256(path: str | os.PathLike) -> str:
    """Hex SHA-256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def render_identity(scene_file: str, scene, estimator, settings, seed: int) -> dict:
    """Everything that decides the numbers of pass ``i`` (JSON-serialisable).

    Parameters
    ----------
    scene_file : str
        The scene file as given; its bytes are hashed, and so are the mesh files it uses.
    scene : Scene
        The scene after command-line overrides (its scatter range counts).
    estimator : Estimator
    settings : RenderSettings
    seed : int

    Notes
    -----
    The reference's sampler version (:data:`psurf_core.reference.SAMPLER`) is included, so
    a checkpoint of an older path tracer is refused. Settings an estimator ignores are left
    out (``photons`` for the reference, the kernel radius for unbiased estimators), so
    changing them does not block a resume. The memory budget is included: it changes how
    hits are chunked and so the order of floating-point sums, and a resumed render must be
    bit-identical to an uninterrupted one.
    """
    meshes = sorted({lt.source for lt in (*scene.lights, *scene.occluders)
                     if getattr(lt, "source", "") and os.path.isfile(lt.source)})
    ident = {
        "scene_sha256": file_sha256(scene_file),
        "mesh_sha256": {os.path.basename(m): file_sha256(m) for m in meshes},
        "resolution": [int(scene.camera.width), int(scene.camera.height)],
        "estimator": estimator.spec,
        "seed": int(seed),
        "spp": int(settings.spp),
        "min_scatter": int(scene.min_scatter),
        "max_scatter": int(scene.max_scatter),
        "memory_budget_mib": int(settings.memory_budget_mib),
    }
    if settings.pixel_sampler != "independent":
        # Only when set: checkpoints made before the r2 sampler existed stay resumable.
        ident["pixel_sampler"] = settings.pixel_sampler
    if settings.photon_sampler != "independent":
        ident["photon_sampler"] = settings.photon_sampler
    if estimator.reference:
        # A checkpoint of another path tracer would resume into a mix of two samplers.
        from .reference import SAMPLER

        ident["reference_sampler"] = SAMPLER
    else:
        ident["photons"] = int(settings.photons)
    if estimator.kernel:
        ident["radius"] = None if settings.radius is None else float(settings.radius)
        ident["radius_shrink"] = float(settings.radius_shrink)
    return ident


def identity_differences(saved: dict, current: dict) -> list[tuple[str, object, object]]:
    """``(key, saved value, current value)`` for every key on which two identities differ."""
    keys = list(current) + [k for k in saved if k not in current]
    return [(k, saved.get(k), current.get(k)) for k in keys if saved.get(k) != current.get(k)]


def save_checkpoint(directory: str | os.PathLike, acc: Welford, identity: dict, *,
                    seconds: float, version: str, extra: dict | None = None) -> str:
    """Write ``acc`` and its metadata to ``DIR/checkpoint.npz`` atomically.

    Parameters
    ----------
    directory : path
        Must exist.
    acc : Welford
        Not modified; ``n``, ``mean``, ``m2`` (and ``m3``, ``m4``, ``peak``, ``sum_m2`` when
        it knows them) are written as they are.
    identity : dict
        :func:`render_identity` of the render.
    seconds : float
        Render time spent on these ``n`` passes (over every session).
    version : str
        The psurf version.
    extra : dict, optional
        More JSON-serialisable bookkeeping (scene path, argv, ...).

    Returns
    -------
    str
        The checkpoint file written.
    """
    final = checkpoint_path(directory)
    meta = {"format": FORMAT, "version": version, "passes": int(acc.n),
            "seconds": float(seconds), "written": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
            "tails": bool(acc.has_tails), "sums": acc.sum_m2 is not None,
            "identity": identity, **(extra or {})}
    arrays = {"n": np.int64(acc.n), "mean": np.asarray(acc.mean, dtype=np.float64),
              "m2": np.asarray(acc.m2, dtype=np.float64)}
    if acc.has_tails:
        arrays.update({k: np.asarray(getattr(acc, k), dtype=np.float64) for k in _TAIL_KEYS})
    if acc.sum_m2 is not None:
        arrays[_SUM_KEY] = np.asarray(acc.sum_m2, dtype=np.float64)
    tmp = os.path.join(os.fspath(directory), f".{CHECKPOINT_FILE}.{os.getpid()}.tmp")
    try:
        with open(tmp, "wb") as f:
            np.savez(f, **arrays, meta=np.str_(json.dumps(meta)))
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, final)
    finally:
        _remove_temporary(tmp)
    _fsync_dir(os.fspath(directory))
    return final


def _remove_temporary(tmp: str) -> None:
    """Remove a failed write's temporary file; where that fails too (a read-only mount, the
    directory gone) the write's own error is the one raised, and the next render in the
    directory removes the file."""
    try:
        if os.path.exists(tmp):
            os.remove(tmp)
    except OSError:
        pass


def _fsync_dir(directory: str) -> None:
    """Make the rename durable (best effort: not every platform can open a directory)."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def load_checkpoint(directory: str | os.PathLike) -> Checkpoint:
    """Read and sanity-check ``DIR/checkpoint.npz``.

    Raises
    ------
    CheckpointError
        One line naming the file: missing, unreadable, not a psurf checkpoint, another
        format, inconsistent arrays.

    Notes
    -----
    A format-1 checkpoint loads with ``accumulator.has_tails`` False, and one written
    before the image-sum moment was kept with ``accumulator.sum_m2`` None (see the module
    docstring).
    """
    directory = os.fspath(directory)
    path = checkpoint_path(directory)
    if not os.path.isdir(directory):
        raise CheckpointError(f"{directory}: not a directory")
    if not os.path.isfile(path):
        raise CheckpointError(f"{path}: no checkpoint here")
    try:
        # Opened here (not by np.load) so that a corrupt file is closed on every error path.
        with open(path, "rb") as f:
            d = np.load(f, allow_pickle=False)
            if not isinstance(d, np.lib.npyio.NpzFile):
                raise CheckpointError(f"{path}: not a psurf checkpoint (not an .npz archive)")
            with d:
                missing = {"n", "mean", "m2", "meta"} - set(d.files)
                if missing:
                    raise CheckpointError(f"{path}: not a psurf checkpoint (missing "
                                          f"{', '.join(sorted(missing))})")
                n = int(d["n"])
                mean = np.array(d["mean"], dtype=np.float64)
                m2 = np.array(d["m2"], dtype=np.float64)
                meta = json.loads(str(d["meta"]))
                tails = {k: np.array(d[k], dtype=np.float64) for k in _TAIL_KEYS
                         if k in d.files}
                sum_m2 = (np.array(d[_SUM_KEY], dtype=np.float64) if _SUM_KEY in d.files
                          else None)
    except CheckpointError:
        raise
    except Exception as e:  # truncated zip, bad JSON, pickled arrays, ...
        msg = " ".join(f"{type(e).__name__}: {e}".split())
        raise CheckpointError(f"{path}: unreadable checkpoint ({msg})") from None
    if not isinstance(meta, dict) or not isinstance(meta.get("identity"), dict):
        raise CheckpointError(f"{path}: not a psurf checkpoint (no identity in its metadata)")
    fmt = meta.get("format")
    if fmt not in READABLE_FORMATS:
        raise CheckpointError(f"{path}: checkpoint format {fmt!r}, this psurf reads formats "
                              f"{', '.join(map(str, READABLE_FORMATS))}")
    if n < 0 or mean.shape != m2.shape or mean.ndim != 3 or mean.shape[-1] != 3:
        raise CheckpointError(f"{path}: inconsistent accumulator (n = {n}, mean "
                              f"{mean.shape}, m2 {m2.shape})")
    if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(m2))):
        raise CheckpointError(f"{path}: accumulator holds non-finite values")
    acc = Welford(n, mean, m2)
    if fmt >= 2 and meta.get("tails"):
        missing = [k for k in _TAIL_KEYS if k not in tails]
        if missing:
            raise CheckpointError(f"{path}: format-2 checkpoint without its "
                                  f"{', '.join(missing)}")
        if any(a.shape != mean.shape for a in tails.values()):
            raise CheckpointError(f"{path}: inconsistent accumulator (m3, m4, peak shapes "
                                  f"{[a.shape for a in tails.values()]}, mean {mean.shape})")
        # The peak of no pass is -inf; every other value must be finite.
        peak_ok = np.all(np.isfinite(tails["peak"])) or (n == 0 and np.all(tails["peak"] < 0))
        if not (np.all(np.isfinite(tails["m3"])) and np.all(np.isfinite(tails["m4"]))
                and peak_ok):
            raise CheckpointError(f"{path}: accumulator holds non-finite values")
        acc = Welford(n, mean, m2, tails["m3"], tails["m4"], tails["peak"])
    if fmt >= 2:
        acc.sum_m2 = _sum_moment(path, meta, sum_m2, mean.shape[-1:])
    return Checkpoint(path, acc, meta)


def _sum_moment(path: str, meta: dict, sum_m2: np.ndarray | None, shape: tuple):
    """The checked (C,) image-sum moment, or ``None`` when the file does not keep it."""
    if not meta.get("sums"):
        return None
    if sum_m2 is None:
        raise CheckpointError(f"{path}: checkpoint without its {_SUM_KEY}")
    if sum_m2.shape != shape:
        raise CheckpointError(f"{path}: inconsistent accumulator ({_SUM_KEY} "
                              f"{sum_m2.shape}, channels {shape})")
    if not np.all(np.isfinite(sum_m2)):
        raise CheckpointError(f"{path}: accumulator holds non-finite values")
    return sum_m2
