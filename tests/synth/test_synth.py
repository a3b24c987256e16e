"""The synthetic rig obeys equation (4) and writes valid capture-format datasets."""

from __future__ import annotations

import argparse
import json
import shutil

import cv2
import h5py
import numpy as np
import pytest
from hs_constraint import (
    constraint_residual,
    frame_images,
    gt_points,
    pair_rows,
    true_calibration,
)

from colourhs.capture import CaptureFormatError, load_rig, open_dataset, read_image, validate
from colourhs.cli.commands import frame_indices
from colourhs.common.geometry import project
from colourhs.common.sampling import sample_bilinear
from colourhs.synth import synthesise as synth_dataset
from colourhs.synth.simulated_rig import Nuisances, sensor
from colourhs.synth.synthesise import PRESETS, RenderSelection, synthesise


def _residuals(root, scene, offset_m=0.0, rotate_deg=0.0, **kw):
    rig, images, saturated = frame_images(root, scene)
    pts, nrm = gt_points(root, scene, rig, saturated)
    mu, chroma = true_calibration(root, scene)
    args = {"mu": mu, "chromaticity": chroma} | kw
    c1 = rig.cameras[0]
    ray = pts - c1.centre
    ray /= np.linalg.norm(ray, axis=1, keepdims=True)
    if rotate_deg:
        axis = np.cross(nrm, np.random.default_rng(1).normal(size=nrm.shape))
        axis /= np.linalg.norm(axis, axis=1, keepdims=True)
        th = np.deg2rad(rotate_deg)
        nrm = nrm * np.cos(th) + np.cross(axis, nrm) * np.sin(th)
    cams = {c.name: c for c in rig.cameras}
    w = pair_rows(pts + offset_m * ray, images, cams, rig.reciprocal_pairs(), **args)
    return constraint_residual(w, nrm[:, None, :]), len(pts)


@pytest.mark.parametrize("scene", ["plane", "statue", "toy", "sheet"])
def test_hs_constraint_holds_at_ground_truth(clean_dataset, scene):
    """Eq. (5) with the true mu and p: median |w.n|/|w| < 1e-3 (noise, cross-talk off).

    Measured (640x480): plane 8e-5, statue 1.4e-4, toy 6e-4, sheet 3e-5 (a later
    audit: 2.1e-5, 1.4e-4, 5.5e-4, 3.6e-5; pixels 99075, 58845, 36940, 132275).
    """
    r, n = _residuals(clean_dataset, scene)
    assert n > 18000
    assert np.nanmedian(r) < 1e-3


@pytest.mark.parametrize("scene", ["plane", "statue", "sheet"])
def test_hs_constraint_discriminates_normals_and_depth(clean_dataset, scene):
    """A 10-degree normal error or a 5 mm depth error raises the residual.

    Measured factors (640x480), 10 degrees: plane 1700, statue 860, sheet 4700;
    5 mm along the reference camera's ray (true normal kept): plane 140,
    statue 290, sheet 900 (a later audit: 6100, 860, 3400; 410, 290, 620).
    The base is the rendering's rounding floor (plane 8e-5 before, 2e-5 now),
    so we require half the smallest factor ever measured: 400 and 70.
    """
    base = np.nanmedian(_residuals(clean_dataset, scene)[0])
    rotated = np.nanmedian(_residuals(clean_dataset, scene, rotate_deg=10.0)[0])
    moved = np.nanmedian(_residuals(clean_dataset, scene, offset_m=0.005)[0])
    assert rotated > 400 * base
    assert moved > 70 * base


def test_calibration_is_needed(clean_dataset):
    """Without mu (or without p on the toy) the constraint is clearly violated."""
    good = np.nanmedian(_residuals(clean_dataset, "statue")[0])
    no_mu = np.nanmedian(_residuals(clean_dataset, "statue", mu=None)[0])
    toy_good = np.nanmedian(_residuals(clean_dataset, "toy")[0])
    toy_white = np.nanmedian(_residuals(clean_dataset, "toy", chromaticity=None)[0])
    assert no_mu > 80 * good  # measured 161x
    assert toy_white > 500 * toy_good  # measured 1120x


