"""Tests of colourhs.capture: reading the capture format, version 1 (a valid dataset).

rig.json violations: test_capture_rig.py; layout violations: test_capture_layout.py;
reading images and masks: test_capture_images.py; TIFF images and the names of capture
files: test_capture_tiff.py; builders: capture_helpers.py.
"""

from __future__ import annotations

import pickle
import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from capture_helpers import (
    HEIGHT,
    POSES,
    WIDTH,
    delete,
    edit_json,
    make_dataset,
    rig_dict,
    test_image,
)

from colourhs.capture import (
    CaptureFormatError,
    ImageSpec,
    ReciprocalPair,
    load_rig,
    open_dataset,
    read_image,
)

# --------------------------------------------------------------------------------------------
# The valid dataset


def test_valid_dataset_loads(root: Path) -> None:
    data = open_dataset(root)
    rig = data.rig
    assert data.root == root
    assert rig.path == root / "rig.json"
    assert rig.camera_names == ("cam1", "cam2", "cam3")
    assert [c.light_colour for c in rig.cameras] == ["blue", "red", "green"]
    assert [c.light_channel for c in rig.cameras] == [2, 0, 1]
    assert rig.image == ImageSpec(WIDTH, HEIGHT, 16, 1024.0, 60000.0)
    assert data.poses == POSES
    assert data.chromatic_objects == ("slinky", "white")
    assert list(data.scenes) == ["toy", "wave"]
    toy, wave = data.scenes["toy"], data.scenes["wave"]
    assert toy.frames == ("000000",)
    assert (toy.chromatic, toy.dynamic, toy.description) == ("slinky", False, "toy")
    assert toy.has_masks and toy.has_gt
    assert wave.frames == ("000000", "000001")
    assert (wave.chromatic, wave.dynamic, wave.description) == (None, True, "")
    assert not wave.has_masks and not wave.has_gt
    np.testing.assert_array_equal(rig.chromatic_light, [0.0, -0.3, -0.6])


def test_camera_geometry(root: Path) -> None:
    rig = load_rig(root / "rig.json")
    doc = rig_dict()
    cam1 = rig.camera("cam1")
    np.testing.assert_allclose(cam1.centre, [0.0, 0.0, -0.8])
    for cam, entry in zip(rig.cameras, doc["cameras"], strict=True):
        R, t = np.array(entry["R"]), np.array(entry["t"])
        np.testing.assert_allclose(cam.centre, -R.T @ t)
        assert cam.K.shape == (3, 3) and cam.dist.shape == (5,)
        assert cam.K.dtype == np.float64 and cam.t.shape == (3,)
    cam3 = rig.camera("cam3")
    R, t = cam3.R, cam3.t
    np.testing.assert_allclose(cam3.light_centre, R.T @ (np.array([0.05, -0.02, 0.0]) - t))
    np.testing.assert_allclose(rig.camera("cam2").light_centre, rig.camera("cam2").centre)
    # The light centre in camera coordinates is the offset.
    np.testing.assert_allclose(R @ cam3.light_centre + t, [0.05, -0.02, 0.0], atol=1e-15)
    with pytest.raises(ValueError):
        cam1.K[0, 0] = 1.0  # arrays are read-only: the dataclass is frozen


def test_reciprocal_pairs(root: Path) -> None:
    rig = load_rig(root)
    red, green, blue = 0, 1, 2
    assert rig.reciprocal_pairs() == (
        ReciprocalPair("cam1", "cam2", channel_a=red, channel_b=blue),
        ReciprocalPair("cam1", "cam3", channel_a=green, channel_b=blue),
        ReciprocalPair("cam2", "cam3", channel_a=green, channel_b=red),
    )


def test_unknown_camera_is_a_key_error(root: Path) -> None:
    with pytest.raises(KeyError, match="no camera 'cam9'"):
        load_rig(root).camera("cam9")


