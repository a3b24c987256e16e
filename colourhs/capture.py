"""Read and validate datasets in the Colour HS capture format, version 1.

The format is specified in ``capture-format.md`` (the contract between a
capture rig or the synthetic renderer and the pipeline). This module is the
pipeline's only reader of that layout: :func:`open_dataset` validates a whole
dataset and :func:`load_rig`, :func:`read_image` and :func:`read_mask` read its
parts. Anything malformed is refused with a :class:`CaptureFormatError` whose
message starts with the offending file's path, then ``": "`` and the problem.

Conventions (all from the format): lengths are in metres, geometry follows
OpenCV (a world point X maps to camera coordinates ``R X + t``), images are
R, G, B in that order, and channel indices follow :data:`COLOURS`.
"""

from __future__ import annotations

import json
import math
import re
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import cv2
import numpy as np

from colourhs.geometry import camera_centre, light_centre

__all__ = [
    "COLOURS",
    "FORMAT",
    "Board",
    "Camera",
    "CaptureFormatError",
    "Dataset",
    "ImageSpec",
    "ReciprocalPair",
    "Rig",
    "Scene",
    "load_rig",
    "open_dataset",
    "read_image",
    "read_mask",
    "rig_from_dict",
]

FORMAT = "colourhs-capture/1"
"""Value of the ``format`` key of rig.json that this module reads."""

COLOURS = ("red", "green", "blue")
"""Light / channel colours; the index of a colour is its image channel (R, G, B)."""

DIST_LENGTHS = (0, 4, 5, 8, 12, 14)
"""Lengths of an OpenCV distortion vector that rig.json may give."""

ROTATION_TOLERANCE = 1e-6
"""Largest accepted entry of ``|R R^T - I|`` and of ``|det R - 1|``."""

_NAME = re.compile(r"[A-Za-z0-9_-]+")
_FRAME = re.compile(r"[0-9]{6}")
_MARKER_ID = re.compile(r"[0-9]+")
_STATIC_FRAME = "000000"
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_PNG_HEADER_BYTES = 33  # signature (8) + IHDR length, type, data (13) and CRC
# PNG colour type -> (channels, description, allowed bit depths)
_PNG_COLOUR_TYPES = {
    0: (1, "greyscale", (1, 2, 4, 8, 16)),
    2: (3, "RGB", (8, 16)),
    3: (3, "palette", (1, 2, 4, 8)),
    4: (2, "greyscale+alpha", (8, 16)),
    6: (4, "RGBA", (8, 16)),
}
_MISSING = object()


# --------------------------------------------------------------------------------------------
# Errors


#: The rig has no ambient light (the format's rule): without masks, an object is
#: the pixels brighter than this fraction of full scale (above black level) in
#: some channel. The silhouettes, the object masks and the reconstruction's
#: foreground all use it.
LIT_THRESHOLD = 0.02
#: Darkest intensity (fraction of full scale) whose ratio to another is still
#: measured: the data term's and the chromaticity's samples at or below it are
#: unusable (1 % of full scale: 2.5 8-bit levels, where quantisation alone is a
#: 12 % error of the ratio).
MIN_SIGNAL = 0.01


class CaptureFormatError(ValueError):
    """A dataset, or one of its files, breaks the capture format.

    Parameters
    ----------
    path : str or Path
        The offending file or folder (for a missing one, the path where it should be).
    problem : str
        What is wrong, in words.

    Attributes
    ----------
    path : Path
    problem : str
    """

    def __init__(self, path: str | Path, problem: str) -> None:
        self.path = Path(path)
        self.problem = str(problem)
        super().__init__(f"{self.path}: {self.problem}")

    def __reduce__(self):
        return (type(self), (self.path, self.problem))


class UnknownNameError(KeyError):
    """A scene, frame, camera, object, pose or marker the dataset does not have.

    A KeyError (lookups by name), whose message names what exists; ``str()``
    is the message itself, not KeyError's quoted repr.
    """

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""


# --------------------------------------------------------------------------------------------
# Rig types


@dataclass(frozen=True)
class ImageSpec:
    """Size and encoding shared by all images of a dataset.

    Attributes
    ----------
    width, height : int
        Image size in pixels.
    bit_depth : int
        8 or 16 bits per channel.
    black_level, white_level : float
        Raw values of zero and of full scale; a value at ``white_level`` is saturated.
    """

    width: int
    height: int
    bit_depth: int
    black_level: float
    white_level: float

    @property
    def dtype(self) -> type[np.unsignedinteger]:
        """NumPy type of raw pixel values (``uint8`` or ``uint16``)."""
        return np.uint8 if self.bit_depth == 8 else np.uint16


