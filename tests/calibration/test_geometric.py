"""The geometric calibration (``colourhs calibrate-rig``): the cameras' intrinsics,
distortion and poses from views of a ChArUco target, rig.json and the report.

Fast tests first, on detections without images: a known rig (a random-tiny-lens
rig's cameras with their rational terms and skew, with k1 k2 p1 p2 k3 and skew, or
with the thin prism), board poses, the corners projected by the package's camera
model, exactly or with 0.1 px noise.
Then the corner detector on a rendered view, the stage on a small rendered dataset
(a ray caster here: the board's raster seen through each camera's lens) and the
command line; last, when the synthetic renderer has ``geometric/`` captures, the
stage on a tiny synthetic dataset against its true rig (slow).

Comparisons are in the reference camera's frame (the calibration's world) unless
a test says otherwise; the distortion is compared as the pixel displacement it
makes, over the image area the views' corners cover.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
from itertools import combinations
from pathlib import Path
from types import SimpleNamespace

import cv2
import numpy as np
import pytest
from rig_examples import contract_example
from scipy.spatial.transform import Rotation

from colourhs.calibration.board import charuco_board, charuco_layout, render_board
from colourhs.calibration.geometric import (
    LensModel,
    board_corners,
    calibrate_cameras,
    calibrate_rig,
    calibration_report,
    corner_coverage,
    detect_charuco,
    in_world,
    lens_model,
)
from colourhs.capture import load_rig, rig_from_dict
from colourhs.cli.parser import main
from colourhs.common.geometry import (
    camera_centre,
    look_at,
    normalised_coordinates,
    project,
    ray_directions,
)
from colourhs.evaluation.rig_errors import distortion_field_error

W, H = 640, 480
LAYOUT = charuco_layout(10, 8, 0.025, 0.019, "DICT_4X4_50")  # 0.25 x 0.2 m, 63 corners
AIMS = [(0, 0), (-1, -1), (1, -1), (1, 1), (-1, 1), (-1, 0), (1, 0), (0, -1), (0, 1)]


# --------------------------------------------------------------------------------------------
# Helpers: a known rig, board poses, projected corners, the errors


def _random_cameras(seed: int, n_dist: int, skew: bool) -> list:
    """The cameras of a random-tiny-lens rig at W x H: rational and thin-prism lens
    terms and a skew of up to 1 % of f; ``dist`` cut to ``n_dist``, the skew kept or 0."""
    from colourhs.synth.randomranges import RANGES_BY_NAME
    from colourhs.synth.randomrig import draw_random
    from colourhs.synth.simulated_rig import Nuisances

    draw = draw_random(
        seed,
        W,
        H,
        Nuisances(),
        ranges=RANGES_BY_NAME["random-tiny-lens"],
        n_poses=2,
        sheet_frames=1,
        statue_level=2,
    )
    cams = []
    for c in draw.rig.cameras:
        K = np.array(c.K, float)
        if not skew:
            K[0, 1] = 0.0
        cams.append(dataclasses.replace(c, K=K, dist=np.array(c.dist[:n_dist], float)))
    return cams


def _board_poses(cams, n: int, seed: int, layout=LAYOUT, reach=(0.13, 0.1)) -> dict:
    """``n`` board poses (R_b, t_b) around the rig's fixation point: the target's centre
    aimed in turn at the field's centre, corners and edges (``reach`` metres out), slanted
    20 to 45 degrees about an axis in any direction, rolled, at +-0.1 m of depth."""
    rng = np.random.default_rng(seed)
    axis = np.mean([c.R[2] for c in cams], axis=0)
    axis /= np.linalg.norm(axis)
    x = np.cross([0.0, 1.0, 0.0], axis)
    x /= np.linalg.norm(x)
    frame = np.column_stack([x, np.cross(axis, x), axis])  # the board's z along the view
    (nx, ny), s = layout["squares"], layout["square_length"]
    half = np.array([nx * s / 2, ny * s / 2, 0.0])
    poses = {}
    for k in range(n):
        ax, ay = AIMS[k % len(AIMS)]
        dx, dy, depth = rng.uniform(-0.02, 0.02), rng.uniform(-0.02, 0.02), rng.uniform(-0.1, 0.1)
        centre = frame @ np.array([ax * reach[0] + dx, ay * reach[1] + dy, depth])
        phi, slant = rng.uniform(0, 2 * np.pi), np.radians(rng.uniform(20, 45))
        tilt = [slant * np.cos(phi), slant * np.sin(phi), rng.uniform(-0.3, 0.3)]
        Rb = frame @ Rotation.from_rotvec(tilt).as_matrix()
        poses[f"p{k:02d}"] = (Rb, centre - Rb @ half)
    return poses


def _detections(cams, poses, noise_px: float, seed: int, size=(W, H), layout=LAYOUT) -> dict:
    """camera -> pose -> (ids, corners_px): the corners inside the image, projected by the
    package's camera model, plus Gaussian noise of ``noise_px`` per coordinate."""
    rng = np.random.default_rng(seed)
    X = board_corners(layout)
    out = {}
    for c in cams:
        out[c.name] = {}
        for pose, (Rb, tb) in poses.items():
            uv = project(X @ Rb.T + tb, c.K, c.dist, c.R, c.t)
            w, h = size
            inside = np.all(np.isfinite(uv), axis=1)
            inside &= (uv[:, 0] >= 0) & (uv[:, 0] <= w - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= h - 1)
            ids = np.flatnonzero(inside)
            out[c.name][pose] = (ids, uv[ids] + rng.normal(scale=noise_px, size=(ids.size, 2)))
    return out


