"""Read and validate rig.json: :func:`load_rig` and :func:`rig_from_dict`.

The document is first checked against ``rig.schema.json`` (:func:`rig_schema`,
JSON Schema Draft 2020-12, shipped with the package): the format's
machine-readable spec of every key, type, array shape, enumeration and range.
What a schema cannot say is checked here: each R is a rotation
(:data:`ROTATION_TOLERANCE`), black_level < white_level, camera names are
unique and the lights' colours all different, the board's dictionary is one
OpenCV knows, its marker ids are unique (as integers) and in the dictionary,
and every marker lies wholly on the board; the optional ``geometric_board`` (a
ChArUco target) is one :func:`colourhs.capture.targets.charuco_layout` accepts
(a dictionary OpenCV knows with an id for every marker, markers smaller than
their squares). The first violation found is a
:class:`~colourhs.capture.base.CaptureFormatError`. Re-exported by
:mod:`colourhs.capture`.
"""

from __future__ import annotations

import functools
import json
from importlib import resources
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from colourhs.capture.base import CaptureFormatError
from colourhs.capture.jsonvalues import _check_schema, _frozen, _read_json, _Validator
from colourhs.capture.rig import Board, Camera, ImageSpec, Rig, _square_corners
from colourhs.capture.targets import aruco_dictionary, charuco_layout

DIST_LENGTHS = (0, 4, 5, 8, 12, 14)
"""Lengths of an OpenCV distortion vector that rig.json may give (as its schema says)."""

ROTATION_TOLERANCE = 1e-6
"""Largest accepted entry of ``|R R^T - I|`` and of ``|det R - 1|``."""


@functools.cache
def rig_schema() -> dict[str, Any]:
    """rig.json's JSON Schema (Draft 2020-12), the package file ``rig.schema.json``.

    The one parsed copy is shared: do not modify it.
    """
    text = resources.files(__package__).joinpath("rig.schema.json").read_text(encoding="utf-8")
    return json.loads(text)


@functools.cache
def _rig_validator() -> _Validator:
    return _Validator(rig_schema())


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
    _check_schema(data, _rig_validator(), path)
    return Rig(
        image=_image(data["image"], path),
        cameras=_cameras(data["cameras"], path),
        board=_board(data["board"], path),
        chromatic_light=_frozen(data["chromatic_light"]["position"]),
        path=path,
        geometric_board=_geometric_board(data.get("geometric_board"), path),
    )


def _image(obj: dict[str, Any], path: Path) -> ImageSpec:
    black, white = float(obj["black_level"]), float(obj["white_level"])
    if white <= black:
        raise CaptureFormatError(
            path, f"image.white_level {white:g} must be greater than black_level {black:g}"
        )
    return ImageSpec(int(obj["width"]), int(obj["height"]), int(obj["bit_depth"]), black, white)


def _cameras(entries: list[dict[str, Any]], path: Path) -> tuple[Camera, ...]:
    cameras = tuple(_camera(entry, f"cameras[{i}]", path) for i, entry in enumerate(entries))
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


def _camera(obj: dict[str, Any], where: str, path: Path) -> Camera:
    R = np.array(obj["R"], dtype=np.float64)
    _check_rotation(R, f"{where}.R", path)
    dist = np.array(obj.get("dist", []), dtype=np.float64)
    light = obj["light"]
    return Camera(
        name=obj["name"],
        K=_frozen(obj["K"]),
        dist=_frozen(np.concatenate([dist, np.zeros(max(0, 5 - dist.size))])),
        R=_frozen(R),
        t=_frozen(obj["t"]),
        light_colour=light["colour"],
        light_offset=_frozen(light.get("offset", [0.0, 0.0, 0.0])),
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


def _board(obj: dict[str, Any], path: Path) -> Board:
    dictionary = obj["dictionary"]
    capacity = _dictionary_size(dictionary)
    if capacity is None:
        raise CaptureFormatError(
            path, f"board.dictionary {dictionary!r} is not a known OpenCV ArUco dictionary"
        )
    length = float(obj["marker_length"])
    size = np.array(obj["size"], dtype=np.float64)
    markers: dict[int, np.ndarray] = {}
    for key, centre in obj["markers"].items():
        marker_id = int(key)
        if marker_id in markers:
            raise CaptureFormatError(path, f"board.markers: marker id {marker_id} appears twice")
        if marker_id >= capacity:
            raise CaptureFormatError(
                path, f"board.markers: id {marker_id} is not in {dictionary} ({capacity} markers)"
            )
        xy = np.array(centre, dtype=np.float64)
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
        marker_length=length,
        size=(float(size[0]), float(size[1])),
        markers=dict(sorted(markers.items())),
    )


def _geometric_board(obj: dict[str, Any] | None, path: Path) -> dict[str, Any] | None:
    """The ChArUco description of ``geometric_board`` (None when absent), as
    :func:`~colourhs.capture.targets.charuco_layout` returns it (ints and floats)."""
    if obj is None:
        return None
    dictionary = obj["dictionary"]
    if _dictionary_size(dictionary) is None:
        raise CaptureFormatError(
            path,
            f"geometric_board.dictionary {dictionary!r} is not a known OpenCV ArUco dictionary",
        )
    sx, sy = obj["squares"]
    try:
        return charuco_layout(sx, sy, obj["square_length"], obj["marker_length"], dictionary)
    except ValueError as err:
        raise CaptureFormatError(path, f"geometric_board: {err}") from None


def _dictionary_size(name: str) -> int | None:
    """Number of markers in an OpenCV predefined ArUco dictionary (None if unknown)."""
    try:
        return int(aruco_dictionary(name).bytesList.shape[0])
    except (ValueError, cv2.error):
        return None
