"""Tests of colourhs.capture: the optional ChArUco target (rig.json's ``geometric_board``)
and its captures (``geometric/<pose>/<camera>.<ext>``), and the target's geometry
(colourhs.capture.targets) against OpenCV's board."""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from capture_helpers import (
    CAMERAS,
    assign,
    delete,
    edit_json,
    make_dataset,
    raises,
    write_camera_images,
)
from rig_examples import DOCS, contract_example

from colourhs.capture import (
    CaptureFormatProblems,
    UnknownNameError,
    load_rig,
    open_dataset,
    rig_from_dict,
    validate,
)
from colourhs.capture.targets import (
    charuco_black_squares,
    charuco_board,
    charuco_corners,
    charuco_layout,
    charuco_markers,
    charuco_size,
)

TARGET = {
    "type": "charuco",
    "dictionary": "DICT_4X4_50",
    "squares": [7, 5],
    "square_length": 0.03,
    "marker_length": 0.0225,
}


def with_target(root: Path, poses: tuple[str, ...] = ("g01", "g02")) -> Path:
    """The dataset at ``root`` with TARGET in rig.json and a geometric/ pose per name."""
    edit_json(root / "rig.json", assign("geometric_board", value=TARGET))
    for pose in poses:
        write_camera_images(root / "geometric" / pose, 16)
    return root


# --------------------------------------------------------------------------------------------
# rig.json's geometric_board


def test_rig_without_geometric_board_has_none(root: Path) -> None:
    """Backward compatible: a rig.json without the block (every rig before it) reads as
    before, its target None; the dataset has no geometric poses."""
    assert load_rig(root).geometric_board is None
    data = open_dataset(root)
    assert data.geometric_poses == ()
    assert validate(root)["geometric_poses"] == []


def test_geometric_board_is_the_charuco_description() -> None:
    """The block reads as charuco_layout returns it (squares as ints, lengths as
    floats), so the calibration builds OpenCV's board from it; other keys of the
    block are ignored, as everywhere in rig.json."""
    data = contract_example()
    data["geometric_board"] = {**TARGET, "squares": [7.0, 5], "square_length": 0.03, "note": "A4"}
    rig = rig_from_dict(data)
    assert rig.geometric_board == charuco_layout(7, 5, 0.03, 0.0225, "DICT_4X4_50")
    assert [type(v) for v in rig.geometric_board["squares"]] == [int, int]
    assert charuco_board(rig.geometric_board).getChessboardSize() == (7, 5)


def test_the_documented_example_is_valid() -> None:
    """docs/capture-format.md's geometric_board example is a target rig.json accepts."""
    text = DOCS.read_text(encoding="utf-8").split('"geometric_board": {"type"', 1)[1]
    block = json.loads('{"type"' + text.split("}", 1)[0] + "}")
    data = contract_example() | {"geometric_board": block}
    assert rig_from_dict(data).geometric_board == block


GEOMETRIC_BOARD_CASES = {
    "not-object": (assign("geometric_board", value="A4"), "geometric_board must be a JSON object"),
    "type": (
        assign("geometric_board", "type", value="chessboard"),
        "geometric_board.type is 'chessboard', expected 'charuco'",
    ),
    "no-squares": (
        delete("geometric_board", "squares"),
        "missing required key geometric_board.squares",
    ),
    "one-square": (
        assign("geometric_board", "squares", value=[1, 5]),
        "geometric_board.squares must be a list of 2 integers >= 2: the chessboard's squares "
        "across (x) and down (y), got a list of 2: [1, 5]",
    ),
    "squares-fraction": (
        assign("geometric_board", "squares", value=[7.5, 5]),
        "geometric_board.squares must be a list of 2 integers >= 2",
    ),
    "square-zero": (
        assign("geometric_board", "square_length", value=0),
        "geometric_board.square_length must be a number > 0 (m): a chessboard square's side, got 0",
    ),
    "marker-too-large": (
        assign("geometric_board", "marker_length", value=0.03),
        "geometric_board: marker length 30 mm must be positive and less than the square "
        "length 30 mm (the marker sits inside a white square)",
    ),
    "dictionary-unknown": (
        assign("geometric_board", "dictionary", value="DICT_9X9_1"),
        "geometric_board.dictionary 'DICT_9X9_1' is not a known OpenCV ArUco dictionary",
    ),
    "dictionary-too-small": (
        assign("geometric_board", "squares", value=[12, 10]),
        "geometric_board: a 12 x 10 ChArUco target has 60 markers; DICT_4X4_50 has only 50 ids",
    ),
}


@pytest.mark.parametrize(
    ("change", "phrase"), GEOMETRIC_BOARD_CASES.values(), ids=GEOMETRIC_BOARD_CASES.keys()
)
def test_geometric_board_violation(root: Path, change: Callable[[Any], Any], phrase: str) -> None:
    edit_json(root / "rig.json", assign("geometric_board", value=dict(TARGET)))
    edit_json(root / "rig.json", change)
    with raises(root / "rig.json", phrase):
        load_rig(root)


# --------------------------------------------------------------------------------------------
# geometric/ captures


