"""Tests of colourhs.capture: reading and validating the capture format, version 1."""

from __future__ import annotations

import json
import pickle
import re
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from colourhs.capture import (
    COLOURS,
    CaptureFormatError,
    ImageSpec,
    ReciprocalPair,
    load_rig,
    open_dataset,
    read_image,
    read_mask,
)

WIDTH, HEIGHT = 32, 24
CAMERAS = (("cam1", "blue"), ("cam2", "red"), ("cam3", "green"))
LEVELS = {16: (1024, 60000), 8: (16, 250)}
POSES = ("pose_a", "pose_b", "pose_c")


# --------------------------------------------------------------------------------------------
# Building a small valid dataset


def rot_y(degrees: float) -> np.ndarray:
    """Rotation about the y axis."""
    a = np.radians(degrees)
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rig_dict(bit_depth: int = 16) -> dict[str, Any]:
    """A valid rig.json document: cam1 at the world origin's -z side, cam2/cam3 turned by ±20°."""
    black, white = LEVELS[bit_depth]
    angles = (0.0, 20.0, -20.0)
    cameras = []
    for (name, colour), angle in zip(CAMERAS, angles, strict=True):
        cameras.append(
            {
                "name": name,
                "K": [[40.0, 0.0, 15.5], [0.0, 40.0, 11.5], [0.0, 0.0, 1.0]],
                "dist": [0.0, 0.0, 0.0, 0.0, 0.0],
                "R": rot_y(angle).tolist(),
                "t": [0.0 if angle == 0 else 0.01, 0.0, 0.8],
                "light": {"colour": colour, "offset": [0.0, 0.0, 0.0]},
            }
        )
    cameras[2]["light"]["offset"] = [0.05, -0.02, 0.0]
    return {
        "format": "colourhs-capture/1",
        "units": "m",
        "image": {
            "width": WIDTH,
            "height": HEIGHT,
            "bit_depth": bit_depth,
            "black_level": black,
            "white_level": white,
        },
        "cameras": cameras,
        "board": {
            "dictionary": "DICT_4X4_50",
            "marker_length": 0.04,
            "size": [0.30, 0.22],
            "markers": {"0": [0.03, 0.03], "1": [0.27, 0.03], "2": [0.27, 0.19], "3": [0.03, 0.19]},
        },
        "chromatic_light": {"position": [0.0, -0.3, -0.6]},
    }


def write_png(path: Path, rgb: np.ndarray) -> None:
    """Write an RGB(A) or single-channel image as PNG (cv2 wants B, G, R order)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    if rgb.ndim == 3 and rgb.shape[2] == 3:
        pixels = rgb[..., ::-1]
    elif rgb.ndim == 3 and rgb.shape[2] == 4:
        pixels = rgb[..., [2, 1, 0, 3]]
    else:
        pixels = rgb
    assert cv2.imwrite(str(path), np.ascontiguousarray(pixels))


def test_image(bit_depth: int = 16, seed: int = 0) -> np.ndarray:
    """Random raw RGB values between the black and white levels."""
    black, white = LEVELS[bit_depth]
    dtype = np.uint16 if bit_depth == 16 else np.uint8
    rng = np.random.default_rng(seed)
    return rng.integers(black, white, size=(HEIGHT, WIDTH, 3)).astype(dtype)


test_image.__test__ = False  # a helper, not a test


def write_camera_images(folder: Path, bit_depth: int) -> None:
    for i, (name, _) in enumerate(CAMERAS):
        write_png(folder / f"{name}.png", test_image(bit_depth, seed=i))


def write_json(path: Path, data: Any) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, indent=1))


def make_dataset(root: Path, bit_depth: int = 16) -> Path:
    """Write a small valid dataset: 3 poses, chromatic white + slinky, scenes toy and wave."""
    write_json(root / "rig.json", rig_dict(bit_depth))
    for pose in POSES:
        write_camera_images(root / "photometric" / pose, bit_depth)
    for obj in ("white", "slinky"):
        for colour in COLOURS:
            write_camera_images(root / "chromatic" / obj / colour, bit_depth)
    toy = root / "scenes" / "toy"
    write_json(toy / "scene.json", {"chromatic": "slinky", "dynamic": False, "description": "toy"})
    write_camera_images(toy / "frames" / "000000", bit_depth)
    mask = np.zeros((HEIGHT, WIDTH), np.uint8)
    mask[5:15, 8:20] = 255
    for name, _ in CAMERAS:
        write_png(toy / "masks" / "000000" / f"{name}.png", mask)
    (toy / "gt").mkdir()
    (toy / "gt" / "000000.ply").write_text(
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
        "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"
    )
    wave = root / "scenes" / "wave"
    write_json(wave / "scene.json", {"dynamic": True})
    for frame in ("000000", "000001"):
        write_camera_images(wave / "frames" / frame, bit_depth)
    (root / "notes.txt").write_text("extra files are ignored\n")
    return root


@pytest.fixture(scope="module")
def template(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return make_dataset(tmp_path_factory.mktemp("template") / "dataset")


@pytest.fixture
def root(template: Path, tmp_path: Path) -> Path:
    """A fresh copy of the valid dataset, free to mutate."""
    return Path(shutil.copytree(template, tmp_path / "dataset"))


def edit_json(path: Path, change: Callable[[Any], Any]) -> None:
    """Apply ``change`` to a JSON document in place (its return value, if any, replaces it)."""
    data = json.loads(path.read_text())
    result = change(data)
    write_json(path, data if result is None else result)


def raises(path: Path, phrase: str) -> Any:
    """Expect a CaptureFormatError whose message is ``<path>: ...phrase...``."""
    return pytest.raises(
        CaptureFormatError, match=re.escape(f"{path}: ") + ".*" + re.escape(phrase)
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
    """A stage opens the scenes it uses (issue 12: its rule declares what it reads):
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
# Reading images and masks


