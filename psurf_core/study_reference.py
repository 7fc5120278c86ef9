"""The image an equal-time study (:func:`psurf_core.study.compare`) measures errors against:
:class:`Reference`, read from an ``app.py render`` / ``compare`` .npz by
:func:`load_reference` or rendered by the study itself (the path tracer, for
:func:`default_reference_seconds`).

``Reference.floor`` is the relMSE the reference's own noise adds to every estimator's score;
``Reference.reliability`` says whether its per-pixel error estimate can be trusted
(:mod:`psurf_core.reliability`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from . import reliability as rl
from .metrics import var_relmse
from .scene import Scene, SceneError
from .study_report import _hi

__all__ = ["REFERENCE_TIME_FACTOR", "Reference", "default_reference_seconds", "load_reference"]

#: Default reference time: this many times the total time of one run of every estimator.
REFERENCE_TIME_FACTOR = 2.0

@dataclass
class Reference:
    """The image errors are measured against.

    Attributes
    ----------
    mean : (H, W, 3) float64
    var : (H, W, 3) float64 or None
        Per-pass variance (for the noise floor); None when unknown.
    passes : int or None
    seconds : float or None
        Render time (None for a file without it).
    source : str
        ``"render"`` (made by :func:`compare`) or the .npz path it was read from.
    estimator : str
    seed : int or None
    moments : dict or None
        The pass-moment arrays of :func:`psurf_core.reliability.npz_fields` (``m2``, ``m3``,
        ``m4``, ``peak``), for the reliability check; None when unknown.
    """

    mean: np.ndarray
    var: np.ndarray | None = None
    passes: int | None = None
    seconds: float | None = None
    source: str = "render"
    estimator: str = "reference"
    seed: int | None = None
    moments: dict | None = None

    def reliability(self) -> dict:
        """:func:`psurf_core.reliability.summarize` of the reference's pass moments."""
        rel = None
        if self.moments and self.passes:
            rel = rl.from_npz({**self.moments, "mean": self.mean, "passes": self.passes})
        what = ("the reference" if self.source == "render" else
                f"the reference {os.path.basename(self.source)}")
        return rl.summarize(rel, what)

    @property
    def floor(self) -> float | None:
        """relMSE that the reference's own noise adds to every estimator's score."""
        if self.var is None or not self.passes:
            return None
        return var_relmse(self.var / self.passes, self.mean)


def load_reference(path: str, scene: Scene) -> Reference:
    """Read a reference image from an ``app.py render`` / ``compare`` .npz.

    Raises
    ------
    SceneError
        Missing or unreadable file, no ``mean``, a resolution other than the scene camera's,
        non-finite pixels, or a recorded scatter range other than the scene's, pass moments
        of another shape.

    Notes
    -----
    Files written before the pass moments were recorded load with ``moments=None`` (the
    reliability check then says it could not be made).
    """
    try:
        with np.load(path, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except FileNotFoundError:
        raise SceneError(f"--reference {path}: file not found") from None
    except (OSError, ValueError) as e:
        raise SceneError(f"--reference {path}: cannot read .npz ({e})") from None
    if "mean" not in data:
        raise SceneError(f"--reference {path}: no 'mean' array (expected an app.py render .npz)")
    mean = np.asarray(data["mean"], dtype=np.float64)
    cam = scene.camera
    if mean.shape != (cam.height, cam.width, 3):
        raise SceneError(f"--reference {path}: image is {'x'.join(map(str, mean.shape))}, the "
                         f"scene renders {cam.height}x{cam.width}x3 (height x width x RGB)")
    if not np.isfinite(mean).all():
        raise SceneError(f"--reference {path}: 'mean' has non-finite pixels")
    if "min_scatter" in data and "max_scatter" in data:
        lo, hi = int(data["min_scatter"]), int(data["max_scatter"])
        if (lo, hi) != (scene.min_scatter, scene.max_scatter):
            raise SceneError(f"--reference {path}: rendered for scatter counts "
                             f"[{lo}, {_hi(hi)}], this comparison is "
                             f"[{scene.min_scatter}, {_hi(scene.max_scatter)}] "
                             "(use --min-scatter/--max-scatter or another reference)")
    var = data.get("var")
    passes = int(data["passes"]) if "passes" in data else None
    moments = None
    if all(k in data for k in rl.NPZ_KEYS):
        moments = {k: np.asarray(data[k], dtype=np.float64) for k in rl.NPZ_KEYS}
        bad = [k for k, a in moments.items() if a.shape != mean.shape]
        if bad:
            raise SceneError(f"--reference {path}: pass moments {', '.join(bad)} are not "
                             f"{'x'.join(map(str, mean.shape))} like 'mean'")
    return Reference(
        mean=mean,
        var=None if var is None else np.asarray(var, dtype=np.float64),
        passes=passes,
        seconds=float(data["seconds"]) if "seconds" in data else None,
        source=os.fspath(path),
        estimator=str(data["estimator"]) if "estimator" in data else "?",
        seed=int(data["seed"]) if "seed" in data else None,
        moments=moments,
    )


def default_reference_seconds(seconds: float, n_estimators: int) -> float:
    """``REFERENCE_TIME_FACTOR x seconds x n_estimators`` (twice one run of every estimator)."""
    return REFERENCE_TIME_FACTOR * seconds * max(1, n_estimators)

