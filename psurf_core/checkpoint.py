"""Checkpoints of a progressive render: save the accumulator atomically, load it, check it.

A checkpoint is one file ``DIR/checkpoint.npz`` (numpy only, no pickle) holding

* ``n``, ``mean``, ``m2``: the :class:`~psurf_core.accumulate.Welford` accumulator (float64,
  bit-exact), so that continuing at pass ``n`` gives exactly the image an uninterrupted
  render with the same seed gives (pass ``i`` draws from ``SeedSequence([seed, i])``);
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

__all__ = ["CHECKPOINT_FILE", "FORMAT", "Checkpoint", "CheckpointError", "checkpoint_path",
           "file_sha256", "identity_differences", "load_checkpoint", "render_identity",
           "save_checkpoint"]

#: File name inside the checkpoint directory.
CHECKPOINT_FILE = "checkpoint.npz"

#: Version of the checkpoint layout (bumped when the fields change meaning).
FORMAT = 1


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
    Settings an estimator ignores are left out (``photons`` for the reference, the kernel
    radius for unbiased estimators), so changing them does not block a resume. The memory
    budget is included: it changes how hits are chunked and so the order of floating-point
    sums, and a resumed render must be bit-identical to an uninterrupted one.
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
    if not estimator.reference:
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
        Not modified; ``n``, ``mean`` and ``m2`` are written as they are.
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
            "identity": identity, **(extra or {})}
    tmp = os.path.join(os.fspath(directory), f".{CHECKPOINT_FILE}.{os.getpid()}.tmp")
    try:
        with open(tmp, "wb") as f:
            np.savez(f, n=np.int64(acc.n), mean=np.asarray(acc.mean, dtype=np.float64),
                     m2=np.asarray(acc.m2, dtype=np.float64), meta=np.str_(json.dumps(meta)))
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
    except CheckpointError:
        raise
    except Exception as e:  # truncated zip, bad JSON, pickled arrays, ...
        msg = " ".join(f"{type(e).__name__}: {e}".split())
        raise CheckpointError(f"{path}: unreadable checkpoint ({msg})") from None
    if not isinstance(meta, dict) or not isinstance(meta.get("identity"), dict):
        raise CheckpointError(f"{path}: not a psurf checkpoint (no identity in its metadata)")
    if meta.get("format") != FORMAT:
        raise CheckpointError(f"{path}: checkpoint format {meta.get('format')!r}, this psurf "
                              f"reads format {FORMAT}")
    if n < 0 or mean.shape != m2.shape or mean.ndim != 3 or mean.shape[-1] != 3:
        raise CheckpointError(f"{path}: inconsistent accumulator (n = {n}, mean "
                              f"{mean.shape}, m2 {m2.shape})")
    if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(m2))):
        raise CheckpointError(f"{path}: accumulator holds non-finite values")
    return Checkpoint(path, Welford(n, mean, m2), meta)