def _without_cell(detections, camera: str, u_max: float, v_max: float) -> dict:
    """``detections`` with ``camera``'s corners above-left of (u_max, v_max) removed."""
    out = {c: dict(per_pose) for c, per_pose in detections.items()}
    for pose, (ids, uv) in detections[camera].items():
        keep = ~((uv[:, 0] < u_max) & (uv[:, 1] < v_max))
        out[camera][pose] = (ids[keep], uv[keep])
    return out


def _in_frame(cam, R0, t0) -> tuple[np.ndarray, np.ndarray]:
    """A camera's (R, t) in the frame X' = R0 X + t0 of its world."""
    R = cam.R @ R0.T
    return R, cam.t - R @ t0


def _rotation_deg(Ra: np.ndarray, Rb: np.ndarray) -> float:
    return float(np.degrees(np.linalg.norm(Rotation.from_matrix(Ra.T @ Rb).as_rotvec())))


def _field_error(cam, K, dist, corners_px: np.ndarray, size=(W, H)) -> float:
    """Largest difference (pixels) of the lens's displacement, true against estimated,
    inside the convex hull of ``corners_px`` (:func:`distortion_field_error`)."""
    return distortion_field_error(cam.K, cam.dist, K, dist, size, corners_px)


def _errors(cams, cal, detections) -> dict[str, dict[str, float]]:
    """Per camera: focal length (relative), principal point (px), skew (px), distortion
    field (px), rotation (deg) and centre (mm), true rig in the reference camera's frame."""
    ref = cams[0]
    out = {}
    for c in cams:
        K, dist = cal.K[c.name], cal.dist[c.name]
        R, t = _in_frame(c, ref.R, ref.t)
        corners = np.concatenate([uv for _, uv in detections[c.name].values()])
        out[c.name] = {
            "f": float(np.max(np.abs(np.diag(K)[:2] / np.diag(c.K)[:2] - 1))),
            "pp_px": float(np.max(np.abs(K[:2, 2] - c.K[:2, 2]))),
            "skew_px": abs(float(K[0, 1] - c.K[0, 1])),
            "field_px": _field_error(c, K, dist, corners),
            "rotation_deg": _rotation_deg(R, cal.R[c.name]),
            "centre_mm": 1e3 * _distance(camera_centre(R, t), cal.R[c.name], cal.t[c.name]),
        }
    return out


def _distance(centre: np.ndarray, R: np.ndarray, t: np.ndarray) -> float:
    """Distance (m) from ``centre`` to the centre of the camera (R, t)."""
    return float(np.linalg.norm(centre - camera_centre(R, t)))


def _worst(errors: dict) -> dict[str, float]:
    keys = next(iter(errors.values()))
    return {k: max(e[k] for e in errors.values()) for k in keys}


# --------------------------------------------------------------------------------------------
# Fixtures: one calibration each, shared by the tests that read it


RATIONAL = LensModel(8, True, 8)


@pytest.fixture(scope="module")
def exact():
    """Exact corners of the rational-and-skew rig; the second camera's corners in the
    image's top-left cell left out (its coverage warning)."""
    cams = _random_cameras(3, 8, skew=True)
    poses = _board_poses(cams, 14, seed=1)
    det = _without_cell(_detections(cams, poses, 0.0, seed=2), cams[1].name, W / 4, H / 4)
    cal = calibrate_cameras(det, LAYOUT, (W, H), RATIONAL)
    return SimpleNamespace(cams=cams, poses=poses, det=det, cal=cal)