def test_board(root: Path) -> None:
    board = load_rig(root).board
    assert board.dictionary == "DICT_4X4_50"
    assert board.marker_length == 0.04
    assert board.size == (0.30, 0.22)
    assert list(board.markers) == [0, 1, 2, 3]
    np.testing.assert_allclose(
        board.marker_corners(1),
        [[0.25, 0.01, 0.0], [0.29, 0.01, 0.0], [0.29, 0.05, 0.0], [0.25, 0.05, 0.0]],
    )
    with pytest.raises(KeyError):
        board.marker_corners(7)


@pytest.mark.parametrize(
    ("dist", "expected"),
    [
        (None, [0.0] * 5),
        ([], [0.0] * 5),
        ([0.1, 0.2, 0.3, 0.4], [0.1, 0.2, 0.3, 0.4, 0.0]),
        ([0.1, 0.2, 0.3, 0.4, 0.5], [0.1, 0.2, 0.3, 0.4, 0.5]),
        ([0.1] * 8, [0.1] * 8),
        ([0.1] * 12 + [0.0, 0.0], [0.1] * 12 + [0.0, 0.0]),
    ],
)
def test_distortion_padding(root: Path, dist: list[float] | None, expected: list[float]) -> None:
    def change(doc: dict) -> None:
        if dist is None:
            del doc["cameras"][0]["dist"]
        else:
            doc["cameras"][0]["dist"] = dist

    edit_json(root / "rig.json", change)
    np.testing.assert_array_equal(load_rig(root).camera("cam1").dist, expected)


def test_light_offset_defaults_to_zero(root: Path) -> None:
    edit_json(root / "rig.json", delete("cameras", 2, "light", "offset"))
    cam3 = load_rig(root).camera("cam3")
    np.testing.assert_array_equal(cam3.light_offset, [0.0, 0.0, 0.0])
    np.testing.assert_allclose(cam3.light_centre, cam3.centre)


def test_path_accessors(root: Path) -> None:
    data = open_dataset(root)
    assert data.photometric_image("pose_b", "cam2") == root / "photometric/pose_b/cam2.png"
    assert data.chromatic_image("white", "green", "cam3") == root / "chromatic/white/green/cam3.png"
    assert data.frame_image("wave", 1, "cam1") == root / "scenes/wave/frames/000001/cam1.png"
    assert data.frame_image("wave", "000001", "cam1").is_file()
    assert data.mask_image("toy", "000000", "cam2") == root / "scenes/toy/masks/000000/cam2.png"
    assert data.gt_mesh("toy", 0) == root / "scenes/toy/gt/000000.ply"
    assert data.gt_photometric is None
    (root / "gt").mkdir()
    (root / "gt" / "photometric.h5").write_bytes(b"")
    assert open_dataset(root).gt_photometric == root / "gt" / "photometric.h5"


@pytest.mark.parametrize(
    "call",
    [
        lambda d: d.photometric_image("pose_z", "cam1"),
        lambda d: d.photometric_image("pose_a", "cam9"),
        lambda d: d.chromatic_image("teapot", "red", "cam1"),
        lambda d: d.chromatic_image("white", "yellow", "cam1"),
        lambda d: d.frame_image("nope", 0, "cam1"),
        lambda d: d.frame_image("wave", 7, "cam1"),
        lambda d: d.mask_image("wave", 0, "cam1"),
        lambda d: d.gt_mesh("wave", 0),
    ],
)
def test_path_accessors_refuse_unknown_names(root: Path, call: Callable) -> None:
    with pytest.raises(KeyError):
        call(open_dataset(root, check_images=False))


def test_load_rig_accepts_folder_and_open_dataset_accepts_rig_json(root: Path) -> None:
    assert load_rig(root).path == root / "rig.json"
    assert open_dataset(root / "rig.json").root == root


def test_extra_files_and_folders_are_ignored(root: Path) -> None:
    (root / "README.md").write_text("notes")
    (root / "calibration_notes").mkdir()
    (root / "photometric" / "notes.txt").write_text("notes")
    (root / "photometric" / ".hidden").mkdir()
    (root / "photometric" / "pose_a" / "cam1_preview.jpg").write_bytes(b"jpeg")
    (root / "scenes" / "toy" / "frames" / "readme.txt").write_text("notes")
    (root / "scenes" / "notes.txt").write_text("notes")
    (root / "chromatic" / "notes.txt").write_text("notes")
    data = open_dataset(root)
    assert data.poses == POSES
    assert list(data.scenes) == ["toy", "wave"]


