"""Tests of colourhs.capture: rig.json violations, each a one-line CaptureFormatError."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from capture_helpers import assign, delete, edit_json, raises, rot_y

from colourhs.capture import load_rig, open_dataset

# --------------------------------------------------------------------------------------------
# rig.json violations


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