@dataclass(frozen=True, eq=False)
class Camera:
    """One calibrated camera with its collocated light.

    Attributes
    ----------
    name : str
        Camera name; also the image file stem ``<name>.png``.
    K : ndarray, shape (3, 3)
        Intrinsic matrix, pixels.
    dist : ndarray, shape (n,), n >= 5
        OpenCV distortion coefficients (k1, k2, p1, p2, k3, ...), zero-padded to at least 5.
    R : ndarray, shape (3, 3)
        World-to-camera rotation.
    t : ndarray, shape (3,)
        World-to-camera translation, metres (``x_cam = R X + t``).
    light_colour : str
        Colour filter of the camera's light, one of :data:`COLOURS`.
    light_offset : ndarray, shape (3,)
        Light centre in camera coordinates, metres.
    """

    name: str
    K: np.ndarray
    dist: np.ndarray
    R: np.ndarray
    t: np.ndarray
    light_colour: str
    light_offset: np.ndarray

    @property
    def centre(self) -> np.ndarray:
        """Camera centre in world coordinates, metres: ``-R^T t``."""
        return camera_centre(self.R, self.t)

    @property
    def light_centre(self) -> np.ndarray:
        """Light centre in world coordinates, metres: ``R^T (offset - t)``."""
        return light_centre(self.R, self.t, self.light_offset)

    @property
    def light_channel(self) -> int:
        """Image channel (index into :data:`COLOURS`) of the light's colour."""
        return COLOURS.index(self.light_colour)


@dataclass(frozen=True, eq=False)
class Board:
    """The flat calibration board with its ArUco markers.

    Board frame: origin at the top-left corner, x to the right, y down, board
    plane z = 0, metres.

    Attributes
    ----------
    dictionary : str
        Name of the OpenCV predefined ArUco dictionary, e.g. ``"DICT_4X4_50"``.
    marker_length : float
        Side of each square marker, metres.
    size : tuple of float
        Board (width, height), metres.
    markers : dict of int to ndarray, shape (2,)
        Marker id to marker centre (x, y) in the board frame, metres; ids ascending.
    """

    dictionary: str
    marker_length: float
    size: tuple[float, float]
    markers: dict[int, np.ndarray]

    def marker_corners(self, marker_id: int) -> np.ndarray:
        """Corners of one marker in the board frame.

        Parameters
        ----------
        marker_id : int
            A marker id of the board.

        Returns
        -------
        ndarray, shape (4, 3)
            Corners in metres, OpenCV order: top-left, top-right, bottom-right,
            bottom-left (x right, y down, z = 0).

        Raises
        ------
        KeyError
            If the board has no such marker.
        """
        if marker_id not in self.markers:
            raise UnknownNameError(
                f"board has no marker {marker_id!r}; ids: {sorted(self.markers)}"
            )
        return _square_corners(self.markers[marker_id], self.marker_length)

    def white(self, xy: np.ndarray, margin_m) -> np.ndarray:
        """True where board-frame points ``xy`` (N, 2) lie on the white surface.

        Points within ``margin_m`` (metres; a scalar or one value per point)
        of the board's edge or of a marker are left out (the rendered or
        printed edge blurs over a pixel or two).
        """
        w, h = self.size
        x, y = xy[:, 0], xy[:, 1]
        ok = (x > margin_m) & (x < w - margin_m) & (y > margin_m) & (y < h - margin_m)
        half = self.marker_length / 2 + margin_m
        for centre in self.markers.values():
            ok &= ~((np.abs(x - centre[0]) < half) & (np.abs(y - centre[1]) < half))
        return ok


@dataclass(frozen=True)
class ReciprocalPair:
    """Two cameras whose lights and channels form a Helmholtz reciprocal pair.

    Attributes
    ----------
    cam_a, cam_b : str
        Camera names, in rig order.
    channel_a : int
        Channel of ``cam_a`` recording ``cam_b``'s light (index into :data:`COLOURS`).
    channel_b : int
        Channel of ``cam_b`` recording ``cam_a``'s light.
    """

    cam_a: str
    cam_b: str
    channel_a: int
    channel_b: int


