"""The ChArUco target of rig.json's ``geometric_board``: its description and its geometry.

A ChArUco target (a chessboard with an ArUco marker in each white square) is what
the ``geometric/`` captures show, for a geometric calibration of the cameras. Its
description is a JSON object, rig.json's ``geometric_board`` block
(``docs/capture-format.md``), with the keys:

``type``
    ``"charuco"``.
``dictionary``
    Name of the OpenCV predefined ArUco dictionary (``DICT_...``) of its markers.
``squares``
    [squares_x, squares_y]: chessboard squares across (x) and down (y), integers >= 2.
``square_length``
    Side of a chessboard square, metres.
``marker_length``
    Side of a marker, metres, less than ``square_length``.

:func:`charuco_layout` builds (and checks) the description; rig.json's reader,
the printer (:mod:`colourhs.calibration.board`) and the renderer
(:mod:`colourhs.synth`) share it and the geometry below, so that what is printed,
rendered and read back is one target.

Target frame: the board frame of the capture format (x to the right, y down, the
target the plane z = 0, seen from its printed face) with the chessboard's outer
top-left corner as origin; the target is ``squares_x * square_length`` by
``squares_y * square_length`` metres. OpenCV's pattern (not its legacy one): the
top-left square (i, j) = (0, 0) is black, and square (i, j) is white where
``i + j`` is odd. Each white square holds a marker of side ``marker_length``
centred in it, axis-aligned, its top-left module at its top-left corner; the
markers' ids are 0, 1, ... row by row from the top left. Interior corner k
(row-major, ``(squares_x - 1) * (squares_y - 1)`` of them) lies at
``((k % (squares_x - 1) + 1) * square_length, (k // (squares_x - 1) + 1) *
square_length)``: :func:`charuco_corners`, the corner ids OpenCV's
:class:`cv2.aruco.CharucoDetector` reports.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import cv2
import numpy as np

__all__ = [
    "CHARUCO_MARKER_FRACTION",
    "DEFAULT_DICTIONARY",
    "aruco_dictionary",
    "charuco_black_squares",
    "charuco_board",
    "charuco_corners",
    "charuco_layout",
    "charuco_markers",
    "charuco_size",
    "checked_charuco",
]

DEFAULT_DICTIONARY = "DICT_5X5_100"
"""ArUco dictionary of a new printed target: 100 ids with more bits between any two than 4x4's."""

CHARUCO_MARKER_FRACTION = 0.75
"""A ChArUco marker's side as a fraction of its square's when none is given."""


def aruco_dictionary(name: str) -> cv2.aruco.Dictionary:
    """OpenCV's predefined ArUco dictionary ``name`` (``"DICT_4X4_50"``, ...).

    Raises
    ------
    ValueError
        For a name OpenCV does not know, listing the names it knows.
    """
    code = getattr(cv2.aruco, name, None) if str(name).startswith("DICT_") else None
    if not isinstance(code, int):
        known = ", ".join(n for n in dir(cv2.aruco) if n.startswith("DICT_"))
        raise ValueError(f"unknown ArUco dictionary {name!r}; OpenCV's: {known}")
    return cv2.aruco.getPredefinedDictionary(code)


def charuco_layout(
    squares_x: int,
    squares_y: int,
    square_length: float,
    marker_length: float,
    dictionary: str = DEFAULT_DICTIONARY,
) -> dict[str, Any]:
    """The JSON description of a ChArUco target (the keys are in the module's docstring).

    Parameters
    ----------
    squares_x, squares_y : int
        Chessboard squares across and down, >= 2 each.
    square_length : float
        Side of a square, metres.
    marker_length : float
        Side of a marker, metres; less than ``square_length``.
    dictionary : str
        OpenCV predefined ArUco dictionary of the markers.

    Returns
    -------
    dict
        ``{"type": "charuco", "dictionary", "squares": [x, y], "square_length",
        "marker_length"}``: squares as ints, lengths as floats.

    Raises
    ------
    ValueError
        For an unknown dictionary, fewer than 2 squares a way, a non-positive length,
        a marker not smaller than its square, or more markers than the dictionary has.
    """
    aruco = aruco_dictionary(dictionary)
    sx, sy = int(squares_x), int(squares_y)
    if sx != squares_x or sy != squares_y or sx < 2 or sy < 2:
        raise ValueError(
            f"a ChArUco target needs at least 2 x 2 squares (whole numbers), got "
            f"{squares_x} x {squares_y}"
        )
    square, marker = float(square_length), float(marker_length)
    if not (math.isfinite(square) and square > 0):
        raise ValueError(f"square length must be a positive number of metres, got {square:g}")
    if not (math.isfinite(marker) and 0 < marker < square):
        raise ValueError(
            f"marker length {_mm(marker)} mm must be positive and less than the square "
            f"length {_mm(square)} mm (the marker sits inside a white square)"
        )
    needed, capacity = sx * sy // 2, int(aruco.bytesList.shape[0])
    if needed > capacity:
        raise ValueError(
            f"a {sx} x {sy} ChArUco target has {needed} markers; {dictionary} has only "
            f"{capacity} ids: give fewer squares or a larger dictionary"
        )
    return {
        "type": "charuco",
        "dictionary": dictionary,
        "squares": [sx, sy],
        "square_length": square,
        "marker_length": marker,
    }


