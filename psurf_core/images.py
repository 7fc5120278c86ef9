"""Image output helpers: tone mapping, false colour, figures with colour bars, EXR probing.

numpy, imageio and matplotlib only (matplotlib through its object-oriented API and the Agg
canvas, never ``pyplot``, so no GUI backend is touched). Images are ``(H, W, 3)`` arrays with
row 0 at the top, as the renderer produces them.

Tone mapping (used by ``app.py render --png`` and the demo): the exposure maps the
``percentile``-th percentile (default 99.5) of the pixel luminance to 1, then values are
clipped to [0, 1] and encoded with the sRGB transfer function. A few bright pixels (fireflies,
the glow right at a light) then saturate instead of darkening the whole image.
"""

from __future__ import annotations

import os

import numpy as np

__all__ = [
    "DEFAULT_PERCENTILE",
    "LUMINANCE",
    "auto_exposure",
    "can_write_exr",
    "comparison_figure",
    "false_colour",
    "figure_png",
    "linear_to_srgb",
    "log_range",
    "luminance",
    "relative_mse",
    "tone_map",
    "write_exr",
    "write_png",
]

#: Percentile of the luminance that the automatic exposure maps to white.
DEFAULT_PERCENTILE = 99.5

#: Rec. 709 / sRGB luminance weights.
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])

#: Smallest positive value shown on a log scale (values below are clamped to it).
_LOG_FLOOR = 1e-30


def luminance(img: np.ndarray) -> np.ndarray:
    """Relative luminance of a linear RGB image.

    Parameters
    ----------
    img : (H, W, 3) array_like
        Linear RGB.

    Returns
    -------
    (H, W) float64
    """
    return np.asarray(img, dtype=np.float64) @ LUMINANCE


def auto_exposure(img: np.ndarray, percentile: float = DEFAULT_PERCENTILE) -> float:
    """Exposure (a scale factor) that maps a high luminance percentile to 1.

    Parameters
    ----------
    img : (H, W, 3) array_like
        Linear RGB (non-finite pixels are ignored).
    percentile : float
        In (0, 100]; the luminance at this percentile of the positive pixels becomes white.

    Returns
    -------
    float
        ``1 / L_p``; falls back to ``1 / max`` when the percentile is 0, and to 1 for an image
        without positive finite pixels.
    """
    lum = luminance(img)
    lum = lum[np.isfinite(lum) & (lum > 0)]
    if lum.size == 0:
        return 1.0
    level = float(np.percentile(lum, percentile))
    if not level > 0:
        level = float(lum.max())
    return 1.0 / level


def linear_to_srgb(x: np.ndarray) -> np.ndarray:
    """The sRGB transfer function (IEC 61966-2-1) on values in [0, 1].

    Parameters
    ----------
    x : array_like
        Linear values; clipped to [0, 1] first.

    Returns
    -------
    ndarray of float64
        Encoded values in [0, 1].
    """
    x = np.clip(np.asarray(x, dtype=np.float64), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def tone_map(img: np.ndarray, exposure: float | None = None,
             percentile: float = DEFAULT_PERCENTILE) -> np.ndarray:
    """Linear RGB to 8-bit sRGB.

    Parameters
    ----------
    img : (H, W, 3) array_like
        Linear RGB radiance.
    exposure : float, optional
        Scale applied before clipping; by default :func:`auto_exposure` of ``img``.
    percentile : float
        Passed to :func:`auto_exposure` when ``exposure`` is not given.

    Returns
    -------
    (H, W, 3) uint8
        Non-finite pixels become black.
    """
    img = np.asarray(img, dtype=np.float64)
    if exposure is None:
        exposure = auto_exposure(img, percentile)
    x = np.where(np.isfinite(img), img, 0.0) * exposure
    return np.round(linear_to_srgb(x) * 255.0).astype(np.uint8)


def log_range(values: np.ndarray) -> tuple[float, float]:
    """A ``(vmin, vmax)`` range for a log-scale plot of non-negative values.

    Parameters
    ----------
    values : array_like
        Non-negative values (zeros and non-finite values are ignored).

    Returns
    -------
    (float, float)
        The 1st and 100th percentiles of the positive values (``vmin < vmax``); ``(1e-3, 1)``
        when no value is positive.
    """
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v) & (v > 0)]
    if v.size == 0:
        return 1e-3, 1.0
    lo, hi = float(np.percentile(v, 1.0)), float(v.max())
    if not hi > lo:
        lo, hi = hi / 10.0, hi * 10.0
    return max(lo, _LOG_FLOOR), hi