def test_every_marker_detected_in_demo_board_images(plane_calibrated):
    """OpenCV's ArUco detector finds every marker of every demo board image, accurately.

    The board images are the demo preset's (conftest's ``plane_calibrated`` renders
    the demo rig's board poses with its seed).
    """
    root, _ = plane_calibrated
    rig = load_rig(root)
    board = rig.board
    poses = json.loads((root / "gt" / "board_poses.json").read_text())
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    det = cv2.aruco.ArucoDetector(
        cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, board.dictionary)), params
    )
    errors, n_images = [], []
    for pose_dir in sorted((root / "photometric").iterdir()):
        pose = poses[pose_dir.name]
        R, t = np.array(pose["R"]), np.array(pose["t"])
        for cam in rig.cameras:
            img, _ = read_image(pose_dir / f"{cam.name}.png", rig.image)
            grey = np.clip(img.mean(axis=2) * 2 * 255, 0, 255).astype(np.uint8)
            corners, ids, _ = det.detectMarkers(grey)
            assert ids is not None, f"{pose_dir.name}/{cam.name}: no marker found"
            assert sorted(ids.ravel()) == sorted(board.markers), f"{pose_dir.name}/{cam.name}"
            for c, i in zip(corners, ids.ravel(), strict=True):
                truth = project(
                    board.marker_corners(int(i)) @ R.T + t, cam.K, cam.dist, cam.R, cam.t
                )
                errors.append(c.reshape(4, 2) - truth)
            n_images.append(img)
    assert len(n_images) == 3 * PRESETS["demo"].n_poses
    err = np.concatenate(errors)
    # No global shift (a half-pixel convention error would show here): measured
    # mean (0.011, -0.006) px before, 0.0022 px in a later audit (the change
    # not traced); bound 0.025, twice the worst. ArUco's sub-pixel corners sit
    # ~0.2 px inside the true convex corner (a detector bias; the rendered edges
    # are unbiased, see test_rendered_marker_edges_are_unbiased): median 0.29 px.
    assert np.linalg.norm(err.mean(axis=0)) < 0.025
    assert np.median(np.linalg.norm(err, axis=1)) < 0.5


def test_rendered_marker_edges_are_unbiased(clean_dataset):
    """The 50 % crossing of each marker edge lies on its true projection.

    Measured on 640x480 with 2x2 supersampling: mean offset below 0.01 px
    (0.0012 px in a later audit; bound 0.0025), spread 0.1 px (0.127).
    """
    rig = load_rig(clean_dataset)
    board = rig.board
    poses = json.loads((clean_dataset / "gt" / "board_poses.json").read_text())
    R, t = np.array(poses["plane"]["R"]), np.array(poses["plane"]["t"])
    offsets = []
    ts = np.linspace(-0.003, 0.003, 121)  # metres across the edge, inside to outside
    for cam in rig.cameras:
        img, _ = read_image(clean_dataset / f"scenes/plane/frames/000000/{cam.name}.png", rig.image)
        grey = img.mean(axis=2)
        for mid in board.markers:
            corners = board.marker_corners(mid)
            for k in range(4):
                a, b = corners[k], corners[(k + 1) % 4]
                for s in (0.3, 0.5, 0.7):
                    m = a + (b - a) * s
                    out = (m - corners.mean(axis=0)) / np.linalg.norm(m - corners.mean(axis=0))
                    pts = (m + ts[:, None] * out) @ R.T + t
                    uv = project(pts, cam.K, cam.dist, cam.R, cam.t)
                    prof = sample_bilinear(grey, uv)
                    half = (np.median(prof[:20]) + np.median(prof[-20:])) / 2
                    j = int(np.argmax(prof > half))
                    tc = ts[j - 1] + (half - prof[j - 1]) / (prof[j] - prof[j - 1]) * (
                        ts[1] - ts[0]
                    )
                    offsets.append(tc * np.linalg.norm(uv[-1] - uv[0]) / (ts[-1] - ts[0]))
    offsets = np.array(offsets)
    assert abs(offsets.mean()) < 0.0025
    assert offsets.std() < 0.25


def test_tiny_dataset_is_valid_and_complete(tiny_dataset):
    ds = open_dataset(tiny_dataset)
    assert ds.rig.camera_names == ("cam1", "cam2", "cam3")
    assert [c.light_colour for c in ds.rig.cameras] == ["blue", "red", "green"]
    assert len(ds.poses) >= 7
    assert set(ds.scenes) == {"plane", "statue", "toy", "sheet"}
    assert ds.scenes["sheet"].dynamic and len(ds.scenes["sheet"].frames) == 3
    assert ds.scenes["toy"].chromatic == "toy"
    assert {"white", "toy", "statue"} <= set(ds.chromatic_objects)
    for scene in ds.scenes.values():
        assert scene.has_masks and scene.has_gt
    assert ds.gt_photometric is not None
    # Three camera centres are never collinear.
    c = np.array([cam.centre for cam in ds.rig.cameras])
    area = np.linalg.norm(np.cross(c[1] - c[0], c[2] - c[0])) / 2
    assert area > 0.05
    for cam in ds.rig.cameras:
        assert 0.75 < np.linalg.norm(cam.centre) < 0.85


