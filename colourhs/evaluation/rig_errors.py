"""A calibrated rig against the true one: each camera's intrinsic and pose errors.

The two rigs may live in different world frames (a geometric calibration
fixes its world to the reference camera or to a board pose): both are
expressed in their reference camera's frame first, so the reference's own
pose error is zero by construction and every other camera's is its pose
relative to the reference, which is what the HS constraint uses.
"""

from __future__ import annotations

import numpy as np

from colourhs.common.geometry import camera_centre, normalised_coordinates, pixels_of

__all__ = ["distortion_field_error", "in_reference_frame", "ray_errors", "rig_errors"]

GRID = (65, 49)
"""Points across and down the image where the distortion fields are compared (a
grid at a few per cent of the image's size: the fields are smooth)."""


def in_reference_frame(R: np.ndarray, t: np.ndarray, R0: np.ndarray, t0: np.ndarray):
    """A camera's world-to-camera (R, t) in the frame X' = R0 X + t0 (the reference
    camera's), metres."""
    R = np.asarray(R, float) @ np.asarray(R0, float).T
    return R, np.asarray(t, float) - R @ np.asarray(t0, float)


def distortion_field_error(
    K_true, dist_true, K_est, dist_est, size: tuple[int, int], mask_uv=None
) -> float:
    """Largest difference (pixels) between two lens models' displacement fields.

    At each grid point of the image: the distortion-free pixel of its true ray
    (true K), and the displacement each model makes there with its own K; the
    focal length's and principal point's own errors are left to their figures.

    Parameters
    ----------
    size : (width, height) of the image, pixels.
    mask_uv : optional (N, 2) pixels; only grid points inside their convex hull count
        (the region the calibration's corners covered). Default: the whole image.
    """
    w, h = size
    gu, gv = np.meshgrid(np.linspace(0, w - 1, GRID[0]), np.linspace(0, h - 1, GRID[1]))
    grid = np.stack([gu, gv], axis=-1).reshape(-1, 2)
    if mask_uv is not None:
        import cv2

        hull = cv2.convexHull(np.asarray(mask_uv, np.float32))
        inside = [cv2.pointPolygonTest(hull, (float(u), float(v)), False) >= 0 for u, v in grid]
        grid = grid[np.array(inside)]
    K_true, K_est = np.asarray(K_true, float), np.asarray(K_est, float)
    xy = normalised_coordinates(grid, K_true, dist_true)
    u_true, v_true = pixels_of(xy[:, 0], xy[:, 1], K_true, dist_true)
    ideal = xy @ K_true[:2, :2].T + K_true[:2, 2]  # the same rays without distortion
    yn = (ideal[:, 1] - K_est[1, 2]) / K_est[1, 1]
    xn = (ideal[:, 0] - K_est[0, 2] - K_est[0, 1] * yn) / K_est[0, 0]
    u_est, v_est = pixels_of(xn, yn, K_est, dist_est)
    shift_true = np.column_stack([u_true, v_true]) - ideal
    shift_est = np.column_stack([u_est, v_est]) - ideal
    return float(np.linalg.norm(shift_true - shift_est, axis=1).max())


def _rays(camera, R_ref, t_ref, grid: np.ndarray) -> np.ndarray:
    """Unit directions (N, 3) of the pixels ``grid`` of ``camera`` in its rig's reference
    frame (``R_ref``, ``t_ref``: the reference camera's pose)."""
    R, _ = in_reference_frame(camera.R, camera.t, R_ref, t_ref)
    xy = normalised_coordinates(grid, np.asarray(camera.K, float), camera.dist)
    d = np.column_stack([xy, np.ones(len(xy))])
    return (d / np.linalg.norm(d, axis=1, keepdims=True)) @ R