@dataclass(frozen=True, eq=False)
class Rig:
    """Contents of a validated rig.json.

    Attributes
    ----------
    cameras : tuple of Camera
        The cameras in rig.json order.
    image : ImageSpec
        Size and encoding of all images.
    board : Board
        The calibration board.
    chromatic_light : ndarray, shape (3,)
        World position of the chromatic-capture light, metres.
    path : Path
        The rig.json file this was read from.
    """

    cameras: tuple[Camera, ...]
    image: ImageSpec
    board: Board
    chromatic_light: np.ndarray
    path: Path

    @property
    def camera_names(self) -> tuple[str, ...]:
        """Camera names in rig order."""
        return tuple(cam.name for cam in self.cameras)

    def camera(self, name: str) -> Camera:
        """Look a camera up by name.

        Raises
        ------
        KeyError
            If the rig has no camera of that name.
        """
        for cam in self.cameras:
            if cam.name == name:
                return cam
        raise UnknownNameError(
            f"rig {self.path} has no camera {name!r}; cameras: {self.camera_names}"
        )

    def reciprocal_pairs(self) -> tuple[ReciprocalPair, ...]:
        """Every unordered camera pair ``i < j`` in rig order, with its channels.

        Camera i records camera j's light in the channel of j's light colour and
        vice versa.
        """
        return tuple(
            ReciprocalPair(a.name, b.name, channel_a=b.light_channel, channel_b=a.light_channel)
            for i, a in enumerate(self.cameras)
            for b in self.cameras[i + 1 :]
        )


# --------------------------------------------------------------------------------------------
# Dataset types


@dataclass(frozen=True)
class Scene:
    """One scene of a dataset.

    Attributes
    ----------
    name : str
        Folder name under ``scenes/``.
    frames : tuple of str
        Frame folder names (6 digits), ascending; gaps are allowed.
    chromatic : str or None
        Folder under ``chromatic/`` with the object's coloured captures; None for a white
        surface.
    dynamic : bool
        True for a sequence of a moving or deforming surface. Without a scene.json, or without
        its ``dynamic`` key, a scene is dynamic unless its only frame is ``000000``.
    description : str
        Free text ("" when absent).
    has_masks : bool
        Whether ``masks/`` exists (then every frame has a mask per camera).
    has_gt : bool
        Whether ``gt/`` exists (then every frame has ``gt/<frame>.ply``).
    """

    name: str
    frames: tuple[str, ...]
    chromatic: str | None
    dynamic: bool
    description: str
    has_masks: bool
    has_gt: bool


@dataclass(frozen=True, eq=False)
class Dataset:
    """A validated dataset: rig plus the names of everything captured.

    Attributes
    ----------
    root : Path
        The dataset folder.
    rig : Rig
        Contents of rig.json.
    poses : tuple of str
        Photometric board poses (folder names under ``photometric/``), ascending.
    chromatic_objects : tuple of str
        Folders under ``chromatic/`` (``"white"`` included when present), ascending.
    scenes : dict of str to Scene
        Scenes by name, ascending.
    """

    root: Path
    rig: Rig
    poses: tuple[str, ...]
    chromatic_objects: tuple[str, ...]
    scenes: dict[str, Scene]

    def scene(self, name: str) -> Scene:
        """The scene ``name``; :class:`UnknownNameError` naming the dataset's scenes."""
        _known(name, tuple(self.scenes), "scene")
        return self.scenes[name]

    def photometric_image(self, pose: str, camera: str) -> Path:
        """Path of ``photometric/<pose>/<camera>.png``."""
        _known(pose, self.poses, "photometric pose")
        self.rig.camera(camera)
        return self.root / "photometric" / pose / f"{camera}.png"

    def chromatic_image(self, obj: str, colour: str, camera: str) -> Path:
        """Path of ``chromatic/<obj>/<colour>/<camera>.png``."""
        _known(obj, self.chromatic_objects, "chromatic object")
        _known(colour, COLOURS, "colour")
        self.rig.camera(camera)
        return self.root / "chromatic" / obj / colour / f"{camera}.png"

    def frame_image(self, scene: str, frame: str | int, camera: str) -> Path:
        """Path of ``scenes/<scene>/frames/<frame>/<camera>.png``; ``frame`` may be an int."""
        frame = self._frame(scene, frame)
        self.rig.camera(camera)
        return self.root / "scenes" / scene / "frames" / frame / f"{camera}.png"

    def mask_image(self, scene: str, frame: str | int, camera: str) -> Path:
        """Path of ``scenes/<scene>/masks/<frame>/<camera>.png``.

        Raises
        ------
        KeyError
            If the scene has no masks (or the scene, frame or camera is unknown).
        """
        frame = self._frame(scene, frame)
        if not self.scene(scene).has_masks:
            raise UnknownNameError(f"scene {scene!r} has no masks")
        self.rig.camera(camera)
        return self.root / "scenes" / scene / "masks" / frame / f"{camera}.png"

    def gt_mesh(self, scene: str, frame: str | int) -> Path:
        """Path of ``scenes/<scene>/gt/<frame>.ply``.

        Raises
        ------
        KeyError
            If the scene has no ground truth (or the scene or frame is unknown).
        """
        frame = self._frame(scene, frame)
        if not self.scene(scene).has_gt:
            raise UnknownNameError(f"scene {scene!r} has no ground-truth meshes")
        return self.root / "scenes" / scene / "gt" / f"{frame}.ply"

    @property
    def gt_photometric(self) -> Path | None:
        """Path of ``gt/photometric.h5`` when the dataset has it, else None."""
        path = self.root / "gt" / "photometric.h5"
        return path if path.is_file() else None

    def _frame(self, scene: str, frame: str | int) -> str:
        _known(scene, tuple(self.scenes), "scene")
        name = f"{frame:06d}" if isinstance(frame, int) else frame
        _known(name, self.scenes[scene].frames, f"frame of scene {scene!r}")
        return name


