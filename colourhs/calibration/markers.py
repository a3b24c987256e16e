"""Marker poses stage: the calibration board's rigid pose in every photometric shot.

For each board pose (folder under ``photometric/``) and each camera the ArUco
markers are detected (:func:`detect_markers`), their corners refined to the
straight marker borders, each marker corner seen by two or more cameras is
triangulated, and the board's rigid pose is fitted to the board model
(:func:`board_pose_from_corners`): a closed-form Kabsch fit to the triangulated
corners, refined by minimising the reprojection error of every detected corner
in every camera. The calibration plane of a pose (section IV-A of the paper:
"an anchor point and a normal to the calibration plane") is the board centre
in the world and the normal of the board's white face. :func:`marker_poses`
does this for a whole dataset and writes one CSV.

Conventions follow ``capture-format.md``: metres, world X = R X_board + t for
the board pose, pixel (0, 0) is the centre of the top-left pixel.

Corner refinement. ArUco's ``CORNER_REFINE_SUBPIX`` corners sit a fraction
of a pixel inside the true convex marker corners, more so on small images.
:func:`detect_markers` therefore re-locates every
border edge: along many points of each side it samples the grey-level profile
across the edge, estimates the black and white levels locally (a linear trend
along the side, from the profile's flat parts), takes the 50 % crossing, fits
a straight line to the crossings (in distortion-free pixel coordinates when
the camera is given) and intersects adjacent lines.
"""

from __future__ import annotations

import re
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
from scipy.ndimage import map_coordinates
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from colourhs.capture import Board, Camera, Dataset, Rig, dataset_of, read_image
from colourhs.common.files import atomic_output
from colourhs.common.geometry import normalised_coordinates, pixels_of, project, triangulate
from colourhs.common.progress import bar

__all__ = [
    "BoardPose",
    "board_pose_from_corners",
    "csv_columns",
    "detect_markers",
    "marker_poses",
    "read_marker_poses",
    "to_grey8",
]

GREY_TARGET = 230.0
"""8-bit value that the 99th percentile of the grey image is scaled to for detection."""

_STEP_PX = 0.1  # sampling step across an edge, pixels
_SPACING_PX = 0.5  # spacing of the profiles along a side, pixels (at least)
_PROFILES = 60  # at most this many profiles per side
_EXTENT_PX = 3.5  # profiles reach at most this far either side of the edge, pixels
_END_GAP_PX = 1.5  # profiles keep this far from the marker corners, pixels
_FLAT_PX = 1.5  # |offset| beyond which a profile is taken as flat (levels), pixels
_MAX_SHIFT = 0.15  # refined corners further than this (fraction of the side) are not trusted
_ITERATIONS = 2  # edge-fitting passes per marker


# --------------------------------------------------------------------------------------------
# Detection


def to_grey8(image_rgb: np.ndarray, target: float = GREY_TARGET) -> np.ndarray:
    """8-bit grey image for the marker detector.

    Parameters
    ----------
    image_rgb : ndarray, shape (H, W, 3) or (H, W)
        Linear image, any scale (e.g. float in [0, 1] from ``read_image``).
    target : float
        8-bit value the 99th percentile of the grey image maps to.

    Returns
    -------
    ndarray of uint8, shape (H, W)
        Mean of the channels scaled so its 99th percentile reads ``target``, clipped to
        [0, 255]. An all-black image gives zeros.
    """
    grey = _grey(image_rgb)
    p99 = float(np.percentile(grey, 99.0))
    scale = target / p99 if p99 > 0 else 0.0
    return np.clip(np.rint(grey * scale), 0, 255).astype(np.uint8)