def test_mu_varies_about_twenty_percent(tiny_dataset):
    """The true mu maps vary by about +-20 % across the frame."""
    with h5py.File(tiny_dataset / "gt" / "photometric.h5") as f:
        keys = [f"{c}/{k}" for c in f for k in f[c]]
        assert len(keys) == 6
        for key in keys:
            mu = f[key][()]
            rel = mu / np.median(mu)
            spread = (np.percentile(rel, 99) - np.percentile(rel, 1)) / 2
            assert 0.1 < spread < 0.35, (key, spread)


def test_crosstalk_and_exposure(tiny_dataset):
    model = json.loads((tiny_dataset / "gt" / "rig_model.json").read_text())
    for cam in model["cameras"]:
        X = np.array(cam["crosstalk"])
        off = X[~np.eye(3, dtype=bool)]
        assert np.allclose(np.diag(X), 1) and off.min() >= 0.03 and off.max() <= 0.08
    # A white board near the working distance reads 40-60 % of full scale in the
    # channels that record the other cameras' lights (median over its white area).
    rig = load_rig(tiny_dataset)
    for cam in rig.cameras:
        img, _ = read_image(tiny_dataset / "photometric" / "pose03" / f"{cam.name}.png", rig.image)
        for ch in range(3):
            if ch == cam.light_channel:
                continue
            vals = img[..., ch][img[..., ch] > 0.2]
            assert 0.3 < np.median(vals) < 0.65


def test_sensor_noise_is_about_one_percent():
    rng = np.random.default_rng(0)
    signal = np.full(200_000, 0.5)
    dn = sensor(signal, rng, Nuisances()).astype(float)
    rel = np.std(dn) / (np.mean(dn) - 0)
    assert 0.008 < rel < 0.015
    assert abs(np.mean(dn) / 65535 - 0.5) < 2e-5  # measured 8.7e-6 (seeded)
    clean = sensor(signal, rng, Nuisances.none())
    assert np.all(clean == np.rint(0.5 * 65535))
    assert sensor(np.array([1.7]), rng, Nuisances())[0] == 65535  # saturation clips


def test_saturation_is_flagged(tiny_dataset):
    rig, _, saturated = frame_images(tiny_dataset, "statue")
    assert any(s.any() for s in saturated.values())  # glossy highlights clip
    frac = np.mean([s.mean() for s in saturated.values()])
    assert frac < 0.02


def test_deterministic_for_a_seed(tmp_path):
    chromatic = RenderSelection(parts=("chromatic",))
    a = synthesise(tmp_path / "a", "tiny", selection=chromatic, workers=1)
    b = synthesise(tmp_path / "b", "tiny", selection=chromatic, workers=2)
    c = synthesise(tmp_path / "c", "tiny", seed=1, selection=chromatic)
    rel = "chromatic/toy/red/cam2.png"
    assert (a / rel).read_bytes() == (b / rel).read_bytes()
    assert (a / rel).read_bytes() != (c / rel).read_bytes()


def _files(root):
    return {str(p.relative_to(root)): p for p in sorted(root.rglob("*")) if p.is_file()}


