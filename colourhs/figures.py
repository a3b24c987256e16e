"""Figures of the pipeline's calibration results (matplotlib, Agg backend, no display)."""

from __future__ import annotations

import os
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

__all__ = ["chromaticity_figure", "chromaticity_rgb"]


def chromaticity_rgb(p: np.ndarray) -> np.ndarray:
    """Display image of a chromaticity map: each pixel's ``p / max(p)``, NaN black.

    Parameters
    ----------
    p : ndarray, shape (H, W, 3)
        ``(p_R, p_G, p_B)`` per pixel, NaN where unknown.

    Returns
    -------
    ndarray of float32, shape (H, W, 3)
        R, G, B in [0, 1]: the surface's colour under the rig's white light at full brightness.
    """
    p = np.asarray(p, dtype=np.float64)
    peak = np.max(p, axis=-1, keepdims=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        rgb = p / peak
    rgb[~np.all(np.isfinite(rgb), axis=-1)] = 0.0
    return np.clip(rgb, 0.0, 1.0).astype(np.float32)


def chromaticity_figure(
    intensity: np.ndarray,
    maps: dict[str, np.ndarray],
    out_png: str | Path,
    title: str | None = None,
    intensity_label: str | None = None,
) -> Path:
    """The paper's Figure 6: the object's intensity image and its chromaticity map per camera.

    Parameters
    ----------
    intensity : ndarray, shape (H, W)
        An intensity image of the object (e.g. the sum of its three chromatic captures' matching
        channels in one camera); shown in grey, scaled to its 99.5th percentile.
    maps : dict of str to ndarray, shape (H, W, 3)
        Camera name to chromaticity map, shown by :func:`chromaticity_rgb`.
    out_png : str or Path
        PNG file to write (written in place; callers wanting atomicity pass a temporary name).
    title : str, optional
        Figure title (e.g. the object's name).
    intensity_label : str, optional
        Camera of the intensity image, for its panel title.

    Returns
    -------
    Path
        ``out_png``.
    """
    intensity = np.asarray(intensity, dtype=np.float64)
    finite = intensity[np.isfinite(intensity)]
    top = np.percentile(finite, 99.5) if finite.size else 1.0
    grey = np.clip(np.nan_to_num(intensity / (top if top > 0 else 1.0)), 0.0, 1.0)
    n = 1 + len(maps)
    h, w = intensity.shape
    fig, axes = plt.subplots(1, n, figsize=(3.2 * n, 3.2 * h / w + 0.6), squeeze=False)
    axes = axes[0]
    axes[0].imshow(grey, cmap="gray", vmin=0.0, vmax=1.0, interpolation="nearest")
    axes[0].set_title("intensity" + (f" ({intensity_label})" if intensity_label else ""))
    for ax, (camera, p) in zip(axes[1:], maps.items(), strict=True):
        ax.imshow(chromaticity_rgb(p), interpolation="nearest")
        ax.set_title(f"chromaticity {camera}")
    for ax in axes:
        ax.set_axis_off()
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    out_png = Path(out_png)
    try:
        fig.savefig(out_png, dpi=100, format="png")
    finally:
        plt.close(fig)
    if not os.path.getsize(out_png):
        raise OSError(f"{out_png}: empty figure written")
    return out_png


def mu_maps_figure(
    maps: dict[str, np.ndarray], calibrated: dict[str, np.ndarray], out_png: str | Path
) -> Path:
    """The paper's Figure 3: heat maps of the six Helmholtz cameras' mu maps.

    Each map is shown relative to its median over the calibrated region
    (mu is defined up to one scale per reciprocal pair), with the
    uncalibrated part greyed out.

    Parameters
    ----------
    maps : ``"<camera>/<colour>"`` -> (H, W) mu map.
    calibrated : same keys -> (H, W) bool calibrated region.
    out_png : PNG file to write.
    """
    keys = sorted(maps)
    cols = 2
    rows = int(np.ceil(len(keys) / cols))
    h, w = next(iter(maps.values())).shape
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.4 * rows * h / w + 0.4),
                             squeeze=False)  # fmt: skip
    for ax in axes.ravel():
        ax.set_axis_off()
    for ax, key in zip(axes.ravel(), keys, strict=False):
        m = calibrated[key]
        rel = maps[key] / np.median(maps[key][m]) if m.any() else maps[key]
        shown = np.where(m, rel, np.nan)
        im = ax.imshow(shown, cmap="turbo", vmin=0.75, vmax=1.25, interpolation="nearest")
        ax.imshow(np.where(m, np.nan, 0.5), cmap="gray", vmin=0, vmax=1, alpha=0.6)
        ax.set_title(f"mu {key} (relative)")
        fig.colorbar(im, ax=ax, fraction=0.046, pad=0.02)
    fig.tight_layout()
    out_png = Path(out_png)
    out_png.parent.mkdir(parents=True, exist_ok=True)
    try:
        fig.savefig(out_png, dpi=90, format="png")
    finally:
        plt.close(fig)
    return out_png
