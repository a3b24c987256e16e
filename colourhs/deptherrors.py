"""Depth and normal errors of a depth map against the ground truth mesh.

A depth file (:mod:`colourhs.depthfile`) compared pixel by pixel with the
ground truth rendered into its reference camera
(:func:`colourhs.raycast.render_depth_normals`); used by the evaluation
stage (:mod:`colourhs.evaluate`) and the accuracy benchmarks.
"""

from __future__ import annotations

import numpy as np

from colourhs.depthfile import DepthMap
from colourhs.raycast import render_depth_normals


def depth_summary(
    depth_error_m: np.ndarray, normal_error_deg: np.ndarray, truth_pixels: int
) -> dict:
    """Depth and normal error statistics over the pixels both reconstructed and true.

    Parameters
    ----------
    depth_error_m : ndarray
        Signed depth errors (metres) of the compared pixels (NaN entries ignored).
    normal_error_deg : ndarray
        Normal angle errors (degrees) of the compared pixels (NaN entries ignored).
    truth_pixels : int
        Pixels where the ground truth is visible (the coverage's denominator).

    Returns
    -------
    dict
        ``depth_median_mm``, ``depth_rms_mm``, ``depth_p95_mm`` (of the absolute
        error), ``normal_median_deg``, ``coverage`` (compared / truth pixels; None
        where there are no truth pixels) and ``truth_pixels``; the errors are None
        where there is nothing to compare.
    """
    e = np.abs(np.asarray(depth_error_m, float).ravel()) * 1e3
    e = e[np.isfinite(e)]
    a = np.asarray(normal_error_deg, float).ravel()
    a = a[np.isfinite(a)]
    truth_pixels = int(truth_pixels)
    out = {
        "depth_median_mm": None,
        "depth_rms_mm": None,
        "depth_p95_mm": None,
        "normal_median_deg": None,
        "coverage": e.size / truth_pixels if truth_pixels > 0 else None,
        "truth_pixels": truth_pixels,
    }
    if e.size:
        out["depth_median_mm"] = float(np.median(e))
        out["depth_rms_mm"] = float(np.sqrt(np.mean(e**2)))
        out["depth_p95_mm"] = float(np.percentile(e, 95))
    if a.size:
        out["normal_median_deg"] = float(np.median(a))
    return out


def depth_errors(
    depth_map: DepthMap,
    gt_vertices: np.ndarray,
    gt_triangles: np.ndarray,
    gt_normals: np.ndarray,
    width: int | None = None,
    height: int | None = None,
    truth: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray, dict]:
    """Per-pixel depth and normal errors of a depth map against a GT mesh.

    The GT is rendered into the depth map's reference camera
    (:func:`colourhs.raycast.render_depth_normals`: z-depth and interpolated
    vertex normals facing the camera at every pixel centre).

    Parameters
    ----------
    depth_map : DepthMap
    gt_vertices, gt_triangles, gt_normals : ndarray
        The GT mesh (metres) and its unit vertex normals.
    width, height : int, optional
        Image size, pixels (default: the depth map's; must match it).
    truth : (depth, normals), optional
        The GT already rendered into the reference camera
        (:func:`colourhs.raycast.depth_normal_maps` of a cast the caller also
        uses for something else); the GT mesh arguments are then not cast again.

    Returns
    -------
    depth_error : ndarray, shape (H, W)
        Reconstructed minus true z-depth, metres; NaN where either is missing.
    normal_error : ndarray, shape (H, W)
        Angle between reconstructed and true normals, degrees; NaN where either is missing.
    metrics : dict
        :func:`depth_summary` of the two maps.
    """
    width = depth_map.width if width is None else int(width)
    height = depth_map.height if height is None else int(height)
    if (height, width) != depth_map.depth.shape:
        raise ValueError(
            f"{depth_map.path}: depth map is {depth_map.depth.shape}, image is {(height, width)}"
        )
    if truth is None:
        truth = render_depth_normals(
            np.asarray(gt_vertices, float),
            np.asarray(gt_triangles),
            np.asarray(gt_normals, float),
            depth_map,
            width,
            height,
        )
    gd, gn = truth
    depth = np.asarray(depth_map.depth, float)
    err = depth - gd  # NaN where either is NaN
    n = np.asarray(depth_map.normal, float)
    with np.errstate(invalid="ignore"):
        n = n / np.linalg.norm(n, axis=2, keepdims=True)
        ang = np.degrees(np.arccos(np.clip(np.sum(n * gn, axis=2), -1.0, 1.0)))
    ang[~np.isfinite(err)] = np.nan
    return err, ang, depth_summary(err, ang, int(np.isfinite(gd).sum()))


# --------------------------------------------------------------------------- rule functions