def checked_charuco(layout: Mapping[str, Any]) -> dict[str, Any]:
    """``layout`` checked and normalised by :func:`charuco_layout` (a new dict).

    Raises
    ------
    ValueError
        If ``layout`` is not a ChArUco description :func:`charuco_layout` accepts.
    """
    if layout.get("type") != "charuco":
        raise ValueError(f"not a ChArUco description (type {layout.get('type')!r})")
    try:
        sx, sy = layout["squares"]
        return charuco_layout(
            sx, sy, layout["square_length"], layout["marker_length"], layout["dictionary"]
        )
    except (KeyError, TypeError) as err:
        raise ValueError(f"ChArUco description without a valid {err}") from None


def charuco_board(layout: Mapping[str, Any]) -> cv2.aruco.CharucoBoard:
    """The :class:`cv2.aruco.CharucoBoard` of a :func:`charuco_layout` description
    (OpenCV's pattern, not the legacy one: the frame of the module's docstring).

    Raises
    ------
    ValueError
        If the description is not one :func:`charuco_layout` accepts.
    """
    c = checked_charuco(layout)
    board = cv2.aruco.CharucoBoard(
        tuple(c["squares"]),
        c["square_length"],
        c["marker_length"],
        aruco_dictionary(c["dictionary"]),
    )
    board.setLegacyPattern(False)
    return board


def charuco_size(layout: Mapping[str, Any]) -> tuple[float, float]:
    """Width and height of the target (its chessboard), metres."""
    (sx, sy), square = layout["squares"], float(layout["square_length"])
    return sx * square, sy * square


def _squares(layout: Mapping[str, Any], white: bool) -> list[tuple[int, int]]:
    """The (i, j) (column, row) of the white or the black squares, row by row."""
    sx, sy = layout["squares"]
    return [(i, j) for j in range(sy) for i in range(sx) if (i + j) % 2 == int(white)]


def charuco_markers(layout: Mapping[str, Any]) -> dict[int, np.ndarray]:
    """Marker id -> centre (2,) in the target frame, metres: one marker centred in each
    white square, ids 0, 1, ... row by row."""
    square = float(layout["square_length"])
    return {
        k: (np.array([i, j], float) + 0.5) * square
        for k, (i, j) in enumerate(_squares(layout, white=True))
    }


def charuco_black_squares(layout: Mapping[str, Any]) -> np.ndarray:
    """The black chessboard squares (K, 4) as x0, y0, x1, y1 in the target frame, metres,
    row by row."""
    square = float(layout["square_length"])
    cells = np.array(_squares(layout, white=False), float).reshape(-1, 2)
    return np.concatenate([cells, cells + 1.0], axis=1) * square


def charuco_corners(layout: Mapping[str, Any]) -> np.ndarray:
    """The interior chessboard corners (N, 3) in the target frame, metres, z = 0; row k is
    the corner of ChArUco id k (row-major from the top left)."""
    (sx, sy), square = layout["squares"], float(layout["square_length"])
    i, j = np.meshgrid(np.arange(1, sx), np.arange(1, sy))
    return np.column_stack([i.ravel() * square, j.ravel() * square, np.zeros(i.size)])


def _mm(metres: float) -> str:
    """A length in metres as millimetres for a message or caption (to 0.01 mm)."""
    return f"{round(metres * 1e3, 2):g}"