def detect_markers(
    image_rgb: np.ndarray, board: Board, camera: Camera | None = None, refine: bool = True
) -> dict[int, np.ndarray]:
    """Detect the board's ArUco markers in one image and refine their corners.

    Parameters
    ----------
    image_rgb : ndarray, shape (H, W, 3)
        Linear R, G, B image (e.g. float in [0, 1] from :func:`colourhs.capture.read_image`).
        Markers are black on the white board; the background may be black.
    board : Board
        The board (dictionary and marker ids) from rig.json.
    camera : Camera, optional
        The camera that took the image. When given, the marker borders are fitted as
        straight lines in distortion-free pixel coordinates (its K and dist); without
        it, in raw pixels (a lens-distorted border is then slightly curved).
    refine : bool
        Refine ArUco's sub-pixel corners by fitting lines to the four marker borders
        (default). With False, ArUco's ``CORNER_REFINE_SUBPIX`` corners are returned.

    Returns
    -------
    dict of int to ndarray, shape (4, 2)
        Marker id to corners in pixels (u, v), OpenCV order (top-left, top-right,
        bottom-right, bottom-left of the marker, as in :meth:`Board.marker_corners`).
        Only ids of the board; empty when no marker is found. If an id is found twice,
        the larger detection is kept.
    """
    grey = _grey(image_rgb)
    dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, board.dictionary))
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    detector = cv2.aruco.ArucoDetector(dictionary, params)
    corners, ids, _ = detector.detectMarkers(to_grey8(grey))
    found: dict[int, np.ndarray] = {}
    if ids is None:
        return found
    for quad, marker_id in zip(corners, np.asarray(ids).ravel(), strict=True):
        marker_id = int(marker_id)
        quad = np.asarray(quad, float).reshape(4, 2)
        if marker_id not in board.markers:
            continue
        if marker_id in found and _area(found[marker_id]) >= _area(quad):
            continue
        found[marker_id] = quad
    if refine:
        found = {
            mid: _refine_marker(grey, quad, _margins(board, mid), board, camera)
            for mid, quad in found.items()
        }
    return dict(sorted(found.items()))


def _grey(image: np.ndarray) -> np.ndarray:
    img = np.asarray(image, dtype=np.float64)
    return img.mean(axis=2) if img.ndim == 3 else img


def _area(quad: np.ndarray) -> float:
    x, y = quad[:, 0], quad[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def _margins(board: Board, marker_id: int) -> np.ndarray:
    """White margin (4,) outside each side of a marker, metres (to the board edge).

    Side k runs from corner k to corner k + 1 (top, right, bottom, left).
    """
    x, y = board.markers[marker_id]
    h = board.marker_length / 2
    w, H = board.size
    out = np.array([y - h, w - (x + h), H - (y + h), x - h])
    # A neighbouring marker closer than the board edge also ends the white margin.
    for other, (ox, oy) in board.markers.items():
        if other == marker_id:
            continue
        if abs(oy - y) < 2 * h:  # side by side horizontally
            gap = abs(ox - x) - 2 * h
            out[1 if ox > x else 3] = min(out[1 if ox > x else 3], gap)
        if abs(ox - x) < 2 * h:  # above / below
            gap = abs(oy - y) - 2 * h
            out[2 if oy > y else 0] = min(out[2 if oy > y else 0], gap)
    return np.maximum(out, 0.0)


class _Lens:
    """Map between raw pixels and distortion-free pixels (same K) of one camera."""

    def __init__(self, camera: Camera | None) -> None:
        self.camera = camera
        if camera is not None:
            self.K = np.asarray(camera.K, float)
            self.Kinv = np.linalg.inv(self.K)
            self.dist = np.asarray(camera.dist, float)

    def to_ideal(self, uv: np.ndarray) -> np.ndarray:
        if self.camera is None:
            return np.asarray(uv, float)
        xy = normalised_coordinates(uv, self.K, self.dist)
        return xy @ self.K[:2, :2].T + self.K[:2, 2]

    def to_pixel(self, ideal: np.ndarray) -> np.ndarray:
        if self.camera is None:
            return np.asarray(ideal, float)
        ideal = np.asarray(ideal, float)
        h = np.concatenate([ideal, np.ones(ideal.shape[:-1] + (1,))], axis=-1)
        x = h @ self.Kinv.T
        u, v = pixels_of(x[..., 0] / x[..., 2], x[..., 1] / x[..., 2], self.K, self.dist)
        return np.stack([u, v], axis=-1)


def _refine_marker(
    grey: np.ndarray, quad: np.ndarray, margins_m: np.ndarray, board: Board, camera
) -> np.ndarray:
    """Corners (4, 2) from straight-line fits to the four border edges; ``quad`` if that fails."""
    lens = _Lens(camera)
    q = lens.to_ideal(quad)
    cell_m = board.marker_length / (_marker_cells(board.dictionary))
    for _ in range(_ITERATIONS):
        lines = []
        for k in range(4):
            line = _fit_edge(grey, lens, q, k, cell_m, margins_m[k], board.marker_length)
            if line is None:
                return quad
            lines.append(line)
        new = np.array([_intersect(lines[k - 1], lines[k]) for k in range(4)])
        if not np.all(np.isfinite(new)):
            return quad
        q = new
    refined = lens.to_pixel(q)
    side = np.mean(np.linalg.norm(quad - np.roll(quad, 1, axis=0), axis=1))
    if np.max(np.linalg.norm(refined - quad, axis=1)) > max(_MAX_SHIFT * side, 1.0):
        return quad
    return refined


def _marker_cells(dictionary: str) -> int:
    """Cells across a marker, border included (e.g. 6 for a 4x4 dictionary)."""
    d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary))
    return int(d.markerSize) + 2