def test_read_image_values(tmp_path: Path) -> None:
    spec = ImageSpec(WIDTH, HEIGHT, 16, black_level=1024, white_level=60000)
    raw = np.full((HEIGHT, WIDTH, 3), 1024, np.uint16)
    raw[0, 0] = (1024, 30512, 60000)  # R at black, G mid scale, B at white (saturated)
    raw[0, 1] = (0, 65535, 2048)  # below black (clipped to 0), above white (1, saturated)
    raw[0, 2] = (59999, 1024, 1024)  # just below white: not saturated
    write_png(tmp_path / "cam1.png", raw)
    image, saturated = read_image(tmp_path / "cam1.png", spec)
    assert image.shape == (HEIGHT, WIDTH, 3) and image.dtype == np.float32
    assert saturated.shape == (HEIGHT, WIDTH) and saturated.dtype == bool
    np.testing.assert_allclose(image[0, 0], [0.0, 0.5, 1.0])
    np.testing.assert_allclose(image[0, 1], [0.0, 1.0, 1024 / 58976], rtol=1e-6)
    np.testing.assert_allclose(image[0, 2], [58975 / 58976, 0.0, 0.0], rtol=1e-6)
    assert saturated[0, 0] and saturated[0, 1] and not saturated[0, 2]
    assert saturated.sum() == 2
    assert np.all(image[1:] == 0.0)


def test_read_mask_one_and_three_channels(tmp_path: Path) -> None:
    spec = ImageSpec(WIDTH, HEIGHT, 16, 0, 65535)
    grey = np.zeros((HEIGHT, WIDTH), np.uint8)
    grey[2:5, 3:9] = 255
    colour = np.zeros((HEIGHT, WIDTH, 3), np.uint8)
    colour[2:5, 3:9, 1] = 1  # non-zero in one channel only
    write_png(tmp_path / "grey.png", grey)
    write_png(tmp_path / "colour.png", colour)
    for name in ("grey.png", "colour.png"):
        mask = read_mask(tmp_path / name, spec)
        assert mask.dtype == bool and mask.shape == (HEIGHT, WIDTH)
        np.testing.assert_array_equal(mask, grey != 0)


SPEC16 = ImageSpec(WIDTH, HEIGHT, 16, 0, 65535)


