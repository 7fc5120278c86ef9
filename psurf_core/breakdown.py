"""Per-technique and per-scatter-count breakdowns of a render (the talk's MIS pictures).

A pass's image is a sum over hits of per-photon contributions. Through ``render_pass``'s
``tally`` hook every chunk of hits is also binned by *technique* and *scatter count* ``K``
(``prims.K[hits.prim]``), before (``unweighted``) and after (``weighted``) the MIS weight,
into two stacks of images of shape ``(T, NK, H, W, 3)``:

* ``weighted[t, k]``: what technique ``t`` adds to the pass image from paths of scatter count
  bin ``k``. Summed over ``t`` and ``k`` it is the pass image (same hits, same scale).
* ``unweighted[t, k]``: the same hits without the MIS weight: technique ``t`` alone, an
  unbiased estimate of the whole ``K`` bin wherever ``t`` can produce those paths (the talk's
  "2nd bounce, unweighted").

Scatter counts are binned as ``K = k_min, ..., k_max - 1`` and one last bin ``K >= k_max``
(the scene may have no upper bound; when it caps K at or below ``k_max`` the last bin is that
cap exactly); :attr:`BreakdownLayout.labels` names them.

Derived pictures (:class:`BreakdownAccumulator`, progressive means over passes):

* per-technique weighted images ``weighted.sum(axis=1)``; they sum to the image;
* per-technique *weight maps*: technique ``t``'s share of the pixel's luminance,
  ``L(weighted_t) / L(sum_t weighted_t)`` in [0, 1], summing to 1 over the techniques where
  the pixel is non-zero (0 elsewhere). In expectation it is the contribution-weighted mean
  of technique ``t``'s MIS weight over the paths through the pixel,
  ``integral w_t f / integral f``; for a technique alone it is 1 wherever the pixel is
  non-zero;
* per-K images ``weighted.sum(axis=0)``; they sum to the image too.

numpy only; loops run over techniques and chunks, never over hits or pixels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .accumulate import Welford
from .estimators import Estimator
from .geometry import Blockers
from .images import luminance
from .render import RenderSettings, render_pass
from .scene import Scene

__all__ = [
    "DEFAULT_K_MAX",
    "BreakdownAccumulator",
    "BreakdownLayout",
    "PassBreakdown",
    "render_pass_breakdown",
    "weight_maps",
]

#: Scatter counts from this one up share the last bin (``K >= DEFAULT_K_MAX``).
DEFAULT_K_MAX = 4


@dataclass(frozen=True)
class BreakdownLayout:
    """Which technique and which scatter-count bin each slot of a breakdown stack holds.

    Attributes
    ----------
    techniques : tuple of str
        Technique names in estimator order (``Estimator.techniques``).
    k_min, k_max : int
        Bins ``K = k_min .. k_max - 1`` and a last bin ``K >= k_max`` (``k_max >= k_min``).
    shape : (int, int)
        Image ``(H, W)``.
    last_exact : bool
        The scene caps K at ``k_max``, so the last bin holds ``K = k_max`` only.
    """

    techniques: tuple
    k_min: int
    k_max: int
    shape: tuple
    last_exact: bool = False

    @classmethod
    def of(cls, scene: Scene, estimator: Estimator, k_max: int = DEFAULT_K_MAX):
        """The layout for ``estimator`` on ``scene`` (bins from the smallest K it produces)."""
        k_min = max(min((t.min_k for t in estimator.techniques), default=1), scene.min_scatter)
        hi, exact = int(k_max), False
        if 0 < scene.max_scatter <= hi:  # the scene caps K: the last bin is exactly K = cap
            hi, exact = scene.max_scatter, True
        hi = max(hi, k_min)
        return cls(tuple(t.name for t in estimator.techniques), int(k_min), hi,
                   (scene.camera.height, scene.camera.width), exact)

    @property
    def n_k(self) -> int:
        """Number of scatter-count bins."""
        return self.k_max - self.k_min + 1

    @property
    def ks(self) -> tuple:
        """The first K of every bin."""
        return tuple(range(self.k_min, self.k_max + 1))

    @property
    def labels(self) -> tuple:
        """Bin labels: ``"K=2"``, ..., ``"K>=4"`` (``"K=4"`` when the scene caps K at 4)."""
        last = f"K={self.k_max}" if self.last_exact else f"K>={self.k_max}"
        return tuple(f"K={k}" for k in self.ks[:-1]) + (last,)

    def k_bin(self, k: int) -> int:
        """The bin index of scatter count ``k`` (ValueError below ``k_min``)."""
        if k < self.k_min:
            raise ValueError(f"K={k}: the breakdown starts at K={self.k_min}")
        return min(int(k), self.k_max) - self.k_min

    @property
    def stack_shape(self) -> tuple:
        """``(T, NK, H, W, 3)``."""
        return (len(self.techniques), self.n_k, *self.shape, 3)


@dataclass
class PassBreakdown:
    """One pass split by technique and scatter count.

    Attributes
    ----------
    layout : BreakdownLayout
    unweighted, weighted : (T, NK, H, W, 3) float64
        Per-pixel estimates of this pass (already divided by photons and rays per pixel).
    """

    layout: BreakdownLayout
    unweighted: np.ndarray
    weighted: np.ndarray


class _Tally:
    """The ``tally`` callback: bins every chunk of hits into flat (T * NK * P, 3) sums."""

    def __init__(self, layout: BreakdownLayout, estimator: Estimator, n_pixels: int):
        self.layout = layout
        self.n_pixels = n_pixels
        # Techniques are matched by identity (one instance per estimator slot), by name as a
        # fallback for a caller that rebuilt the instances.
        self.slot = {id(t): i for i, t in enumerate(estimator.techniques)}
        self.by_name = {t.name: i for i, t in enumerate(estimator.techniques)}
        n = len(layout.techniques) * layout.n_k * n_pixels
        self.size = n
        self.unweighted = np.zeros((n, 3))
        self.weighted = np.zeros((n, 3))

    def __call__(self, tech, hits, prims, rays, unweighted, weighted) -> None:
        t = self.slot.get(id(tech), self.by_name.get(tech.name))
        if t is None:
            raise KeyError(f"tally: technique {tech.name!r} is not in the estimator")
        lay = self.layout
        k = np.minimum(np.asarray(prims.K)[hits.prim], lay.k_max) - lay.k_min
        if np.any(k < 0):
            raise ValueError(f"tally: {tech.name} produced K < {lay.k_min}")
        flat = (t * lay.n_k + k) * self.n_pixels + rays.pixel[hits.ray]
        for c in range(3):
            self.unweighted[:, c] += np.bincount(flat, weights=unweighted[:, c],
                                                 minlength=self.size)
            self.weighted[:, c] += np.bincount(flat, weights=weighted[:, c],
                                               minlength=self.size)


def render_pass_breakdown(
    scene: Scene,
    estimator: Estimator,
    pass_index: int,
    seed: int,
    settings: RenderSettings,
    *,
    k_max: int = DEFAULT_K_MAX,
    blockers: Blockers | None = None,
    layout: BreakdownLayout | None = None,
) -> tuple[np.ndarray, PassBreakdown]:
    """Render pass ``pass_index`` (the same image as ``render_pass``) and its breakdown.

    Parameters
    ----------
    k_max : int
        Scatter counts ``>= k_max`` share the last bin (ignored when ``layout`` is given).
    layout : BreakdownLayout, optional
        Defaults to ``BreakdownLayout.of(scene, estimator, k_max)``.

    Returns
    -------
    image : (H, W, 3) float64
        The pass image, bit-identical to ``render_pass`` with the same arguments.
    breakdown : PassBreakdown
    """
    if estimator.reference:
        raise ValueError("the path tracer ('reference') has no techniques to break down")
    layout = BreakdownLayout.of(scene, estimator, k_max) if layout is None else layout
    n_pixels = scene.camera.n_pixels
    tally = _Tally(layout, estimator, n_pixels)
    img = render_pass(scene, estimator, pass_index, seed, settings, blockers=blockers,
                      tally=tally)
    # Same scale as the pass image: per photon -> per pass, per ray -> per pixel.
    scale = 1.0 / (settings.photons * settings.spp)
    shape = layout.stack_shape
    return img, PassBreakdown(layout, tally.unweighted.reshape(shape) * scale,
                              tally.weighted.reshape(shape) * scale)


def weight_maps(weighted_by_technique: np.ndarray) -> np.ndarray:
    """Each technique's share of the pixel's luminance.

    Parameters
    ----------
    weighted_by_technique : (T, H, W, 3) array_like
        Per-technique weighted images (non-negative contributions).

    Returns
    -------
    (T, H, W) float64
        ``L(image_t) / sum_t L(image_t)`` where the total is positive, else 0. In [0, 1] and
        summing to 1 over ``t`` where defined; never NaN.
    """
    lum = np.clip(luminance(weighted_by_technique), 0.0, None)
    total = lum.sum(axis=0)
    ok = total > 0
    return np.where(ok, lum / np.where(ok, total, 1.0), 0.0)


class BreakdownAccumulator:
    """Progressive means (and per-pass variances, Welford) of the breakdown stacks.

    Parameters
    ----------
    layout : BreakdownLayout

    Attributes
    ----------
    unweighted, weighted : Welford
        Over ``(T, NK, H, W, 3)`` stacks; merged in pass order they equal a serial run.
    """

    def __init__(self, layout: BreakdownLayout):
        self.layout = layout
        self.unweighted = Welford.empty(layout.stack_shape)
        self.weighted = Welford.empty(layout.stack_shape)

    @property
    def n(self) -> int:
        """Passes seen."""
        return self.weighted.n

    def add(self, b: PassBreakdown) -> None:
        """Add one pass (in pass order)."""
        if b.layout != self.layout:
            raise ValueError("breakdown layout differs from the accumulator's")
        self.unweighted.add(b.unweighted)
        self.weighted.add(b.weighted)

    def add_arrays(self, unweighted: np.ndarray, weighted: np.ndarray) -> None:
        """Add one pass given as its two ``(T, NK, H, W, 3)`` stacks."""
        self.add(PassBreakdown(self.layout, unweighted, weighted))

    # ------------------------------------------------------------------ derived means
    @property
    def image(self) -> np.ndarray:
        """(H, W, 3) mean image (the sum of every technique and bin)."""
        return self.weighted.mean.sum(axis=(0, 1))

    def technique_images(self) -> np.ndarray:
        """(T, H, W, 3) mean weighted image of each technique (they sum to :attr:`image`)."""
        return self.weighted.mean.sum(axis=1)

    def technique_weights(self) -> np.ndarray:
        """(T, H, W) each technique's share of the pixel (see :func:`weight_maps`)."""
        return weight_maps(self.technique_images())

    def k_images(self, weighted: bool = True) -> np.ndarray:
        """(NK, H, W, 3) mean image of each scatter-count bin, summed over techniques.

        With ``weighted=False`` the sum of unweighted images counts each path once per
        technique that can produce it (it is *not* an estimate of the bin); use
        :meth:`unweighted_k` for one technique.
        """
        stack = self.weighted if weighted else self.unweighted
        return stack.mean.sum(axis=0)

    def index(self, technique) -> int:
        """Slot of ``technique`` (a name or an index) in the stacks (KeyError if absent)."""
        if isinstance(technique, str):
            try:
                return self.layout.techniques.index(technique)
            except ValueError:
                raise KeyError(f"technique {technique!r} is not in "
                               f"{', '.join(self.layout.techniques)}") from None
        return int(technique)

    def unweighted_k(self, technique, k: int) -> np.ndarray:
        """(H, W, 3) mean unweighted image of ``technique`` (name or index) at scatter count
        ``k``'s bin: that technique alone, an estimate of the whole bin."""
        return self.unweighted.mean[self.index(technique), self.layout.k_bin(k)]

    def weighted_k(self, technique, k: int) -> np.ndarray:
        """(H, W, 3) mean weighted image of ``technique`` at ``k``'s bin."""
        return self.weighted.mean[self.index(technique), self.layout.k_bin(k)]
