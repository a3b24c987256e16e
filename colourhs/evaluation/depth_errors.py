"""Depth and normal errors of a depth map against the ground truth mesh.

A depth file (:mod:`colourhs.common.depthfile`) compared pixel by pixel with the
ground truth rendered into its reference camera
(:func:`colourhs.common.raycast.render_depth_normals`); used by the evaluation
stage (:mod:`colourhs.evaluation.accuracy`) and the accuracy benchmarks. Where the depth
file carries its per-pixel 1-sigma uncertainty (``depth_sigma``), the same
pixels also say how well that sigma predicts the error (:func:`sigma_summary`);
:func:`uncertainty_summary` needs no ground truth. Where it carries why each pixel
has no depth (``dropped``), :func:`drop_summary` says where the ground truth's
pixels without a depth went.
"""

from __future__ import annotations

import numpy as np

from colourhs.common.depthfile import DepthMap
from colourhs.common.metrics_csv import DROP_COLUMNS, DROP_REASONS, GAUSSIAN_WITHIN, SIGMA_MULTIPLES
from colourhs.common.raycast import render_depth_normals

__all__ = [
    "GAUSSIAN_WITHIN",
    "SIGMA_MULTIPLES",
    "depth_errors",
    "depth_summary",
    "drop_summary",
    "sigma_summary",
    "uncertainty_summary",
]


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
        error), ``depth_signed_median_mm`` (median of the signed error,
        reconstructed minus true: the bias), ``normal_median_deg``, ``coverage``
        (compared / truth pixels; None where there are no truth pixels) and
        ``truth_pixels``; the errors are None where there is nothing to compare.
    """
    signed = np.asarray(depth_error_m, float).ravel() * 1e3
    signed = signed[np.isfinite(signed)]
    e = np.abs(signed)
    a = np.asarray(normal_error_deg, float).ravel()
    a = a[np.isfinite(a)]
    truth_pixels = int(truth_pixels)
    out = {
        "depth_median_mm": None,
        "depth_rms_mm": None,
        "depth_p95_mm": None,
        "depth_signed_median_mm": None,
        "normal_median_deg": None,
        "coverage": e.size / truth_pixels if truth_pixels > 0 else None,
        "truth_pixels": truth_pixels,
    }
    if e.size:
        out["depth_median_mm"] = float(np.median(e))
        out["depth_rms_mm"] = float(np.sqrt(np.mean(e**2)))
        out["depth_p95_mm"] = float(np.percentile(e, 95))
        out["depth_signed_median_mm"] = float(np.median(signed))
    if a.size:
        out["normal_median_deg"] = float(np.median(a))
    return out


def sigma_summary(depth_error_m: np.ndarray, depth_sigma_m: np.ndarray | None) -> dict:
    """How well a depth map's 1-sigma uncertainty predicts its error against the truth.

    Over the compared pixels (finite ``depth_error_m``, the pixels of
    :func:`depth_summary`) that have a finite sigma.

    Parameters
    ----------
    depth_error_m : ndarray, shape (H, W) or (N,)
        Signed depth errors, metres (NaN: not compared).
    depth_sigma_m : ndarray of the same shape, or None
        1-sigma uncertainty of each pixel's depth, metres (NaN: none); None where
        the depth file has none.

    Returns
    -------
    dict
        ``depth_sigma_median_mm`` (median sigma, mm), ``sigma_within_<k>`` for k in
        :data:`SIGMA_MULTIPLES` (share of those pixels with ``|error| <= k sigma``;
        :data:`GAUSSIAN_WITHIN` for a calibrated sigma) and ``sigma_pixels`` (how
        many pixels; 0 where none). The values are None without sigma or pixels.
    """
    out = {"depth_sigma_median_mm": None, "sigma_pixels": 0}
    out |= {f"sigma_within_{k}": None for k in SIGMA_MULTIPLES}
    if depth_sigma_m is None:
        return out
    err = np.asarray(depth_error_m, float).ravel()
    sigma = np.asarray(depth_sigma_m, float).ravel()
    if err.shape != sigma.shape:
        raise ValueError(f"depth sigma has {sigma.size} values, the errors {err.size}")
    ok = np.isfinite(err) & np.isfinite(sigma)
    out["sigma_pixels"] = int(ok.sum())
    if not ok.any():
        return out
    err, sigma = np.abs(err[ok]), sigma[ok]
    out["depth_sigma_median_mm"] = float(np.median(sigma)) * 1e3
    for k in SIGMA_MULTIPLES:
        out[f"sigma_within_{k}"] = float(np.mean(err <= k * sigma))
    return out


def uncertainty_summary(depth_map: DepthMap) -> dict:
    """A depth map's own uncertainty, without ground truth.

    Parameters
    ----------
    depth_map : DepthMap

    Returns
    -------
    dict
        ``expected_depth_error_mm``: the median ``depth_sigma`` over the
        reconstructed pixels (``mask`` with a finite depth and sigma), mm: the
        error the reconstruction expects of itself; ``uncertain_share``: the
        ``uncertain`` (flagged) pixels over the reconstructed (``mask`` with a
        finite depth, not flagged) plus the flagged ones. Each None where the file
        lacks its dataset (files written before them, the visual hull) or has no
        such pixel. ``reciprocity_defect_deg``: the median over the reconstructed
        points of the half-vector angle between a reciprocal pair's two readings
        (the largest pair's; :meth:`colourhs.capture.Rig.reciprocity_defect`), 0
        with collocated lights; a glossy surface's depth can be off by more than
        its ``depth_sigma`` where it is not 0 (None where the file does not say).
    """
    defect = (depth_map.params or {}).get("reciprocity_defect_deg")
    out = {
        "expected_depth_error_mm": None,
        "uncertain_share": None,
        "reciprocity_defect_deg": None if defect is None else float(defect),
    }
    reconstructed = np.asarray(depth_map.mask, bool) & np.isfinite(depth_map.depth)
    if depth_map.depth_sigma is not None:
        sigma = np.asarray(depth_map.depth_sigma, float)
        sigma = sigma[reconstructed & np.isfinite(sigma)]
        if sigma.size:
            out["expected_depth_error_mm"] = float(np.median(sigma)) * 1e3
    if depth_map.uncertain is not None:
        flagged = np.asarray(depth_map.uncertain, bool)
        total = int((reconstructed & ~flagged).sum() + flagged.sum())
        if total:
            out["uncertain_share"] = float(flagged.sum()) / total
    return out


def drop_summary(depth_map: DepthMap, truth_valid: np.ndarray) -> dict:
    """Where the ground truth's pixels without a depth went: the share lost to each reason.

    Parameters
    ----------
    depth_map : DepthMap
        A depth map with its ``dropped`` codes (code ``k + 1``: ``DROP_REASONS[k]``).
    truth_valid : ndarray of bool, shape (H, W)
        Pixels where the ground truth has a depth (finite depth of
        :func:`colourhs.common.raycast.render_depth_normals`).

    Returns
    -------
    dict
        ``dropped_<reason>`` for each reason of :data:`colourhs.common.metrics_csv.DROP_REASONS`:
        the share (0 to 1, of the ground truth's pixels) without a finite depth whose
        code is that reason; ``dropped_other``: the share without a finite depth and
        with code 0 (lost without a reason). Codes of pixels that have a depth are
        not counted, so the shares plus :func:`depth_summary`'s ``coverage`` (the share
        with a finite depth) add to 1. All None where the map has no ``dropped`` or
        the ground truth no pixel.

    Raises
    ------
    ValueError
        When ``truth_valid`` is not of the depth map's shape.
    """
    out = dict.fromkeys(DROP_COLUMNS)
    truth = np.asarray(truth_valid, bool)
    if truth.shape != depth_map.depth.shape:
        raise ValueError(f"truth mask is {truth.shape}, the depth map {depth_map.depth.shape}")
    total = int(truth.sum())
    if depth_map.dropped is None or total == 0:
        return out
    lost = truth & ~np.isfinite(depth_map.depth)
    codes = np.asarray(depth_map.dropped, np.intp)[lost]
    counts = np.bincount(codes, minlength=len(DROP_REASONS) + 1)
    for k, reason in enumerate(DROP_REASONS):
        out[f"dropped_{reason}"] = float(counts[k + 1]) / total
    out["dropped_other"] = float(counts[0]) / total
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
    (:func:`colourhs.common.raycast.render_depth_normals`: z-depth and interpolated
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
        (:func:`colourhs.common.raycast.depth_normal_maps` of a cast the caller also
        uses for something else); the GT mesh arguments are then not cast again.

    Returns
    -------
    depth_error : ndarray, shape (H, W)
        Reconstructed minus true z-depth, metres; NaN where either is missing.
    normal_error : ndarray, shape (H, W)
        Angle between reconstructed and true normals, degrees; NaN where either is missing.
    metrics : dict
        :func:`depth_summary` of the two maps, :func:`sigma_summary` of the depth
        errors and the depth map's ``depth_sigma``, and :func:`drop_summary` of the
        depth map over the ground truth's pixels.
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
    truth_valid = np.isfinite(gd)
    metrics = depth_summary(err, ang, int(truth_valid.sum()))
    metrics |= sigma_summary(err, depth_map.depth_sigma) | drop_summary(depth_map, truth_valid)
    return err, ang, metrics


# --------------------------------------------------------------------------- rule functions