def test_dataset_lists_geometric_poses_and_images(root: Path) -> None:
    """Poses ascending, one image per camera, PNG or TIFF per file (as photometric/);
    validate counts them and lists the poses."""
    before = validate(root)["images"]
    with_target(root, ("g02", "g01", "g03"))
    tif = root / "geometric" / "g03" / "cam2.png"
    assert cv2.imwrite(str(tif.with_suffix(".tif")), cv2.imread(str(tif), cv2.IMREAD_UNCHANGED))
    tif.unlink()
    data = open_dataset(root)
    assert data.geometric_poses == ("g01", "g02", "g03")
    assert data.rig.geometric_board == TARGET
    assert data.geometric_image("g01", "cam1") == root / "geometric/g01/cam1.png"
    assert data.geometric_image("g03", "cam2") == root / "geometric/g03/cam2.tif"
    summary = validate(root)
    assert summary["geometric_poses"] == ["g01", "g02", "g03"]
    assert summary["images"] == before + 3 * len(CAMERAS)
    assert list(summary).index("geometric_poses") == list(summary).index("poses") + 1


def test_geometric_image_refuses_unknown_names(root: Path) -> None:
    data = open_dataset(with_target(root))
    with pytest.raises(UnknownNameError, match="unknown geometric pose 'pose_a'; known: g01, g02"):
        data.geometric_image("pose_a", "cam1")
    with pytest.raises(UnknownNameError, match="no camera 'cam9'"):
        data.geometric_image("g01", "cam9")


def test_geometric_folder_without_geometric_board_names_both(root: Path) -> None:
    write_camera_images(root / "geometric" / "g01", 16)
    with raises(root / "geometric", f"but {root / 'rig.json'} has no geometric_board"):
        open_dataset(root)


def remove(rel: str) -> Callable[[Path], None]:
    def change(root: Path) -> None:
        path = root / rel
        shutil.rmtree(path) if path.is_dir() else path.unlink()

    return change


LAYOUT_CASES = {
    "missing-camera": (
        remove("geometric/g02/cam3.png"),
        "geometric/g02/cam3.png",
        "missing image of camera 'cam3' (geometric pose g02)",
    ),
    "png-and-tiff": (
        lambda root: shutil.copy(root / "geometric/g01/cam1.png", root / "geometric/g01/cam1.tif"),
        "geometric/g01/cam1.png",
        "2 images of camera 'cam1' (geometric pose g01): cam1.png and cam1.tif; keep one",
    ),
    "pose-name": (
        lambda root: (root / "geometric/g01").rename(root / "geometric/g 01"),
        "geometric/g 01",
        "geometric pose name 'g 01' has characters other than letters, digits",
    ),
    "no-poses": (
        lambda root: [remove(f"geometric/{p}")(root) for p in ("g01", "g02")],
        "geometric",
        "geometric/ holds no pose folders",
    ),
    "wrong-size": (
        lambda root: cv2.imwrite(
            str(root / "geometric/g01/cam2.png"), np.zeros((5, 5, 3), np.uint16)
        ),
        "geometric/g01/cam2.png",
        "wrong image size",
    ),
}


@pytest.mark.parametrize(
    ("change", "rel", "phrase"), LAYOUT_CASES.values(), ids=LAYOUT_CASES.keys()
)
def test_geometric_layout_violation(
    root: Path, change: Callable[[Path], Any], rel: str, phrase: str
) -> None:
    """geometric/ follows photometric/'s per-camera file rules, each problem one line."""
    change(with_target(root))
    with raises(root / rel, phrase):
        open_dataset(root)


def test_validate_names_geometric_problems_among_others(root: Path) -> None:
    with_target(root)
    remove("geometric/g02/cam3.png")(root)
    remove("photometric/pose_a/cam1.png")(root)
    with pytest.raises(CaptureFormatProblems) as info:
        validate(root)
    paths = {p.path for p in info.value.problems}
    assert paths == {root / "geometric/g02/cam3.png", root / "photometric/pose_a/cam1.png"}


def test_rig_json_with_the_target_and_no_captures_is_valid(tmp_path: Path) -> None:
    """The block describes the target; its captures are optional (a rig.json written
    before the captures, or kept after the calibration)."""
    root = make_dataset(tmp_path / "d")
    edit_json(root / "rig.json", assign("geometric_board", value=TARGET))
    assert open_dataset(root).geometric_poses == ()


# --------------------------------------------------------------------------------------------
# The target's geometry (colourhs.capture.targets) is OpenCV's


@pytest.mark.parametrize("squares", [(7, 5), (8, 6), (5, 4), (2, 3)])
def test_target_geometry_is_opencvs(squares: tuple[int, int]) -> None:
    """Markers (ids, centres), interior corners and size where OpenCV's board has them;
    the black squares are the chessboard squares without a marker."""
    layout = charuco_layout(*squares, 0.03, 0.0225, "DICT_4X4_50")
    board = charuco_board(layout)
    centres = charuco_markers(layout)
    assert list(centres) == [int(i) for i in np.ravel(board.getIds())]
    for mid, obj in zip(centres, board.getObjPoints(), strict=True):
        corners = np.asarray(obj, float).reshape(4, 3)[:, :2]
        np.testing.assert_allclose(centres[mid], corners.mean(axis=0), atol=1e-7)
    corners = np.asarray(board.getChessboardCorners(), float)
    np.testing.assert_allclose(charuco_corners(layout), corners, atol=1e-7)
    black = charuco_black_squares(layout)
    assert len(black) + len(centres) == squares[0] * squares[1]
    assert tuple(black[0]) == (0.0, 0.0, 0.03, 0.03)  # the top-left square is black
    with_marker = {tuple(np.floor(c / 0.03).astype(int)) for c in centres.values()}
    black_cells = {tuple(np.rint(b[:2] / 0.03).astype(int)) for b in black}
    assert not with_marker & black_cells
    assert charuco_size(layout) == (squares[0] * 0.03, squares[1] * 0.03)