@pytest.mark.parametrize(
    ("content", "phrase"),
    [
        (None, "image file not found"),
        (b"not a png at all", "unreadable PNG"),
        (np.zeros((HEIGHT, WIDTH), np.uint16), "1 channel(s) (greyscale PNG), expected 3"),
        (np.zeros((HEIGHT, WIDTH, 4), np.uint16), "4 channel(s) (RGBA PNG), expected 3"),
        (np.zeros((HEIGHT, WIDTH, 3), np.uint8), "wrong bit depth: 8-bit PNG, expected 16-bit"),
        (np.zeros((HEIGHT, 31, 3), np.uint16), "found 31x24, expected 32x24"),
    ],
    ids=["missing", "not-png", "grey", "rgba", "bit-depth", "size"],
)
def test_read_image_refuses(tmp_path: Path, content: Any, phrase: str) -> None:
    path = tmp_path / "cam1.png"
    if isinstance(content, bytes):
        path.write_bytes(content)
    elif content is not None:
        write_png(path, content)
    with raises(path, phrase):
        read_image(path, SPEC16)


def test_read_image_refuses_truncated_png(tmp_path: Path) -> None:
    path = tmp_path / "cam1.png"
    write_png(path, test_image())
    path.write_bytes(path.read_bytes()[:60])  # header intact, pixel data cut
    with raises(path, "unreadable PNG"):
        read_image(path, SPEC16)


@pytest.mark.parametrize(
    ("content", "phrase"),
    [
        (None, "mask file not found"),
        (np.zeros((HEIGHT, WIDTH), np.uint16), "wrong bit depth: 16-bit PNG, expected 8-bit"),
        (np.zeros((HEIGHT, WIDTH, 4), np.uint8), "4 channel(s) (RGBA PNG), expected 1 or 3"),
        (np.zeros((10, WIDTH), np.uint8), "found 32x10, expected 32x24"),
    ],
    ids=["missing", "bit-depth", "rgba", "size"],
)
def test_read_mask_refuses(tmp_path: Path, content: Any, phrase: str) -> None:
    path = tmp_path / "mask.png"
    if content is not None:
        write_png(path, content)
    with raises(path, phrase):
        read_mask(path, SPEC16)


# --------------------------------------------------------------------------------------------
# CaptureFormatError


def test_error_message_and_attributes(tmp_path: Path) -> None:
    err = CaptureFormatError(tmp_path / "rig.json", "something is wrong")
    assert str(err) == f"{tmp_path / 'rig.json'}: something is wrong"
    assert err.path == tmp_path / "rig.json" and err.problem == "something is wrong"
    assert isinstance(err, ValueError)
    copy = pickle.loads(pickle.dumps(err))
    assert str(copy) == str(err) and copy.path == err.path


# --------------------------------------------------------------------------------------------
# rig.json violations


def delete(*keys: str | int) -> Callable[[Any], None]:
    """A change that removes ``doc[k0][k1]...[kn]``."""

    def change(doc: Any) -> None:
        for key in keys[:-1]:
            doc = doc[key]
        del doc[keys[-1]]

    return change


def assign(*keys: str | int, value: Any) -> Callable[[Any], None]:
    """A change that sets ``doc[k0][k1]...[kn] = value``."""

    def change(doc: Any) -> None:
        for key in keys[:-1]:
            doc = doc[key]
        doc[keys[-1]] = value

    return change


NOT_ROTATION = (rot_y(20.0) * 1.01).tolist()
REFLECTION = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]]