def _known(name: str, names: tuple[str, ...], what: str) -> None:
    if name not in names:
        raise UnknownNameError(f"unknown {what} {name!r}; known: {', '.join(names) or 'none'}")


# --------------------------------------------------------------------------------------------
# rig.json


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


def _square_corners(centre: np.ndarray, side: float) -> np.ndarray:
    """Corners (TL, TR, BR, BL) of an axis-aligned square in the board plane, shape (4, 3)."""
    h = side / 2.0
    offsets = np.array([[-h, -h], [h, -h], [h, h], [-h, h]])
    return np.column_stack([centre + offsets, np.zeros(4)])


# --------------------------------------------------------------------------------------------
# JSON helpers


class _DuplicateKey(Exception):
    pass


def _reject_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    result: dict[str, Any] = {}
    for key, value in pairs:
        if key in result:
            raise _DuplicateKey(key)
        result[key] = value
    return result


def _read_json(path: Path, what: str) -> Any:
    """Decode a JSON file, refusing duplicate keys; errors name ``path``."""
    if not path.is_file():
        raise CaptureFormatError(path, f"{what} not found")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise CaptureFormatError(path, "not valid JSON: not UTF-8 text") from None
    except OSError as err:
        raise CaptureFormatError(path, f"cannot read {what}: {err.strerror}") from None
    try:
        return json.loads(text, object_pairs_hook=_reject_duplicates)
    except json.JSONDecodeError as err:
        raise CaptureFormatError(
            path, f"not valid JSON: {err.msg} (line {err.lineno}, column {err.colno})"
        ) from None
    except _DuplicateKey as err:
        raise CaptureFormatError(path, f"not valid JSON: duplicate key {err.args[0]!r}") from None


def _field(obj: dict[str, Any], key: str, where: str, path: Path) -> Any:
    """``obj[key]``, or a "missing required key" error naming ``where.key``."""
    if key not in obj:
        full = f"{where}.{key}" if where else key
        raise CaptureFormatError(path, f"missing required key {full}")
    return obj[key]


def _show(value: Any, limit: int = 60) -> str:
    """Short JSON-like rendering of a value for error messages."""
    text = json.dumps(value, default=repr)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _as_object(value: Any, where: str, path: Path) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise CaptureFormatError(path, f"{where} must be a JSON object, got {_show(value)}")
    return value


def _as_str(value: Any, where: str, path: Path) -> str:
    if not isinstance(value, str):
        raise CaptureFormatError(path, f"{where} must be a string, got {_show(value)}")
    return value


def _is_number(value: Any) -> bool:
    if isinstance(value, bool):
        return False
    if isinstance(value, int):
        return abs(value) < 2**1023
    return isinstance(value, float) and math.isfinite(value)


def _as_number(value: Any, where: str, path: Path) -> float:
    if not _is_number(value):
        raise CaptureFormatError(path, f"{where} must be a finite number, got {_show(value)}")
    return float(value)


def _as_int(value: Any, where: str, path: Path) -> int:
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, int):
        raise CaptureFormatError(path, f"{where} must be an integer, got {_show(value)}")
    return value