def test_a_slice_of_the_sequence_equals_the_full_render(tiny_dataset, tmp_path):
    """Sheet frames 1-2 of 0-2 alone: every file equals the full render's (same
    seed and preset; PNG, PLY, JSON and HDF5 bytes), and only frame 000000's
    images, masks and mesh are missing. The slice, whose frames start at 000001,
    is a valid dataset."""
    frames_1_2 = RenderSelection(frames=range(1, 3))
    part = synthesise(tmp_path / "slice", "tiny", selection=frames_1_2)
    full, sliced = _files(tiny_dataset), _files(part)
    missing = {f"scenes/sheet/{k}/000000{e}" for k, e in (("frames", ""), ("masks", ""))}
    missing = {f"{m}/{c}.png" for m in missing for c in ("cam1", "cam2", "cam3")}
    assert set(full) - set(sliced) == missing | {"scenes/sheet/gt/000000.ply"}
    assert set(sliced) <= set(full)
    different = [k for k, p in sliced.items() if p.read_bytes() != full[k].read_bytes()]
    assert different == []
    assert len(sliced) == 139  # 139 of the full render's 146 files (45 geometric images)
    summary = validate(part)
    assert open_dataset(part).scenes["sheet"].frames == ("000001", "000002")
    assert summary["scenes"]["sheet"]["frames"] == 2
    with pytest.raises(ValueError, match="frames \\[3\\]: the tiny preset's sheet has frames 0-2"):
        synthesise(tmp_path / "x", "tiny", selection=RenderSelection(frames=[2, 3]))
    with pytest.raises(ValueError, match="the sheet, which is not rendered"):
        plane_only = RenderSelection(scenes=("plane",), frames=[2])
        synthesise(tmp_path / "x", "tiny", selection=plane_only)


def test_frame_indices_of_the_command_line():
    assert frame_indices("40-59") == tuple(range(40, 60))
    assert frame_indices("7,0-2") == (0, 1, 2, 7)
    for bad in ("5-a", "-3", "", "4,"):
        with pytest.raises(argparse.ArgumentTypeError, match="expected FIRST-LAST"):
            frame_indices(bad)


def test_failed_render_leaves_nothing(tmp_path, monkeypatch):
    def boom(*_a, **_k):
        raise RuntimeError("disk full")

    monkeypatch.setattr(synth_dataset, "_render_job", boom)
    with pytest.raises(RuntimeError, match="disk full"):
        synthesise(tmp_path / "x", "tiny", workers=1)
    assert list(tmp_path.iterdir()) == []


def test_refuses_to_overwrite(tmp_path):
    (tmp_path / "x").mkdir()
    with pytest.raises(FileExistsError, match="already exists"):
        synthesise(tmp_path / "x", "tiny")


def test_malformed_copies_fail_with_the_right_message(tiny_dataset, tmp_path):
    bad = tmp_path / "bad"
    shutil.copytree(tiny_dataset, bad)
    missing = bad / "scenes" / "sheet" / "frames" / "000001" / "cam2.png"
    missing.unlink()
    with pytest.raises(CaptureFormatError, match="000001.*cam2"):
        open_dataset(bad)
    shutil.copy(tiny_dataset / missing.relative_to(bad), missing)
    rig = json.loads((bad / "rig.json").read_text())
    rig["cameras"][1]["R"][0][0] = 0.5
    (bad / "rig.json").write_text(json.dumps(rig))
    with pytest.raises(CaptureFormatError, match=r"rig\.json.*rotation"):
        open_dataset(bad)
    rig["cameras"][1]["R"] = json.loads((tiny_dataset / "rig.json").read_text())["cameras"][1]["R"]
    rig["cameras"][2]["light"]["colour"] = "blue"
    (bad / "rig.json").write_text(json.dumps(rig))
    with pytest.raises(CaptureFormatError, match=r"rig\.json.*blue"):
        open_dataset(bad)


@pytest.mark.slow
def test_a_noise_free_copy_differs_from_its_dataset_by_the_noise_alone(tmp_path):
    """noise_free_chromatic: the chromatic captures of a dataset rendered without noise
    and cross-talk come out the same files when its nuisances are passed (only the
    noise goes, and it was off already), and differ when they are not (the default
    puts the cross-talk back); the other entries are the dataset's own."""
    from colourhs.synth.synthesise import noise_free_chromatic

    nuisances = Nuisances().without("noise", "crosstalk")
    selection = RenderSelection(parts=("chromatic",), scenes=("toy",))
    data = synthesise(tmp_path / "d", "tiny", nuisances=nuisances, selection=selection, workers=1)
    same = noise_free_chromatic(data, tmp_path / "a", "tiny", scenes=("toy",), nuisances=nuisances)
    other = noise_free_chromatic(data, tmp_path / "b", "tiny", scenes=("toy",))
    files = sorted((data / "chromatic" / "toy").rglob("*.png"))
    assert len(files) >= 6
    for f in files:
        rel = f.relative_to(data)
        assert (same / rel).read_bytes() == f.read_bytes()
    assert any((other / f.relative_to(data)).read_bytes() != f.read_bytes() for f in files)
    assert (same / "rig.json").resolve() == (data / "rig.json").resolve()
