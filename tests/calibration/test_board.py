"""Printable targets: layouts, true-scale rendering, prints and ``colourhs board``.

Every print is checked by reading it back as a user's tools would: the markers
detected with OpenCV's ArUco (and ChArUco) detectors in the rendered image, their
pixel positions turned into metres by the image's resolution, and compared with
the layout; the vector prints by their declared physical size.
"""

from __future__ import annotations

import json
import re
import xml.etree.ElementTree as ET
import zlib

import cv2
import numpy as np
import pytest
from PIL import Image
from rig_examples import contract_example

from colourhs.calibration.board import (
    PAGE_FOOTER_M,
    PAGE_MARGIN_M,
    board_layout,
    charuco_board,
    charuco_layout,
    check_board_block,
    json_path,
    render_board,
    write_board,
)
from colourhs.calibration.markers import detect_markers
from colourhs.capture import CaptureFormatError, rig_from_dict
from colourhs.cli.parser import main

TOLERANCE_MM = 0.1  # the bound on every recovered position and length
DPI = 200  # 0.127 mm pixels: fast, and coarse enough that sub-pixel accuracy matters


@pytest.fixture(scope="module")
def block():
    """The default board: DICT_5X5_100, 0.30 x 0.22 m, 40 mm markers, densest grid."""
    return board_layout()


def _aruco(image: np.ndarray, dictionary: str) -> dict[int, np.ndarray]:
    """OpenCV's ArUco detections (sub-pixel corners), id -> corners (4, 2), pixels."""
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    aruco = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary))
    corners, ids, _ = cv2.aruco.ArucoDetector(aruco, params).detectMarkers(image)
    assert ids is not None
    pairs = zip(corners, ids.ravel(), strict=True)
    return {int(i): np.asarray(c, float).reshape(4, 2) for c, i in pairs}


def _metres(uv: np.ndarray, dpi: float, origin_m: float = 0.0) -> np.ndarray:
    """Pixel coordinates ((0, 0) the top-left pixel's centre) to metres from ``origin_m``."""
    return (np.asarray(uv, float) + 0.5) * 0.0254 / dpi - origin_m


def _marker_errors_mm(found: dict, block: dict, dpi: float, origin_m: float = 0.0):
    """Largest centre and side errors (mm) of the detected markers against the layout."""
    centre, side = [], []
    for key, xy in block["markers"].items():
        corners = _metres(found[int(key)], dpi, origin_m)
        centre.append(np.linalg.norm(corners.mean(axis=0) - xy))
        sides = np.linalg.norm(corners - np.roll(corners, 1, axis=0), axis=1)
        side.append(np.max(np.abs(sides - block["marker_length"])))
    return 1e3 * max(centre), 1e3 * max(side)


# --------------------------------------------------------------------------------------------
# Layouts


def test_default_layout_is_the_densest_regular_grid_and_a_valid_rig_board(block):
    """0.30 x 0.22 m with 40 mm markers of 7 cells and 2-cell gaps: 5 x 4 markers, the
    outer ones one gap from the edges, no two closer than the gap; the block is rig.json's."""
    assert block["dictionary"] == "DICT_5X5_100" and block["size"] == [0.30, 0.22]
    assert list(block["markers"]) == [str(k) for k in range(20)]
    xy = np.array(list(block["markers"].values()))
    L, gap = block["marker_length"], 2 * 0.04 / 7
    assert len(np.unique(xy[:, 0])) == 5 and len(np.unique(xy[:, 1])) == 4
    assert np.allclose(xy.min(axis=0), gap + L / 2, atol=1e-6)
    assert np.allclose(xy.max(axis=0), np.array([0.30, 0.22]) - gap - L / 2, atol=1e-6)
    dx = np.abs(xy[:, None, :] - xy[None, :, :]).max(axis=-1)  # Chebyshev distances
    assert dx[~np.eye(len(xy), dtype=bool)].min() >= L + gap - 1e-6
    assert xy[1, 0] > xy[0, 0] and xy[5, 1] > xy[0, 1]  # row by row from the top left
    rig = rig_from_dict({**contract_example(), "board": json.loads(json.dumps(block))})
    assert sorted(rig.board.markers) == list(range(20))
    assert check_board_block(block).marker_length == 0.04