def _all_numbers(value: Any) -> bool:
    if isinstance(value, list):
        return all(_all_numbers(v) for v in value)
    return _is_number(value)


def _float_array(value: Any, shape: tuple[int | None, ...], where: str, path: Path) -> np.ndarray:
    """A nested JSON list of finite numbers as a float64 array of ``shape`` (None: any length)."""
    dims = "x".join("n" if n is None else str(n) for n in shape)
    wanted = f"a list of {dims} numbers" if len(shape) == 1 else f"a {dims} array of numbers"
    problem = f"{where} must be {wanted}, got {_show(value)}"
    if not isinstance(value, list) or not _all_numbers(value):
        raise CaptureFormatError(path, problem)
    try:
        array = np.array(value, dtype=np.float64)
    except (ValueError, TypeError, OverflowError):
        raise CaptureFormatError(path, problem) from None
    if array.ndim != len(shape) or any(
        n is not None and n != m for n, m in zip(shape, array.shape, strict=True)
    ):
        raise CaptureFormatError(path, problem)
    return array


def _frozen(array: np.ndarray) -> np.ndarray:
    array = np.array(array, dtype=np.float64)
    array.flags.writeable = False
    return array


# --------------------------------------------------------------------------------------------
# PNG images


class _PngHeader(NamedTuple):
    width: int
    height: int
    bit_depth: int
    colour_type: int


def _parse_png_header(path: Path, head: bytes) -> _PngHeader:
    """Decode the signature and IHDR chunk at the start of a PNG file."""
    if len(head) < _PNG_HEADER_BYTES or head[:8] != _PNG_SIGNATURE:
        raise CaptureFormatError(path, "unreadable PNG: not a PNG file")
    length, chunk = struct.unpack(">I4s", head[8:16])
    if length != 13 or chunk != b"IHDR":
        raise CaptureFormatError(path, "unreadable PNG: no IHDR chunk")
    (crc,) = struct.unpack(">I", head[29:33])
    if zlib.crc32(head[12:29]) != crc:
        raise CaptureFormatError(path, "unreadable PNG: corrupt IHDR chunk")
    width, height, depth, colour_type = struct.unpack(">IIBB", head[16:26])
    allowed = _PNG_COLOUR_TYPES.get(colour_type, (0, "", ()))[2]
    if width == 0 or height == 0 or depth not in allowed:
        raise CaptureFormatError(path, "unreadable PNG: invalid IHDR chunk")
    return _PngHeader(width, height, depth, colour_type)


def _read_png_header(path: Path, what: str) -> _PngHeader:
    """Read only the header of a PNG file (fast: 33 bytes)."""
    try:
        with path.open("rb") as file:
            head = file.read(_PNG_HEADER_BYTES)
    except FileNotFoundError:
        raise CaptureFormatError(path, f"{what} not found") from None
    except OSError as err:
        raise CaptureFormatError(path, f"cannot read {what}: {err.strerror}") from None
    return _parse_png_header(path, head)


def _check_header(
    path: Path, header: _PngHeader, spec: ImageSpec, channels: tuple[int, ...], depth: int
) -> None:
    """Refuse a PNG whose channel count, bit depth or size is not the expected one."""
    count, kind, _ = _PNG_COLOUR_TYPES[header.colour_type]
    wanted = " or ".join(map(str, channels))
    if header.colour_type == 3:
        raise CaptureFormatError(path, f"wrong channels: palette PNG, expected {wanted} channels")
    if count not in channels:
        raise CaptureFormatError(
            path, f"wrong channels: {count} channel(s) ({kind} PNG), expected {wanted}"
        )
    if header.bit_depth != depth:
        raise CaptureFormatError(
            path, f"wrong bit depth: {header.bit_depth}-bit PNG, expected {depth}-bit"
        )
    if (header.width, header.height) != (spec.width, spec.height):
        raise CaptureFormatError(
            path,
            f"wrong image size: found {header.width}x{header.height}, expected "
            f"{spec.width}x{spec.height} (width x height)",
        )


def _check_image_header(path: Path, header: _PngHeader, spec: ImageSpec) -> None:
    _check_header(path, header, spec, channels=(3,), depth=spec.bit_depth)


def _check_mask_header(path: Path, header: _PngHeader, spec: ImageSpec) -> None:
    _check_header(path, header, spec, channels=(1, 3), depth=8)