def ray_errors(true_cameras, est_cameras, size: tuple[int, int]) -> dict:
    """Per camera, what its intrinsics, distortion and pose do to the reconstruction's
    shape together: the estimated rig turned as a whole onto the true one about the
    reference camera's centre (the rotation that best maps every camera's estimated
    rays of a pixel grid onto the true ones, Kabsch), ``ray_deg`` the largest angle
    between a pixel's true and estimated rays over the image (degrees) and
    ``aligned_centre_mm`` the distance of the camera centres (mm). A principal point
    and a rotation that trade against each other (narrow fields) leave both small; a
    rotation of the whole rig changes no shape and is left out. Beyond the issue's
    per-parameter figures."""
    w, h = size
    gu, gv = np.meshgrid(np.linspace(0, w - 1, GRID[0]), np.linspace(0, h - 1, GRID[1]))
    grid = np.stack([gu, gv], axis=-1).reshape(-1, 2)
    t0, e0 = true_cameras[0], est_cameras[0]
    true = [_rays(c, np.asarray(t0.R, float), np.asarray(t0.t, float), grid) for c in true_cameras]
    est = [_rays(c, np.asarray(e0.R, float), np.asarray(e0.t, float), grid) for c in est_cameras]
    u, _, vt = np.linalg.svd(np.concatenate(est).T @ np.concatenate(true))
    Q = (u @ np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))]) @ vt).T  # est -> true
    out = {}
    for tc, ec, dt, de in zip(true_cameras, est_cameras, true, est, strict=True):
        de = de @ Q.T
        sin = np.linalg.norm(np.cross(dt, de), axis=1)  # the angle to rounding error
        ct = camera_centre(*in_reference_frame(tc.R, tc.t, t0.R, t0.t))
        ce = camera_centre(*in_reference_frame(ec.R, ec.t, e0.R, e0.t))
        out[tc.name] = {
            "ray_deg": float(np.degrees(np.arctan2(sin, np.sum(dt * de, axis=1))).max()),
            "aligned_centre_mm": 1e3 * float(np.linalg.norm(ct - Q @ ce)),
        }
    return out


def rig_errors(true_cameras, est_cameras, size: tuple[int, int], masks=None) -> dict:
    """Per camera: the errors of ``est_cameras`` against ``true_cameras``.

    Parameters
    ----------
    true_cameras, est_cameras : sequences of objects with ``name``, ``K``, ``dist``,
        ``R``, ``t`` (rig.json's cameras, :class:`colourhs.capture.Camera`), the
        first the reference, in the same order.
    size : (width, height) of the images, pixels.
    masks : optional {camera name: (N, 2) pixels} for :func:`distortion_field_error`.

    Returns
    -------
    dict
        Camera name -> ``f_rel`` (largest of |fx / fx_true - 1|, |fy / fy_true - 1|),
        ``pp_px``, ``skew_px``, ``field_px`` (:func:`distortion_field_error`),
        ``rotation_deg`` and ``centre_mm`` (relative to the reference camera),
        ``ray_deg`` and ``aligned_centre_mm`` (:func:`ray_errors`).
    """
    from scipy.spatial.transform import Rotation  # here: importing an evaluation needs no scipy

    t0, e0 = true_cameras[0], est_cameras[0]
    rays = ray_errors(true_cameras, est_cameras, size)
    out = {}
    for tc, ec in zip(true_cameras, est_cameras, strict=True):
        Kt, Ke = np.asarray(tc.K, float), np.asarray(ec.K, float)
        Rt, tt = in_reference_frame(tc.R, tc.t, t0.R, t0.t)
        Re, te = in_reference_frame(ec.R, ec.t, e0.R, e0.t)
        turn = Rotation.from_matrix(Rt.T @ Re).as_rotvec()
        mask = None if masks is None else masks.get(tc.name)
        out[tc.name] = {
            "f_rel": float(np.max(np.abs(np.diag(Ke)[:2] / np.diag(Kt)[:2] - 1))),
            "pp_px": float(np.max(np.abs(Ke[:2, 2] - Kt[:2, 2]))),
            "skew_px": abs(float(Ke[0, 1] - Kt[0, 1])),
            "field_px": distortion_field_error(Kt, tc.dist, Ke, ec.dist, size, mask),
            "rotation_deg": float(np.degrees(np.linalg.norm(turn))),
            "centre_mm": 1e3 * float(np.linalg.norm(camera_centre(Rt, tt) - camera_centre(Re, te))),
        } | rays[tc.name]
    return out
