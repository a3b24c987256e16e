"""Geometric calibration of the rig's cameras from views of a ChArUco target.

Beyond the paper, which takes the cameras as calibrated. Each camera's
intrinsics ``K`` (pixels, with the skew ``K[0, 1]`` where the model has one),
its lens distortion (OpenCV's coefficients, the package's camera model:
:mod:`colourhs.common.geometry`) and the three cameras' poses are measured
from ``geometric/<pose>/<camera>.png``: the target of rig.json's
``geometric_board`` block (:func:`colourhs.calibration.board.charuco_layout`)
seen in many poses, by one, two or three cameras at a time.

Steps:

1. :func:`detect_charuco`: the target's chessboard corners in one image
   (OpenCV's ``CharucoDetector``, then each corner at the saddle point of the
   linear grey image, :func:`refine_saddles`).
2. :func:`calibrate_cameras`: per camera, ``cv2.calibrateCamera`` with k1 k2 p1
   p2 k3 gives a first K, distortion and the board's pose in each of its views
   (the richer models' own start, their rational terms free, lands far along
   their degenerate directions); the cameras are posed relative to the
   reference camera from the board poses they share; then one bundle
   adjustment refines everything jointly over every corner of every view with
   the model's coefficients (:func:`bundle_adjust`).
3. :func:`calibrate_rig`: reads a dataset's captures, writes rig.json (the
   measured cameras merged into the existing one) and a report
   (:func:`calibration_report`).

Why a bundle adjustment of its own rather than ``cv2.calibrateMultiview``: the
package's camera model has a skew ``K[0, 1]``, which OpenCV's pinhole
calibrations fix at 0; ``calibrateMultiview`` takes one point set per frame in
single precision, with visibility per camera and frame rather than per point,
while a ChArUco view holds the corners it holds; and the loss (Huber at
:data:`HUBER_PX`: a bad corner does not pull the fit), the world frame (a camera
or a board pose) and the parameters' uncertainties are then ours. The
parameters: per camera fx, fy, cx, cy (pixels), the skew where fitted, the
distortion coefficients; per camera but the reference its pose relative to the
reference camera (a rotation vector and a translation in metres); per board pose
its pose in the reference camera's frame. The reference camera's frame and the
board's ``square_length`` fix the gauge and the scale.

What the views can and cannot tell apart, over the narrow fields of these rigs
(20 to 35 degrees). The tangential terms p1, p2 trade against a shift of the
principal point with a tilt of the camera (or of every board pose): the
principal point and the cameras' rotations are the least certain figures, while
the projection of any point, which is what the later stages use, holds to the
corners' noise. With the rational terms k4-k6 the ratio of two polynomials
in r^2 also mimics a change of focal length; with the thin-prism terms s1-s4
the trade above holds to first order, so that the principal point and the
rotations are not measurable at all (:func:`_stages`). The report gives each
camera's 1-sigma (:attr:`Calibration.sd`).

Conventions (capture format): OpenCV's world-to-camera ``R``, ``t`` (a world
point X maps to ``R X + t``), metres, pixel (0, 0) the centre of the top-left
pixel (also OpenCV's convention for detected corners). A board pose maps the
board frame (origin at the chessboard's outer top-left corner, x right, y
down, the target in z = 0; :mod:`colourhs.calibration.board`) into the world:
``X_world = R_b X_board + t_b``.
"""

from __future__ import annotations

import copy
import json
import logging
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from colourhs.calibration.board import charuco_board
from colourhs.calibration.markers import to_grey8
from colourhs.common.files import atomic_output, write_json
from colourhs.common.geometry import camera_centre, pixels_of
from colourhs.common.progress import bar, stage

log = logging.getLogger(__name__)

__all__ = [
    "COVERAGE_GRID",
    "HUBER_PX",
    "MIN_CORNERS",
    "MIN_VIEWS",
    "WORLD_FIT_TOL_DEG",
    "WORLD_FIT_TOL_FRACTION",
    "Calibration",
    "LensModel",
    "board_corners",
    "bundle_adjust",
    "calibrate_cameras",
    "calibrate_rig",
    "calibration_report",
    "corner_coverage",
    "detect_charuco",
    "in_base_world",
    "in_world",
    "lens_model",
    "merge_rig",
    "refine_saddles",
    "report_summary",
    "world_transform",
]

MIN_VIEWS = 6
"""Least number of usable views (board poses) a camera needs: its intrinsics and
distortion come from its own views, and fewer than about six tilted views of a
planar target leave the focal length and the distortion poorly determined."""

MIN_CORNERS = 8
"""Least number of detected corners (not all on one line) that makes a view usable:
a homography needs 4, the margin guards against a view that only grazes the target."""

HUBER_PX = 1.0
"""Scale of the bundle adjustment's Huber loss, pixels: residuals below it count
quadratically (corner noise is about 0.1 px), larger ones linearly, so that one
mislocated corner does not pull the fit."""

COVERAGE_GRID = 4
"""The image is divided into this many cells across and down for the coverage figure;
a corner cell without any detected corner is named in a warning (the distortion
there is extrapolated)."""

_N_DIST = (4, 5, 8, 12)  # the distortion models fitted (OpenCV's, tilt left out)


# --------------------------------------------------------------------------------------------
# Model and detection


@dataclass(frozen=True)
class LensModel:
    """The camera model a calibration fits.

    Attributes
    ----------
    n_dist : int
        Distortion coefficients fitted, OpenCV's order: 4 (k1 k2 p1 p2), 5 (+ k3),
        8 (+ rational k4-k6) or 12 (+ thin prism s1-s4).
    skew : bool
        Whether ``K[0, 1]`` is fitted (else 0).
    written : int
        Length of ``dist`` in the rig.json written (14 keeps a 14-coefficient
        entry's length, its tilt terms zero).
    """

    n_dist: int = 5
    skew: bool = False
    written: int = 5

    def __post_init__(self) -> None:
        if self.n_dist not in _N_DIST:
            raise ValueError(
                f"a lens model of {self.n_dist} distortion coefficients is not one of "
                f"OpenCV's that the package models; choose from {_N_DIST}"
            )


def lens_model(dist, K=None) -> LensModel:
    """The model of a rig.json camera entry: the length of its ``dist`` (none: 5) and
    whether its ``K`` has a skew. A 14-coefficient entry is fitted with 12 (the package
    refuses a tilted sensor) and written with 14."""
    n = 0 if dist is None else len(np.ravel(dist))
    skew = K is not None and float(np.asarray(K, float)[0, 1]) != 0.0
    fitted = {0: 5, 14: 12}.get(n, n)
    return LensModel(fitted, skew, max(n, 5) if n != 4 else 4)