RIG_CASES = {
    "format-missing": (delete("format"), "missing required key format"),
    "format-wrong": (
        assign("format", value="colourhs-capture/2"),
        "format is 'colourhs-capture/2'",
    ),
    "units-mm": (assign("units", value="mm"), "units is 'mm', expected 'm'"),
    "top-level-list": (lambda doc: [doc], "the top level must be a JSON object"),
    "no-K": (delete("cameras", 1, "K"), "missing required key cameras[1].K"),
    "no-name": (delete("cameras", 0, "name"), "missing required key cameras[0].name"),
    "no-R": (delete("cameras", 2, "R"), "missing required key cameras[2].R"),
    "no-t": (delete("cameras", 2, "t"), "missing required key cameras[2].t"),
    "no-light": (delete("cameras", 0, "light"), "missing required key cameras[0].light"),
    "no-colour": (
        delete("cameras", 0, "light", "colour"),
        "missing required key cameras[0].light.colour",
    ),
    "no-image": (delete("image"), "missing required key image"),
    "no-width": (delete("image", "width"), "missing required key image.width"),
    "no-white": (delete("image", "white_level"), "missing required key image.white_level"),
    "no-cameras": (delete("cameras"), "missing required key cameras"),
    "no-board": (delete("board"), "missing required key board"),
    "no-markers": (delete("board", "markers"), "missing required key board.markers"),
    "no-dictionary": (delete("board", "dictionary"), "missing required key board.dictionary"),
    "cameras-not-list": (assign("cameras", value={}), "cameras must be a list"),
    "camera-not-object": (assign("cameras", 1, value="cam2"), "cameras[1] must be a JSON object"),
    "K-2x2": (
        assign("cameras", 1, "K", value=[[40.0, 0.0], [0.0, 40.0]]),
        "cameras[1].K must be a 3x3 array of numbers",
    ),
    "K-ragged": (
        assign("cameras", 1, "K", value=[[40.0, 0.0, 1.0], [0.0, 40.0], [0.0, 0.0, 1.0]]),
        "cameras[1].K must be a 3x3 array of numbers",
    ),
    "K-strings": (
        assign("cameras", 1, "K", value=[["40", 0, 1], [0, 40, 1], [0, 0, 1]]),
        "cameras[1].K must be a 3x3 array of numbers",
    ),
    "K-lower": (
        assign("cameras", 1, "K", 2, 0, value=0.5),
        "cameras[1].K[2][0] must be 0, as K is upper triangular (to 1e-12), got 0.5",
    ),
    "K-22": (
        assign("cameras", 1, "K", 2, 2, value=2.0),
        "cameras[1].K[2][2] must be 1 (to 1e-12), got 2.0",
    ),
    "K-fx": (
        assign("cameras", 0, "K", 0, 0, value=-40.0),
        "cameras[0].K[0][0] must be fx > 0 (pixels), got -40.0",
    ),
    "K-fy": (assign("cameras", 0, "K", 1, 1, value=0.0), "cameras[0].K[1][1] must be fy > 0"),
    "dist-3": (
        assign("cameras", 0, "dist", value=[0.1, 0.2, 0.3]),
        "cameras[0].dist must be a list of 0, 4, 5, 8, 12 or 14 numbers",
    ),
    "dist-6": (assign("cameras", 0, "dist", value=[0.0] * 6), "got a list of 6: [0.0, 0.0"),
    "dist-not-list": (assign("cameras", 0, "dist", value=0.0), "cameras[0].dist must be a list"),
    "dist-tilted": (
        assign("cameras", 0, "dist", value=[0.0] * 12 + [0.01, 0.0]),
        "cameras[0].dist[12] must be 0: the tilted-sensor model (tau_x, tau_y) is not supported",
    ),
    "R-scaled": (assign("cameras", 2, "R", value=NOT_ROTATION), "cameras[2].R is not a rotation"),
    "R-reflection": (assign("cameras", 2, "R", value=REFLECTION), "det(R) = -1, expected +1"),
    "R-2x3": (
        assign("cameras", 2, "R", value=[[1, 0, 0], [0, 1, 0]]),
        "cameras[2].R must be a 3x3",
    ),
    "t-short": (assign("cameras", 0, "t", value=[0.0, 0.8]), "cameras[0].t must be a list of 3"),
    "t-bool": (assign("cameras", 0, "t", value=[0.0, True, 0.8]), "cameras[0].t must be a list"),
    "t-nan": (assign("cameras", 0, "t", value=[0.0, float("nan"), 0.8]), "cameras[0].t must be"),
    "offset-short": (
        assign("cameras", 0, "light", "offset", value=[0.0]),
        "cameras[0].light.offset must be a list of 3 numbers",
    ),
    "name-twice": (
        assign("cameras", 2, "name", value="cam1"),
        "camera name 'cam1' appears twice (cameras[0] and cameras[2])",
    ),
    "name-space": (
        assign("cameras", 1, "name", value="cam 2"),
        "cameras[1].name must be a string of letters, digits, '_' and '-' (the image file stem), "
        'got "cam 2"',
    ),
    "name-slash": (assign("cameras", 1, "name", value="../cam2"), 'got "../cam2"'),
    "name-empty": (assign("cameras", 1, "name", value=""), 'stem), got ""'),
    "name-newline": (assign("cameras", 1, "name", value="cam2\n"), 'got "cam2\\n"'),
    "name-number": (assign("cameras", 1, "name", value=2), "cameras[1].name must be a string"),
    "colour-twice": (
        assign("cameras", 2, "light", "colour", value="blue"),
        "two lights of one colour: cameras[0] (cam1) and cameras[2] (cam3) both have a blue",
    ),
    "colour-yellow": (
        assign("cameras", 1, "light", "colour", value="yellow"),
        "cameras[1].light.colour is 'yellow', expected 'red', 'green' or 'blue'",
    ),
    "colour-case": (
        assign("cameras", 1, "light", "colour", value="Red"),
        "colour is 'Red', expected 'red'",
    ),
    "two-cameras": (
        delete("cameras", 2),
        "cameras must be a list of exactly 3 cameras (one per light colour: red, green, blue), "
        "got a list of 2",
    ),
    "four-cameras": (
        lambda doc: doc["cameras"].append(dict(doc["cameras"][0], name="cam4")),
        "exactly 3 cameras (one per light colour: red, green, blue), got a list of 4",
    ),
    "bit-depth-12": (assign("image", "bit_depth", value=12), "image.bit_depth is 12, expected 8"),
    "bit-depth-str": (assign("image", "bit_depth", value="16"), "bit_depth must be an integer"),
    "width-zero": (assign("image", "width", value=0), "image.width must be an integer > 0"),
    "width-float": (assign("image", "width", value=32.5), "image.width must be an integer"),
    "white-equals-black": (
        assign("image", "white_level", value=1024),
        "white_level 1024 must be greater than black_level 1024",
    ),
    "white-below-black": (
        assign("image", "white_level", value=100),
        "must be greater than black_level",
    ),
    "white-out-of-range": (
        assign("image", "white_level", value=65536),
        "image.white_level must be at most 65535 (16-bit), got 65536",
    ),
    "white-out-of-range-8": (
        lambda doc: doc["image"].update(bit_depth=8, black_level=0, white_level=1000),
        "image.white_level must be at most 255 (8-bit), got 1000",
    ),
    "black-negative": (
        assign("image", "black_level", value=-1),
        "image.black_level must be a number >= 0 (raw value), got -1",
    ),
    "dictionary-unknown": (
        assign("board", "dictionary", value="DICT_9X9_50"),
        "board.dictionary 'DICT_9X9_50' is not a known OpenCV ArUco dictionary",
    ),
    "dictionary-not-dict": (
        assign("board", "dictionary", value="getPredefinedDictionary"),
        "board.dictionary must be the name of an OpenCV predefined ArUco dictionary (DICT_...)",
    ),
    "marker-id-letter": (
        assign("board", "markers", "a", value=[0.15, 0.1]),
        "board.markers key 'a' must be a marker id (decimal digits)",
    ),
    "marker-id-float": (
        assign("board", "markers", "1.5", value=[0.15, 0.1]),
        "key '1.5' must be a marker id",
    ),
    "marker-id-negative": (
        assign("board", "markers", "-4", value=[0.15, 0.1]),
        "key '-4' must be a marker id",
    ),
    "marker-id-newline": (
        assign("board", "markers", "4\n", value=[0.15, 0.1]),
        "key '4\\n' must be a marker id",
    ),
    "marker-id-twice": (
        assign("board", "markers", "01", value=[0.15, 0.1]),
        "marker id 1 appears twice",
    ),
    "marker-id-range": (
        assign("board", "markers", "50", value=[0.15, 0.1]),
        "id 50 is not in DICT_4X4_50 (50 markers)",
    ),
    "marker-outside-left": (
        assign("board", "markers", "0", value=[0.01, 0.03]),
        "marker 0 (centre [0.01, 0.03], side 0.04 m) lies outside the board",
    ),
    "marker-outside-bottom": (
        assign("board", "markers", "2", value=[0.27, 0.21]),
        "marker 2 (centre [0.27, 0.21], side 0.04 m) lies outside the board",
    ),
    "marker-centre-3": (
        assign("board", "markers", "2", value=[0.27, 0.19, 0.0]),
        "board.markers.2 must be a list of 2 numbers",
    ),
    "markers-empty": (
        assign("board", "markers", value={}),
        "board.markers must be a JSON object of at least one marker id -> centre [x, y] (m)",
    ),
    "marker-length-zero": (
        assign("board", "marker_length", value=0),
        "board.marker_length must be a number > 0 (m): every marker's side, got 0",
    ),
    "board-size-1": (assign("board", "size", value=[0.3]), "board.size must be a list of 2"),
    "no-chromatic-light": (delete("chromatic_light"), "missing required key chromatic_light"),
    "no-chromatic-position": (
        delete("chromatic_light", "position"),
        "missing required key chromatic_light.position",
    ),
    "chromatic-light-2": (
        assign("chromatic_light", "position", value=[0.0, -0.3]),
        "chromatic_light.position must be a list of 3 numbers",
    ),
    "chromatic-light-text": (
        assign("chromatic_light", value="above"),
        "chromatic_light must be a JSON object",
    ),
}


