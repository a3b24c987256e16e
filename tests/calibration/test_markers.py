"""Marker poses stage: detection, corner refinement, pose fit and the dataset CSV.

Accuracy bounds. The demo preset (640x480, f = 1250 px) has a pixel of about
0.64 mm at the 0.8 m working distance; the target there is a plane normal within
0.05 degree and a plane offset within 0.1 mm (measured: 0.0065 degree, 0.0094 mm
before, 0.0058 degree, 0.0081 mm now; the tests bound 0.012 degree and 0.018 mm).
The tiny preset (160x120, f = 312.5 px) has a pixel four times larger (2.6 mm),
so corner noise and every error it causes scale by four: 0.2 degree and 0.4 mm
(measured over seeds 0..3: at most 0.082 degree and 0.118 mm, RMS reprojection
0.13 px; seed 0, the one tested, now 0.040 degree, 0.114 mm, 0.122 px): the tests
bound 0.1 degree, 0.2 mm and 0.25 px.
"""

from __future__ import annotations

import json
import shutil
import warnings
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest

from colourhs.calibration.markers import (
    BoardPose,
    board_pose_from_corners,
    csv_columns,
    detect_markers,
    marker_poses,
    read_marker_poses,
    to_grey8,
)
from colourhs.capture import load_rig, read_image
from colourhs.common.geometry import look_at, project

TINY_NORMAL_DEG = 0.1
TINY_OFFSET_MM = 0.2
TINY_RMS_PX = 0.25


