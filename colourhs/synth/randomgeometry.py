"""The geometry of a random draw: cameras, calibration board and its poses.

:func:`_draw_geometry` draws, from the seed's ``geometry`` stream, the three
cameras (working distance, field of view, the irregular camera triangle,
intrinsics and lens distortion, names and colours), the ArUco board and its
poses, then the scenes (:mod:`colourhs.synth.randomscenes`); a draw whose
board or objects cannot be placed is redrawn as a whole. The ranges are the
table of :mod:`colourhs.synth.randomrig`
(:class:`~colourhs.synth.randomranges.RandomRanges`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
import numpy as np

from colourhs.capture import Camera
from colourhs.common.geometry import look_at
from colourhs.synth import scenes as sc
from colourhs.synth.poses import (
    PoseAcceptance,
    PoseRanges,
    _board_visible,
    _marker_quads,
    _min_cell_px,
    board_poses,
    rotation_xyz,
)
from colourhs.synth.randomranges import (
    DICTIONARY_SIZES,
    NAME_STYLES,
    POSITIONAL_STYLES,
    _stream,
)
from colourhs.synth.randomscenes import _draw_scenes, _object_shapes
from colourhs.synth.simulated_rig import COLOURS


@dataclass(frozen=True)
class _View:
    """The cameras and image size, all that visibility tests need (duck-types RigModel)."""

    cameras: tuple[Camera, ...]
    width: int
    height: int


# --------------------------------------------------------------------------- geometry
def _draw_geometry(seed, width, height, rg, n_poses, sheet_frames, statue_level) -> dict:
    rng = _stream(seed, "geometry")
    shapes = _object_shapes(statue_level)
    for _ in range(rg.attempts):
        geo = _draw_cameras(rng, width, height, rg)
        view = _View(tuple(geo["cameras"]), width, height)
        board = _draw_board(rng, rg)
        if board is None:
            continue
        poses = _draw_poses(rng, view, board, rg, geo, n_poses)
        if poses is None:
            continue
        scenes = _draw_scenes(rng, view, rg, geo, shapes, sheet_frames)
        if scenes is None:
            continue
        return geo | {"board": board, "poses": poses, "scenes": scenes}
    raise RuntimeError(f"seed {seed}: no rig with placeable boards and objects in {rg.attempts}")


def _pair_angles(rng, rg) -> np.ndarray:
    while True:
        a = rng.uniform(*rg.pair_angle_deg, 3)
        if a.max() - a.min() >= rg.pair_angle_spread_deg:
            return a


def _camera_directions(angles_deg: np.ndarray) -> np.ndarray | None:
    """Unit vectors (3, 3) with the given pairwise angles (12, 13, 23), or None if impossible."""
    a12, a13, a23 = np.deg2rad(angles_deg)
    u1 = np.array([0.0, 0.0, 1.0])
    u2 = np.array([np.sin(a12), 0.0, np.cos(a12)])
    z = np.cos(a13)
    x = (np.cos(a23) - z * np.cos(a12)) / np.sin(a12)
    y2 = 1.0 - x * x - z * z
    if y2 <= 1e-6:
        return None
    return np.stack([u1, u2, np.array([x, np.sqrt(y2), z])])


def _draw_cameras(rng, width, height, rg) -> dict:
    while True:
        D = rng.uniform(*rg.distance_m)
        hfov = rng.uniform(*rg.hfov_deg)
        half = D * np.tan(np.deg2rad(hfov) / 2)
        if rg.field_half_width_m[0] <= half <= rg.field_half_width_m[1]:
            break
    while True:
        angles = _pair_angles(rng, rg)
        u = _camera_directions(angles)
        if u is not None:
            break
    # Centre the triangle on -z (cameras in front of the scene, looking along +z),
    # then turn it about the viewing axis.
    m = u.sum(axis=0)
    m /= np.linalg.norm(m)
    target = np.array([0.0, 0.0, -1.0])
    axis = np.cross(m, target)
    Q = sc.axis_angle(axis, np.arccos(np.clip(m @ target, -1, 1)))
    psi = np.deg2rad(rng.uniform(0, 360))
    Rz = sc.axis_angle([0, 0, 1], psi)
    u = u @ (Rz @ Q).T
    focal = (width / 2) / np.tan(np.deg2rad(hfov) / 2)
    cams, rolls = [], []
    for i in range(3):
        Di = D * (1 + rng.uniform(-rg.camera_distance_rel, rg.camera_distance_rel))
        centre = Di * u[i]
        aim = rng.normal(0, rg.aim_rel * D, 3)
        R0, _ = look_at(centre, aim)
        roll = rng.uniform(-rg.roll_deg, rg.roll_deg)
        R = sc.axis_angle([0, 0, 1], np.deg2rad(roll)) @ R0
        t = -R @ centre
        f = focal * (1 + rng.uniform(-rg.focal_rel, rg.focal_rel))
        K = np.array(
            [
                [f, 0.0, (width - 1) / 2 + rng.uniform(-1, 1) * rg.principal_rel * width],
                [
                    0.0,
                    f * (1 + rng.uniform(-rg.aspect_rel, rg.aspect_rel)),
                    (height - 1) / 2 + rng.uniform(-1, 1) * rg.principal_rel * height,
                ],
                [0.0, 0.0, 1.0],
            ]
        )
        dist = np.array(
            [rng.uniform(*rg.k1), rng.uniform(*rg.k2), *rng.normal(0, rg.tangential_sd, 2), 0.0]
        )
        # No draws without these terms: the other presets' seeds keep their rigs.
        if rg.rational or rg.thin_prism_sd or rg.skew_rel:
            k456 = rng.uniform(-rg.rational, rg.rational, 3)
            dist = np.concatenate([dist, k456, rng.normal(0, rg.thin_prism_sd, 4)])
            K[0, 1] = rng.uniform(-1, 1) * rg.skew_rel * f
        cams.append(Camera(f"_{i}", K, dist, R, t, "red", np.zeros(3)))
        rolls.append(float(roll))
    # Names, colours and the order of rig.json.
    style = NAME_STYLES[int(rng.integers(len(NAME_STYLES)))]
    if style in POSITIONAL_STYLES:
        names = _positional_names(cams, style)
    else:
        names = [style[k] for k in rng.permutation(3)]
    colours = [COLOURS[k] for k in rng.permutation(3)]
    order = [int(k) for k in rng.permutation(3)]
    cams = [
        replace(c, name=n, light_colour=col) for c, n, col in zip(cams, names, colours, strict=True)
    ]
    return {
        "distance": float(D),
        "hfov": float(hfov),
        "focal": float(focal),
        "half_width": float(half),
        "pair_angles": [float(a) for a in angles],
        "cameras": [cams[k] for k in order],
        "rolls": [rolls[k] for k in order],
        "names": style,
    }


def _positional_names(cams, style) -> list[str]:
    """left/right/top-like names: the highest camera is 'top', then left and right by x."""
    c = np.array([cam.centre for cam in cams])
    top = int(np.argmin(c[:, 1]))  # world y points down
    rest = [k for k in range(3) if k != top]
    left, right = sorted(rest, key=lambda k: c[k, 0])
    names = [""] * 3
    names[left], names[right], names[top] = style
    return names


def _draw_board(rng, rg) -> dict | None:
    w = rng.uniform(*rg.board_width_m)
    h = w * rng.uniform(*rg.board_aspect)
    dictionary = str(rng.choice(rg.dictionaries))
    n = int(rng.integers(rg.n_markers[0], rg.n_markers[1] + 1))
    L = rng.uniform(*rg.marker_length_m)
    ids = np.sort(rng.choice(DICTIONARY_SIZES[dictionary], n, replace=False))
    d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary))
    gap = rg.marker_gap_cells * L / (d.markerSize + 2)
    lo = np.array([gap + L / 2, gap + L / 2])
    hi = np.array([w - gap - L / 2, h - gap - L / 2])
    if np.any(hi < lo):
        return None
    centres = None
    for _ in range(20):
        centres = _layout(rng, n, lo, hi, L + gap)
        if centres is not None:
            break
    if centres is None:
        return None
    return {
        "dictionary": dictionary,
        "marker_length": float(L),
        "size": [float(w), float(h)],
        "markers": {
            str(int(i)): [float(x), float(y)] for i, (x, y) in zip(ids, centres, strict=True)
        },
    }


def _layout(rng, n, lo, hi, pitch) -> list | None:
    """``n`` square centres in the box [lo, hi], at least ``pitch`` apart in x or in y.

    Each centre is the best of 30 random candidates: the one farthest from those placed.
    """
    centres = []
    for _ in range(n):
        cand = rng.uniform(lo, hi, (30, 2))
        if centres:
            c = np.array(centres)
            apart = np.abs(cand[:, None, :] - c[None]) >= pitch  # (30, k, 2)
            ok = np.all(apart.any(axis=-1), axis=1)
            if not ok.any():
                return None
            cand = cand[ok]
            dmin = np.min(np.linalg.norm(cand[:, None] - c[None], axis=-1), axis=1)
            centres.append(cand[int(np.argmax(dmin))])
        else:
            centres.append(cand[0])
    return centres


def _draw_poses(rng, view, board, rg, geo, n_poses):
    """``n_poses`` calibration poses and the held-out plane (last), or None if unplaceable.

    With ``rg.plane_slant_deg`` the plane is drawn by :func:`_slanted_plane`
    after the calibration poses, from the same stream; without it the plane
    is the last of ``n_poses + 1`` calibration-like poses, so that presets
    without the option keep their seeds' draws.
    """
    slanted = rg.plane_slant_deg is not None
    try:
        poses = board_poses(
            view,
            board,
            n_poses + (0 if slanted else 1),
            rng,
            PoseRanges(
                depth_m=rg.pose_depth_rel * geo["distance"],
                lateral_m=rg.pose_offcentre * geo["half_width"],
                tilt_deg=rg.pose_slant_deg,
                roll_deg=rg.pose_roll_deg,
                any_direction=True,
            ),
            PoseAcceptance(
                margin_px=rg.margin_px,
                max_incidence_deg=rg.pose_incidence_deg,
                min_cell_px=rg.pose_min_cell_px,
            ),
            tries=300,
        )
    except RuntimeError:
        return None
    if not slanted:
        return poses
    plane = _slanted_plane(rng, view, board, rg, geo)
    return None if plane is None else [*poses, plane]


#: Draws of the slanted plane before the whole rig is redrawn: as many as a
#: calibration pose gets (board_poses' ``tries`` above).
PLANE_TRIES = 300


def _slanted_plane(rng, view, board, rg, geo):
    """The held-out plane at a slant U(``rg.plane_slant_deg``) to the reference camera.

    The slant is the angle between the board's normal (its white side) and
    the line of sight from the reference camera (the first in rig.json order)
    to the board's centre; the normal leans from that line towards a direction
    U(0, 360) deg about it, the board turns U(-roll, roll) about its normal
    (roll ``rg.pose_roll_deg``), and its centre is placed as a calibration
    pose's (+-``pose_offcentre`` of the field's half-width in x and y,
    +-``pose_depth_rel`` D in z). Kept under the calibration poses' rules
    (whole board in every view with the margin, incidence and cell size).

    Returns
    -------
    (R_b, t_b) with world X = R_b X_board + t_b, or None if no draw of
    :data:`PLANE_TRIES` is kept.
    """
    corners = sc.board_corners(board["size"])
    centre_b = corners.mean(axis=0)
    markers = _marker_quads(board) if rg.pose_min_cell_px > 0 else None
    ref = geo["cameras"][0].centre
    lateral = rg.pose_offcentre * geo["half_width"]
    depth = rg.pose_depth_rel * geo["distance"]
    down = np.array([0.0, 0.0, -1.0])  # the board's white side in its own frame
    for _ in range(PLANE_TRIES):
        c = rng.uniform([-lateral, -lateral, -depth], [lateral, lateral, depth])
        slant = np.deg2rad(rng.uniform(*rg.plane_slant_deg))
        azimuth = np.deg2rad(rng.uniform(0, 360))
        roll = np.deg2rad(rng.uniform(-rg.pose_roll_deg, rg.pose_roll_deg))
        sight = (ref - c) / np.linalg.norm(ref - c)
        e1 = np.cross(sight, np.eye(3)[np.argmin(np.abs(sight))])  # any axis not along it
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(sight, e1)
        axis = np.cos(azimuth) * e1 + np.sin(azimuth) * e2
        normal = sc.axis_angle(axis, slant) @ sight
        # The shortest turn of the board's white side onto the normal, then the roll.
        turn = np.cross(down, normal)
        angle = np.arctan2(np.linalg.norm(turn), down @ normal)
        R0 = sc.axis_angle(turn, angle) if np.linalg.norm(turn) > 1e-12 else np.eye(3)
        R = R0 @ rotation_xyz(0, 0, roll)
        t = c - R @ centre_b
        world = corners @ R.T + t
        if not _board_visible(view, world, normal, rg.margin_px, rg.pose_incidence_deg):
            continue
        if markers is not None and _min_cell_px(view, markers, R, t) < rg.pose_min_cell_px:
            continue
        return R, t
    return None