def test_frames_may_have_gaps(root: Path) -> None:
    wave = root / "scenes" / "wave" / "frames"
    (wave / "000001").rename(wave / "000007")
    assert open_dataset(root).scenes["wave"].frames == ("000000", "000007")


def test_scene_json_is_optional(root: Path) -> None:
    (root / "scenes" / "wave" / "scene.json").unlink()
    (root / "scenes" / "toy" / "scene.json").unlink()
    scenes = open_dataset(root).scenes
    assert scenes["wave"].dynamic  # several frames: a sequence
    assert not scenes["toy"].dynamic  # the single frame 000000: static
    assert scenes["toy"].chromatic is None and scenes["toy"].description == ""


def test_chromatic_folder_is_optional_without_references(root: Path) -> None:
    shutil.rmtree(root / "chromatic")
    (root / "scenes" / "toy" / "scene.json").unlink()
    assert open_dataset(root).chromatic_objects == ()


def test_scenes_folder_is_optional(root: Path) -> None:
    shutil.rmtree(root / "scenes")
    assert open_dataset(root).scenes == {}


def test_open_dataset_reads_only_the_named_scenes(root: Path) -> None:
    """A stage opens the scenes it uses (its rule declares what it reads):
    another scene's files are not read, a malformed one included."""
    (root / "scenes" / "toy" / "scene.json").write_text("{not json")
    (root / "scenes" / "toy" / "frames" / "000000" / "cam1.png").unlink()
    data = open_dataset(root, scenes=["wave"])
    assert list(data.scenes) == ["wave"] and data.scenes["wave"].frames == ("000000", "000001")
    assert open_dataset(root, scenes=()).scenes == {}
    with pytest.raises(KeyError, match="unknown scene 'nosuch'; known: toy, wave"):
        open_dataset(root, scenes=["nosuch"])
    with pytest.raises(CaptureFormatError, match="scene.json"):
        open_dataset(root)


def test_eight_bit_dataset(tmp_path: Path) -> None:
    root = make_dataset(tmp_path / "d8", bit_depth=8)
    data = open_dataset(root)
    assert data.rig.image == ImageSpec(WIDTH, HEIGHT, 8, 16.0, 250.0)
    image, saturated = read_image(data.photometric_image("pose_a", "cam1"), data.rig.image)
    raw = test_image(8, seed=0).astype(np.float32)
    np.testing.assert_allclose(image, (raw - 16) / (250 - 16), rtol=1e-6)
    assert image.dtype == np.float32 and not saturated.any()


# --------------------------------------------------------------------------------------------
# CaptureFormatError


def test_error_message_and_attributes(tmp_path: Path) -> None:
    err = CaptureFormatError(tmp_path / "rig.json", "something is wrong")
    assert str(err) == f"{tmp_path / 'rig.json'}: something is wrong"
    assert err.path == tmp_path / "rig.json" and err.problem == "something is wrong"
    assert isinstance(err, ValueError)
    copy = pickle.loads(pickle.dumps(err))
    assert str(copy) == str(err) and copy.path == err.path


def test_every_public_name_resolves() -> None:
    """The package loads its submodules on first use: every name of
    ``__all__`` still resolves, is listed by dir() and keeps its own module; an
    unknown name is an AttributeError."""
    import colourhs.capture as capture

    for name in capture.__all__:
        value = getattr(capture, name)
        module = getattr(value, "__module__", None)
        assert module is None or module.startswith("colourhs.capture."), (name, module)
    assert set(capture.__all__) <= set(dir(capture)) and len(capture.__all__) == 25
    with pytest.raises(AttributeError, match="no attribute 'nosuch'"):
        capture.nosuch  # noqa: B018