def false_colour(values: np.ndarray, vmin: float | None = None, vmax: float | None = None,
                 cmap: str = "viridis") -> np.ndarray:
    """Map scalar values to RGB with a log scale and a perceptually uniform colour map.

    Parameters
    ----------
    values : (H, W) array_like
        Non-negative values (e.g. a per-pixel variance).
    vmin, vmax : float, optional
        The log-scale range; by default :func:`log_range`. Values outside are clamped.
    cmap : str
        A matplotlib colour map; ``viridis`` and ``cividis`` are colour-blind safe.

    Returns
    -------
    (H, W, 3) uint8
    """
    from matplotlib import colormaps

    lo, hi = log_range(values)
    lo = lo if vmin is None else vmin
    hi = hi if vmax is None else vmax
    t = _log_unit(values, lo, hi)
    rgb = colormaps[cmap](t)[..., :3]
    return np.round(rgb * 255.0).astype(np.uint8)


def _log_unit(values: np.ndarray, lo: float, hi: float) -> np.ndarray:
    v = np.asarray(values, dtype=np.float64)
    v = np.where(np.isfinite(v), v, 0.0)
    llo, lhi = np.log10(max(lo, _LOG_FLOOR)), np.log10(max(hi, lo * 1.0001, _LOG_FLOOR))
    lv = np.log10(np.clip(v, max(lo, _LOG_FLOOR), None))
    return np.clip((lv - llo) / (lhi - llo), 0.0, 1.0)


def _atomic_target(path: str) -> str:
    """A temporary name beside ``path`` that keeps its extension (for format detection)."""
    d, base = os.path.split(os.path.abspath(path))
    stem, ext = os.path.splitext(base)
    return os.path.join(d, f".{stem}.{os.getpid()}.tmp{ext}")


def write_atomically(path: str, write) -> None:
    """``write(target)`` to a temporary name beside ``path`` (same extension), then move it
    into place: a failed write leaves nothing behind."""
    target = _atomic_target(path)
    try:
        write(target)
        os.replace(target, path)
    finally:
        if os.path.exists(target):
            os.remove(target)


def write_png(path: str, rgb8: np.ndarray, *, atomic: bool = True) -> None:
    """Write an 8-bit RGB image as PNG.

    Parameters
    ----------
    path : str
        Destination; with ``atomic`` the file is written beside it under a temporary name
        and moved into place, so a failed write leaves nothing behind.
    rgb8 : (H, W, 3) uint8
    atomic : bool
    """
    import imageio.v3 as iio

    def write(target):
        iio.imwrite(target, np.ascontiguousarray(rgb8, dtype=np.uint8), extension=".png")

    if atomic:
        write_atomically(path, write)
    else:
        write(path)


def can_write_exr() -> tuple[bool, str]:
    """Whether OpenEXR output is available (the ``openexr`` package).

    Returns
    -------
    ok : bool
    reason : str
        Empty when ``ok``; otherwise why not (for an error message).
    """
    try:
        import OpenEXR  # noqa: F401
    except ImportError as e:
        return False, f"OpenEXR output needs the 'openexr' package ({e}); install it or drop --exr"
    return True, ""


def write_exr(path: str, img: np.ndarray) -> None:
    """Write a linear float RGB image as OpenEXR (float32, ZIP), atomically.

    Parameters
    ----------
    path : str
    img : (H, W, 3) array_like
        Row 0 is the top of the image.
    """
    import OpenEXR

    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    rgb = np.ascontiguousarray(img, dtype=np.float32)
    write_atomically(path, lambda target: OpenEXR.File(header, {"RGB": rgb}).write(target))


