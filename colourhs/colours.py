"""Colours of scalar values (per-vertex errors on meshes, error maps).

Only ``matplotlib.colormaps`` (no pyplot, no backend): :mod:`colourhs.evaluate`
colours its error meshes with it, :mod:`colourhs.figures` its figures.
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