@pytest.fixture(scope="module")
def noisy():
    """The same rig with its lens cut to k1 k2 p1 p2 k3 (the random presets' model) and
    the same poses, every corner with Gaussian noise of 0.1 px per coordinate."""
    cams = _random_cameras(3, 5, skew=True)
    poses = _board_poses(cams, 14, seed=1)
    det = _detections(cams, poses, 0.1, seed=2)
    cal = calibrate_cameras(det, LAYOUT, (W, H), LensModel(5, True, 5))
    return SimpleNamespace(cams=cams, poses=poses, det=det, cal=cal)


# --------------------------------------------------------------------------------------------
# The model and the target


def test_board_corners_are_opencvs_charuco_corners():
    X = board_corners(LAYOUT)
    assert X.shape == (63, 3) and np.all(X[:, 2] == 0)
    opencv = np.asarray(charuco_board(LAYOUT).getChessboardCorners(), float).reshape(-1, 3)
    np.testing.assert_allclose(X, opencv, atol=1e-7)
    np.testing.assert_allclose(
        X[[0, 8, 9]], [[0.025, 0.025, 0], [0.225, 0.025, 0], [0.025, 0.05, 0]]
    )


def test_lens_model_is_read_from_a_rig_json_camera():
    K_skew = [[1000.0, 2.0, 320.0], [0.0, 1000.0, 240.0], [0.0, 0.0, 1.0]]
    K = [[1000.0, 0.0, 320.0], [0.0, 1000.0, 240.0], [0.0, 0.0, 1.0]]
    assert lens_model(None, K) == LensModel(5, False, 5)
    assert lens_model([0.0] * 4, K) == LensModel(4, False, 4)
    assert lens_model([0.0] * 8, K_skew) == LensModel(8, True, 8)
    assert lens_model([0.0] * 14, K) == LensModel(12, False, 14)
    with pytest.raises(ValueError, match="6 distortion coefficients"):
        LensModel(6)


# --------------------------------------------------------------------------------------------
# Synthetic detections


def test_exact_corners_recover_the_rig(exact):
    """Rational model and skew, exact corners: every parameter to round-off's reach."""
    errors = _errors(exact.cams, exact.cal, exact.det)
    worst = _worst(errors)
    print("exact corners, worst over the cameras:", worst)
    assert worst["f"] < 1e-4  # 0.01 %
    assert worst["pp_px"] < 0.05
    assert worst["skew_px"] < 0.05
    assert worst["field_px"] < 0.01
    assert worst["rotation_deg"] < 0.001
    assert worst["centre_mm"] < 0.02
    report = calibration_report(exact.cal, exact.det, (W, H))
    assert report["rms_px"] < 1e-4


def test_noisy_corners_recover_the_rig_within_the_noise(noisy):
    """0.1 px of noise on every corner (k1 k2 p1 p2 k3 and a skew). Over a narrow field
    (here 26 degrees) the tangential terms p1, p2 trade against a shift of the principal
    point with a tilt of the camera (or of every board pose): from these 14 views the
    covariance at the solution gives the principal point a 1-sigma of about 1.5 px, the
    cameras' rotations 0.07 degrees and their translations 0.6 mm, and the errors are of
    that size (measured: f 0.05 %, principal point 2.2 px, skew 0.11 px, distortion
    0.18 px, rotation 0.065 degrees, centre 0.7 mm). Each error is checked against its
    own 1-sigma too, so that the report's uncertainties can be trusted."""
    errors = _errors(noisy.cams, noisy.cal, noisy.det)
    worst = _worst(errors)
    print("0.1 px noise, worst over the cameras:", worst)
    sd = noisy.cal.sd
    print("1-sigma:", sd)
    assert worst["f"] < 1e-3
    assert worst["pp_px"] < 3.0
    assert worst["skew_px"] < 0.3
    assert worst["field_px"] < 0.3
    assert worst["rotation_deg"] < 0.1
    assert worst["centre_mm"] < 1.0
    for cam in noisy.cams:
        e, s = errors[cam.name], sd[cam.name]
        assert e["pp_px"] < 4 * max(s["c_px"]), (cam.name, e, s)
        assert e["f"] * cam.K[0, 0] < 4 * max(s["f_px"]), (cam.name, e, s)
        if cam is not noisy.cams[0]:
            assert e["rotation_deg"] < 4 * s["rotation_deg"], (cam.name, e, s)
    report = calibration_report(noisy.cal, noisy.det, (W, H))
    assert 0.13 < report["rms_px"] < 0.15  # 0.1 px per coordinate: 0.141 px per corner