def _true_poses(root: Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    data = json.loads((root / "gt" / "board_poses.json").read_text())
    return {k: (np.array(v["R"]), np.array(v["t"])) for k, v in data.items()}


def _plane_errors(table: pd.DataFrame, root: Path, rig) -> tuple[np.ndarray, np.ndarray]:
    """Per pose: normal error (degrees) and the larger of the two offset errors (mm)."""
    truth = _true_poses(root)
    centre = np.array([rig.board.size[0] / 2, rig.board.size[1] / 2, 0.0])
    angles, offsets = [], []
    for _, row in table.iterrows():
        R, t = truth[row["pose"]]
        n_true, p_true = R @ [0.0, 0.0, -1.0], R @ centre + t
        n = row[["normal_x", "normal_y", "normal_z"]].to_numpy(float)
        p = row[["point_x", "point_y", "point_z"]].to_numpy(float)
        angles.append(np.degrees(np.arccos(np.clip(n @ n_true, -1.0, 1.0))))
        offsets.append(1e3 * max(abs(n @ (p_true - p)), abs(n_true @ (p - p_true))))
    return np.array(angles), np.array(offsets)


def _copy_photometric(src: Path, dst: Path) -> Path:
    """rig.json, photometric/ and gt/board_poses.json of a dataset: a valid smaller dataset."""
    dst.mkdir(parents=True)
    shutil.copy(src / "rig.json", dst / "rig.json")
    shutil.copytree(src / "photometric", dst / "photometric")
    (dst / "gt").mkdir()
    shutil.copy(src / "gt" / "board_poses.json", dst / "gt" / "board_poses.json")
    return dst


def _black_image(path: Path, rig) -> None:
    """Overwrite a capture with a board-free image at the black level."""
    img = np.full((rig.image.height, rig.image.width, 3), rig.image.black_level, np.uint16)
    assert cv2.imwrite(str(path), img)


def _paint_out(path: Path, rig, cam, R, t, marker_ids) -> None:
    """Paint the given markers of one capture white (the board's bright level)."""
    raw = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    white = np.percentile(raw.reshape(-1, 3), 99, axis=0)
    mask = np.zeros(raw.shape[:2], np.uint8)
    for m in marker_ids:
        uv = project(rig.board.marker_corners(m) @ R.T + t, cam.K, cam.dist, cam.R, cam.t)
        cv2.fillConvexPoly(mask, np.round(uv).astype(np.int32), 1)
    mask = cv2.dilate(mask, np.ones((5, 5), np.uint8)).astype(bool)
    raw[mask] = white.astype(np.uint16)
    assert cv2.imwrite(str(path), raw)


@pytest.fixture(scope="module")
def tiny_table(tiny_dataset, tmp_path_factory):
    out = tmp_path_factory.mktemp("markers") / "calib" / "marker_poses.csv"
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no pose of the clean dataset may be left out
        table = marker_poses(tiny_dataset, out)
    return table, out


# --------------------------------------------------------------------------------------------
# Detection


def test_to_grey8_scales_the_99th_percentile():
    img = np.zeros((100, 100, 3), np.float32)
    img[:50] = 0.4
    img[50:] = 0.1
    g = to_grey8(img)
    assert g.dtype == np.uint8 and g.shape == (100, 100)
    assert g[0, 0] == 230 and g[99, 0] == round(0.1 / 0.4 * 230)
    assert not to_grey8(np.zeros((4, 4, 3))).any()


def test_detected_corners_are_unbiased(tiny_dataset):
    """Edge-fitted corners lie on the true corners; ArUco's alone sit ~0.35 px inside."""
    rig = load_rig(tiny_dataset)
    board = rig.board
    errors, radial, radial_aruco = [], [], []
    for pose, (R, t) in _true_poses(tiny_dataset).items():
        if pose == "plane":
            continue
        for cam in rig.cameras:
            img, _ = read_image(tiny_dataset / "photometric" / pose / f"{cam.name}.png", rig.image)
            found = detect_markers(img, board, camera=cam)
            aruco = detect_markers(img, board, refine=False)
            assert sorted(found) == sorted(aruco) == sorted(board.markers)
            for m, uv in found.items():
                true = project(board.marker_corners(m) @ R.T + t, cam.K, cam.dist, cam.R, cam.t)
                out = true - true.mean(axis=0)
                out /= np.linalg.norm(out, axis=1, keepdims=True)
                errors.append(np.linalg.norm(uv - true, axis=1))
                radial.append(np.sum((uv - true) * out, axis=1))
                radial_aruco.append(np.sum((aruco[m] - true) * out, axis=1))
    errors = np.concatenate(errors)
    assert np.sqrt(np.mean(errors**2)) < 0.12  # measured 0.072 px (0.075 before)
    assert errors.max() < 0.5  # measured 0.33 px (edges along pixel rows alias)
    assert abs(np.mean(radial)) < 0.006  # measured 0.0015 px (-0.003 before)
    assert np.mean(radial_aruco) < -0.2  # measured -0.37 px: the bias that refinement removes


def test_no_marker_in_a_black_image(tiny_dataset):
    rig = load_rig(tiny_dataset)
    assert detect_markers(np.zeros((120, 160, 3), np.float32), rig.board) == {}


# --------------------------------------------------------------------------------------------
# Pose fit


def _synthetic_detections(rig, R, t, drop=()):
    out = {}
    for cam in rig.cameras:
        out[cam.name] = {
            m: project(rig.board.marker_corners(m) @ R.T + t, cam.K, cam.dist, cam.R, cam.t)
            for m in rig.board.markers
            if (cam.name, m) not in drop
        }
    return out


def test_board_pose_from_exact_corners(tiny_dataset):
    rig = load_rig(tiny_dataset)
    c0 = np.array([0.01, -0.02, 0.03])
    R = look_at(c0, c0 + [0.2, -0.1, 1.0])[0].T  # board-to-world: board +z away from the rig
    centre = np.array([rig.board.size[0] / 2, rig.board.size[1] / 2, 0.0])
    t = c0 - R @ centre
    # cam3 sees only marker 0; marker 3 is seen by cam1 alone (not triangulated).
    drop = {("cam3", m) for m in (1, 2, 3)} | {("cam2", 3)}
    pose = board_pose_from_corners(_synthetic_detections(rig, R, t, drop), rig)
    assert isinstance(pose, BoardPose)
    assert np.allclose(pose.R, R, atol=1e-8) and np.allclose(pose.t, t, atol=1e-9)
    assert np.allclose(pose.point, c0, atol=1e-9)
    assert np.allclose(pose.normal, R @ [0, 0, -1.0], atol=1e-8)
    assert np.isclose(np.linalg.norm(pose.normal), 1.0)
    assert pose.rms_px < 1e-9  # measured 3.4e-14 px: round-off
    assert pose.n_markers == 3
    assert pose.markers == {"cam1": (0, 1, 2, 3), "cam2": (0, 1, 2), "cam3": (0,)}


def test_board_pose_needs_a_marker_seen_twice(tiny_dataset):
    rig = load_rig(tiny_dataset)
    R, t = np.eye(3), np.zeros(3)
    only_cam1 = {"cam1": _synthetic_detections(rig, R, t)["cam1"], "cam2": {}}
    with pytest.raises(ValueError, match="two or more cameras"):
        board_pose_from_corners(only_cam1, rig)
    with pytest.raises(ValueError, match="cam9"):
        board_pose_from_corners({"cam9": {}}, rig)


# --------------------------------------------------------------------------------------------
# Dataset stage


def test_tiny_marker_poses_accuracy(tiny_dataset, tiny_table):
    table, _ = tiny_table
    rig = load_rig(tiny_dataset)
    poses = sorted(p.name for p in (tiny_dataset / "photometric").iterdir())
    assert list(table["pose"]) == poses
    assert list(table.columns) == csv_columns(rig.camera_names)
    assert (table["n_markers"] == 4).all()
    assert (table[[f"markers_{c}" for c in rig.camera_names]] == "0 1 2 3").all().all()
    angles, offsets = _plane_errors(table, tiny_dataset, rig)
    assert angles.max() < TINY_NORMAL_DEG
    assert offsets.max() < TINY_OFFSET_MM
    assert table["rms_px"].max() < TINY_RMS_PX
    n = table[["normal_x", "normal_y", "normal_z"]].to_numpy()
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0)
    for k, (_, row) in enumerate(table.iterrows()):  # normals point towards the cameras
        p = row[["point_x", "point_y", "point_z"]].to_numpy(float)
        view = np.array([c.centre for c in rig.cameras]) - p
        assert np.all(view @ row[["normal_x", "normal_y", "normal_z"]].to_numpy(float) > 0)
        R = row[[f"R{i}{j}" for i in range(3) for j in range(3)]].to_numpy(float).reshape(3, 3)
        assert np.allclose(R @ R.T, np.eye(3), atol=1e-9)
        assert np.allclose(R @ [0, 0, -1.0], n[k], atol=1e-9)


