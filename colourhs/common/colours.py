"""Colours of scalar values (per-vertex errors on meshes, error maps).

Only ``matplotlib.colormaps`` (no pyplot, no backend): :mod:`colourhs.evaluation.accuracy`
colours its error meshes with it, :mod:`colourhs.report.figures` its figures.
"""

from __future__ import annotations

import matplotlib
import numpy as np

#: Colour of vertices with no value in :func:`value_colours`.
NO_VALUE_GREY = 0.5


def value_colours(
    values: np.ndarray, vmin: float, vmax: float, cmap: str = "viridis"
) -> np.ndarray:
    """Colours of scalar values under a matplotlib colormap (e.g. per-vertex error on a mesh).

    Parameters
    ----------
    values : array_like, shape (N,)
        Scalars; NaN (or inf) where unknown.
    vmin, vmax : float
        Values mapped to the colormap's two ends; values outside are clipped.
    cmap : str
        Matplotlib colormap name.

    Returns
    -------
    ndarray of float64, shape (N, 3)
        RGB in [0, 1]; non-finite values are grey (0.5, 0.5, 0.5).
    """
    values = np.asarray(values, dtype=np.float64).reshape(-1)
    span = float(vmax) - float(vmin)
    with np.errstate(invalid="ignore", divide="ignore"):
        s = (values - float(vmin)) / span if span > 0 else values * 0.0
    finite = np.isfinite(s)
    s = np.clip(np.where(finite, s, 0.0), 0.0, 1.0)
    rgb = np.asarray(matplotlib.colormaps[cmap](s)[:, :3], dtype=np.float64)
    rgb[~finite] = NO_VALUE_GREY
    return rgb


def colour_values(
    rgb: np.ndarray, vmin: float, vmax: float, cmap: str = "viridis", tol: float = 0.05
) -> np.ndarray:
    """The values :func:`value_colours` gave ``rgb`` (its inverse, to 1/255 of the range).

    Each colour is matched to the nearest of the colormap's 256 entries; a colour
    farther than ``tol`` from all of them (the no-value grey) gives NaN.

    Parameters
    ----------
    rgb : array_like, shape (N, 3)
        Colours, floats in [0, 1] or uint8 (e.g. the vertex colours of an
        error-coloured mesh, :func:`colourhs.evaluation.accuracy.evaluate_frame`).
    vmin, vmax : float
        The values of the colormap's two ends, as given to :func:`value_colours`.
    cmap : str
        Matplotlib colormap name.
    tol : float
        Largest RGB distance (in [0, 1] units) to the colormap that still counts.

    Returns
    -------
    ndarray of float64, shape (N,)
        The values, in ``[vmin, vmax]``; NaN for colours off the colormap.
    """
    rgb = np.asarray(rgb).reshape(-1, 3)
    rgb = rgb / 255.0 if np.issubdtype(rgb.dtype, np.integer) else rgb.astype(np.float64)
    lut = np.asarray(matplotlib.colormaps[cmap](np.linspace(0.0, 1.0, 256))[:, :3])
    from scipy.spatial import cKDTree

    dist, k = cKDTree(lut).query(rgb)
    values = float(vmin) + (float(vmax) - float(vmin)) * k / 255.0
    return np.where(dist <= tol, values, np.nan)