def _fit_edge(grey, lens, q, k, cell_m, margin_m, length_m):
    """Line (point, unit direction) through the 50 % crossings of side k of quad ``q``.

    ``q`` is in the lens's ideal (distortion-free) pixels; side k runs from corner k to
    corner k + 1. Returns None when too few crossings are found.
    """
    a, b = q[k], q[(k + 1) % 4]
    side = float(np.linalg.norm(b - a))
    if side < 4 * _END_GAP_PX:
        return None
    tangent = (b - a) / side
    normal = np.array([-tangent[1], tangent[0]])
    if normal @ ((a + b) / 2 - q.mean(axis=0)) < 0:
        normal = -normal  # outwards, from the black border to the white board
    # Pixels per metre across this side, from the two adjacent sides.
    across = (np.linalg.norm(q[(k + 2) % 4] - b) + np.linalg.norm(q[(k + 3) % 4] - a)) / 2
    scale = across / length_m
    inner = float(np.clip(0.8 * cell_m * scale, 1.0, _EXTENT_PX))
    outer = float(np.clip(min(cell_m * scale, margin_m * scale - _FLAT_PX), 1.0, _EXTENT_PX))
    spacing = max(_SPACING_PX, (side - 2 * _END_GAP_PX) / _PROFILES)
    s = np.arange(_END_GAP_PX, side - _END_GAP_PX + 1e-9, spacing)
    d = np.arange(-np.floor(inner / _STEP_PX), np.floor(outer / _STEP_PX) + 1) * _STEP_PX
    pts = a + s[:, None, None] * tangent + d[None, :, None] * normal  # (S, D, 2)
    uv = lens.to_pixel(pts)
    prof = map_coordinates(
        grey, [uv[..., 1].ravel(), uv[..., 0].ravel()], order=1, mode="constant", cval=np.nan
    ).reshape(uv.shape[:2])
    # Local black and white levels: a linear trend along the side fitted to the flat parts.
    flat_in = d <= -min(_FLAT_PX, 0.6 * inner)
    flat_out = d >= min(_FLAT_PX, 0.6 * outer)
    black = _trend(s, np.median(prof[:, flat_in], axis=1))  # NaN where off the image
    white = _trend(s, np.median(prof[:, flat_out], axis=1))
    if black is None or white is None:
        return None
    contrast = white - black
    ok = contrast > 0
    f = (prof - black[:, None]) / np.where(ok, contrast, 1.0)[:, None]
    crossing = _half_crossings(f, d)
    crossing[~ok] = np.nan
    good = np.isfinite(crossing)
    if good.sum() < 5:
        return None
    pts = a + s[good, None] * tangent + crossing[good, None] * normal
    return _fit_line(pts)