def board_corners(layout: Mapping[str, Any]) -> np.ndarray:
    """The target's interior chessboard corners in the board frame, metres, (M, 3).

    Corner k (OpenCV's ChArUco id) lies at ``((k % (nx - 1) + 1) s, (k // (nx - 1) + 1) s,
    0)`` for ``squares`` [nx, ny] and ``square_length`` s (:mod:`colourhs.calibration.board`).
    """
    board = charuco_board(layout)  # validates the description
    nx, ny = layout["squares"]
    s = float(layout["square_length"])
    k = np.arange((nx - 1) * (ny - 1))
    out = np.column_stack([(k % (nx - 1) + 1) * s, (k // (nx - 1) + 1) * s, np.zeros(k.size)])
    opencv = np.asarray(board.getChessboardCorners(), float).reshape(-1, 3)
    if not np.allclose(out, opencv, rtol=0.0, atol=1e-6):
        raise RuntimeError("OpenCV's ChArUco corners are not where the board module puts them")
    return out


def detect_charuco(
    image_rgb: np.ndarray, layout: Mapping[str, Any]
) -> tuple[np.ndarray, np.ndarray]:
    """The ChArUco target's chessboard corners in one image.

    The markers are found on the grey image scaled like the marker stage's
    (:func:`colourhs.calibration.markers.to_grey8`) and OpenCV's ``CharucoDetector``
    interpolates the corners between them; each corner is then refined to the saddle
    point of the linear (unquantised) grey image (:func:`refine_saddles`).

    Parameters
    ----------
    image_rgb : ndarray, shape (H, W, 3) or (H, W)
        Linear image, any scale (e.g. float in [0, 1] from ``read_image``).
    layout : dict
        The ``geometric_board`` description (:func:`colourhs.calibration.board.charuco_layout`).

    Returns
    -------
    ids : ndarray of int, shape (N,)
        Corner ids (:func:`board_corners` rows), ascending; empty when none is found.
    corners_px : ndarray, shape (N, 2)
        Their pixel positions (u, v), (0, 0) the centre of the top-left pixel.
    """
    img = np.asarray(image_rgb, np.float64)
    grey = img.mean(axis=2) if img.ndim == 3 else img
    detector = cv2.aruco.CharucoDetector(charuco_board(layout))
    corners, ids, _, _ = detector.detectBoard(to_grey8(grey))
    if ids is None or len(ids) == 0:
        return np.zeros(0, int), np.zeros((0, 2))
    ids = np.asarray(ids, int).ravel()
    uv = np.asarray(corners, np.float64).reshape(-1, 2)
    order = np.argsort(ids)
    ids, uv = ids[order], uv[order]
    if len(ids) > 1:
        uv = refine_saddles(grey, uv)
    return ids, uv


def refine_saddles(grey: np.ndarray, corners_px: np.ndarray) -> np.ndarray:
    """Chessboard corners refined to the saddle point of the smoothed image, pixels (N, 2).

    A chessboard corner is a point-symmetric X-junction (whatever the angle between its
    edges, so under perspective too), and so is the image smoothed by a Gaussian: its
    gradient vanishes at the corner. A quadratic is fitted to the smoothed image (cubic
    spline samples every half pixel in a disc around the estimate) and the estimate
    moves to the quadratic's saddle point until it settles. Over a disc centred on the
    corner the fit's linear terms, odd functions, see only the pattern's odd part, zero:
    the fixed point is the corner itself. Gaussian and disc scale with the distance
    between corners (:data:`_SADDLE_SIGMA`, :data:`_SADDLE_RADIUS`), to stay clear of
    the markers' edges: ``cv2.cornerSubPix`` (gradients orthogonal to the offsets
    from the corner) weighs every edge in its window alike, and on squares of a few
    tens of pixels a window that holds the corner's own edges holds a marker's too.

    Parameters
    ----------
    grey : (H, W) linear grey image.
    corners_px : (N, 2) first estimates (u, v) within a pixel or two, N >= 2.

    Returns
    -------
    (N, 2) refined corners; an estimate whose fit is not a saddle, or that moves more
    than a quarter of the distance to the nearest corner, is kept as given.
    """
    from scipy.ndimage import map_coordinates, spline_filter

    uv = np.asarray(corners_px, float).reshape(-1, 2)
    gaps = np.linalg.norm(uv[:, None] - uv[None], axis=-1)
    np.fill_diagonal(gaps, np.inf)
    spacing = float(np.median(gaps.min(axis=1)))
    sigma = float(np.clip(_SADDLE_SIGMA * spacing, 0.7, 2.0))
    radius = float(np.clip(_SADDLE_RADIUS * spacing, 1.5, 4.0))
    image = np.asarray(grey, np.float32)
    smooth = spline_filter(cv2.GaussianBlur(image, (0, 0), sigma).astype(np.float64), order=3)
    o = np.arange(-radius, radius + 1e-9, 0.5)
    ox, oy = (a.ravel() for a in np.meshgrid(o, o))
    disc = ox**2 + oy**2 <= radius**2
    ox, oy = ox[disc], oy[disc]
    fit = np.linalg.pinv(np.column_stack([ox * ox, ox * oy, oy * oy, ox, oy, np.ones_like(ox)]))
    out, ok = uv.copy(), np.ones(len(uv), bool)
    for _ in range(_SADDLE_ITERATIONS):
        coords = [out[:, 1:2] + oy, out[:, 0:1] + ox]
        values = map_coordinates(smooth, coords, order=3, mode="nearest", prefilter=False)
        a, b, c, d, e, _ = fit @ values.T
        det = 4.0 * a * c - b * b
        ok &= det < 0  # a saddle: the Hessian's eigenvalues of opposite signs
        with np.errstate(divide="ignore", invalid="ignore"):
            step = np.column_stack([(b * e - 2.0 * c * d) / det, (b * d - 2.0 * a * e) / det])
        step[~ok] = 0.0
        out += step
        if np.max(np.hypot(step[:, 0], step[:, 1])) < 1e-4:
            break
    ok &= np.linalg.norm(out - uv, axis=1) < 0.25 * gaps.min(axis=1)
    out[~ok] = uv[~ok]
    return out


_SADDLE_SIGMA = 0.04  # Gaussian of the saddle fit, times the corner spacing (pixels)
_SADDLE_RADIUS = 0.1  # radius of its disc of samples, times the corner spacing
_SADDLE_ITERATIONS = 20


# --------------------------------------------------------------------------------------------
# Calibration


@dataclass
class Calibration:
    """The cameras and board poses a calibration measured.

    Attributes
    ----------
    cameras : tuple of str
        Camera names; the first is the reference.
    K, dist, R, t : dict of str to ndarray
        Per camera: intrinsics (3, 3) in pixels, distortion (n_dist,), world-to-camera
        rotation (3, 3) and translation (3,) in metres, in the world frame ``world``.
    board_poses : dict of str to (ndarray, ndarray)
        Per board pose used, (R_b, t_b): board frame to world, ``X = R_b X_board + t_b``.
    residuals_px : dict of str to dict of str to ndarray
        Per camera and pose, the reprojection residuals (N, 2) of the corners used, pixels.
    views_left_out : dict of str to dict of str to str
        Per camera, the poses whose view was not used and why.
    world : str
        ``"reference"`` or ``"board:<pose>"``.
    model : LensModel
    sd : dict of str to dict
        Per camera, 1-sigma uncertainties from the residuals' spread
        (:func:`bundle_adjust`): ``f_px`` [fx, fy], ``c_px`` [cx, cy], ``skew_px``,
        ``rotation_deg`` and ``translation_mm`` of its pose relative to the reference
        camera (0 for the reference itself).
    """

    cameras: tuple[str, ...]
    K: dict[str, np.ndarray]
    dist: dict[str, np.ndarray]
    R: dict[str, np.ndarray]
    t: dict[str, np.ndarray]
    board_poses: dict[str, tuple[np.ndarray, np.ndarray]]
    residuals_px: dict[str, dict[str, np.ndarray]]
    views_left_out: dict[str, dict[str, str]] = field(default_factory=dict)
    world: str = "reference"
    model: LensModel = field(default_factory=LensModel)
    sd: dict[str, dict[str, Any]] = field(default_factory=dict)


def calibrate_cameras(
    detections: Mapping[str, Mapping[str, tuple[np.ndarray, np.ndarray]]],
    layout: Mapping[str, Any],
    image_size: tuple[int, int],
    model: LensModel | None = None,
    world: str = "reference",
) -> Calibration:
    """Intrinsics, distortion and poses of every camera from its ChArUco detections.

    Parameters
    ----------
    detections : dict of camera name to dict of pose name to (ids, corners_px)
        What :func:`detect_charuco` found in each camera's view of each pose (a pose a
        camera did not see may be missing). The first camera is the reference.
    layout : dict
        The ``geometric_board`` description: corner positions and the scale (metres).
    image_size : (int, int)
        Image width and height, pixels.
    model : LensModel, optional
        The model to fit (default :class:`LensModel`: 5 coefficients, no skew).
    world : str
        ``"reference"`` (the first camera at R = I, t = 0) or ``"board:<pose>"`` (that
        pose's board frame).

    Returns
    -------
    Calibration

    Raises
    ------
    ValueError
        A camera with fewer than :data:`MIN_VIEWS` usable views (named, with its views
        and their corner counts), a camera that shares no view with the reference or
        with a camera posed from it, or a world pose that is not among the views used.
    """
    model = model or LensModel()
    names = tuple(detections)
    if not names:
        raise ValueError("no camera's detections were given")
    X = board_corners(layout)
    views, left_out = _usable_views(detections, X, layout)
    _check_views(names, views, detections)
    _check_world(world, views)
    width, height = (int(v) for v in image_size)
    init = {c: _calibrate_one(views[c], X, (width, height), model) for c in names}
    cam_poses = _relative_poses(names, init)
    board = _board_poses(names, init, cam_poses)
    for fitted in _stages(model):
        fit = bundle_adjust(views, X, init, cam_poses, board, fitted)
        init = {c: _Initial(fit["K"][c], fit["dist"][c], {}) for c in names}
        cam_poses = {c: (fit["R"][c], fit["t"][c]) for c in names}
        board = fit["board"]
    cal = Calibration(
        cameras=names,
        K=fit["K"],
        dist=fit["dist"],
        R=fit["R"],
        t=fit["t"],
        board_poses=board,
        residuals_px=fit["residuals_px"],
        views_left_out=left_out,
        model=model,
        sd=fit["sd"],
    )
    return in_world(cal, world)


def _stages(model: LensModel) -> list[LensModel]:
    """The bundle adjustments run in turn: the thin-prism model after the model without
    it (its s1, s3 with p2, p1 trade against a rotation of the camera plus a shift of its
    principal point to first order: started from s = 0 the fit stays on the solution
    nearest the model without thin prism, instead of wandering along that valley)."""
    if model.n_dist == 12:
        return [LensModel(8, model.skew, 8), model]
    return [model]


def _usable_views(detections, X, layout):
    """Per camera the views with >= MIN_CORNERS corners not on one line; the others
    with why."""
    views: dict[str, dict[str, tuple[np.ndarray, np.ndarray]]] = {}
    left_out: dict[str, dict[str, str]] = {}
    square = float(layout["square_length"])
    for cam, per_pose in detections.items():
        views[cam], left_out[cam] = {}, {}
        for pose, (ids, uv) in sorted(per_pose.items()):
            ids = np.asarray(ids, int).ravel()
            uv = np.asarray(uv, float).reshape(-1, 2)
            if ids.size < MIN_CORNERS:
                left_out[cam][pose] = f"{ids.size} corners (fewer than {MIN_CORNERS})"
                continue
            pts = X[ids, :2] - X[ids, :2].mean(axis=0)
            if np.linalg.svd(pts, compute_uv=False)[1] < 0.5 * square:
                left_out[cam][pose] = "its corners lie on one line"
                continue
            views[cam][pose] = (ids, uv)
    return views, left_out


def _check_world(world: str, views) -> None:
    """ValueError for a world that is neither ``reference`` nor a used ``board:<pose>``."""
    if world == "reference":
        return
    used = sorted({p for per_pose in views.values() for p in per_pose})
    if not world.startswith("board:"):
        raise ValueError(
            f"world {world!r}: expected 'reference' or 'board:POSE' (calibrate-rig: also 'base')"
        )
    if world.removeprefix("board:") not in used:
        raise ValueError(
            f"world {world!r}: no usable view of the target in pose "
            f"{world.removeprefix('board:')!r}; poses used: {', '.join(used) or 'none'}"
        )


def _check_views(names, views, detections) -> None:
    for cam in names:
        if len(views[cam]) < MIN_VIEWS:
            seen = ", ".join(
                f"{pose} ({len(np.ravel(ids))} corners)"
                for pose, (ids, _) in sorted(detections[cam].items())
            )
            raise ValueError(
                f"camera {cam} has {len(views[cam])} usable views of the ChArUco target; "
                f"it needs at least {MIN_VIEWS} with >= {MIN_CORNERS} corners each "
                f"(its views: {seen or 'none'})"
            )
    posed, frontier = {names[0]}, [names[0]]
    while frontier:
        shared = set(views[frontier.pop()])
        for cam in names:
            if cam not in posed and shared & set(views[cam]):
                posed.add(cam)
                frontier.append(cam)
    lonely = [c for c in names if c not in posed]
    if lonely:
        raise ValueError(
            f"camera(s) {', '.join(lonely)} share no usable view of the target with the "
            f"reference camera {names[0]} (or a camera posed from it), so they cannot be "
            f"posed: capture poses that both see (views of {names[0]}: "
            f"{', '.join(sorted(views[names[0]])) or 'none'}; of "
            + "; of ".join(f"{c}: {', '.join(sorted(views[c])) or 'none'}" for c in lonely)
            + ")"
        )


@dataclass
class _Initial:
    K: np.ndarray
    dist: np.ndarray  # (n_dist,)
    board: dict[str, tuple[np.ndarray, np.ndarray]]  # pose -> board-to-camera (R, t)


def _calibrate_one(views, X, size, model: LensModel) -> _Initial:
    """``cv2.calibrateCamera`` of one camera's views: k1 k2 p1 p2 k3 (k3 fixed at 0 for the
    4-coefficient model), the start of every model's bundle adjustment."""
    poses = sorted(views)
    obj = [X[views[p][0]].astype(np.float32) for p in poses]
    img = [views[p][1].astype(np.float32).reshape(-1, 1, 2) for p in poses]
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12)
    _, K, dist, rvecs, tvecs = cv2.calibrateCamera(
        obj,
        img,
        size,
        None,
        None,
        flags=cv2.CALIB_FIX_K3 if model.n_dist == 4 else 0,
        criteria=criteria,
    )
    dist = np.asarray(dist, float).ravel()
    d = np.zeros(model.n_dist)
    d[: min(dist.size, d.size)] = dist[: d.size]
    board = {
        p: (cv2.Rodrigues(np.asarray(r, float))[0], np.asarray(tv, float).ravel())
        for p, r, tv in zip(poses, rvecs, tvecs, strict=True)
    }
    return _Initial(np.asarray(K, float), d, board)


def _relative_poses(names, init) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Each camera's pose relative to the reference (reference -> camera), through the
    board poses it shares with a camera already posed (breadth first)."""
    poses = {names[0]: (np.eye(3), np.zeros(3))}
    frontier = [names[0]]
    while frontier:
        known = frontier.pop(0)
        Rk, tk = poses[known]
        for cam in names:
            shared = sorted(set(init[cam].board) & set(init[known].board))
            if cam in poses or not shared:
                continue
            rots, trans = [], []
            for p in shared:
                Rcb, tcb = init[cam].board[p]
                Rkb, tkb = init[known].board[p]
                R = Rcb @ Rkb.T  # known camera -> this camera
                rots.append(R @ Rk)
                trans.append(R @ (tk - tkb) + tcb)
            poses[cam] = (Rotation.from_matrix(rots).mean().as_matrix(), np.median(trans, axis=0))
            frontier.append(cam)
    return poses


def _board_poses(names, init, cam_poses) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Each board pose in the reference camera's frame, from the first camera that sees it."""
    out = {}
    for cam in names:
        Rc, tc = cam_poses[cam]
        for p, (Rcb, tcb) in init[cam].board.items():
            if p not in out:
                out[p] = (Rc.T @ Rcb, Rc.T @ (tcb - tc))
    return dict(sorted(out.items()))


@dataclass
class _Packing:
    """Where each parameter sits in the bundle adjustment's vector."""

    names: tuple[str, ...]
    poses: tuple[str, ...]
    model: LensModel

    @property
    def n_intr(self) -> int:
        return 4 + int(self.model.skew) + self.model.n_dist

    def intr(self, c: int) -> slice:
        return slice(c * self.n_intr, (c + 1) * self.n_intr)

    def cam(self, c: int) -> slice:  # c >= 1
        base = len(self.names) * self.n_intr + (c - 1) * 6
        return slice(base, base + 6)

    def pose(self, p: int) -> slice:
        base = len(self.names) * self.n_intr + (len(self.names) - 1) * 6 + p * 6
        return slice(base, base + 6)

    @property
    def size(self) -> int:
        return self.pose(len(self.poses)).start

    def K_dist(self, x: np.ndarray, c: int) -> tuple[np.ndarray, np.ndarray]:
        v = x[self.intr(c)]
        fx, fy, cx, cy = v[:4]
        skew = v[4] if self.model.skew else 0.0
        K = np.array([[fx, skew, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
        return K, np.array(v[4 + int(self.model.skew) :])

    def pack(self, init, cam_poses, board) -> np.ndarray:
        """The parameter vector of starting values (:func:`bundle_adjust`'s arguments)."""
        x = np.zeros(self.size)
        for c, cam in enumerate(self.names):
            K, given = np.asarray(init[cam].K, float), np.ravel(init[cam].dist)
            d = np.zeros(self.model.n_dist)
            d[: min(d.size, given.size)] = given[: d.size]
            intr = [K[0, 0], K[1, 1], K[0, 2], K[1, 2]] + ([K[0, 1]] if self.model.skew else [])
            x[self.intr(c)] = np.concatenate([intr, d])
            if c:
                x[self.cam(c)] = _rotvec_t(*cam_poses[cam])
        for p, pose in enumerate(self.poses):
            x[self.pose(p)] = _rotvec_t(*board[pose])
        return x

    def unpack(self, x: np.ndarray, res: np.ndarray, obs) -> dict[str, Any]:
        """:func:`bundle_adjust`'s result from the parameter vector and the residuals."""
        out: dict[str, Any] = {"K": {}, "dist": {}, "R": {}, "t": {}, "residuals_px": {}}
        for c, cam in enumerate(self.names):
            out["K"][cam], out["dist"][cam] = self.K_dist(x, c)
            out["R"][cam], out["t"][cam] = (
                (np.eye(3), np.zeros(3)) if c == 0 else _pose(x[self.cam(c)])
            )
            mine = obs["cam"] == c
            out["residuals_px"][cam] = {
                pose: res[mine & (obs["pose"] == p)]
                for p, pose in enumerate(self.poses)
                if np.any(mine & (obs["pose"] == p))
            }
        out["board"] = {pose: _pose(x[self.pose(p)]) for p, pose in enumerate(self.poses)}
        return out

    def deviations(self, sd: np.ndarray) -> dict[str, dict[str, Any]]:
        """Per camera, the 1-sigma of its parameters (:attr:`Calibration.sd`)."""
        out = {}
        for c, cam in enumerate(self.names):
            v = sd[self.intr(c)]
            pose = sd[self.cam(c)] if c else np.zeros(6)
            out[cam] = {
                "f_px": [float(v[0]), float(v[1])],
                "c_px": [float(v[2]), float(v[3])],
                "skew_px": float(v[4]) if self.model.skew else 0.0,
                "rotation_deg": math.degrees(float(np.linalg.norm(pose[:3]))),
                "translation_mm": 1e3 * float(np.linalg.norm(pose[3:])),
            }
        return out


def bundle_adjust(views, X, init, cam_poses, board, model: LensModel) -> dict[str, Any]:
    """Refine every camera's intrinsics and distortion, the cameras' poses relative to
    the reference and every board pose jointly, minimising the reprojection error of
    every corner in every view.

    Parameters
    ----------
    views : dict camera -> dict pose -> (ids, corners_px)
        The views used (the first camera is the reference).
    X : (M, 3) board corners, metres (:func:`board_corners`).
    init : dict camera -> object with ``K`` (3, 3) and ``dist``
        Starting intrinsics (``dist`` zero-padded or cut to the model's length).
    cam_poses : dict camera -> (R, t)
        Starting poses, reference camera frame to camera.
    board : dict pose -> (R_b, t_b)
        Starting board poses, board frame to the reference camera's frame.
    model : LensModel

    Returns
    -------
    dict with ``K``, ``dist``, ``R``, ``t`` (per camera, reference camera frame),
    ``board`` (per pose), ``residuals_px`` (per camera and pose, (N, 2), pixels) and
    ``sd`` (per camera, :attr:`Calibration.sd`: the covariance ``s^2 (J^T W J)^-1`` at the
    solution, ``s^2`` the weighted residuals' variance per degree of freedom).

    Levenberg-Marquardt (MINPACK, ``x_scale='jac'`` evening out parameters of pixels,
    metres and radians) on a dense Jacobian by central differences: a corner's residual
    depends on its camera's parameters and its board pose only, so a pair of
    evaluations differences one parameter of every camera, or of every board pose, at
    once (:func:`_column_groups`); MINPACK's QR keeps the precision that the normal
    equations of these nearly degenerate lens models (rational terms over a narrow
    field) would lose. The Huber loss (:data:`HUBER_PX`, on each corner's residual
    length) by iteratively reweighted rounds: a round with weights 1, then with
    ``min(1, HUBER_PX / |e|)`` until the weights settle (one round when no corner is
    beyond it).
    """
    names = tuple(views)
    pack = _Packing(names, tuple(board), model)
    x = pack.pack(init, cam_poses, board)
    obs = _observations(views, pack, X)
    groups, column_rows = _column_groups(pack), _column_rows(pack, obs)
    weights = np.ones(len(obs["cam"]))
    for _ in range(_IRLS_ROUNDS):
        root_w = np.repeat(np.sqrt(weights), 2)

        def residuals(v, root_w=root_w):
            return root_w * _residuals(v, pack, obs).ravel()

        def jacobian(v, residuals=residuals):
            return _jacobian(residuals, v, groups, column_rows, 2 * len(obs["cam"]))

        x = least_squares(
            residuals,
            x,
            jac=jacobian,
            method="lm",
            x_scale="jac",
            ftol=1e-14,
            xtol=1e-14,
            gtol=1e-15,
            max_nfev=_MAX_NFEV,
        ).x
        norms = np.linalg.norm(_residuals(x, pack, obs), axis=1)
        new = np.minimum(1.0, HUBER_PX / np.maximum(norms, 1e-300))
        if np.allclose(new, weights, rtol=0.0, atol=1e-3):
            break
        weights = new
    out = pack.unpack(x, _residuals(x, pack, obs), obs)
    root_w = np.repeat(np.sqrt(weights), 2)

    def weighted(v):
        return root_w * _residuals(v, pack, obs).ravel()

    J = _jacobian(weighted, x, groups, column_rows, 2 * len(obs["cam"]))
    out["sd"] = pack.deviations(_standard_deviations(J, weighted(x)))
    return out


def _standard_deviations(J: np.ndarray, r: np.ndarray) -> np.ndarray:
    """1-sigma of each parameter, ``sqrt(diag(s^2 (J^T J)^-1))`` with ``s^2 = |r|^2 / (m - n)``,
    by the SVD of the column-scaled J (directions the data do not fix at all, singular
    values below 1e-12 of the largest, are left out rather than made infinite)."""
    m, n = J.shape
    s2 = float(r @ r) / max(m - n, 1)
    scale = np.linalg.norm(J, axis=0)
    scale[scale == 0] = 1.0
    _, sv, vt = np.linalg.svd(J / scale, full_matrices=False)
    inv = np.zeros_like(sv)
    keep = sv > 1e-12 * sv[0]
    inv[keep] = 1.0 / sv[keep] ** 2
    return np.sqrt(s2 * ((vt.T**2) @ inv)) / scale


def _pose(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(R, t) of a rotation vector and translation (6,)."""
    return Rotation.from_rotvec(v[:3]).as_matrix(), np.array(v[3:6], float)


def _rotvec_t(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The rotation vector and translation (6,) of (R, t)."""
    return np.concatenate([Rotation.from_matrix(R).as_rotvec(), np.ravel(t)])


def _observations(views, pack: _Packing, X) -> dict[str, np.ndarray]:
    cam, pose, pts, uv = [], [], [], []
    index = {p: k for k, p in enumerate(pack.poses)}
    for c, name in enumerate(pack.names):
        for p, (ids, corners) in views[name].items():
            cam.append(np.full(len(ids), c))
            pose.append(np.full(len(ids), index[p]))
            pts.append(X[ids])
            uv.append(corners)
    return {
        "cam": np.concatenate(cam),
        "pose": np.concatenate(pose),
        "X": np.concatenate(pts),
        "uv": np.concatenate(uv),
    }


def _residuals(x: np.ndarray, pack: _Packing, obs) -> np.ndarray:
    """Projected minus detected corners (N, 2), pixels."""
    n_poses = len(pack.poses)
    pose_v = x[pack.pose(0).start : pack.pose(n_poses).start].reshape(n_poses, 6)
    Rb = Rotation.from_rotvec(pose_v[:, :3]).as_matrix()
    Xr = np.einsum("nij,nj->ni", Rb[obs["pose"]], obs["X"]) + pose_v[obs["pose"], 3:]
    out = np.empty_like(obs["uv"])
    for c in range(len(pack.names)):
        pick = obs["cam"] == c
        Xc = Xr[pick]
        if c:
            R, t = _pose(x[pack.cam(c)])
            Xc = Xc @ R.T + t
        K, d = pack.K_dist(x, c)
        u, v = pixels_of(Xc[:, 0] / Xc[:, 2], Xc[:, 1] / Xc[:, 2], K, d)
        out[pick] = np.column_stack([u, v]) - obs["uv"][pick]
    return out


def _column_groups(pack: _Packing) -> list[np.ndarray]:
    """Parameters whose residuals do not overlap, differenced together: the same
    intrinsic of every camera, the same pose parameter of every camera, of every board
    pose (a corner depends on its own camera and board pose only)."""
    n = len(pack.names)
    groups = [np.array([pack.intr(c).start + k for c in range(n)]) for k in range(pack.n_intr)]
    groups += [np.array([pack.cam(c).start + k for c in range(1, n)]) for k in range(6)]
    groups += [np.array([pack.pose(p).start + k for p in range(len(pack.poses))]) for k in range(6)]
    return [g for g in groups if g.size]


def _column_rows(pack: _Packing, obs) -> list[np.ndarray]:
    """For each parameter, the residual rows it moves: its camera's or its board pose's."""
    cam_rows = [np.flatnonzero(np.repeat(obs["cam"], 2) == c) for c in range(len(pack.names))]
    pose_rows = [np.flatnonzero(np.repeat(obs["pose"], 2) == p) for p in range(len(pack.poses))]
    out: list[np.ndarray] = [np.zeros(0, int)] * pack.size
    for c, rows in enumerate(cam_rows):
        for k in range(pack.intr(c).start, pack.intr(c).stop):
            out[k] = rows
        if c:
            for k in range(pack.cam(c).start, pack.cam(c).stop):
                out[k] = rows
    for p, rows in enumerate(pose_rows):
        for k in range(pack.pose(p).start, pack.pose(p).stop):
            out[k] = rows
    return out


def _jacobian(fun, x: np.ndarray, groups, column_rows, n_rows: int) -> np.ndarray:
    """Dense Jacobian (n_rows, x.size) of the residuals by central differences, one pair
    of evaluations per column group (:func:`_column_groups`); a column keeps only its
    own rows (:func:`_column_rows`)."""
    J = np.zeros((n_rows, x.size))
    for cols in groups:
        h = _STEP * np.maximum(1.0, np.abs(x[cols]))
        xp, xm = x.copy(), x.copy()
        xp[cols] += h
        xm[cols] -= h
        diff = fun(xp) - fun(xm)
        for col, step in zip(cols, h, strict=True):
            rows = column_rows[col]
            J[rows, col] = diff[rows] / (2.0 * step)
    return J


_STEP = float(np.finfo(float).eps) ** (1.0 / 3.0)  # central differences' relative step
_IRLS_ROUNDS = 6  # reweightings of the Huber loss (one when no corner is beyond HUBER_PX)
_MAX_NFEV = 100  # Levenberg-Marquardt evaluations per round


def in_world(cal: Calibration, world: str) -> Calibration:
    """``cal`` (in its own world frame) expressed in another world frame.

    Parameters
    ----------
    cal : Calibration
    world : str
        ``"reference"``: the first camera's frame (its R = I, t = 0); ``"board:<pose>"``:
        the target's frame in that pose (its R_b = I, t_b = 0).

    Returns
    -------
    Calibration
        The same cameras and board poses, moved rigidly (intrinsics, residuals unchanged).

    Raises
    ------
    ValueError
        An unknown world, or a pose that is not among the calibration's board poses.
    """
    if world == "reference":
        R0, t0 = cal.R[cal.cameras[0]], cal.t[cal.cameras[0]]  # old world -> new world
    elif world.startswith("board:"):
        pose = world.removeprefix("board:")
        if pose not in cal.board_poses:
            raise ValueError(
                f"world {world!r}: no board pose {pose!r} among the views used "
                f"({', '.join(cal.board_poses)})"
            )
        Rb, tb = cal.board_poses[pose]  # board -> old world, so old world -> board is its inverse
        R0, t0 = Rb.T, -Rb.T @ tb
    else:
        raise ValueError(f"world {world!r}: expected 'reference' or 'board:POSE'")
    return _moved(cal, R0, t0, world)


def in_base_world(cal: Calibration, old_cameras: list[Mapping[str, Any]]) -> Calibration:
    """``cal`` expressed in the world frame of an existing rig.json's cameras (``world``
    ``"base"``): the rigid map of :func:`world_transform` from that world to ``cal``'s,
    inverted, so that ground truth, lights and anything else given in the old world
    keep their coordinates.

    Raises
    ------
    ValueError
        Where the old cameras do not describe the rig (:func:`_world_fits`: beyond
        :data:`WORLD_FIT_TOL_DEG` or :data:`WORLD_FIT_TOL_FRACTION` after the fit).
    """
    A, b, rot_rms, centre_rms = world_transform(old_cameras, cal.R, cal.t)
    if not _world_fits(cal, rot_rms, centre_rms):
        raise ValueError(
            "world 'base': the base rig's cameras do not match the calibrated ones "
            f"(rotations {rot_rms:.2f} deg RMS, centres {centre_rms * 1e3:.1f} mm RMS apart "
            f"after the best rigid fit; at most {WORLD_FIT_TOL_DEG:g} deg and "
            f"{WORLD_FIT_TOL_FRACTION:.0%} of the baseline), so their world frame is unknown: "
            "give their poses roughly, or choose the world 'reference' or 'board:POSE'"
        )
    return _moved(cal, A.T, -A.T @ b, "base")  # X_old = A^T (X_new - b)


def _moved(cal: Calibration, R0: np.ndarray, t0: np.ndarray, world: str) -> Calibration:
    """``cal``'s cameras and board poses in the frame ``X_new = R0 X_old + t0``."""
    # X_new = R0 X_old + t0; a camera's x_c = R X_old + t = R R0^T (X_new - t0) + t.
    R = {c: _orthonormal(cal.R[c] @ R0.T) for c in cal.cameras}
    t = {c: cal.t[c] - R[c] @ t0 for c in cal.cameras}
    boards = {p: (_orthonormal(R0 @ Rb), R0 @ tb + t0) for p, (Rb, tb) in cal.board_poses.items()}
    return replace(cal, R=R, t=t, board_poses=boards, world=world)


# --------------------------------------------------------------------------------------------
# Report


def corner_coverage(
    corners_px: np.ndarray, image_size: tuple[int, int], grid: int = COVERAGE_GRID
) -> tuple[float, list[str]]:
    """How much of the image a camera's detected corners cover.

    Parameters
    ----------
    corners_px : (N, 2) every corner the camera's views used, pixels.
    image_size : (width, height), pixels.
    grid : cells across and down.

    Returns
    -------
    coverage : float
        Fraction of the ``grid`` x ``grid`` cells holding at least one corner.
    uncovered : list of str
        The image-corner cells (``top-left``, ``top-right``, ``bottom-left``,
        ``bottom-right``) without any: there the distortion is extrapolated.
    """
    w, h = image_size
    uv = np.asarray(corners_px, float).reshape(-1, 2)
    col = np.clip(np.floor((uv[:, 0] + 0.5) / w * grid), 0, grid - 1).astype(int)
    row = np.clip(np.floor((uv[:, 1] + 0.5) / h * grid), 0, grid - 1).astype(int)
    hit = np.zeros((grid, grid), bool)
    hit[row, col] = True
    cells = {(0, 0): "top-left", (0, grid - 1): "top-right"}
    cells |= {(grid - 1, 0): "bottom-left", (grid - 1, grid - 1): "bottom-right"}
    return float(hit.mean()), [name for (r, c), name in cells.items() if not hit[r, c]]


def calibration_report(
    cal: Calibration, views: Mapping[str, Mapping[str, tuple]], image_size: tuple[int, int]
) -> dict[str, Any]:
    """The calibration's figures as JSON: per camera the reprojection RMS overall and per
    pose (pixels), the views used and left out, the corner coverage (:func:`corner_coverage`);
    per camera pair the angle between the optical axes (degrees) and the baseline
    (metres); and a warning per camera whose coverage leaves an image corner out.

    ``views`` holds each camera's detections (pose -> (ids, corners_px)); only the
    views the calibration used count for the coverage.
    """
    cameras, warnings = {}, []
    all_res = []
    for cam in cal.cameras:
        res = cal.residuals_px[cam]
        used = sorted(res)
        stacked = np.concatenate([res[p] for p in used])
        all_res.append(stacked)
        corners = np.concatenate([np.asarray(views[cam][p][1], float) for p in used])
        coverage, uncovered = corner_coverage(corners, image_size)
        cameras[cam] = {
            "rms_px": _rms(stacked),
            "max_px": float(np.linalg.norm(stacked, axis=1).max()),
            "rms_px_per_pose": {p: _rms(res[p]) for p in used},
            "views": used,
            "views_left_out": dict(cal.views_left_out.get(cam, {})),
            "corners": len(stacked),
            "coverage": coverage,
            "uncovered_corner_cells": uncovered,
            "K": cal.K[cam].tolist(),
            "dist": cal.dist[cam].tolist(),
            "sd": cal.sd.get(cam, {}),
        }
        if uncovered:
            warnings.append(
                f"camera {cam}: no target corner in the {', '.join(uncovered)} cell(s) of a "
                f"{COVERAGE_GRID} x {COVERAGE_GRID} grid over the image; the distortion "
                "there is extrapolated: add views with the target in those image corners"
            )
    pairs = []
    for i, a in enumerate(cal.cameras):
        for b in cal.cameras[i + 1 :]:
            za, zb = cal.R[a][2], cal.R[b][2]  # optical axes
            angle = math.atan2(float(np.linalg.norm(np.cross(za, zb))), float(za @ zb))
            base = camera_centre(cal.R[a], cal.t[a]) - camera_centre(cal.R[b], cal.t[b])
            pairs.append(
                {
                    "cameras": [a, b],
                    "angle_deg": math.degrees(angle),
                    "baseline_m": float(np.linalg.norm(base)),
                }
            )
    return {
        "world": cal.world,
        "reference_camera": cal.cameras[0],
        "model": {"dist_coefficients": cal.model.n_dist, "skew": cal.model.skew},
        "rms_px": _rms(np.concatenate(all_res)),
        "cameras": cameras,
        "pairs": pairs,
        "board_poses": {
            p: {"R": R.tolist(), "t": t.tolist()} for p, (R, t) in cal.board_poses.items()
        },
        "warnings": warnings,
    }


def report_summary(report: Mapping[str, Any]) -> str:
    """A few lines of :func:`calibration_report`'s figures for the terminal."""
    lines = [
        f"world frame {report['world']}, reference camera {report['reference_camera']}; "
        f"{report['model']['dist_coefficients']} distortion coefficients"
        + (" and a skew" if report["model"]["skew"] else "")
        + f"; reprojection RMS {report['rms_px']:.3f} px"
    ]
    for cam, c in report["cameras"].items():
        K = c["K"]
        worst = max(c["rms_px_per_pose"].items(), key=lambda kv: kv[1])
        lines.append(
            f"{cam}: RMS {c['rms_px']:.3f} px (worst pose {worst[0]} {worst[1]:.3f} px) over "
            f"{len(c['views'])} views, {c['corners']} corners, coverage "
            f"{100 * c['coverage']:.0f} %; f {K[0][0]:.2f} {K[1][1]:.2f} px (+-"
            f"{c['sd'].get('f_px', [0.0])[0]:.2f}), principal point {K[0][2]:.2f} "
            f"{K[1][2]:.2f} px (+-{max(c['sd'].get('c_px', [0.0])):.2f})"
        )
    for p in report["pairs"]:
        a, b = p["cameras"]
        lines.append(
            f"{a}-{b}: optical axes {p['angle_deg']:.2f} deg apart, baseline "
            f"{1e3 * p['baseline_m']:.2f} mm"
        )
    return "\n".join(lines)


def _rms(res: np.ndarray) -> float:
    """RMS length of residual vectors (N, 2), pixels."""
    return float(np.sqrt(np.mean(np.sum(np.asarray(res) ** 2, axis=-1))))


# --------------------------------------------------------------------------------------------
# rig.json


def world_transform(
    old_cameras: list[Mapping[str, Any]], new_R: Mapping, new_t: Mapping
) -> tuple[np.ndarray, np.ndarray, float, float]:
    """The rigid map ``X_new = A X_old + b`` from an old rig's world frame to the new one.

    For every camera the old and new poses describe the same camera, so
    ``A = R_new^T R_old``; the rotations are averaged (chordal mean) and ``b`` fitted to
    the camera centres (``c_new = A c_old + b``, least squares).

    Parameters
    ----------
    old_cameras : rig.json camera entries (``name``, ``R``, ``t``).
    new_R, new_t : the new poses by camera name.

    Returns
    -------
    A : (3, 3) rotation.
    b : (3,) translation, metres.
    rotation_rms_deg : RMS disagreement of the cameras' rotations with A, degrees.
    centre_rms_m : RMS disagreement of the cameras' centres with the fit, metres.
    """
    rots, old_c, new_c = [], [], []
    for entry in old_cameras:
        R_old, t_old = np.asarray(entry["R"], float), np.asarray(entry["t"], float)
        R_new, t_new = np.asarray(new_R[entry["name"]]), np.asarray(new_t[entry["name"]])
        rots.append(R_new.T @ R_old)
        old_c.append(camera_centre(R_old, t_old))
        new_c.append(camera_centre(R_new, t_new))
    A = Rotation.from_matrix(rots).mean().as_matrix()
    old_c, new_c = np.array(old_c), np.array(new_c)
    b = (new_c - old_c @ A.T).mean(axis=0)
    angles = [np.linalg.norm(Rotation.from_matrix(A.T @ r).as_rotvec()) for r in rots]
    rot_rms = math.degrees(float(np.sqrt(np.mean(np.square(angles)))))
    centre_rms = float(np.sqrt(np.mean(np.sum((old_c @ A.T + b - new_c) ** 2, axis=1))))
    return A, b, rot_rms, centre_rms


WORLD_FIT_TOL_DEG = 5.0
"""Largest RMS disagreement (degrees) of the old rig's camera rotations with the rigid
map to the new world for which world positions (``chromatic_light.position``) are
carried over; beyond it the old cameras do not describe the rig (a placeholder)."""

WORLD_FIT_TOL_FRACTION = 0.1
"""The same for the camera centres, as a fraction of the new rig's mean baseline."""


def merge_rig(base: Mapping[str, Any], cal: Calibration) -> tuple[dict[str, Any], dict[str, Any]]:
    """rig.json with the calibrated cameras merged into ``base`` (a decoded rig.json).

    Each camera's ``K``, ``dist``, ``R`` and ``t`` are replaced (``dist`` of the model's
    written length); everything else is kept: names, lights (colours, offsets, in
    camera coordinates), ``image``, ``board``, ``geometric_board``, unknown keys. The
    world positions (``chromatic_light.position``) are carried into the new world frame
    with :func:`world_transform`; when the old cameras do not fit it (beyond
    :data:`WORLD_FIT_TOL_DEG` or :data:`WORLD_FIT_TOL_FRACTION`) they are kept as they
    were, with a warning.

    Returns
    -------
    rig : dict
        The new rig.json contents.
    info : dict
        ``old_world``: the fit of the old cameras to the new ones (``rotation_rms_deg``,
        ``centre_rms_mm``, ``carried``: whether world positions were carried over);
        ``warnings``: list of str.
    """
    rig = copy.deepcopy(dict(base))
    entries = rig.get("cameras", [])
    names = [e.get("name") for e in entries]
    missing = [c for c in names if c not in cal.K]
    if missing or len(names) != len(cal.cameras):
        raise ValueError(
            f"the rig's cameras {names} are not the calibrated ones {list(cal.cameras)}"
        )
    warnings = []
    A, b, rot_rms, centre_rms = world_transform(entries, cal.R, cal.t)
    usable = _world_fits(cal, rot_rms, centre_rms)
    light = rig.get("chromatic_light", {})
    if "position" in light:
        if usable:
            new = A @ np.asarray(light["position"], float) + b
            light["position"] = [float(v) for v in new]
        else:
            warnings.append(
                "the old rig's cameras do not match the calibrated ones (rotations "
                f"{rot_rms:.2f} deg RMS, centres {centre_rms * 1e3:.1f} mm RMS apart after "
                "the best rigid fit), so the world frame they describe is unknown: "
                "chromatic_light.position is kept as it was; check it is in the new world "
                f"frame ({cal.world})"
            )
    for entry in entries:
        cam = entry["name"]
        d = np.zeros(cal.model.written)
        d[: cal.model.n_dist] = cal.dist[cam]
        entry["K"] = np.asarray(cal.K[cam], float).tolist()
        entry["dist"] = d.tolist()
        entry["R"] = _orthonormal(cal.R[cam]).tolist()
        entry["t"] = np.asarray(cal.t[cam], float).tolist()
    fit = {"rotation_rms_deg": rot_rms, "centre_rms_mm": 1e3 * centre_rms, "carried": usable}
    return rig, {"old_world": fit, "warnings": warnings}


def _world_fits(cal: Calibration, rot_rms_deg: float, centre_rms_m: float) -> bool:
    """Whether an old rig's cameras fit ``cal``'s (:func:`world_transform`'s residuals)
    within :data:`WORLD_FIT_TOL_DEG` and :data:`WORLD_FIT_TOL_FRACTION` of ``cal``'s mean
    baseline: then they describe the rig and their world frame is known."""
    centres = [camera_centre(cal.R[c], cal.t[c]) for c in cal.cameras]
    baselines = [np.linalg.norm(p - q) for i, p in enumerate(centres) for q in centres[i + 1 :]]
    scale = float(np.mean(baselines)) if baselines else 0.0
    return rot_rms_deg <= WORLD_FIT_TOL_DEG and centre_rms_m <= WORLD_FIT_TOL_FRACTION * scale


def _orthonormal(R: np.ndarray) -> np.ndarray:
    """The nearest rotation (SVD): a product of rotations drifts by ~1e-16 per step."""
    u, _, vt = np.linalg.svd(np.asarray(R, float))
    return u @ vt


def _rig_text(rig: Mapping[str, Any]) -> str:
    """rig.json as indented JSON with each list of numbers on one line."""
    text = json.dumps(rig, indent=2)
    return re.sub(r"\[[^\[\]{}\"]*\]", lambda m: json.dumps(json.loads(m.group(0))), text) + "\n"


# --------------------------------------------------------------------------------------------
# The stage


def calibrate_rig(
    dataset_dir: str | Path,
    out_json: str | Path,
    world: str = "reference",
    base_rig: str | Path | None = None,
    report_json: str | Path | None = None,
) -> dict[str, Any]:
    """Calibrate the rig's cameras from a dataset's ``geometric/`` captures; write rig.json.

    Parameters
    ----------
    dataset_dir : str or Path
        The dataset: ``geometric/<pose>/<camera>.png`` (or ``.tif``), and rig.json unless
        ``base_rig`` is given.
    out_json : str or Path
        The rig.json to write: the calibrated cameras merged into the base
        (:func:`merge_rig`), checked by rig.json's reader first, written atomically.
    world : str
        ``"reference"`` (the first camera of rig.json at R = I, t = 0),
        ``"board:<pose>"`` (the target's frame in that pose) or ``"base"`` (the base
        rig.json's own world, :func:`in_base_world`: its cameras must be roughly right;
        ground truth and world positions given in it stay valid).
    base_rig : str or Path, optional
        The rig.json to merge into and take the names, image encoding, model
        (:func:`lens_model` of each camera) and ``geometric_board`` from; default the
        dataset's.
    report_json : str or Path, optional
        Also write the report (:func:`calibration_report`) here.

    Returns
    -------
    dict
        The report, with the warnings of the merge among its ``warnings`` and
        ``rig_check``, the calibrated rig against the photometric captures (None
        without them).

    Raises
    ------
    ValueError
        No ``geometric/`` folder, no ``geometric_board`` in rig.json, too few views of a
        camera, a camera that cannot be posed, or a rig.json that the result would break.
        Also where the dataset has photometric captures and the calibrated rig
        disagrees with them (:func:`colourhs.calibration.rig_check.validate_rig`: a
        camera moved between the geometric and the photometric captures).
    """
    from colourhs.capture import read_image, rig_from_dict

    root = Path(dataset_dir)
    base_path = Path(base_rig) if base_rig is not None else root / "rig.json"
    if not base_path.is_file():
        raise ValueError(f"{base_path}: no rig.json to merge the calibration into")
    base = json.loads(base_path.read_text(encoding="utf-8"))
    rig = rig_from_dict(base, base_path)
    layout = getattr(rig, "geometric_board", None) or base.get("geometric_board")
    if not layout:
        raise ValueError(
            f"{base_path}: no geometric_board block (the ChArUco target's description; "
            "`colourhs board OUT.pdf --charuco SQUARES_X SQUARES_Y --square-length M` "
            "writes one beside the print)"
        )
    files = _geometric_files(root, rig.camera_names)
    if world not in ("reference", "base"):  # a pose not captured is named before any work
        _check_world(world, {"captures": dict.fromkeys(files)})
    detections: dict[str, dict[str, tuple[np.ndarray, np.ndarray]]] = {
        c: {} for c in rig.camera_names
    }
    for pose in bar(files, "calibrate-rig: ChArUco corners", unit="pose"):
        for cam, path in files[pose].items():
            detections[cam][pose] = detect_charuco(read_image(path, rig.image)[0], layout)
    models = {lens_model(e.get("dist"), e["K"]) for e in base["cameras"]}
    model = max(models, key=lambda m: (m.n_dist, m.skew, m.written))
    size = (rig.image.width, rig.image.height)
    stage(log, f"calibrate-rig: bundle adjustment of {len(files)} poses")
    fitted_world = "reference" if world == "base" else world
    cal = calibrate_cameras(detections, layout, size, model, fitted_world)
    if world == "base":
        cal = in_base_world(cal, base["cameras"])
    report = calibration_report(cal, detections, size)
    new_rig, info = merge_rig(base, cal)
    report["old_world"] = info["old_world"]
    report["warnings"] += info["warnings"]
    checked = rig_from_dict(new_rig, out_json)  # the reader accepts it, or nothing is written
    report["rig_check"] = _photometric_check(root, checked)
    with atomic_output(out_json) as tmp:
        tmp.write_text(_rig_text(new_rig), encoding="utf-8")
    if report_json is not None:
        write_json(report_json, report)
    return report


def _photometric_check(root: Path, rig) -> dict | None:
    """The calibrated ``rig`` against the dataset's photometric captures
    (:func:`colourhs.calibration.rig_check.validate_rig`), before it is written: cameras
    moved between the geometric and the photometric captures are a ValueError here.
    None where the dataset has no photometric poses (or is the geometric captures
    alone)."""
    from colourhs.calibration.rig_check import validate_rig
    from colourhs.capture import CaptureFormatError, open_dataset

    try:
        ds = open_dataset(root, check_images=False, scenes=())
    except CaptureFormatError:  # geometric/ and rig.json alone: nothing to check against
        return None
    if not ds.poses:
        return None
    try:
        return validate_rig(replace(ds, rig=rig))
    except CaptureFormatError as e:
        raise ValueError(
            f"{rig.path}: not written: the calibrated cameras disagree with the photometric "
            f"captures of {root} ({e.problem}); were cameras moved between the geometric/ "
            "and the photometric/ captures?"
        ) from None


def _geometric_files(root: Path, cameras: tuple[str, ...]) -> dict[str, dict[str, Path]]:
    """pose -> camera -> image file of ``geometric/`` (the views that exist).

    The dataset reader's poses and files (``Dataset.geometric_poses``,
    ``geometric_image``) where it reads the dataset; else (a folder of the
    geometric captures and rig.json alone, or a reader without them) the pose
    folders under ``geometric/`` and :func:`colourhs.capture.dataset.capture_files`.
    """
    from colourhs.capture import CaptureFormatError, open_dataset
    from colourhs.capture.dataset import capture_files

    folder = root / "geometric"
    if not folder.is_dir():
        raise ValueError(
            f"{folder}: no geometric/ folder (the ChArUco target's views, "
            "geometric/<pose>/<camera>.png)"
        )
    try:
        ds = open_dataset(root, check_images=False, scenes=())
        poses, image = tuple(ds.geometric_poses), ds.geometric_image
    except (CaptureFormatError, AttributeError):
        poses = tuple(
            sorted(p.name for p in folder.iterdir() if p.is_dir() and not p.name.startswith("."))
        )

        def image(pose: str, camera: str) -> Path:
            found = capture_files(folder / pose, camera)
            return found[0] if found else folder / pose / f"{camera}.png"

    out = {p: {c: image(p, c) for c in cameras} for p in poses}
    out = {p: {c: f for c, f in files.items() if f.is_file()} for p, files in out.items()}
    if not any(out.values()):
        raise ValueError(f"{folder}: no view of any camera ({', '.join(cameras)}) in it")
    return out