def test_csv_round_trip(tiny_table):
    table, path = tiny_table
    assert path.is_file()
    assert not [p for p in path.parent.iterdir() if p != path]  # no temporary left behind
    back = read_marker_poses(path)
    pd.testing.assert_frame_equal(back, table, check_exact=True)


def test_unusable_poses_are_left_out_with_a_warning(tiny_dataset, tmp_path):
    root = _copy_photometric(tiny_dataset, tmp_path / "painted")
    rig = load_rig(root)
    truth = _true_poses(root)
    # pose00: two of the three cameras see no board at all.
    for name in ("cam1", "cam2"):
        _black_image(root / "photometric" / "pose00" / f"{name}.png", rig)
    # pose01: markers 0 and 1 painted white in every camera, 2 markers left.
    R, t = truth["pose01"]
    for cam in rig.cameras:
        _paint_out(root / "photometric" / "pose01" / f"{cam.name}.png", rig, cam, R, t, (0, 1))
    # pose02: marker 3 painted out in cam1 and cam2 only: 3 markers still triangulated.
    R, t = truth["pose02"]
    for cam in rig.cameras[:2]:
        _paint_out(root / "photometric" / "pose02" / f"{cam.name}.png", rig, cam, R, t, (3,))
    out = tmp_path / "poses.csv"
    with pytest.warns(UserWarning) as record:
        table = marker_poses(root, out)
    messages = [str(w.message) for w in record]
    assert any("'pose00'" in m for m in messages) and any("'pose01'" in m for m in messages)
    assert len(messages) == 2
    assert list(table["pose"]) == ["pose02", "pose03", "pose04", "pose05", "pose06"]
    row = table.iloc[0]
    assert row["n_markers"] == 3
    assert (row["markers_cam1"], row["markers_cam3"]) == ("0 1 2", "0 1 2 3")
    angles, offsets = _plane_errors(table, root, rig)
    assert angles.max() < TINY_NORMAL_DEG and offsets.max() < TINY_OFFSET_MM
    # With min_markers=2, pose01 (two markers seen by all cameras) is kept.
    with pytest.warns(UserWarning, match="'pose00'"):
        kept = marker_poses(root, tmp_path / "poses2.csv", min_markers=2)
    assert "pose01" in set(kept["pose"]) and "pose00" not in set(kept["pose"])


def test_fewer_than_three_usable_poses_is_an_error(tiny_dataset, tmp_path):
    root = _copy_photometric(tiny_dataset, tmp_path / "dark")
    rig = load_rig(root)
    for pose in ("pose02", "pose03", "pose04", "pose05", "pose06"):
        for cam in rig.camera_names:
            _black_image(root / "photometric" / pose / f"{cam}.png", rig)
    out = tmp_path / "out" / "poses.csv"
    with pytest.warns(UserWarning), pytest.raises(ValueError) as err:
        marker_poses(root, out)
    msg = str(err.value)
    assert str(root) in msg and "pose00" in msg and "pose06" in msg
    assert not out.exists()
    assert not out.parent.exists() or not any(out.parent.iterdir())


def test_demo_preset_plane_accuracy(plane_calibrated, tmp_path):
    """Demo preset: normals within 0.05 degree and offsets within 0.1 mm for every pose.

    The board captures are the demo preset's own (conftest's ``plane_calibrated``
    renders the demo rig's board poses with its seed); this runs the stage again on
    them rather than reading the fixture's table, so the test times the stage.
    """
    root, _ = plane_calibrated
    rig = load_rig(root)
    table = marker_poses(root, tmp_path / "demo_marker_poses.csv")
    assert list(table["pose"]) == sorted(p.name for p in (root / "photometric").iterdir())
    assert (table["n_markers"] == len(rig.board.markers)).all()
    angles, offsets = _plane_errors(table, root, rig)
    assert angles.max() < 0.012  # measured 0.0058 degree (0.0065 before)
    assert offsets.max() < 0.018  # measured 0.0081 mm (0.0094 before)
    assert table["rms_px"].max() < 0.15  # measured 0.081 px (0.091 before)