def test_a_given_number_of_markers_takes_the_squarest_grid():
    six = board_layout("DICT_4X4_50", (0.26, 0.20), 0.035, 6)
    xy = np.array(list(six["markers"].values()))
    assert len(np.unique(xy[:, 0])) == 3 and len(np.unique(xy[:, 1])) == 2
    five = board_layout("DICT_4X4_50", (0.26, 0.20), 0.035, 5)  # a 3 x 2 grid, one empty
    assert np.allclose(np.array(list(five["markers"].values())), xy[:5])
    one = board_layout("DICT_4X4_50", (0.1, 0.1), 0.04, 1)
    assert one["markers"] == {"0": [0.05, 0.05]}


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"dictionary": "DICT_9X9_7"}, "unknown ArUco dictionary 'DICT_9X9_7'.*DICT_4X4_50"),
        ({"n_markers": 21}, r"21 markers of 40 mm do not fit .* at most 5 x 4 = 20"),
        ({"size": (0.05, 0.2)}, "needs a board of at least 62.86 mm each way"),
        ({"dictionary": "DICT_4X4_50", "marker_length": 0.01, "n_markers": 60}, "has 50"),
        ({"marker_length": -0.01}, "marker length must be a positive"),
        ({"n_markers": 0}, "at least 1"),
    ],
)
def test_impossible_layouts_are_refused_naming_the_problem(kwargs, message):
    with pytest.raises(ValueError, match=message):
        board_layout(**kwargs)


def test_a_board_block_is_checked_by_the_rig_reader(block):
    outside = {**block, "markers": {**block["markers"], "20": [0.299, 0.1]}}
    with pytest.raises(CaptureFormatError, match="board.markers: marker 20 .* outside the board"):
        check_board_block(outside)
    with pytest.raises(CaptureFormatError, match="board.markers.*id 99 is not in DICT_4X4_50"):
        check_board_block({**block, "dictionary": "DICT_4X4_50", "markers": {"99": [0.1, 0.1]}})
    with pytest.raises(CaptureFormatError, match="'DICT_NONE' is not a known OpenCV ArUco"):
        render_board({**block, "dictionary": "DICT_NONE"})


def test_charuco_layout_is_plain_json_and_refuses_impossible_targets():
    layout = charuco_layout(7, 5, 0.04, 0.03, "DICT_5X5_100")
    assert json.loads(json.dumps(layout)) == {
        "type": "charuco",
        "dictionary": "DICT_5X5_100",
        "squares": [7, 5],
        "square_length": 0.04,
        "marker_length": 0.03,
    }
    board = charuco_board(layout)
    assert board.getChessboardSize() == (7, 5) and len(board.getIds()) == 17
    with pytest.raises(ValueError, match="less than the square length 40 mm"):
        charuco_layout(7, 5, 0.04, 0.04)
    with pytest.raises(ValueError, match="at least 2 x 2 squares"):
        charuco_layout(1, 5, 0.04, 0.03)
    with pytest.raises(ValueError, match="has 60 markers; DICT_4X4_50 has only 50"):
        charuco_layout(12, 10, 0.02, 0.015, "DICT_4X4_50")
    with pytest.raises(ValueError, match="unknown ArUco dictionary 'DICT_X'"):
        charuco_layout(7, 5, 0.04, 0.03, "DICT_X")


# --------------------------------------------------------------------------------------------
# True scale and orientation


def test_rendered_markers_are_where_the_layout_says(block):
    """Every marker found by OpenCV's detector; its centre and side, from pixels and
    the resolution, within 0.1 mm of the layout."""
    image = render_board(block, dpi=DPI)
    assert image.shape == (round(0.22 / 0.0254 * DPI), round(0.30 / 0.0254 * DPI))
    found = _aruco(image, block["dictionary"])
    assert sorted(found) == list(range(20))
    centre_mm, side_mm = _marker_errors_mm(found, block, DPI)
    assert centre_mm < TOLERANCE_MM and side_mm < TOLERANCE_MM, (centre_mm, side_mm)


