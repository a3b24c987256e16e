"""Random calibration-board poses that every camera of a rig sees (synthetic data).

Shared by the fixed presets (:mod:`colourhs.synth.synthesise`) and the
randomised ones (:mod:`colourhs.synth.randomrig`).
"""

from __future__ import annotations

import cv2
import numpy as np

from colourhs.common.geometry import project
from colourhs.synth import scenes as sc
from colourhs.synth.simulated_rig import RigModel


def rotation_xyz(ax: float, ay: float, az: float) -> np.ndarray:
    """Rotation Rz(az) Ry(ay) Rx(ax), angles in radians (extrinsic x, y, z)."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_euler("xyz", [ax, ay, az]).as_matrix()


def board_poses(
    rig: RigModel,
    board: dict,
    n: int,
    rng: np.random.Generator,
    margin_px: float = 4.0,
    *,
    depth_m: float = 0.07,
    lateral_m: float = 0.05,
    tilt_deg: float = 25.0,
    roll_deg: float = 15.0,
    max_incidence_deg: float = 60.0,
    any_direction: bool = False,
    min_cell_px: float = 0.0,
    tries: int = 1000,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Random hand-held-like board poses filling the working volume.

    Depths are stratified over +-``depth_m`` around the working distance
    (the world origin), lateral offsets of the board's centre up to
    +-``lateral_m`` in x and y, and roll about the board's normal up to
    +-``roll_deg``. The tilt is up to +-``tilt_deg`` about the x and the y
    axis independently, or, with ``any_direction``, a slant of up to
    ``tilt_deg`` about an axis in any direction of the board plane. A pose is
    kept only if every camera sees the whole board (with ``margin_px``) from
    its white side at less than ``max_incidence_deg`` incidence and, when
    ``min_cell_px`` > 0, every marker's cells (the shortest projected side
    over the cell count, border included) span at least that many pixels.
    ``rig`` needs only ``cameras`` (K, dist, R, t) and ``width``, ``height``.
    The defaults are those of the tiny, demo and paper presets.

    Returns a list of (R_b, t_b), world X = R_b X_board + t_b.

    Raises
    ------
    RuntimeError
        If some pose is not found in ``tries`` draws.
    """
    corners = sc.board_corners(board["size"])
    centre_b = corners.mean(axis=0)
    markers = _marker_quads(board) if min_cell_px > 0 else None
    depths = rng.permutation(np.linspace(-depth_m, depth_m, n))
    out = []
    for z in depths:
        for _ in range(tries):
            if any_direction:
                slant, azimuth, roll = rng.uniform([0, 0, -roll_deg], [tilt_deg, 360, roll_deg])
                a = np.deg2rad(azimuth)
                axis = [np.cos(a), np.sin(a), 0.0]
                R = sc.axis_angle(axis, np.deg2rad(slant)) @ rotation_xyz(0, 0, np.deg2rad(roll))
            else:
                lim = [tilt_deg, tilt_deg, roll_deg]
                R = rotation_xyz(*np.deg2rad(rng.uniform(np.negative(lim), lim)))
            c = np.array([*rng.uniform(-lateral_m, lateral_m, 2), z])
            t = c - R @ centre_b
            if not _board_visible(
                rig, corners @ R.T + t, R @ [0, 0, -1.0], margin_px, max_incidence_deg
            ):
                continue
            if markers is not None and _min_cell_px(rig, markers, R, t) < min_cell_px:
                continue
            out.append((R, t))
            break
        else:
            raise RuntimeError("could not place a board pose visible to every camera")
    return out


def _marker_quads(board: dict) -> tuple[np.ndarray, int]:
    """Corners (n_markers, 4, 3) of the board's markers (board frame) and their cell count."""
    d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, board["dictionary"]))
    h = board["marker_length"] / 2
    quads = [
        [[x - h, y - h, 0], [x + h, y - h, 0], [x + h, y + h, 0], [x - h, y + h, 0]]
        for x, y in board["markers"].values()
    ]
    return np.array(quads, float), d.markerSize + 2


def _min_cell_px(rig, markers, R, t) -> float:
    """Smallest projected marker cell (shortest side / cells) over markers and cameras, px."""
    quads, cells = markers
    world = quads @ R.T + t
    best = np.inf
    for cam in rig.cameras:
        uv = project(world, cam.K, cam.dist, cam.R, cam.t)
        sides = np.linalg.norm(uv - np.roll(uv, -1, axis=1), axis=-1)
        best = min(best, float(np.nanmin(sides)) / cells)
    return best


def in_view(rig, points: np.ndarray, margin: float) -> bool:
    """Whether every camera of ``rig`` (``cameras``, ``width``, ``height``) sees
    all ``points`` (N, 3) in front of it, at least ``margin`` pixels inside."""
    for cam in rig.cameras:
        uv = project(points, cam.K, cam.dist, cam.R, cam.t)
        if not np.all(np.isfinite(uv)):
            return False
        if np.any(uv < margin) or np.any(uv[:, 0] > rig.width - 1 - margin):
            return False
        if np.any(uv[:, 1] > rig.height - 1 - margin):
            return False
    return True


def _board_visible(rig, corners_w, normal_w, margin, max_incidence_deg=60.0):
    if not in_view(rig, corners_w, margin):
        return False
    for cam in rig.cameras:
        view = cam.centre - corners_w.mean(axis=0)
        if normal_w @ view / np.linalg.norm(view) < np.cos(np.deg2rad(max_incidence_deg)):
            return False
    return True