def _trend(s: np.ndarray, y: np.ndarray) -> np.ndarray | None:
    """Least-squares straight line through (s, y), evaluated at s; None if too few values."""
    ok = np.isfinite(y)
    if ok.sum() < 3:
        return None
    coef = np.polyfit(s[ok], y[ok], 1)
    return np.polyval(coef, s)


def _half_crossings(f: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Offset (S,) where each normalised profile ``f`` (S, D) rises through 0.5, nearest 0."""
    below = f[:, :-1] < 0.5
    above = f[:, 1:] >= 0.5
    rising = below & above  # (S, D-1)
    mid = (d[:-1] + d[1:]) / 2
    dist = np.where(rising, np.abs(mid)[None, :], np.inf)
    j = np.argmin(dist, axis=1)
    rows = np.arange(len(f))
    f0, f1 = f[rows, j], f[rows, j + 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        x = d[j] + (0.5 - f0) / (f1 - f0) * (d[1] - d[0])
    x[~np.isfinite(dist[rows, j])] = np.nan
    return x


def _fit_line(pts: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Total-least-squares line (point, unit direction) with outlier rejection."""
    keep = np.ones(len(pts), bool)
    for _ in range(3):
        c = pts[keep].mean(axis=0)
        _, _, vt = np.linalg.svd(pts[keep] - c)
        direction, n = vt[0], vt[1]
        r = (pts - c) @ n
        mad = 1.4826 * np.median(np.abs(r[keep]))
        new = np.abs(r) <= max(4.0 * mad, 0.05)
        if new.sum() < 5 or np.array_equal(new, keep):
            break
        keep = new
    return c, direction


def _intersect(l1, l2) -> np.ndarray:
    (p1, d1), (p2, d2) = l1, l2
    A = np.column_stack([d1, -d2])
    if abs(np.linalg.det(A)) < 1e-9:
        return np.full(2, np.nan)
    s = np.linalg.solve(A, p2 - p1)
    return p1 + s[0] * d1


# --------------------------------------------------------------------------------------------
# Pose


@dataclass(frozen=True)
class BoardPose:
    """The board's rigid pose and calibration plane in one photometric shot.

    Attributes
    ----------
    R : ndarray, shape (3, 3)
        Board-to-world rotation.
    t : ndarray, shape (3,)
        Board-to-world translation, metres (world X = R X_board + t).
    point : ndarray, shape (3,)
        Anchor point of the calibration plane: the board centre in world coordinates, metres.
    normal : ndarray, shape (3,)
        Unit normal of the board's white face in world coordinates, ``R @ [0, 0, -1]``
        (pointing towards the cameras).
    rms_px : float
        RMS reprojection error of all detected corners of all cameras after the fit, pixels.
    markers : dict of str to tuple of int
        Per camera name (rig order), the ids of the markers detected in its image.
    n_markers : int
        Markers triangulated (detected by two or more cameras).
    """

    R: np.ndarray
    t: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    rms_px: float
    markers: dict[str, tuple[int, ...]] = field(default_factory=dict)
    n_markers: int = 0


def board_pose_from_corners(
    detections: Mapping[str, Mapping[int, np.ndarray]], rig: Rig
) -> BoardPose:
    """Fit the board's rigid pose to the markers detected by all cameras.

    Every marker corner seen by two or more cameras is triangulated
    (:func:`colourhs.common.geometry.triangulate`); the board model is aligned to these
    points in closed form (Kabsch), then the 6-dof pose is refined by minimising
    the reprojection error of every detected corner in every camera (markers seen by
    one camera included; Huber loss with a 1 px scale, i.e. least squares for inliers).

    Parameters
    ----------
    detections : mapping of str to (mapping of int to ndarray, shape (4, 2))
        Per camera name, marker id to corners in pixels (as :func:`detect_markers`
        returns). Cameras left out detected nothing; ids not on the board are ignored.
    rig : Rig
        Cameras and board.

    Returns
    -------
    BoardPose

    Raises
    ------
    ValueError
        If no marker is seen by two cameras, or a camera name is not in the rig.
    """
    board = rig.board
    for name in detections:
        if name not in rig.camera_names:
            raise ValueError(f"detections name camera {name!r}, not in rig {rig.camera_names}")
    per_cam = [
        {
            int(m): np.asarray(c, float).reshape(4, 2)
            for m, c in detections.get(cam.name, {}).items()
            if int(m) in board.markers
        }
        for cam in rig.cameras
    ]
    seen_by = {m: sum(m in d for d in per_cam) for m in board.markers}
    tri_ids = [m for m, n in seen_by.items() if n >= 2]
    if not tri_ids:
        raise ValueError("no marker is seen by two or more cameras: cannot triangulate the board")
    uvs = np.full((len(rig.cameras), 4 * len(tri_ids), 2), np.nan)
    for v, d in enumerate(per_cam):
        for j, m in enumerate(tri_ids):
            if m in d:
                uvs[v, 4 * j : 4 * j + 4] = d[m]
    cams = rig.cameras
    world = triangulate(
        uvs, [c.K for c in cams], [c.dist for c in cams], [c.R for c in cams], [c.t for c in cams]
    )
    model = np.concatenate([board.marker_corners(m) for m in tri_ids])
    R0, t0 = _kabsch(model, world)

    # Reprojection refinement over all detected corners of all cameras.
    obs = [(v, m) for v, d in enumerate(per_cam) for m in sorted(d)]
    model_obs = [board.marker_corners(m) for _, m in obs]
    measured = [per_cam[v][m] for v, m in obs]

    def residuals(x):
        R = cv2.Rodrigues(x[:3])[0] @ R0
        t = x[3:]
        out = []
        for (v, _), X, uv in zip(obs, model_obs, measured, strict=True):
            cam = cams[v]
            out.append(project(X @ R.T + t, cam.K, cam.dist, cam.R, cam.t) - uv)
        return np.concatenate(out).ravel()

    x0 = np.concatenate([np.zeros(3), t0])
    fit = least_squares(residuals, x0, loss="huber", f_scale=1.0, x_scale="jac", xtol=1e-12)
    R = cv2.Rodrigues(fit.x[:3])[0] @ R0
    t = fit.x[3:]
    res = residuals(fit.x).reshape(-1, 2)
    rms = float(np.sqrt(np.mean(np.sum(res**2, axis=1)))) if np.all(np.isfinite(res)) else np.inf
    centre = np.array([board.size[0] / 2, board.size[1] / 2, 0.0])
    normal = R @ np.array([0.0, 0.0, -1.0])
    return BoardPose(
        R=R,
        t=t,
        point=R @ centre + t,
        normal=normal / np.linalg.norm(normal),
        rms_px=rms,
        markers={cam.name: tuple(sorted(d)) for cam, d in zip(cams, per_cam, strict=True)},
        n_markers=len(tri_ids),
    )


def _kabsch(model: np.ndarray, world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation and translation minimising sum |R model + t - world|^2 (finite rows only)."""
    ok = np.all(np.isfinite(world), axis=1)
    A, B = model[ok], world[ok]
    ca, cb = A.mean(axis=0), B.mean(axis=0)
    R = Rotation.align_vectors(B - cb, A - ca)[0].as_matrix()  # R (A - ca) ~ B - cb, det +1
    return R, cb - R @ ca


# --------------------------------------------------------------------------------------------
# Dataset stage


def csv_columns(cameras: tuple[str, ...] | list[str]) -> list[str]:
    """Columns of the marker poses CSV for the given camera names, in order."""
    return [
        "pose",
        *(f"markers_{c}" for c in cameras),
        "n_markers",
        "point_x",
        "point_y",
        "point_z",
        "normal_x",
        "normal_y",
        "normal_z",
        *(f"R{i}{j}" for i in range(3) for j in range(3)),
        "t_x",
        "t_y",
        "t_z",
        "rms_px",
    ]


def marker_poses(
    dataset_dir: str | Path | Dataset, out_csv: str | Path, min_markers: int = 3
) -> pd.DataFrame:
    """Board pose and calibration plane of every photometric shot of a dataset.

    Shows a bar over the board poses (:func:`colourhs.common.progress.bar`).

    Parameters
    ----------
    dataset_dir : str, Path or Dataset
        Dataset folder (capture format, version 1); only rig.json and ``photometric/``
        are used.
    out_csv : str or Path
        CSV file to write (parent folders are created). Written to a temporary name and
        renamed, so an error leaves no partial output.
    min_markers : int
        Fewest triangulated markers (each seen by two or more cameras) a pose needs.

    Returns
    -------
    pandas.DataFrame
        One row per usable pose, columns :func:`csv_columns`: ``pose``; ``markers_<camera>``
        (space-separated ids detected by that camera, "" for none); ``n_markers``;
        ``point_x/y/z`` (board centre, world, metres); ``normal_x/y/z`` (unit normal of the
        white face, towards the cameras); ``R00..R22`` and ``t_x/y/z`` (board-to-world
        rotation and translation in metres); ``rms_px`` (RMS reprojection error of all
        detected corners after the fit, pixels).

    Warns
    -----
    UserWarning
        For each pose left out (fewer than ``min_markers`` triangulated markers).

    Raises
    ------
    ValueError
        If fewer than 3 poses are usable (message names the dataset folder and the poses
        found) or ``min_markers`` < 1; :class:`colourhs.capture.CaptureFormatError` (a
        ValueError) for a malformed dataset.
    """
    if int(min_markers) < 1:
        raise ValueError(f"min_markers must be at least 1, got {min_markers}")
    out_csv = Path(out_csv)
    ds = dataset_of(dataset_dir, scenes=())
    rig = ds.rig
    rows = []
    for pose in bar(ds.poses, "markers: board poses", unit="pose"):
        detections = {}
        for cam in rig.cameras:
            image, _ = read_image(ds.photometric_image(pose, cam.name), rig.image)
            detections[cam.name] = detect_markers(image, rig.board, camera=cam)
        seen = {m for d in detections.values() for m in d}
        n_tri = sum(sum(m in d for d in detections.values()) >= 2 for m in seen)
        if n_tri < min_markers:
            warnings.warn(
                f"{ds.root}: pose {pose!r} left out: {n_tri} marker(s) seen by two or more "
                f"cameras, {min_markers} needed "
                + "; ".join(f"{c}: {sorted(d) or 'none'}" for c, d in detections.items()),
                stacklevel=2,
            )
            continue
        bp = board_pose_from_corners(detections, rig)
        rows.append(_row(pose, bp, rig.camera_names))
    if len(rows) < 3:
        usable = [r["pose"] for r in rows]
        raise ValueError(
            f"{ds.root}: only {len(rows)} usable board pose(s) {usable} of the poses found "
            f"{list(ds.poses)}; at least 3 are needed (each with >= {min_markers} markers "
            "seen by two or more cameras)"
        )
    table = pd.DataFrame(rows, columns=csv_columns(rig.camera_names))
    with atomic_output(out_csv) as tmp:
        table.to_csv(tmp, index=False)
    return table


def _row(pose: str, bp: BoardPose, cameras: tuple[str, ...]) -> dict:
    row = {"pose": pose}
    for c in cameras:
        row[f"markers_{c}"] = " ".join(map(str, bp.markers.get(c, ())))
    row["n_markers"] = bp.n_markers
    row.update(zip(("point_x", "point_y", "point_z"), map(float, bp.point), strict=True))
    row.update(zip(("normal_x", "normal_y", "normal_z"), map(float, bp.normal), strict=True))
    row.update({f"R{i}{j}": float(bp.R[i, j]) for i in range(3) for j in range(3)})
    row.update(zip(("t_x", "t_y", "t_z"), map(float, bp.t), strict=True))
    row["rms_px"] = bp.rms_px
    return row


def read_marker_poses(path: str | Path) -> pd.DataFrame:
    """Read a CSV written by :func:`marker_poses` (``markers_*`` columns kept as strings)."""
    head = pd.read_csv(path, nrows=0)
    str_cols = {c: str for c in head.columns if re.match(r"markers_", c) or c == "pose"}
    return pd.read_csv(path, dtype=str_cols, keep_default_na=False)