def _load_png(path: Path, what: str) -> tuple[_PngHeader, np.ndarray]:
    """Read a whole PNG file: its header and its decoded pixels (OpenCV channel order)."""
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise CaptureFormatError(path, f"{what} not found") from None
    except OSError as err:
        raise CaptureFormatError(path, f"cannot read {what}: {err.strerror}") from None
    header = _parse_png_header(path, data[:_PNG_HEADER_BYTES])
    try:
        pixels = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    except cv2.error:
        pixels = None
    if pixels is None:
        raise CaptureFormatError(path, "unreadable PNG: cannot decode the image data")
    return header, pixels


def read_image(path: str | Path, spec: ImageSpec) -> tuple[np.ndarray, np.ndarray]:
    """Read one capture image and normalise it.

    Parameters
    ----------
    path : str or Path
        A 3-channel PNG of the dataset.
    spec : ImageSpec
        The rig's image encoding.

    Returns
    -------
    image : ndarray of float32, shape (H, W, 3)
        R, G, B in [0, 1]: ``(v - black_level) / (white_level - black_level)``, clipped.
    saturated : ndarray of bool, shape (H, W)
        True where any channel is at or above ``white_level`` (no measurement).

    Raises
    ------
    CaptureFormatError
        Missing file, unreadable PNG, not 3 channels, wrong size or bit depth.
    """
    path = Path(path)
    header, bgr = _load_png(path, "image file")
    _check_image_header(path, header, spec)
    if bgr.shape != (spec.height, spec.width, 3) or bgr.dtype != spec.dtype:
        raise CaptureFormatError(
            path, f"unreadable PNG: decoded as {bgr.dtype} {bgr.shape}, expected 3 channels"
        )
    rgb = bgr[..., ::-1]
    saturated = np.any(rgb >= spec.white_level, axis=2)
    scale = np.float32(spec.white_level - spec.black_level)
    image = (rgb.astype(np.float32) - np.float32(spec.black_level)) / scale
    np.clip(image, 0.0, 1.0, out=image)
    return image, saturated


def read_mask(path: str | Path, spec: ImageSpec) -> np.ndarray:
    """Read one silhouette mask.

    Parameters
    ----------
    path : str or Path
        An 8-bit PNG with 1 or 3 channels, of the rig's image size.
    spec : ImageSpec
        The rig's image encoding (only the size is used).

    Returns
    -------
    ndarray of bool, shape (H, W)
        True on the object: where any channel is non-zero.

    Raises
    ------
    CaptureFormatError
        Missing file, unreadable PNG, not 8-bit, not 1 or 3 channels, or wrong size.
    """
    path = Path(path)
    header, pixels = _load_png(path, "mask file")
    _check_mask_header(path, header, spec)
    if pixels.shape[:2] != (spec.height, spec.width) or pixels.dtype != np.uint8:
        raise CaptureFormatError(
            path, f"unreadable PNG: decoded as {pixels.dtype} {pixels.shape}, expected 8-bit"
        )
    return pixels != 0 if pixels.ndim == 2 else np.any(pixels != 0, axis=2)


# --------------------------------------------------------------------------------------------
# Dataset layout


def open_dataset(root: str | Path, check_images: bool = True) -> Dataset:
    """Validate a whole dataset folder and describe its contents.

    Parameters
    ----------
    root : str or Path
        The dataset folder (or its rig.json).
    check_images : bool
        Also check every listed PNG's header: valid PNG, channels, bit depth and size.
        Only headers are read (pixel data is decoded by :func:`read_image`).

    Returns
    -------
    Dataset

    Raises
    ------
    CaptureFormatError
        At the first violation of the format found, naming the file and the problem.
        Files and folders the format does not list are ignored, as are hidden ones
        (names starting with ".").
    """
    root = Path(root)
    if root.is_file() and root.name == "rig.json":
        root = root.parent
    if not root.is_dir():
        raise CaptureFormatError(root, "dataset folder not found")
    rig = load_rig(root / "rig.json")
    poses, pose_images = _find_poses(root / "photometric", rig.camera_names)
    objects, chromatic_images = _find_chromatic(root / "chromatic", rig.camera_names)
    scenes, frame_images, masks = _find_scenes(root / "scenes", rig.camera_names, objects)
    if check_images:
        for image in (*pose_images, *chromatic_images, *frame_images):
            _check_image_header(image, _read_png_header(image, "image file"), rig.image)
        for mask in masks:
            _check_mask_header(mask, _read_png_header(mask, "mask file"), rig.image)
    return Dataset(root, rig, poses, objects, scenes)