def test_marker_corners_are_in_the_order_the_pose_fit_expects(block):
    """A fronto-parallel view of the print (the camera's pixel grid on the board's x
    and y): the repository's detector returns each marker's corners at the board
    positions ``Board.marker_corners`` gives, corner 0 at the top left, so the pose
    fit matches them to the right model points."""
    board = check_board_block(block)
    image = np.repeat(render_board(board, dpi=DPI)[..., None] / 255.0, 3, axis=2)
    found = detect_markers(image, board)
    assert sorted(found) == sorted(board.markers)
    worst = max(
        np.abs(_metres(found[m], DPI) - board.marker_corners(m)[:, :2]).max() for m in found
    )
    assert 1e3 * worst < TOLERANCE_MM, worst


def test_charuco_corners_recover_the_square_length():
    layout = charuco_layout(7, 5, 0.03, 0.0225, "DICT_5X5_100")
    board = charuco_board(layout)
    image = render_board(layout, dpi=DPI)  # a white margin, as on the print
    image = cv2.copyMakeBorder(image, 20, 20, 20, 20, cv2.BORDER_CONSTANT, value=255)
    corners, ids, _, _ = cv2.aruco.CharucoDetector(board).detectBoard(image)
    assert ids is not None and len(ids) == 6 * 4
    xy = _metres(corners.reshape(-1, 2) - 20, DPI)
    truth = np.asarray(board.getChessboardCorners(), float)[ids.ravel(), :2]
    assert 1e3 * np.abs(xy - truth).max() < TOLERANCE_MM
    grid = xy[np.argsort(ids.ravel())].reshape(4, 6, 2)
    square = np.mean(
        np.r_[np.diff(grid[..., 0], axis=1).ravel(), np.diff(grid[..., 1], axis=0).ravel()]
    )
    assert abs(square - 0.03) * 1e3 < TOLERANCE_MM, square


# --------------------------------------------------------------------------------------------
# Prints


def test_png_print_carries_its_resolution_and_the_board_at_true_scale(block, tmp_path):
    out, written = write_board(block, tmp_path / "board.png", dpi=150)
    assert written == tmp_path / "board.board.json" == json_path(out, block)
    with Image.open(out) as png:
        dpi = png.info["dpi"]
        image = np.asarray(png)
    assert dpi[0] == dpi[1] == pytest.approx(150, abs=0.02)  # whole pixels per metre
    page = (0.30 + 2 * PAGE_MARGIN_M, 0.22 + PAGE_MARGIN_M + PAGE_FOOTER_M)
    px_per_m = round(dpi[0] / 0.0254)  # what the pHYs chunk holds
    assert image.shape == (round(page[1] * px_per_m), round(page[0] * px_per_m))
    found = _aruco(image, block["dictionary"])
    assert sorted(found) == list(range(20))
    centre_mm, side_mm = _marker_errors_mm(found, block, dpi[0], PAGE_MARGIN_M)
    assert centre_mm < TOLERANCE_MM and side_mm < TOLERANCE_MM, (centre_mm, side_mm)
    assert json.loads(written.read_text()) == {"board": block}
    rig_from_dict({**contract_example(), **json.loads(written.read_text())})


def _rects(group) -> np.ndarray:
    keys = ("x", "y", "width", "height")
    return np.array([[float(r.get(k)) for k in keys] for r in group])


def test_svg_print_is_exact_and_of_the_page_size(block, tmp_path):
    """Width and height in mm; one rectangle per black module of each marker, each
    marker's modules filling exactly its square (its border is black)."""
    out, _ = write_board(block, tmp_path / "board.svg")
    root = ET.parse(out).getroot()
    ns = {"s": "http://www.w3.org/2000/svg"}
    page_mm = 1e3 * np.array([0.30 + 2 * PAGE_MARGIN_M, 0.22 + PAGE_MARGIN_M + PAGE_FOOTER_M])
    size = [root.get(k) for k in ("width", "height")]
    assert all(v.endswith("mm") for v in size)
    assert np.allclose([float(v[:-2]) for v in size], page_mm, rtol=0, atol=1e-6)
    rects = _rects(root.find("s:g[@id='board']", ns)) - [*[1e3 * PAGE_MARGIN_M] * 2, 0, 0]
    centres = rects[:, :2] + rects[:, 2:] / 2
    L = 1e3 * block["marker_length"]
    aruco = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_5X5_100)
    for key, xy in block["markers"].items():
        xy = 1e3 * np.array(xy)
        mine = rects[np.all(np.abs(centres - xy) < L / 2, axis=1)]
        black = np.count_nonzero(cv2.aruco.generateImageMarker(aruco, int(key), 7) < 128)
        assert len(mine) == black
        assert np.allclose(mine[:, :2].min(axis=0), xy - L / 2, atol=1e-5)
        assert np.allclose((mine[:, :2] + mine[:, 2:]).max(axis=0), xy + L / 2, atol=1e-5)
    assert len(rects) == sum(
        np.count_nonzero(cv2.aruco.generateImageMarker(aruco, int(k), 7) < 128)
        for k in block["markers"]
    )
    assert "print at 100 %" in "".join(root.find("s:text[2]", ns).itertext())


