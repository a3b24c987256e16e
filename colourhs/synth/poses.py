"""Random poses of a printed target that the cameras of a rig see (synthetic data).

Shared by the fixed presets (:mod:`colourhs.synth.synthesise`), the randomised
ones (:mod:`colourhs.synth.randomrig`) and the ChArUco target of every preset
(:mod:`colourhs.synth.geometric_target`, whose poses may leave part of the target
out of some views).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from colourhs.common.geometry import project
from colourhs.synth import scenes as sc
from colourhs.synth.simulated_rig import RigModel


def rotation_xyz(ax: float, ay: float, az: float) -> np.ndarray:
    """Rotation Rz(az) Ry(ay) Rx(ax), angles in radians (extrinsic x, y, z)."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_euler("xyz", [ax, ay, az]).as_matrix()


@dataclass(frozen=True)
class PoseRanges:
    """Where :func:`board_poses` draws the board: offsets around the working
    distance (the world origin) and turns about the board's axes.

    The defaults are those of the tiny, demo and paper presets.

    Attributes
    ----------
    depth_m : depths are stratified over +- this around the working distance,
        metres. Fits the fixed presets' rig only: the randomised presets scale it
        with their working distance (``pose_depth_rel`` of
        :class:`~colourhs.synth.randomranges.RandomRanges`).
    lateral_m : the board's centre is offset up to +- this in x and in y, metres.
        Fits the fixed presets' rig only: the randomised presets scale it with
        their field's half-width (``pose_offcentre`` of
        :class:`~colourhs.synth.randomranges.RandomRanges`).
    tilt_deg : tilt up to +- this about the x and the y axis independently, or,
        with ``any_direction``, a slant up to this, degrees. An angle: the same
        whatever the rig's size.
    roll_deg : roll about the board's normal up to +- this, degrees. An angle:
        the same whatever the rig's size.
    any_direction : the slant's axis drawn in any direction of the board plane
        instead of separate x and y tilts. A choice of distribution, with no scale.
    aims : world (x, y) points, metres, that the poses' centres aim at in turn
        (pose k at ``aims[k % len(aims)]``, offset by up to +- ``lateral_m``), so
        that a few poses cover given parts of the field (the image corners);
        None: every pose aims at the origin.
    """

    depth_m: float = 0.07
    lateral_m: float = 0.05
    tilt_deg: float = 25.0
    roll_deg: float = 15.0
    any_direction: bool = False
    aims: tuple[tuple[float, float], ...] | None = None


@dataclass(frozen=True)
class PoseAcceptance:
    """Which drawn poses :func:`board_poses` keeps: the board seen from its white side
    and with large enough marker cells, whole by every camera or, with ``min_cameras``
    and ``min_share``, in part by some.

    The defaults are those of the tiny, demo and paper presets: every camera sees
    the whole board.

    Attributes
    ----------
    margin_px : a check point of the board (its outline corners by default) is
        in view where it projects at least this far inside the image, pixels. In
        pixels of the image, so it does not depend on the rig's size or distance.
    max_incidence_deg : a camera sees the board only from its white side at less
        than this incidence (at the board's centre), degrees. An angle: the same
        whatever the rig's size.
    min_cell_px : when > 0, every marker's cells (the shortest projected side
        over the cell count, border included) must span at least this in every
        camera, pixels; 0 checks nothing. In pixels of the image, so it does not
        depend on the rig's size or distance.
    min_cameras : the cameras that must see the board; None: every camera. A count.
    min_share : a camera sees the board where at least this share of the check
        points are in view (and the incidence is below ``max_incidence_deg``); 1:
        all of them, the whole board. A fraction, with no scale.
    """

    margin_px: float = 4.0
    max_incidence_deg: float = 60.0
    min_cell_px: float = 0.0
    min_cameras: int | None = None
    min_share: float = 1.0