@pytest.mark.parametrize(("change", "phrase"), RIG_CASES.values(), ids=RIG_CASES.keys())
def test_rig_violation(root: Path, change: Callable[[Any], Any], phrase: str) -> None:
    edit_json(root / "rig.json", change)
    with raises(root / "rig.json", phrase):
        load_rig(root / "rig.json")
    with raises(root / "rig.json", phrase):
        open_dataset(root)


def test_missing_rig_json(root: Path) -> None:
    (root / "rig.json").unlink()
    with raises(root / "rig.json", "rig.json not found"):
        open_dataset(root)
    with raises(root / "rig.json", "rig.json not found"):
        load_rig(root)


@pytest.mark.parametrize(
    ("text", "phrase"),
    [
        ('{"format": "colourhs-capture/1",', "not valid JSON"),
        ("", "not valid JSON"),
        ('{"format": "colourhs-capture/1", "format": "colourhs-capture/1"}', "duplicate key"),
    ],
    ids=["truncated", "empty", "duplicate-key"],
)
def test_rig_json_not_valid_json(root: Path, text: str, phrase: str) -> None:
    (root / "rig.json").write_text(text)
    with raises(root / "rig.json", phrase):
        load_rig(root)


def test_missing_dataset_folder(tmp_path: Path) -> None:
    with raises(tmp_path / "nowhere", "dataset folder not found"):
        open_dataset(tmp_path / "nowhere")