def test_pdf_print_is_vector_and_of_the_page_size(tmp_path):
    layout = charuco_layout(5, 4, 0.03, 0.0225)
    out, written = write_board(layout, tmp_path / "target.pdf")
    data = out.read_bytes()
    box = re.search(rb"/MediaBox\s*\[\s*0\s+0\s+([\d.]+)\s+([\d.]+)\s*\]", data)
    page_m = (0.15 + 2 * PAGE_MARGIN_M, 0.12 + PAGE_MARGIN_M + PAGE_FOOTER_M)
    assert float(box[1]) == pytest.approx(page_m[0] / 0.0254 * 72, abs=0.01)
    assert float(box[2]) == pytest.approx(page_m[1] / 0.0254 * 72, abs=0.01)
    assert b"/Subtype /Image" not in data
    # Drawn at true scale: the top-left (black) square's corner at the margin, in points.
    streams = re.findall(rb"stream\r?\n(.*?)\r?\nendstream", data, re.S)
    text = b"".join(zlib.decompress(s) for s in streams if s[:1] == b"x")
    moves = np.array(re.findall(rb"([\d.]+) ([\d.]+) m\b", text), float)
    corner = np.array([PAGE_MARGIN_M, page_m[1] - PAGE_MARGIN_M]) / 0.0254 * 72  # y up
    assert np.abs(moves - corner).sum(axis=1).min() < 1e-4
    assert written.name == "target.geometric_board.json"
    assert json.loads(written.read_text()) == {"geometric_board": layout}


def test_unknown_print_format_is_refused(block, tmp_path):
    with pytest.raises(ValueError, match=r"must be a \.pdf, \.png or \.svg"):
        write_board(block, tmp_path / "board.jpg")
    assert not list(tmp_path.iterdir())


# --------------------------------------------------------------------------------------------
# Command line


def test_cli_writes_the_print_and_its_block(tmp_path, capsys):
    out = tmp_path / "b.svg"
    argv = ["board", str(out), "--size", "0.2", "0.15", "--markers", "4", "--marker-length", "0.03"]
    assert main(argv) == 0, capsys.readouterr().err
    board = json.loads((tmp_path / "b.board.json").read_text())["board"]
    assert board["size"] == [0.2, 0.15] and list(board["markers"]) == ["0", "1", "2", "3"]
    assert board["dictionary"] == "DICT_5X5_100" and out.exists()
    assert "wrote" in capsys.readouterr().out
    argv = ["board", str(tmp_path / "c.png"), "--charuco", "5", "4", "--square-length", "0.02"]
    assert main([*argv, "--dpi", "100"]) == 0, capsys.readouterr().err
    target = json.loads((tmp_path / "c.geometric_board.json").read_text())["geometric_board"]
    assert target["squares"] == [5, 4] and target["marker_length"] == pytest.approx(0.015)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--markers", "99"], "99 markers of 40 mm do not fit"),
        (["--dictionary", "DICT_FOO"], "unknown ArUco dictionary 'DICT_FOO'"),
        (["--charuco", "5", "4"], "--charuco needs --square-length"),
        (["--charuco", "5", "4", "--square-length", "0.02", "--markers", "3"], "drop --markers"),
        (["--square-length", "0.02"], "give --charuco too"),
    ],
)
def test_cli_names_the_problem_of_an_impossible_board(tmp_path, capsys, argv, message):
    assert main(["board", str(tmp_path / "b.pdf"), *argv]) == 1
    err = capsys.readouterr().err
    assert err.startswith("colourhs board: ") and message in err, err
    assert not list(tmp_path.iterdir())
