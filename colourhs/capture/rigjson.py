"""Read and validate rig.json: :func:`load_rig` and :func:`rig_from_dict`.

Checks every key the format requires: the format version and units, the image
encoding (size, bit depth, black and white levels), exactly three cameras with
one light per colour (an upper-triangular K, an OpenCV distortion vector of
a supported length, a proper rotation R, t, the light's colour and offset), the
ArUco board (a known dictionary, ids within it, every marker inside the board)
and the chromatic light's position. The first violation found is a
:class:`~colourhs.capture.base.CaptureFormatError`. Re-exported by
:mod:`colourhs.capture`.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from colourhs.capture.base import _NAME, COLOURS, FORMAT, CaptureFormatError
from colourhs.capture.jsonvalues import (
    _as_int,
    _as_number,
    _as_object,
    _as_str,
    _field,
    _float_array,
    _frozen,
    _read_json,
    _show,
)
from colourhs.capture.rig import Board, Camera, ImageSpec, Rig, _square_corners

DIST_LENGTHS = (0, 4, 5, 8, 12, 14)
"""Lengths of an OpenCV distortion vector that rig.json may give."""

ROTATION_TOLERANCE = 1e-6
"""Largest accepted entry of ``|R R^T - I|`` and of ``|det R - 1|``."""

_MARKER_ID = re.compile(r"[0-9]+")


def load_rig(path: str | Path) -> Rig:
    """Read and validate rig.json.

    Parameters
    ----------
    path : str or Path
        The rig.json file, or the dataset folder holding it.

    Returns
    -------
    Rig

    Raises
    ------
    CaptureFormatError
        If the file is missing, is not JSON, or breaks the format.
    """
    path = Path(path)
    if path.is_dir():
        path = path / "rig.json"
    data = _read_json(path, "rig.json")
    return rig_from_dict(data, path)


def rig_from_dict(data: Any, path: str | Path = "rig.json") -> Rig:
    """Validate the parsed contents of a rig.json and build a :class:`Rig`.

    Parameters
    ----------
    data : Any
        The decoded JSON document.
    path : str or Path
        The file it came from, used in error messages and kept as ``Rig.path``.

    Raises
    ------
    CaptureFormatError
        If ``data`` breaks the format.
    """
    path = Path(path)
    top = _as_object(data, "the top level", path)
    fmt = _as_str(_field(top, "format", "", path), "format", path)
    if fmt != FORMAT:
        raise CaptureFormatError(path, f"format is {fmt!r}, expected {FORMAT!r}")
    units = _as_str(_field(top, "units", "", path), "units", path)
    if units != "m":
        raise CaptureFormatError(path, f"units is {units!r}, expected 'm' (metres)")
    image = _parse_image(_field(top, "image", "", path), path)
    cameras = _parse_cameras(_field(top, "cameras", "", path), path)
    board = _parse_board(_field(top, "board", "", path), path)
    chromatic = _as_object(_field(top, "chromatic_light", "", path), "chromatic_light", path)
    position = _float_array(
        _field(chromatic, "position", "chromatic_light", path),
        (3,),
        "chromatic_light.position",
        path,
    )
    return Rig(cameras=cameras, image=image, board=board, chromatic_light=position, path=path)


def _parse_image(value: Any, path: Path) -> ImageSpec:
    obj = _as_object(value, "image", path)
    width = _as_int(_field(obj, "width", "image", path), "image.width", path)
    height = _as_int(_field(obj, "height", "image", path), "image.height", path)
    if width <= 0 or height <= 0:
        raise CaptureFormatError(path, f"image size {width}x{height} must be positive")
    bit_depth = _as_int(_field(obj, "bit_depth", "image", path), "image.bit_depth", path)
    if bit_depth not in (8, 16):
        raise CaptureFormatError(path, f"image.bit_depth is {bit_depth}, expected 8 or 16")
    black = _as_number(_field(obj, "black_level", "image", path), "image.black_level", path)
    white = _as_number(_field(obj, "white_level", "image", path), "image.white_level", path)
    top = 2**bit_depth - 1
    if black < 0:
        raise CaptureFormatError(path, f"image.black_level {black:g} is negative")
    if white > top:
        raise CaptureFormatError(
            path, f"image.white_level {white:g} is out of range for {bit_depth}-bit (max {top})"
        )
    if white <= black:
        raise CaptureFormatError(
            path, f"image.white_level {white:g} must be greater than black_level {black:g}"
        )
    return ImageSpec(width, height, bit_depth, float(black), float(white))


def _parse_cameras(value: Any, path: Path) -> tuple[Camera, ...]:
    if not isinstance(value, list):
        raise CaptureFormatError(path, f"cameras must be a list, got {_show(value)}")
    if len(value) != len(COLOURS):
        raise CaptureFormatError(
            path,
            f"rig has {len(value)} cameras, expected exactly {len(COLOURS)} "
            "(one per light colour: red, green, blue)",
        )
    cameras = tuple(_parse_camera(entry, i, path) for i, entry in enumerate(value))
    for i, cam in enumerate(cameras):
        for j in range(i):
            if cameras[j].name == cam.name:
                raise CaptureFormatError(
                    path, f"camera name {cam.name!r} appears twice (cameras[{j}] and cameras[{i}])"
                )
            if cameras[j].light_colour == cam.light_colour:
                raise CaptureFormatError(
                    path,
                    f"two lights of one colour: cameras[{j}] ({cameras[j].name}) and "
                    f"cameras[{i}] ({cam.name}) both have a {cam.light_colour} light",
                )
    return cameras


def _parse_camera(value: Any, index: int, path: Path) -> Camera:
    where = f"cameras[{index}]"
    obj = _as_object(value, where, path)
    name = _as_str(_field(obj, "name", where, path), f"{where}.name", path)
    if not _NAME.fullmatch(name):
        raise CaptureFormatError(
            path,
            f"{where}.name {name!r} is not a valid camera name (letters, digits, '_' and '-' only)",
        )
    K = _float_array(_field(obj, "K", where, path), (3, 3), f"{where}.K", path)
    _check_intrinsics(K, f"{where}.K", path)
    dist = _float_array(obj.get("dist", []), (None,), f"{where}.dist", path)
    if dist.size not in DIST_LENGTHS:
        raise CaptureFormatError(
            path,
            f"{where}.dist has {dist.size} coefficients, expected one of "
            f"{', '.join(map(str, DIST_LENGTHS))}",
        )
    if dist.size == 14 and np.any(dist[12:] != 0):
        raise CaptureFormatError(
            path,
            f"{where}.dist: the tilted-sensor model (tau_x, tau_y = {dist[12:].tolist()}) is "
            "not supported; use at most 12 coefficients (or 14 with the last two zero)",
        )
    dist = np.concatenate([dist, np.zeros(max(0, 5 - dist.size))])
    R = _float_array(_field(obj, "R", where, path), (3, 3), f"{where}.R", path)
    _check_rotation(R, f"{where}.R", path)
    t = _float_array(_field(obj, "t", where, path), (3,), f"{where}.t", path)
    light = _as_object(_field(obj, "light", where, path), f"{where}.light", path)
    colour = _as_str(_field(light, "colour", f"{where}.light", path), f"{where}.light.colour", path)
    if colour not in COLOURS:
        raise CaptureFormatError(
            path, f"{where}.light.colour {colour!r} is not a light colour (red, green or blue)"
        )
    offset = _float_array(light.get("offset", [0.0, 0.0, 0.0]), (3,), f"{where}.light.offset", path)
    return Camera(
        name=name,
        K=_frozen(K),
        dist=_frozen(dist),
        R=_frozen(R),
        t=_frozen(t),
        light_colour=colour,
        light_offset=_frozen(offset),
    )


def _check_intrinsics(K: np.ndarray, where: str, path: Path) -> None:
    lower = (K[1, 0], K[2, 0], K[2, 1])
    if any(abs(v) > 1e-12 for v in lower):
        raise CaptureFormatError(path, f"{where} is not upper-triangular: {K.tolist()}")
    if abs(K[2, 2] - 1.0) > 1e-12:
        raise CaptureFormatError(path, f"{where}[2][2] is {K[2, 2]:g}, expected 1")
    if K[0, 0] <= 0 or K[1, 1] <= 0:
        raise CaptureFormatError(
            path, f"{where} focal lengths must be positive, got fx={K[0, 0]:g}, fy={K[1, 1]:g}"
        )


def _check_rotation(R: np.ndarray, where: str, path: Path) -> None:
    error = float(np.max(np.abs(R @ R.T - np.eye(3))))
    if error > ROTATION_TOLERANCE:
        raise CaptureFormatError(
            path,
            f"{where} is not a rotation: max |R R^T - I| = {error:.3g} > {ROTATION_TOLERANCE:g}",
        )
    det = float(np.linalg.det(R))
    if abs(det - 1.0) > ROTATION_TOLERANCE:
        raise CaptureFormatError(
            path, f"{where} is not a rotation: det(R) = {det:.6g}, expected +1"
        )


def _parse_board(value: Any, path: Path) -> Board:
    obj = _as_object(value, "board", path)
    dictionary = _as_str(_field(obj, "dictionary", "board", path), "board.dictionary", path)
    if not dictionary.startswith("DICT_") or not hasattr(cv2.aruco, dictionary):
        raise CaptureFormatError(
            path, f"board.dictionary {dictionary!r} is not a known OpenCV ArUco dictionary"
        )
    length = _as_number(_field(obj, "marker_length", "board", path), "board.marker_length", path)
    if length <= 0:
        raise CaptureFormatError(path, f"board.marker_length {length:g} must be positive")
    size = _float_array(_field(obj, "size", "board", path), (2,), "board.size", path)
    if np.any(size <= 0):
        raise CaptureFormatError(path, f"board.size {size.tolist()} must be positive")
    markers_obj = _as_object(_field(obj, "markers", "board", path), "board.markers", path)
    if not markers_obj:
        raise CaptureFormatError(path, "board.markers is empty")
    capacity = _dictionary_size(dictionary)
    markers: dict[int, np.ndarray] = {}
    for key, centre in markers_obj.items():
        if not _MARKER_ID.fullmatch(key):
            raise CaptureFormatError(
                path, f"board.markers key {key!r} is not a marker id (a non-negative integer)"
            )
        marker_id = int(key)
        if marker_id in markers:
            raise CaptureFormatError(path, f"board.markers: marker id {marker_id} appears twice")
        if capacity is not None and marker_id >= capacity:
            raise CaptureFormatError(
                path, f"board.markers: id {marker_id} is not in {dictionary} ({capacity} markers)"
            )
        xy = _float_array(centre, (2,), f"board.markers.{key}", path)
        corners = _square_corners(xy, length)
        margin = 1e-9
        if np.any(corners[:, :2] < -margin) or np.any(corners[:, :2] > size + margin):
            raise CaptureFormatError(
                path,
                f"board.markers: marker {marker_id} (centre {xy.tolist()}, side {length:g} m) "
                f"lies outside the board of size {size.tolist()} m",
            )
        markers[marker_id] = _frozen(xy)
    return Board(
        dictionary=dictionary,
        marker_length=float(length),
        size=(float(size[0]), float(size[1])),
        markers=dict(sorted(markers.items())),
    )


def _dictionary_size(name: str) -> int | None:
    """Number of markers in an OpenCV predefined ArUco dictionary (None if unknown)."""
    try:
        return int(cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name)).bytesList.shape[0])
    except (AttributeError, cv2.error, TypeError):
        return None