# --------------------------------------------------------------------------------------------
# Layout violations


def remove(rel: str) -> Callable[[Path], None]:
    def change(root: Path) -> None:
        path = root / rel
        shutil.rmtree(path) if path.is_dir() else path.unlink()

    return change


def rename(rel: str, new_name: str) -> Callable[[Path], None]:
    return lambda root: (root / rel).rename((root / rel).with_name(new_name))


def make_dir(rel: str) -> Callable[[Path], None]:
    return lambda root: (root / rel).mkdir(parents=True)


def write_scene_json(rel: str, text: str) -> Callable[[Path], None]:
    return lambda root: (root / rel).write_text(text)


def edit_scene(rel: str, change: Callable[[Any], Any]) -> Callable[[Path], None]:
    return lambda root: edit_json(root / rel, change)


def copy_frame(scene: str, source: str, target: str) -> Callable[[Path], None]:
    frames = f"scenes/{scene}/frames"
    return lambda root: shutil.copytree(root / frames / source, root / frames / target)


def remove_all(*rels: str) -> Callable[[Path], None]:
    def change(root: Path) -> None:
        for rel in rels:
            remove(rel)(root)

    return change


TOY_JSON = "scenes/toy/scene.json"

# id: (change, offending path relative to the dataset, phrase of the problem)
LAYOUT_CASES = {
    "no-photometric": (remove("photometric"), "photometric", "missing photometric/ folder"),
    "two-poses": (
        remove("photometric/pose_c"),
        "photometric",
        "found 2 poses, at least 3 are required",
    ),
    "pose-missing-camera": (
        remove("photometric/pose_b/cam2.png"),
        "photometric/pose_b/cam2.png",
        "missing image of camera 'cam2' (photometric pose pose_b)",
    ),
    "pose-name": (
        rename("photometric/pose_a", "pose a"),
        "photometric/pose a",
        "pose name 'pose a' has characters other than letters, digits",
    ),
    "white-missing-colour": (
        remove("chromatic/white/green"),
        "chromatic/white/green",
        "missing folder (chromatic white under green light)",
    ),
    "white-missing-camera": (
        remove("chromatic/white/red/cam3.png"),
        "chromatic/white/red/cam3.png",
        "missing image of camera 'cam3' (chromatic white under red light)",
    ),
    "no-white": (
        remove("chromatic/white"),
        "chromatic/white",
        "missing white reference folder",
    ),
    "object-missing-colour": (
        remove("chromatic/slinky/blue"),
        "chromatic/slinky/blue",
        "missing folder (chromatic slinky under blue light)",
    ),
    "object-missing-camera": (
        remove("chromatic/slinky/green/cam1.png"),
        "chromatic/slinky/green/cam1.png",
        "missing image of camera 'cam1'",
    ),
    "object-name": (
        rename("chromatic/slinky", "sl!nky"),
        "chromatic/sl!nky",
        "chromatic object name 'sl!nky' has characters",
    ),
    "no-chromatic-but-referenced": (
        remove("chromatic"),
        TOY_JSON,
        "chromatic object 'slinky' has no folder chromatic/slinky",
    ),
    "scene-json-unknown-object": (
        edit_scene(TOY_JSON, assign("chromatic", value="teapot")),
        TOY_JSON,
        "chromatic object 'teapot' has no folder chromatic/teapot",
    ),
    "scene-json-path-object": (
        edit_scene(TOY_JSON, assign("chromatic", value="../photometric")),
        TOY_JSON,
        "chromatic object '../photometric' has no folder",
    ),
    "scene-json-invalid": (
        write_scene_json(TOY_JSON, "{chromatic: slinky}"),
        TOY_JSON,
        "not valid JSON",
    ),
    "scene-json-list": (
        write_scene_json(TOY_JSON, "[]"),
        TOY_JSON,
        "scene.json must be a JSON object",
    ),
    "scene-json-dynamic-string": (
        edit_scene(TOY_JSON, assign("dynamic", value="no")),
        TOY_JSON,
        'dynamic must be true or false, got "no"',
    ),
    "scene-json-chromatic-number": (
        edit_scene(TOY_JSON, assign("chromatic", value=3)),
        TOY_JSON,
        "chromatic must be a string",
    ),
    "scene-json-description-number": (
        edit_scene(TOY_JSON, assign("description", value=5)),
        TOY_JSON,
        "description must be a string",
    ),
    "static-scene-two-frames": (
        copy_frame("toy", "000000", "000001"),
        TOY_JSON,
        "static scene (dynamic: false) must have the single frame 000000",
    ),
    "frame-name-short": (
        rename("scenes/wave/frames/000001", "1"),
        "scenes/wave/frames/1",
        "frame folder name '1' is not a 6-digit index",
    ),
    "frame-name-word": (
        rename("scenes/wave/frames/000001", "frame01"),
        "scenes/wave/frames/frame01",
        "is not a 6-digit index",
    ),
    "frame-name-long": (
        rename("scenes/wave/frames/000001", "0000001"),
        "scenes/wave/frames/0000001",
        "is not a 6-digit index",
    ),
    "frame-missing-camera": (
        remove("scenes/wave/frames/000001/cam3.png"),
        "scenes/wave/frames/000001/cam3.png",
        "missing image of camera 'cam3' (scene wave frame 000001)",
    ),
    "scene-no-frames": (
        remove_all("scenes/wave/frames/000000", "scenes/wave/frames/000001"),
        "scenes/wave/frames",
        "scene 'wave' has no frames",
    ),
    "scene-no-frames-folder": (
        remove("scenes/wave/frames"),
        "scenes/wave/frames",
        "scene 'wave' has no frames",
    ),
    "scene-name": (
        rename("scenes/wave", "wave.v2"),
        "scenes/wave.v2",
        "scene name 'wave.v2' has characters",
    ),
    "mask-missing-camera": (
        remove("scenes/toy/masks/000000/cam2.png"),
        "scenes/toy/masks/000000/cam2.png",
        "missing image of camera 'cam2' (mask of scene toy)",
    ),
    "mask-folder-missing-frame": (
        make_dir("scenes/wave/masks"),
        "scenes/wave/masks/000000",
        "missing folder (mask of scene wave)",
    ),
    "gt-missing-mesh": (
        make_dir("scenes/wave/gt"),
        "scenes/wave/gt/000000.ply",
        "missing ground-truth mesh of frame 000000",
    ),
}


