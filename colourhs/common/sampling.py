"""Bilinear sampling of images at sub-pixel positions: one footprint for every stage.

:func:`bilinear_footprint` (which texel, which fractions) and
:func:`bilinear_weights` (the four weights) are the one definition of the
bilinear footprint. They are plain NumPy-compatible arithmetic, so the same
functions serve whole arrays in NumPy and, compiled and inlined
(:data:`footprint_jit`, :data:`weights_jit`), single samples in the numba
kernels (the data term, the sides of the reciprocal pairs, the visual hull's
signed distances, the photometric grid).

:func:`sample_bilinear` samples images with them for the calibration stages
and the tests. Not ``scipy.ndimage.map_coordinates`` (order 1 computes the
same weights): this one gives NaN outside the image and for NaN positions,
and samples every channel of an (H, W, C) image with one set of weights.
"""

from __future__ import annotations

import numba as nb
import numpy as np

__all__ = [
    "bilinear_footprint",
    "bilinear_weights",
    "footprint_jit",
    "sample_bilinear",
    "weights_jit",
]


def bilinear_footprint(u, v, width, height):
    """Bilinear footprint of pixel positions (u, v) in a ``width`` x ``height`` image.

    Pixel (0, 0) is the centre of the top-left pixel (OpenCV convention).
    Works on scalars (compiled: :data:`footprint_jit`) and on arrays alike.

    Parameters
    ----------
    u, v : float or ndarray
        Column and row positions, pixels; NaN allowed.
    width, height : int or float
        The image's size, pixels (at least 2 each).

    Returns
    -------
    inside : bool or ndarray
        Whether (u, v) lies in [0, width - 1] x [0, height - 1] (False for NaN).
    u0, v0 : float or ndarray
        The top-left texel of the 2 x 2 footprint, integral floats in
        [0, width - 2] x [0, height - 2]: positions outside are clamped to the
        border first (NaN to 0), so the footprint is always a valid index.
    a, b : float or ndarray
        The fractions u - u0 and v - v0 in [0, 1].
    """
    inside = (u >= 0.0) & (v >= 0.0) & (u <= width - 1.0) & (v <= height - 1.0)
    u = np.fmin(np.fmax(u, 0.0), width - 1.0)
    v = np.fmin(np.fmax(v, 0.0), height - 1.0)
    u0 = np.fmin(np.floor(u), width - 2.0)
    v0 = np.fmin(np.floor(v), height - 2.0)
    return inside, u0, v0, u - u0, v - v0


def bilinear_weights(a, b):
    """The four bilinear weights of fractions ``a`` (along u) and ``b`` (along v).

    Returns ``(w00, w01, w10, w11)`` for the texels (v0, u0), (v0, u0 + 1),
    (v0 + 1, u0) and (v0 + 1, u0 + 1); they sum to 1. Scalars or arrays.
    """
    return (1.0 - a) * (1.0 - b), a * (1.0 - b), (1.0 - a) * b, a * b


footprint_jit = nb.njit(cache=True, inline="always")(bilinear_footprint)
""":func:`bilinear_footprint` for numba kernels (inlined where it is called)."""

weights_jit = nb.njit(cache=True, inline="always")(bilinear_weights)
""":func:`bilinear_weights` for numba kernels (inlined where it is called)."""


def sample_bilinear(image: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinearly interpolate ``image`` (H, W[, C]) at pixel positions ``uv`` (..., 2).

    Positions outside [0, W-1] x [0, H-1] (or NaN) give NaN. Exact
    double-precision weights (``cv2.remap`` quantises them to 1/32 pixel).
    """
    img = np.asarray(image)
    H, W = img.shape[:2]
    uv = np.asarray(uv, float)
    inside, u0, v0, a, b = bilinear_footprint(uv[..., 0], uv[..., 1], W, H)
    u0, v0 = u0.astype(int), v0.astype(int)
    if img.ndim == 3:
        a, b = a[..., None], b[..., None]
    w00, w01, w10, w11 = bilinear_weights(a, b)
    out = (
        w00 * img[v0, u0]
        + w01 * img[v0, u0 + 1]
        + w10 * img[v0 + 1, u0]
        + w11 * img[v0 + 1, u0 + 1]
    ).astype(float)
    out[~inside] = np.nan
    return out