def board_poses(
    rig: RigModel,
    board: dict,
    n: int,
    rng: np.random.Generator,
    ranges: PoseRanges = PoseRanges(),
    acceptance: PoseAcceptance = PoseAcceptance(),
    tries: int = 1000,
    points: np.ndarray | None = None,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Random hand-held-like board poses filling the working volume.

    Depths are stratified over +-``ranges.depth_m`` around the working
    distance (the world origin), lateral offsets of the board's centre up to
    +-``ranges.lateral_m`` in x and y (around ``ranges.aims`` in turn where
    given), and roll about the board's normal up to
    +-``ranges.roll_deg``. The tilt is up to +-``ranges.tilt_deg`` about the x
    and the y axis independently, or, with ``ranges.any_direction``, a slant
    of up to ``ranges.tilt_deg`` about an axis in any direction of the board
    plane. A pose is kept only if it passes ``acceptance``
    (:class:`PoseAcceptance`), whose visibility rules count the board-frame
    ``points`` (N, 3), metres, in view (default the board's outline corners:
    the whole board). ``rig`` needs only ``cameras`` (K, dist, R, t) and
    ``width``, ``height``; ``board`` is rig.json's board block or a ChArUco
    description (:func:`colourhs.synth.scenes.printed_markers`). ``tries`` is
    the number of draws per pose before giving up.

    Returns a list of (R_b, t_b), world X = R_b X_board + t_b.

    Raises
    ------
    RuntimeError
        If some pose is not found in ``tries`` draws.
    """
    board = sc.printed_markers(board)
    corners = sc.board_corners(board["size"])
    centre_b = corners.mean(axis=0)
    points = corners if points is None else np.asarray(points, float)
    need = len(rig.cameras) if acceptance.min_cameras is None else acceptance.min_cameras
    markers = _marker_quads(board) if acceptance.min_cell_px > 0 else None
    depths = rng.permutation(np.linspace(-ranges.depth_m, ranges.depth_m, n))
    out = []
    for k, z in enumerate(depths):
        for _ in range(tries):
            if ranges.any_direction:
                slant, azimuth, roll = rng.uniform(
                    [0, 0, -ranges.roll_deg], [ranges.tilt_deg, 360, ranges.roll_deg]
                )
                a = np.deg2rad(azimuth)
                axis = [np.cos(a), np.sin(a), 0.0]
                R = sc.axis_angle(axis, np.deg2rad(slant)) @ rotation_xyz(0, 0, np.deg2rad(roll))
            else:
                lim = [ranges.tilt_deg, ranges.tilt_deg, ranges.roll_deg]
                R = rotation_xyz(*np.deg2rad(rng.uniform(np.negative(lim), lim)))
            c = np.array([*rng.uniform(-ranges.lateral_m, ranges.lateral_m, 2), z])
            if ranges.aims is not None:
                c[:2] += ranges.aims[k % len(ranges.aims)]
            t = c - R @ centre_b
            seen = _cameras_seeing(
                rig,
                points @ R.T + t,
                (corners @ R.T + t).mean(axis=0),
                R @ [0, 0, -1.0],
                acceptance,
            )
            if seen < need:
                continue
            if markers is not None and _min_cell_px(rig, markers, R, t) < acceptance.min_cell_px:
                continue
            out.append((R, t))
            break
        else:
            raise RuntimeError(
                f"could not place a board pose visible to {need} of the {len(rig.cameras)} "
                f"cameras in {tries} draws"
            )
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
    return all(_share_in_view(rig, cam, points, margin) == 1.0 for cam in rig.cameras)


def _share_in_view(rig, cam, points: np.ndarray, margin: float) -> float:
    """The share of ``points`` (N, 3) in front of ``cam`` that project at least
    ``margin`` pixels inside ``rig``'s image (``width``, ``height``)."""
    uv = project(points, cam.K, cam.dist, cam.R, cam.t)
    u, v = uv[:, 0], uv[:, 1]
    ok = np.isfinite(u) & np.isfinite(v) & (u >= margin) & (v >= margin)
    ok &= (u <= rig.width - 1 - margin) & (v <= rig.height - 1 - margin)
    return float(ok.mean())


def _white_side_seen(cam, centre_w, normal_w, max_incidence_deg: float) -> bool:
    """Whether ``cam`` sees the board's white side (normal ``normal_w``) at its centre
    ``centre_w`` at less than ``max_incidence_deg``."""
    view = cam.centre - centre_w
    return normal_w @ view / np.linalg.norm(view) >= np.cos(np.deg2rad(max_incidence_deg))


def _cameras_seeing(rig, points_w, centre_w, normal_w, acceptance: PoseAcceptance) -> int:
    """How many cameras see the board by ``acceptance``'s rules: ``min_share`` of its
    check points ``points_w`` (N, 3) in view (``margin_px``), its white side at less
    than ``max_incidence_deg``."""
    return sum(
        _share_in_view(rig, cam, points_w, acceptance.margin_px) >= acceptance.min_share
        and _white_side_seen(cam, centre_w, normal_w, acceptance.max_incidence_deg)
        for cam in rig.cameras
    )


def _board_visible(rig, corners_w, normal_w, margin, max_incidence_deg=60.0):
    """Whether every camera sees the whole board (outline ``corners_w``) from its white side."""
    acceptance = PoseAcceptance(margin_px=margin, max_incidence_deg=max_incidence_deg)
    seen = _cameras_seeing(rig, corners_w, corners_w.mean(axis=0), normal_w, acceptance)
    return seen == len(rig.cameras)