@pytest.mark.parametrize(
    ("change", "rel", "phrase"), LAYOUT_CASES.values(), ids=LAYOUT_CASES.keys()
)
def test_layout_violation(root: Path, change: Callable[[Path], Any], rel: str, phrase: str) -> None:
    change(root)
    with raises(root / rel, phrase) as info:
        open_dataset(root, check_images=False)
    assert info.value.path == root / rel


# --------------------------------------------------------------------------------------------
# Image violations found by open_dataset


def overwrite(rel: str, content: np.ndarray | bytes) -> Callable[[Path], None]:
    def change(root: Path) -> None:
        if isinstance(content, bytes):
            (root / rel).write_bytes(content)
        else:
            write_png(root / rel, content)

    return change


RGB16 = np.zeros((HEIGHT, WIDTH, 3), np.uint16)

IMAGE_CASES = {
    "size": (
        "photometric/pose_b/cam1.png",
        np.zeros((HEIGHT, 16, 3), np.uint16),
        "wrong image size: found 16x24, expected 32x24 (width x height)",
    ),
    "size-chromatic": (
        "chromatic/slinky/red/cam2.png",
        np.zeros((HEIGHT + 1, WIDTH, 3), np.uint16),
        "found 32x25, expected 32x24",
    ),
    "bit-depth": (
        "scenes/wave/frames/000001/cam2.png",
        RGB16.astype(np.uint8),
        "wrong bit depth: 8-bit PNG, expected 16-bit",
    ),
    "not-png": ("photometric/pose_a/cam3.png", b"\xff\xd8\xff\xe0 JFIF", "unreadable PNG"),
    "empty-file": ("chromatic/white/blue/cam1.png", b"", "unreadable PNG"),
    "grey": (
        "scenes/toy/frames/000000/cam1.png",
        RGB16[..., 0],
        "wrong channels: 1 channel(s) (greyscale PNG), expected 3",
    ),
    "rgba": (
        "photometric/pose_c/cam2.png",
        np.zeros((HEIGHT, WIDTH, 4), np.uint16),
        "4 channel(s) (RGBA PNG), expected 3",
    ),
    "mask-16-bit": (
        "scenes/toy/masks/000000/cam1.png",
        RGB16[..., 0],
        "wrong bit depth: 16-bit PNG, expected 8-bit",
    ),
    "mask-size": (
        "scenes/toy/masks/000000/cam3.png",
        np.zeros((HEIGHT, WIDTH + 2), np.uint8),
        "found 34x24, expected 32x24",
    ),
    "mask-not-png": ("scenes/toy/masks/000000/cam3.png", b"mask", "unreadable PNG"),
}


@pytest.mark.parametrize(("rel", "content", "phrase"), IMAGE_CASES.values(), ids=IMAGE_CASES.keys())
def test_image_violation(root: Path, rel: str, content: Any, phrase: str) -> None:
    overwrite(rel, content)(root)
    open_dataset(root, check_images=False)  # the layout itself is fine
    with raises(root / rel, phrase) as info:
        open_dataset(root)
    assert info.value.path == root / rel


def test_corrupt_png_header_is_unreadable(root: Path) -> None:
    path = root / "photometric" / "pose_a" / "cam1.png"
    data = bytearray(path.read_bytes())
    data[17] ^= 0xFF  # flip a byte of the IHDR width: its CRC no longer matches
    path.write_bytes(bytes(data))
    with raises(path, "unreadable PNG: corrupt IHDR chunk"):
        open_dataset(root)
