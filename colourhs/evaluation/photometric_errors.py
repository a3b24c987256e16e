"""Photometric calibration results against ground truth (synthetic rigs).

Measures of a result of :func:`colourhs.calibration.photometric.calibrate` (the mu maps
of eq. 2) against the true maps: :func:`mu_map_errors` (each map, up to one
scale per pair) and :func:`pair_ratio_errors` (the ratio ``mu_a / mu_b`` at
points seen by both cameras, what the HS constraint of eq. (5) uses), at the
white-board points of :func:`board_points`.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from colourhs.capture import COLOURS, Board, Rig
from colourhs.common.geometry import project
from colourhs.common.sampling import sample_bilinear


def mu_map_errors(result: dict, truth: dict[str, np.ndarray], rig: Rig) -> pd.DataFrame:
    """RMS log error of recovered mu maps against ground truth, up to one scale per pair.

    For each reciprocal pair, one constant (the pair's free scale) is removed
    from the log maps of both its Helmholtz cameras jointly, over their
    calibrated regions. The row "no calibration" does the same for mu = 1.
    """
    rows = []
    for pr in rig.reciprocal_pairs():
        keys = [f"{pr.cam_a}/{COLOURS[pr.channel_a]}", f"{pr.cam_b}/{COLOURS[pr.channel_b]}"]
        for method in ("calibrated", "no calibration"):
            errs = []
            for key in keys:
                m = result["calibrated"][key]
                est = np.log(result["maps"][key][m]) if method == "calibrated" else 0.0
                errs.append(est - np.log(truth[key][m]))
            shift = np.mean(np.concatenate(errs))
            for key, e in zip(keys, errs, strict=True):
                rms = float(np.sqrt(np.mean((e - shift) ** 2)))
                frac = float(result["calibrated"][key].mean())
                rows.append(
                    {
                        "map": key,
                        "method": method,
                        "rms_log_error": rms,
                        "calibrated_fraction": frac,
                    }
                )
    return pd.DataFrame(rows)


def board_points(board: Board, poses, spacing_m: float = 0.002) -> np.ndarray:
    """World points (N, 3) of the white surface of the board at each pose.

    ``poses``: iterable of (R, t) board-to-world poses; points on a square
    grid of ``spacing_m`` in the board frame, markers and edges (one
    spacing) left out.
    """
    w, h = board.size
    gx, gy = np.meshgrid(np.arange(spacing_m, w, spacing_m), np.arange(spacing_m, h, spacing_m))
    xy = np.stack([gx.ravel(), gy.ravel()], axis=1)
    xy = xy[board.white(xy, spacing_m)]
    pts = np.concatenate([xy, np.zeros((len(xy), 1))], axis=1)
    return np.concatenate([pts @ np.asarray(R, float).T + np.asarray(t, float) for R, t in poses])


def pair_ratio_errors(
    result: dict, truth: dict[str, np.ndarray], rig: Rig, points: np.ndarray
) -> pd.DataFrame:
    """RMS error of ``log(mu_a(u_a) / mu_b(u_b))`` per reciprocal pair at world ``points``.

    This is what the HS constraint (eq. 5) uses of the calibration: the
    ratio of the pair's two maps at the two pixels that see one point. A
    factor constant on each epipolar plane of the pair multiplies both maps
    and cancels here (it scales a row of W), as does the pair's free scale
    (one constant per pair is removed). Points (N, 3), metres, that fall in
    both cameras' images and calibrated regions count; the row
    "no calibration" does the same for mu = 1.

    Returns a DataFrame with ``pair``, ``method``, ``rms_log_error``,
    ``points`` (how many counted).
    """
    rows = []
    for pr in rig.reciprocal_pairs():
        A, B = rig.camera(pr.cam_a), rig.camera(pr.cam_b)
        ka, kb = f"{A.name}/{COLOURS[pr.channel_a]}", f"{B.name}/{COLOURS[pr.channel_b]}"
        uv_a = project(points, A.K, A.dist, A.R, A.t)
        uv_b = project(points, B.K, B.dist, B.R, B.t)
        ok = (sample_bilinear(result["calibrated"][ka].astype(float), uv_a) > 0.999) & (
            sample_bilinear(result["calibrated"][kb].astype(float), uv_b) > 0.999
        )
        true = np.log(sample_bilinear(truth[ka], uv_a[ok])) - np.log(
            sample_bilinear(truth[kb], uv_b[ok])
        )
        est = np.log(sample_bilinear(result["maps"][ka], uv_a[ok])) - np.log(
            sample_bilinear(result["maps"][kb], uv_b[ok])
        )
        for method, e in (("calibrated", est - true), ("no calibration", -true)):
            rms = float(np.sqrt(np.mean((e - e.mean()) ** 2))) if ok.any() else float("nan")
            rows.append(
                {
                    "pair": f"{ka}~{kb}",
                    "method": method,
                    "rms_log_error": rms,
                    "points": int(ok.sum()),
                }
            )
    return pd.DataFrame(rows)