def relative_mse(img: np.ndarray, ref: np.ndarray) -> float:
    """Global relative mean squared error ``mean((img - ref)^2) / mean(ref^2)``.

    Parameters
    ----------
    img, ref : (H, W, 3) array_like

    Returns
    -------
    float
        ``inf`` when the reference is all zero (and ``img`` is not), 0 when both are.

    Notes
    -----
    Normalising by the mean squared reference (not pixel by pixel) keeps dark pixels, where a
    per-pixel ratio explodes, from dominating.
    """
    img = np.asarray(img, dtype=np.float64)
    ref = np.asarray(ref, dtype=np.float64)
    num = float(np.mean((img - ref) ** 2))
    den = float(np.mean(ref**2))
    if den == 0.0:
        return 0.0 if num == 0.0 else float("inf")
    return num / den


def figure_png(path: str, panels: list[dict], *, title: str | None = None,
               ncols: int | None = None, panel_width: float = 3.6) -> None:
    """Draw image panels (with optional colour bars) into one PNG, atomically.

    Parameters
    ----------
    path : str
        Destination PNG.
    panels : list of dict
        Each with ``image`` ((H, W, 3) uint8 or (H, W) float), ``title`` (str) and, for a
        false-colour panel, ``values`` ((H, W) float), ``vmin``, ``vmax``, ``cmap`` and
        ``label`` (colour-bar label); such a panel is drawn with a log-scale colour bar.
    title : str, optional
        Figure title.
    ncols : int, optional
        Panels per row (all in one row by default).
    panel_width : float
        Width of one panel in inches (100 dpi).
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.colors import LogNorm
    from matplotlib.figure import Figure

    n = len(panels)
    ncols = n if ncols is None else max(1, min(ncols, n))
    nrows = -(-n // ncols)
    h, w = np.asarray(panels[0]["image"]).shape[:2]
    bar = 1.0 if any("values" in p for p in panels) else 0.0  # inches taken by a colour bar
    panel_height = (panel_width - bar) * h / w + 0.45
    fig = Figure(figsize=(panel_width * ncols + 0.3, panel_height * nrows + (0.4 if title else 0)),
                 dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(nrows, ncols, squeeze=False)
    for ax in axes.flat[n:]:
        ax.set_axis_off()
    for ax, p in zip(axes.flat, panels, strict=False):
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_title(p.get("title", ""), fontsize=9)
        if "values" in p:
            norm = LogNorm(vmin=p["vmin"], vmax=p["vmax"], clip=True)
            v = np.clip(np.where(np.isfinite(p["values"]), p["values"], 0.0), p["vmin"], None)
            im = ax.imshow(v, cmap=p.get("cmap", "viridis"), norm=norm, interpolation="nearest")
            cb = fig.colorbar(im, ax=ax, pad=0.02, aspect=15)
            cb.set_label(p.get("label", ""), fontsize=8)
            cb.ax.tick_params(labelsize=7)
        else:
            ax.imshow(p["image"], interpolation="nearest")
    if title:
        fig.suptitle(title, fontsize=10)
    write_atomically(path, lambda target: fig.savefig(target, format="png"))


def comparison_figure(path: str, images: dict[str, np.ndarray], variances: dict[str, np.ndarray],
                      *, title: str | None = None, cmap: str = "viridis") -> None:
    """Side-by-side renders (one shared exposure) above their log-variance maps (one scale).

    Parameters
    ----------
    path : str
        Destination PNG.
    images : dict of str to (H, W, 3) ndarray
        Linear mean images by label, in display order.
    variances : dict of str to (H, W, 3) ndarray
        Per-pass variance images by the same labels (shown as luminance variance).
    title : str, optional
    cmap : str
        Colour map of the variance row.
    """
    labels = list(images)
    exposure = min(auto_exposure(images[k]) for k in labels)
    lum_var = {k: luminance(variances[k]) for k in labels}
    lo, hi = log_range(np.concatenate([v.ravel() for v in lum_var.values()]))
    panels = [{"image": tone_map(images[k], exposure), "title": f"{k} (exposure {exposure:.3g})"}
              for k in labels]
    panels += [{"image": lum_var[k], "values": lum_var[k], "vmin": lo, "vmax": hi, "cmap": cmap,
                "title": f"{k}: per-pass variance", "label": "luminance variance (log)"}
               for k in labels]
    figure_png(path, panels, title=title, ncols=len(labels))
