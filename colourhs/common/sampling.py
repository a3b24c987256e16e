"""Exact bilinear sampling of images at sub-pixel positions.

One implementation for the calibration stages (photometric maps and their
errors, the cross-talk LED factor) and the tests' plain-NumPy reference of
the HS constraint (``tests/hs_constraint.py``). Not ``scipy.ndimage.map_coordinates``
(order 1 computes the same weights): this one gives NaN outside the image and for
NaN positions, and samples every channel of an (H, W, C) image with one set of weights.
The compiled kernels inline their own footprint (``reconstruct/dataterm.py``,
``reconstruct/sides.py``, ``carving.py``).
"""

from __future__ import annotations

import numpy as np


def sample_bilinear(image: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinearly interpolate ``image`` (H, W[, C]) at pixel positions ``uv`` (..., 2).

    Pixel (0, 0) is the centre of the top-left pixel (OpenCV convention).
    Positions outside [0, W-1] x [0, H-1] (or NaN) give NaN. Exact
    double-precision weights (``cv2.remap`` quantises them to 1/32 pixel).
    """
    img = np.asarray(image)
    H, W = img.shape[:2]
    uv = np.asarray(uv, float)
    u, v = uv[..., 0], uv[..., 1]
    ok = np.isfinite(u) & np.isfinite(v) & (u >= 0) & (v >= 0) & (u <= W - 1) & (v <= H - 1)
    u = np.where(ok, u, 0.0)
    v = np.where(ok, v, 0.0)
    u0 = np.minimum(np.floor(u).astype(int), W - 2)
    v0 = np.minimum(np.floor(v).astype(int), H - 2)
    a = u - u0
    b = v - v0
    if img.ndim == 3:
        a, b = a[..., None], b[..., None]
    out = (
        (1 - a) * (1 - b) * img[v0, u0]
        + a * (1 - b) * img[v0, u0 + 1]
        + (1 - a) * b * img[v0 + 1, u0]
        + a * b * img[v0 + 1, u0 + 1]
    ).astype(float)
    out[~ok] = np.nan
    return out