def _subfolders(folder: Path) -> list[Path]:
    """Non-hidden sub-folders of ``folder``, by name."""
    return sorted(p for p in folder.iterdir() if p.is_dir() and not p.name.startswith("."))


def _check_name(folder: Path, what: str) -> str:
    if not _NAME.fullmatch(folder.name):
        raise CaptureFormatError(
            folder,
            f"{what} name {folder.name!r} has characters other than letters, digits, '_' and '-'",
        )
    return folder.name


def _camera_images(folder: Path, cameras: tuple[str, ...], what: str) -> list[Path]:
    """``folder/<camera>.png`` for every camera, refusing a missing one."""
    if not folder.is_dir():
        raise CaptureFormatError(folder, f"missing folder ({what})")
    paths = [folder / f"{name}.png" for name in cameras]
    for path, name in zip(paths, cameras, strict=True):
        if not path.is_file():
            raise CaptureFormatError(path, f"missing image of camera {name!r} ({what})")
    return paths


def _find_poses(folder: Path, cameras: tuple[str, ...]) -> tuple[tuple[str, ...], list[Path]]:
    if not folder.is_dir():
        raise CaptureFormatError(folder, "missing photometric/ folder (at least 3 board poses)")
    poses = [_check_name(p, "pose") for p in _subfolders(folder)]
    if len(poses) < 3:
        raise CaptureFormatError(folder, f"found {len(poses)} poses, at least 3 are required")
    images = [
        path
        for pose in poses
        for path in _camera_images(folder / pose, cameras, f"photometric pose {pose}")
    ]
    return tuple(poses), images


def _find_chromatic(folder: Path, cameras: tuple[str, ...]) -> tuple[tuple[str, ...], list[Path]]:
    if not folder.is_dir():
        return (), []
    objects = [_check_name(p, "chromatic object") for p in _subfolders(folder)]
    if objects and "white" not in objects:
        raise CaptureFormatError(
            folder / "white", "missing white reference folder (required when chromatic/ is used)"
        )
    images = [
        path
        for obj in objects
        for colour in COLOURS
        for path in _camera_images(
            folder / obj / colour, cameras, f"chromatic {obj} under {colour} light"
        )
    ]
    return tuple(objects), images


def _find_scenes(
    folder: Path, cameras: tuple[str, ...], objects: tuple[str, ...]
) -> tuple[dict[str, Scene], list[Path], list[Path]]:
    scenes: dict[str, Scene] = {}
    images: list[Path] = []
    masks: list[Path] = []
    if not folder.is_dir():
        return scenes, images, masks
    for scene_dir in _subfolders(folder):
        scene, scene_images, scene_masks = _find_scene(scene_dir, cameras, objects)
        scenes[scene.name] = scene
        images += scene_images
        masks += scene_masks
    return scenes, images, masks


def _find_scene(
    folder: Path, cameras: tuple[str, ...], objects: tuple[str, ...]
) -> tuple[Scene, list[Path], list[Path]]:
    name = _check_name(folder, "scene")
    frames_dir = folder / "frames"
    if not frames_dir.is_dir():
        raise CaptureFormatError(frames_dir, f"scene {name!r} has no frames (missing folder)")
    frames = []
    for frame_dir in _subfolders(frames_dir):
        if not _FRAME.fullmatch(frame_dir.name):
            raise CaptureFormatError(
                frame_dir, f"frame folder name {frame_dir.name!r} is not a 6-digit index"
            )
        frames.append(frame_dir.name)
    if not frames:
        raise CaptureFormatError(frames_dir, f"scene {name!r} has no frames")
    meta = _read_scene_json(folder / "scene.json", objects)
    dynamic = meta.get("dynamic", frames != [_STATIC_FRAME])
    if not dynamic and frames != [_STATIC_FRAME]:
        raise CaptureFormatError(
            folder / "scene.json",
            f"static scene (dynamic: false) must have the single frame {_STATIC_FRAME}, "
            f"found frames {', '.join(frames)}",
        )
    images = [
        path
        for frame in frames
        for path in _camera_images(frames_dir / frame, cameras, f"scene {name} frame {frame}")
    ]
    masks_dir = folder / "masks"
    masks = (
        [
            path
            for frame in frames
            for path in _camera_images(masks_dir / frame, cameras, f"mask of scene {name}")
        ]
        if masks_dir.is_dir()
        else []
    )
    gt_dir = folder / "gt"
    if gt_dir.is_dir():
        for frame in frames:
            if not (gt_dir / f"{frame}.ply").is_file():
                raise CaptureFormatError(
                    gt_dir / f"{frame}.ply", f"missing ground-truth mesh of frame {frame}"
                )
    scene = Scene(
        name=name,
        frames=tuple(frames),
        chromatic=meta.get("chromatic"),
        dynamic=bool(dynamic),
        description=meta.get("description", ""),
        has_masks=masks_dir.is_dir(),
        has_gt=gt_dir.is_dir(),
    )
    return scene, images, masks