def test_thin_prism_model_reproduces_the_views():
    """Thin prism: s1, s3 with p2, p1 absorb a rotation of a camera plus a shift of its
    principal point to first order, so that under noise neither is measurable on its own
    (exact corners pin them through second-order terms only, which the fit may stop short
    of); the focal lengths, the baselines and the corners' positions are measurable.
    Measured: f 3e-9 relative, principal point 2e-5 px, rotation 1e-6 degrees."""
    cams = _random_cameras(5, 12, skew=False)
    poses = _board_poses(cams, 9, seed=4)
    det = _detections(cams, poses, 0.0, seed=5)
    cal = calibrate_cameras(det, LAYOUT, (W, H), LensModel(12, False, 12))
    errors = _errors(cams, cal, det)
    print("thin prism, exact corners:", _worst(errors))
    assert _worst(errors)["f"] < 1e-4
    for a, b in combinations(cams, 2):
        true = np.linalg.norm(a.centre - b.centre)
        est = np.linalg.norm(
            camera_centre(cal.R[a.name], cal.t[a.name])
            - camera_centre(cal.R[b.name], cal.t[b.name])
        )
        assert abs(est - true) < 1e-6, (a.name, b.name, est - true)  # 1 um
    assert calibration_report(cal, det, (W, H))["rms_px"] < 1e-3