def _read_scene_json(path: Path, objects: tuple[str, ...]) -> dict[str, Any]:
    """Validated keys of an optional scene.json ({} when absent); unknown keys are ignored."""
    if not path.exists():
        return {}
    obj = _as_object(_read_json(path, "scene.json"), "scene.json", path)
    meta: dict[str, Any] = {}
    chromatic = obj.get("chromatic")
    if chromatic is not None:
        chromatic = _as_str(chromatic, "chromatic", path)
        if not _NAME.fullmatch(chromatic) or chromatic not in objects:
            raise CaptureFormatError(
                path, f"chromatic object {chromatic!r} has no folder chromatic/{chromatic}"
            )
        meta["chromatic"] = chromatic
    if "dynamic" in obj:
        if not isinstance(obj["dynamic"], bool):
            raise CaptureFormatError(
                path, f"dynamic must be true or false, got {_show(obj['dynamic'])}"
            )
        meta["dynamic"] = obj["dynamic"]
    if obj.get("description") is not None:
        meta["description"] = _as_str(obj["description"], "description", path)
    return meta


def all_images(ds: Dataset) -> list[Path]:
    """Every image and silhouette the dataset lists, in a stable order."""
    cams = ds.rig.camera_names
    paths = [ds.photometric_image(p, c) for p in ds.poses for c in cams]
    paths += [
        ds.chromatic_image(o, col, c) for o in ds.chromatic_objects for col in COLOURS for c in cams
    ]
    for name, scene in sorted(ds.scenes.items()):
        for f in scene.frames:
            paths += [ds.frame_image(name, f, c) for c in cams]
            if scene.has_masks:
                paths += [ds.mask_image(name, f, c) for c in cams]
    return paths


def validate(dataset: str | Path, summary_json: str | Path | None = None) -> dict:
    """Validate a whole dataset, decoding every image, and summarise it.

    Parameters
    ----------
    dataset : the dataset folder (capture format, version 1).
    summary_json : optional path of a JSON summary to write (written only
        when the dataset is valid, atomically).

    Returns
    -------
    dict summary: cameras with their light colours, reciprocal pairs, board
    poses, chromatic objects, scenes with their frame counts, image count and
    the fraction of saturated pixels.

    Raises
    ------
    CaptureFormatError naming the first offending file.
    """
    ds = open_dataset(dataset)
    masks = {ds.mask_image(s, f, c) for s, sc in ds.scenes.items() if sc.has_masks
             for f in sc.frames for c in ds.rig.camera_names}  # fmt: skip
    n_pixels = n_saturated = 0
    paths = all_images(ds)
    for path in paths:
        if path in masks:
            read_mask(path, ds.rig.image)
            continue
        _, saturated = read_image(path, ds.rig.image)
        n_pixels += saturated.size
        n_saturated += int(saturated.sum())
    summary = {
        "dataset": str(Path(dataset).resolve()),
        "format": FORMAT,
        "image": {"width": ds.rig.image.width, "height": ds.rig.image.height,
                  "bit_depth": ds.rig.image.bit_depth},
        "cameras": {c.name: c.light_colour for c in ds.rig.cameras},
        "reciprocal_pairs": [
            [p.cam_a, COLOURS[p.channel_a], p.cam_b, COLOURS[p.channel_b]]
            for p in ds.rig.reciprocal_pairs()
        ],
        "poses": list(ds.poses),
        "chromatic_objects": list(ds.chromatic_objects),
        "scenes": {n: {"frames": len(s.frames), "dynamic": s.dynamic, "chromatic": s.chromatic,
                       "masks": s.has_masks, "ground_truth": s.has_gt}
                   for n, s in sorted(ds.scenes.items())},
        "images": len(paths),
        "saturated_fraction": n_saturated / max(n_pixels, 1),
    }  # fmt: skip
    if summary_json is not None:
        from colourhs.io import write_json

        write_json(summary_json, summary)
    return summary