def test_world_on_a_board_pose_puts_that_target_at_the_origin(exact):
    pose = "p03"
    moved = in_world(exact.cal, f"board:{pose}")
    Rb, tb = moved.board_poses[pose]
    np.testing.assert_allclose(Rb, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(tb, 0.0, atol=1e-12)
    Rb_true, tb_true = exact.poses[pose]  # the true rig in that board's frame
    for c in exact.cams:
        R, t = _in_frame(c, Rb_true.T, -Rb_true.T @ tb_true)
        assert _rotation_deg(R, moved.R[c.name]) < 0.001
        centre = camera_centre(moved.R[c.name], moved.t[c.name])
        assert 1e3 * np.linalg.norm(centre - camera_centre(R, t)) < 0.02
    back = in_world(moved, "reference")
    np.testing.assert_allclose(back.R[exact.cams[0].name], np.eye(3), atol=1e-12)
    np.testing.assert_allclose(back.t[exact.cams[0].name], 0.0, atol=1e-12)
    with pytest.raises(ValueError, match="board:nowhere"):
        in_world(exact.cal, "board:nowhere")
    with pytest.raises(ValueError, match="expected 'reference' or 'board:POSE'"):
        calibrate_cameras(exact.det, LAYOUT, (W, H), RATIONAL, world="camera2")


def test_report_gives_rms_per_pose_pair_geometry_and_warns_of_an_uncovered_corner(exact):
    report = calibration_report(exact.cal, exact.det, (W, H))
    json.dumps(report)  # JSON as it is
    cams = exact.cams
    starved = cams[1].name
    assert report["cameras"][starved]["uncovered_corner_cells"] == ["top-left"]
    named = [w for w in report["warnings"] if f"camera {starved}:" in w]
    assert len(named) == 1 and "top-left" in named[0] and "extrapolated" in named[0]
    for name, c in report["cameras"].items():
        assert set(c["rms_px_per_pose"]) == set(c["views"]) and len(c["views"]) >= 6
        if not c["uncovered_corner_cells"]:
            assert not any(f"camera {name}:" in w for w in report["warnings"])
    assert len(report["pairs"]) == 3
    for pair in report["pairs"]:
        a, b = (next(c for c in cams if c.name == n) for n in pair["cameras"])
        angle = np.degrees(np.arctan2(np.linalg.norm(np.cross(a.R[2], b.R[2])), a.R[2] @ b.R[2]))
        assert abs(pair["angle_deg"] - angle) < 1e-3
        assert abs(pair["baseline_m"] - np.linalg.norm(a.centre - b.centre)) < 1e-7


def test_corner_coverage_counts_cells_and_names_the_empty_image_corners():
    centre = np.array([[W / 2, H / 2], [W / 2 - 100, H / 2 - 80], [W / 2 + 100, H / 2 + 80]])
    coverage, uncovered = corner_coverage(centre, (W, H))
    assert coverage == pytest.approx(2 / 16)
    assert uncovered == ["top-left", "top-right", "bottom-left", "bottom-right"]
    edges = np.array([[0, 0], [W - 1, 0], [0, H - 1], [W - 1, H - 1]], float)
    assert corner_coverage(edges, (W, H)) == (pytest.approx(4 / 16), [])


def test_too_few_views_and_an_unposed_camera_are_named(exact):
    det = {c: dict(v) for c, v in exact.det.items()}
    third = exact.cams[2].name
    det[third] = {p: v for p, v in sorted(det[third].items())[:5]}
    with pytest.raises(ValueError, match=rf"camera {third} has 5 usable views") as err:
        calibrate_cameras(det, LAYOUT, (W, H), RATIONAL)
    assert "at least 6" in str(err.value) and "p00 (" in str(err.value)
    det[third] = {p: (ids[:7], uv[:7]) for p, (ids, uv) in exact.det[third].items()}
    with pytest.raises(ValueError, match="0 usable views.*7 corners"):
        calibrate_cameras(det, LAYOUT, (W, H), RATIONAL)
    # The third camera sees the target in poses no other camera sees.
    det = {c: {p: v for p, v in exact.det[c].items() if p < "p08"} for c in exact.det}
    det[third] = {p + "x": v for p, v in exact.det[third].items()}
    with pytest.raises(ValueError, match=rf"{third} share no usable view .* cannot be posed"):
        calibrate_cameras(det, LAYOUT, (W, H), RATIONAL)


# --------------------------------------------------------------------------------------------
# Images: a ray caster of the target through each camera's lens


def _caster(K, dist, R, t, size, supersample: int):
    """Per camera: the rays of supersample x supersample samples in every pixel."""
    w, h = size
    offs = (np.arange(supersample) + 0.5) / supersample - 0.5
    v, u, dv, du = np.meshgrid(np.arange(h), np.arange(w), offs, offs, indexing="ij")
    uv = np.stack([u + du, v + dv], axis=-1).reshape(-1, 2)
    rays = ray_directions(normalised_coordinates(uv, K, dist), R, unit_length=False)
    return camera_centre(R, t), rays


def _cast(caster, size, supersample, raster, px_per_m, Rb, tb) -> np.ndarray:
    """Grey image (H, W) of the target in pose (Rb, tb): white 0.9, black 0.05, the
    background 0.25; each pixel the mean of its samples."""
    centre, rays = caster
    local_c, local_d = Rb.T @ (centre - tb), rays @ Rb  # the board frame
    s = -local_c[2] / local_d[:, 2]
    xy = (local_c[None, :2] + s[:, None] * local_d[:, :2]) * px_per_m - 0.5
    n = len(xy)
    pad = (-n) % 1024
    maps = np.concatenate([xy, np.full((pad, 2), -10.0)]).astype(np.float32)
    value = cv2.remap(
        raster,
        maps[:, 0].reshape(-1, 1024),
        maps[:, 1].reshape(-1, 1024),
        cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_CONSTANT,
        borderValue=-1.0,
    ).ravel()[:n]
    value = np.where((value < 0) | (s <= 0), 0.25, 0.05 + 0.85 * value)
    w, h = size
    return value.reshape(h, w, supersample * supersample).mean(axis=-1)


PX_PER_M = 8000.0  # the target's raster: 0.125 mm pixels


def _raster(layout) -> np.ndarray:
    return render_board(layout, dpi=PX_PER_M * 0.0254).astype(np.float32) / 255.0


def test_detected_corners_are_within_a_few_hundredths_of_a_pixel():
    """A slanted view through a distorting lens, 30 px squares: the saddle-point
    refinement against the true corners (OpenCV's own interpolated corners were about
    0.1 px off on such a view)."""
    layout = charuco_layout(7, 5, 0.04, 0.03, "DICT_4X4_50")
    size = (320, 240)
    K = np.array([[600.0, 0.0, 159.5], [0.0, 600.0, 119.5], [0.0, 0.0, 1.0]])
    dist = np.array([-0.1, 0.05, 0.001, -0.0005, 0.0])
    R, t = look_at(np.array([0.05, -0.03, -0.8]), np.zeros(3))
    Rb = Rotation.from_rotvec([0.4, -0.3, 0.1]).as_matrix()
    tb = -Rb @ np.array([0.14, 0.1, 0.0])
    image = _cast(_caster(K, dist, R, t, size, 4), size, 4, _raster(layout), PX_PER_M, Rb, tb)
    ids, uv = detect_charuco(np.dstack([image] * 3), layout)
    assert len(ids) == 24  # every interior corner
    truth = project(board_corners(layout)[ids] @ Rb.T + tb, K, dist, R, t)
    err = np.linalg.norm(uv - truth, axis=1)
    print(f"corner error RMS {np.sqrt(np.mean(err**2)):.4f} px, max {err.max():.4f} px")
    assert np.sqrt(np.mean(err**2)) < 0.05 and err.max() < 0.1
    assert detect_charuco(np.zeros((240, 320, 3)), layout)[0].size == 0


SMALL = (320, 240)
SMALL_LAYOUT = charuco_layout(7, 5, 0.04, 0.03, "DICT_4X4_50")  # 0.28 x 0.2 m, 24 corners


def _small_rig() -> dict:
    """The capture format's example rig at 320 x 240 (f 600 px) with a lens, and the
    ChArUco target: the true rig.json of the rendered dataset."""
    rig = contract_example()
    rig["image"].update(width=SMALL[0], height=SMALL[1])
    dists = ([-0.12, 0.08, 8e-4, -5e-4, 0.0], [-0.08, 0.02, -3e-4, 6e-4, 0.0], [-0.1, 0.0, 0, 0, 0])
    for cam, d in zip(rig["cameras"], dists, strict=True):
        cam["K"] = [[600.0, 0.0, 159.5], [0.0, 600.0, 119.5], [0.0, 0.0, 1.0]]
        cam["dist"] = d
    rig["geometric_board"] = SMALL_LAYOUT
    return rig


@pytest.fixture(scope="module")
def rendered(tmp_path_factory) -> Path:
    """A dataset of the geometric captures alone: 10 poses of the target seen by the three
    cameras of :func:`_small_rig` (16-bit PNGs), and a rig.json whose cameras' intrinsics
    are a placeholder (f 2 % off, no distortion) at the true poses."""
    root = tmp_path_factory.mktemp("geometric") / "dataset"
    true = _small_rig()
    truth = rig_from_dict(true)
    poses = _board_poses(truth.cameras, 10, seed=7, layout=SMALL_LAYOUT, reach=(0.08, 0.06))
    raster = _raster(SMALL_LAYOUT)
    for cam in truth.cameras:
        caster = _caster(cam.K, cam.dist, cam.R, cam.t, SMALL, 2)
        for pose, (Rb, tb) in poses.items():
            image = _cast(caster, SMALL, 2, raster, PX_PER_M, Rb, tb)
            path = root / "geometric" / pose / f"{cam.name}.png"
            path.parent.mkdir(parents=True, exist_ok=True)
            cv2.imwrite(str(path), np.dstack([np.round(image * 65535).astype(np.uint16)] * 3))
    base = json.loads(json.dumps(true))
    for cam in base["cameras"]:
        cam["K"][0][0] = cam["K"][1][1] = 612.0
        cam["dist"] = [0.0] * 5
    (root / "rig.json").write_text(json.dumps(base))
    (root.parent / "true_rig.json").write_text(json.dumps(true))
    return root


def test_calibrate_rig_writes_the_measured_cameras_into_rig_json(rendered, tmp_path):
    true = load_rig(rendered.parent / "true_rig.json")
    out, report_path = tmp_path / "rig.json", tmp_path / "report.json"
    report = calibrate_rig(rendered, out, report_json=report_path)
    assert json.loads(report_path.read_text())["rms_px"] == pytest.approx(report["rms_px"])
    rig = load_rig(out)  # the package's reader accepts it
    ref = true.cameras[0]
    worst = {"f": 0.0, "pp_px": 0.0, "rotation_deg": 0.0, "centre_mm": 0.0}
    for c in true.cameras:
        e = rig.camera(c.name)
        R, t = _in_frame(c, ref.R, ref.t)
        worst["f"] = max(worst["f"], float(np.max(np.abs(np.diag(e.K)[:2] / 600.0 - 1))))
        worst["pp_px"] = max(worst["pp_px"], float(np.max(np.abs(e.K[:2, 2] - c.K[:2, 2]))))
        worst["rotation_deg"] = max(worst["rotation_deg"], _rotation_deg(R, e.R))
        worst["centre_mm"] = max(
            worst["centre_mm"], 1e3 * float(np.linalg.norm(e.centre - camera_centre(R, t)))
        )
        assert len(e.dist) == 5 and e.light_colour == c.light_colour
        np.testing.assert_array_equal(e.light_offset, c.light_offset)
    print("rendered dataset:", worst, "RMS", report["rms_px"])
    # Measured: RMS 0.07 px (the renders' aliasing), f 0.06 %, principal point 2.2 px,
    # rotation 0.21 degrees, centre 0.7 mm: the tangential terms' trade with the principal
    # point and the camera's tilt over a 30-degree field (test_noisy_corners_...).
    assert report["rms_px"] < 0.1
    assert worst["f"] < 1e-3 and worst["pp_px"] < 3.5
    assert worst["rotation_deg"] < 0.35 and worst["centre_mm"] < 1.2
    # Not measured, kept: the image, the boards; the chromatic light carried into the
    # new world (the reference camera's frame) by the old cameras' poses.
    written = json.loads(out.read_text())
    base = json.loads((rendered / "rig.json").read_text())
    for key in ("image", "board", "geometric_board", "format", "units"):
        assert written[key] == base[key], key
    old = np.array(base["chromatic_light"]["position"])
    np.testing.assert_allclose(rig.chromatic_light, ref.R @ old + ref.t, atol=2e-3)
    assert report["old_world"]["carried"] and report["world"] == "reference"


def test_calibrate_rig_command_line(rendered, tmp_path, capsys):
    """The command prints its summary; a placeholder base rig (every camera at the origin)
    cannot carry the world positions over: they are kept, with a warning."""
    placeholder = json.loads((rendered / "rig.json").read_text())
    for cam in placeholder["cameras"]:
        cam["R"], cam["t"] = np.eye(3).tolist(), [0.0, 0.0, 0.0]
    base = tmp_path / "placeholder.json"
    base.write_text(json.dumps(placeholder))
    out = tmp_path / "rig.json"
    argv = ["calibrate-rig", str(rendered), str(out), "--base-rig", str(base)]
    assert main([*argv, "--world", "board:p02", "--report", str(tmp_path / "r.json")]) == 0
    printed, err = capsys.readouterr()
    assert "cam1: RMS" in printed and "cam1-cam2: optical axes" in printed
    assert "chromatic_light.position is kept" in err
    written = json.loads(out.read_text())
    assert written["chromatic_light"] == placeholder["chromatic_light"]
    assert json.loads((tmp_path / "r.json").read_text())["world"] == "board:p02"


def test_calibrate_rig_errors_are_one_line(rendered, tmp_path, capsys):
    def one_line(argv) -> str:
        assert main(argv) == 1
        out, err = capsys.readouterr()
        assert err.count("\n") == 1 and "Traceback" not in err and out == "", (out, err)
        return err

    empty = tmp_path / "empty"
    empty.mkdir()
    shutil.copy(rendered / "rig.json", empty / "rig.json")
    assert "no geometric/ folder" in one_line(["calibrate-rig", str(empty), str(tmp_path / "o")])
    bare = tmp_path / "bare"
    shutil.copytree(rendered, bare)
    rig = json.loads((bare / "rig.json").read_text())
    del rig["geometric_board"]
    (bare / "rig.json").write_text(json.dumps(rig))
    assert "no geometric_board" in one_line(["calibrate-rig", str(bare), str(tmp_path / "o")])
    err = one_line(["calibrate-rig", str(rendered), str(tmp_path / "o"), "--world", "board:x"])
    assert "board:x" in err and "p00" in err
    assert not (tmp_path / "o").exists()


# Measured: the centres 0.76 mm and rotations 0.125 deg from the true ones in the base's
# world (the principal point's trade with the tilt, test_calibrate_rig_writes_...); the
# tiny rig's third-camera reprojection 0.116 px (the check's tolerance: 1 px).
CENTRE_BASE_MM, ROTATION_BASE_DEG = 1.0, 0.16
THIRD_PX_TINY = 0.15


def test_world_base_keeps_the_base_rigs_world(rendered, tmp_path):
    """``--world base``: the calibrated cameras in the base rig.json's own world (its
    cameras at the true poses, placeholder intrinsics), so that ground truth and world
    positions given in it stay valid; a placeholder base has no world to keep."""
    true = load_rig(rendered.parent / "true_rig.json")
    report = calibrate_rig(rendered, tmp_path / "rig.json", world="base")
    rig = load_rig(tmp_path / "rig.json")
    centre_mm = max(
        1e3 * float(np.linalg.norm(rig.camera(c.name).centre - c.centre)) for c in true.cameras
    )
    rotation_deg = max(_rotation_deg(c.R, rig.camera(c.name).R) for c in true.cameras)
    print(f"world base: centres {centre_mm:.3f} mm, rotations {rotation_deg:.4f} deg")
    assert report["world"] == "base" and report["old_world"]["carried"]
    assert centre_mm < CENTRE_BASE_MM and rotation_deg < ROTATION_BASE_DEG
    placeholder = json.loads((rendered / "rig.json").read_text())
    for cam in placeholder["cameras"]:
        cam["R"], cam["t"] = np.eye(3).tolist(), [0.0, 0.0, 0.0]
    base = tmp_path / "placeholder.json"
    base.write_text(json.dumps(placeholder))
    with pytest.raises(ValueError, match="world 'base': the base rig's cameras do not match"):
        calibrate_rig(rendered, tmp_path / "o.json", world="base", base_rig=base)
    assert not (tmp_path / "o.json").exists()


def test_calibrate_rig_checks_its_rig_against_the_photometric_captures(tiny_dataset, tmp_path):
    """With photometric captures the calibrated rig is checked against them before it is
    written (colourhs.calibration.rig_check): its figures go into the report, and views
    that disagree (cam1's and cam2's board images swapped: cameras moved between the
    captures) are an error and no file."""
    report = calibrate_rig(tiny_dataset, tmp_path / "rig.json", world="base")
    check = report["rig_check"]
    print("rig check of the calibrated tiny rig:", check)
    assert max(check["third_px"].values()) < THIRD_PX_TINY
    assert abs(check["marker_scale"] - 1) < 2e-3
    moved = tmp_path / "moved"
    shutil.copytree(tiny_dataset, moved, ignore=shutil.ignore_patterns("scenes", "chromatic"))
    for pose in (moved / "photometric").iterdir():
        a, b = pose / "cam1.png", pose / "cam2.png"
        a.rename(pose / "swap.png")
        b.rename(a)
        (pose / "swap.png").rename(b)
    with pytest.raises(ValueError, match="not written: the calibrated cameras disagree"):
        calibrate_rig(moved, tmp_path / "o.json")
    assert not (tmp_path / "o.json").exists()


# --------------------------------------------------------------------------------------------
# The synthetic renderer's geometric captures (slow)


@pytest.fixture(scope="module")
def synthetic_geometric(tmp_path_factory) -> Path:
    """A random-tiny dataset's geometric captures (the renderer's, with every nuisance)."""
    from colourhs.synth.synthesise import PARTS, RenderSelection, synthesise

    if "geometric" not in PARTS:
        pytest.skip("the synthetic renderer has no geometric/ captures (PARTS) yet")
    root = tmp_path_factory.mktemp("synthetic") / "random-tiny"
    return synthesise(root, "random-tiny", seed=1, selection=RenderSelection(parts=("geometric",)))


@pytest.mark.slow
def test_synthetic_geometric_captures_give_the_true_rig(synthetic_geometric, tmp_path):
    """160 x 120 images, squares of about 18 px: the errors are of that scale."""
    root = synthetic_geometric
    true = load_rig(root / "rig.json")
    gt = json.loads((root / "gt" / "geometric_poses.json").read_text())
    pose = sorted(gt)[0]
    report = calibrate_rig(root, tmp_path / "rig.json", world=f"board:{pose}")
    rig = load_rig(tmp_path / "rig.json")
    Rb, tb = np.array(gt[pose]["R"]), np.array(gt[pose]["t"])
    worst = {"f": 0.0, "rotation_deg": 0.0, "centre_mm": 0.0}
    for c in true.cameras:
        e = rig.camera(c.name)
        R, t = _in_frame(c, Rb.T, -Rb.T @ tb)  # the true camera in that target's frame
        worst["f"] = max(worst["f"], float(np.max(np.abs(np.diag(e.K)[:2] / np.diag(c.K)[:2] - 1))))
        worst["rotation_deg"] = max(worst["rotation_deg"], _rotation_deg(R, e.R))
        worst["centre_mm"] = max(
            worst["centre_mm"], 1e3 * float(np.linalg.norm(e.centre - camera_centre(R, t)))
        )
    print("synthetic random-tiny:", worst, "RMS", report["rms_px"])
    assert report["rms_px"] < 0.2
    assert worst["f"] < 0.01 and worst["rotation_deg"] < 1.0 and worst["centre_mm"] < 10.0
