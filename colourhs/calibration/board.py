"""Printable calibration targets: the white marker board of rig.json and a ChArUco target.

The marker board. :func:`board_layout` lays out a regular grid of ArUco markers
(ids 0 to n - 1, row by row from the top left) on a white board and returns the
``board`` block of rig.json (``docs/capture-format.md``: ``dictionary``,
``marker_length`` in metres, ``size`` [width, height] in metres, ``markers``
{id: centre [x, y] in metres}); the block is checked by rig.json's own reader
(:func:`check_board_block`). The outer markers keep a white gap to the board's
edge and the others are spread evenly between them, so the board's middle stays
white (the photometric calibration's surface) and the markers span the board
(the pose's lever arm).

Board frame (capture format): origin at the board's top-left corner, x to the
right, y down, seen from its white face. Each marker is drawn as OpenCV's
:func:`cv2.aruco.generateImageMarker` image with its top-left module at the
marker's corner 0 (:meth:`colourhs.capture.Board.marker_corners`: top-left,
top-right, bottom-right, bottom-left), its rows along the board's y: the corner
order that :func:`colourhs.calibration.markers.detect_markers` returns and the
pose fit matches to the board model.

The ChArUco target (for a geometric calibration of the cameras).
:func:`charuco_layout` describes it as a JSON object, rig.json's
``geometric_board`` block, and :func:`charuco_board` builds the matching
:class:`cv2.aruco.CharucoBoard`; both, the description's keys and the target's
frame are :mod:`colourhs.capture.targets` (re-exported here), which rig.json's
reader and the renderer share.

Printing. :func:`render_board` rasterises either target at true scale (each
pixel the exact share of it that is white). :func:`write_board` writes a
print: PNG (its resolution in the file's pHYs chunk), SVG (vector: one
rectangle per black module or square, millimetres) or PDF (vector, page size =
board + margin), each with crop marks at the board's corners, a labelled scale
bar and a one-line caption in the margin outside the board, and writes the
rig.json block beside it as JSON.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from colourhs.capture import Board, rig_from_dict
from colourhs.capture.targets import (
    CHARUCO_MARKER_FRACTION,
    DEFAULT_DICTIONARY,
    charuco_black_squares,
    charuco_board,
    charuco_layout,
    charuco_markers,
)
from colourhs.capture.targets import _mm as _mm
from colourhs.capture.targets import aruco_dictionary as _dictionary
from colourhs.capture.targets import checked_charuco as _checked_charuco
from colourhs.common.files import atomic_output

__all__ = [
    "CHARUCO_MARKER_FRACTION",
    "DEFAULT_DICTIONARY",
    "DEFAULT_MARKER_LENGTH",
    "DEFAULT_SIZE",
    "GAP_CELLS",
    "PAGE_FOOTER_M",
    "PAGE_MARGIN_M",
    "board_layout",
    "charuco_board",
    "charuco_layout",
    "check_board_block",
    "json_path",
    "render_board",
    "write_board",
]

M_PER_INCH = 0.0254
"""Metres per inch (a dpi of d is d / M_PER_INCH pixels per metre)."""

DEFAULT_SIZE = (0.30, 0.22)
"""Width and height of a new marker board, metres (the capture format's example)."""

DEFAULT_MARKER_LENGTH = 0.04
"""Side of a new board's markers, metres (the capture format's example)."""

GAP_CELLS = 2.0
"""Least white gap between two markers, and between a marker and the board's edge,
in marker cells (modules, border included): the quiet zone the detector needs around
a marker's black border and the white margin its edge refinement samples."""

PAGE_MARGIN_M = 0.012
"""White margin of a print left of, right of and above the board, metres (crop marks)."""

PAGE_FOOTER_M = 0.026
"""White margin of a print below the board, metres (crop marks, scale bar, caption)."""

_CROP_GAP_M = 0.003  # crop marks start this far from the board's corner
_CROP_LENGTH_M = 0.006  # and are this long
_LINE_M = 0.0002  # width of crop marks and scale-bar ticks
_BAR_TOP_M = 0.012  # below the board: top of the scale bar's end ticks
_BAR_TICK_M = 0.003  # height of its end ticks (its 10 mm ticks: half)
_BAR_THICK_M = 0.0006  # thickness of the bar
_BAR_LENGTHS_M = (0.1, 0.05, 0.02, 0.01)  # the longest that fits is drawn
_CAPTION_BASELINE_M = 0.021  # below the board
_EM_M = 0.0035  # font size of the caption and the bar's label (about 10 pt)
_EM_WIDTH = 0.62  # mean advance of a character, in em, for fitting the caption


# --------------------------------------------------------------------------------------------
# Layouts


def board_layout(
    dictionary: str = DEFAULT_DICTIONARY,
    size: tuple[float, float] = DEFAULT_SIZE,
    marker_length: float = DEFAULT_MARKER_LENGTH,
    n_markers: int | None = None,
    gap: float | None = None,
) -> dict[str, Any]:
    """The ``board`` block of rig.json for a regular grid of markers on a white board.

    The grid has as many columns and rows as needed for ``n_markers``, its cells
    as close to square as the board allows; markers fill it row by row from the
    top left, ids 0 to n - 1 (the last row may have empty places). The outer
    markers lie ``gap`` from the board's edge and the others evenly between them.

    Parameters
    ----------
    dictionary : str
        OpenCV predefined ArUco dictionary, e.g. ``"DICT_5X5_100"``.
    size : (float, float)
        Board width and height, metres.
    marker_length : float
        Side of every marker, metres.
    n_markers : int, optional
        Number of markers. None: the densest grid that fits (at most the
        dictionary's number of ids).
    gap : float, optional
        Least white gap between two markers and between a marker and the board's
        edge, metres. None: :data:`GAP_CELLS` marker cells.

    Returns
    -------
    dict
        JSON-able block: ``dictionary``, ``marker_length`` (m), ``size`` [w, h] (m),
        ``markers`` {"id": [x, y]} (centres in the board frame, m, rounded to 1 um).

    Raises
    ------
    ValueError
        For an unknown dictionary, a non-positive length, more markers than the
        dictionary has, or markers that do not fit on the board (the message says
        how many fit); :class:`colourhs.capture.CaptureFormatError` (a ValueError) if
        the block breaks rig.json's rules.
    """
    aruco = _dictionary(dictionary)
    capacity = int(aruco.bytesList.shape[0])
    w, h = (float(v) for v in size)
    length = float(marker_length)
    for name, value in (("marker length", length), ("board width", w), ("board height", h)):
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a positive number of metres, got {value:g}")
    gap = GAP_CELLS * length / (aruco.markerSize + 2) if gap is None else float(gap)
    if not (math.isfinite(gap) and gap >= 0):
        raise ValueError(f"gap must be a non-negative number of metres, got {gap:g}")
    nx_max, ny_max = (_fits(extent, length, gap) for extent in (w, h))
    if nx_max < 1 or ny_max < 1:
        raise ValueError(
            f"a {_mm(length)} mm marker with a {_mm(gap)} mm white gap to the edge needs a "
            f"board of at least {_mm(length + 2 * gap)} mm each way; the board is "
            f"{_mm(w)} x {_mm(h)} mm: give a smaller marker length or a larger board"
        )
    if n_markers is None:
        n = min(nx_max * ny_max, capacity)
    else:
        n = int(n_markers)
        if n < 1:
            raise ValueError(f"the number of markers must be at least 1, got {n}")
        if n > capacity:
            raise ValueError(f"{dictionary} has {capacity} marker ids; {n} markers asked for")
        if n > nx_max * ny_max:
            raise ValueError(
                f"{n} markers of {_mm(length)} mm do not fit on a {_mm(w)} x {_mm(h)} mm board: "
                f"at most {nx_max} x {ny_max} = {nx_max * ny_max} with {_mm(gap)} mm white "
                "gaps; give fewer markers, a smaller marker length or a larger board"
            )
    nx, ny = _grid_shape(n, (nx_max, ny_max), (w, h))
    xs, ys = _spread(nx, w, length, gap), _spread(ny, h, length, gap)
    block = {
        "dictionary": dictionary,
        "marker_length": length,
        "size": [w, h],
        "markers": {
            str(k): [round(float(xs[k % nx]), 6), round(float(ys[k // nx]), 6)] for k in range(n)
        },
    }
    check_board_block(block)
    return block


def _fits(extent: float, length: float, gap: float) -> int:
    """Markers of side ``length`` across ``extent`` with ``gap`` between them and at the ends."""
    return int(math.floor((extent - gap) / (length + gap) + 1e-9))


def _grid_shape(n: int, most: tuple[int, int], size: tuple[float, float]) -> tuple[int, int]:
    """Columns and rows for ``n`` markers within ``most``: squarest cells, then fewest empty."""
    shapes = set()
    for rows in range(1, min(n, most[1]) + 1):
        cols = math.ceil(n / rows)
        if cols <= most[0]:
            shapes.add((cols, math.ceil(n / cols)))

    def cost(shape):
        cols, rows = shape
        return abs(math.log((size[0] / cols) / (size[1] / rows))), cols * rows - n

    return min(sorted(shapes), key=cost)


def _spread(count: int, extent: float, length: float, gap: float) -> np.ndarray:
    """Centres of ``count`` markers across ``extent``: ends ``gap`` from the edges, even steps."""
    if count == 1:
        return np.array([extent / 2])
    return np.linspace(gap + length / 2, extent - gap - length / 2, count)


def check_board_block(block: Mapping[str, Any]) -> Board:
    """The :class:`~colourhs.capture.Board` of a rig.json ``board`` block, checked as
    rig.json's reader checks it (:func:`colourhs.capture.rig_from_dict`: its schema,
    a dictionary OpenCV knows, unique ids in the dictionary, markers wholly on the board).

    Raises
    ------
    CaptureFormatError
        A ValueError naming the key and the problem (``board.markers: ...``).
    """
    rig = {
        "format": "colourhs-capture/1",
        "units": "m",
        "image": {"width": 1, "height": 1, "bit_depth": 8, "black_level": 0, "white_level": 255},
        "cameras": [
            {
                "name": colour,
                "K": np.eye(3).tolist(),
                "R": np.eye(3).tolist(),
                "t": [0.0, 0.0, 0.0],
                "light": {"colour": colour},
            }
            for colour in ("red", "green", "blue")
        ],
        "board": dict(block),
        "chromatic_light": {"position": [0.0, 0.0, 0.0]},
    }
    return rig_from_dict(rig, "board block").board


# --------------------------------------------------------------------------------------------
# Drawing: black axis-aligned rectangles (x0, y0, x1, y1) in metres


@dataclass(frozen=True)
class _Target:
    """What a print shows: the board's black rectangles and what is written beside it."""

    size: tuple[float, float]  # board width, height, m
    black: np.ndarray  # (N, 4) x0, y0, x1, y1, board frame, m; they do not overlap
    caption: str
    key: str  # rig.json key of ``block``
    block: dict[str, Any]


@dataclass(frozen=True)
class _Text:
    x: float  # left end of the baseline, page frame, m
    y: float
    em: float  # font size, m
    text: str


@dataclass(frozen=True)
class _Page:
    size: tuple[float, float]  # m
    board: np.ndarray  # (N, 4) the board's black rectangles, page frame, m
    marks: np.ndarray  # (M, 4) crop marks and scale bar, page frame, m
    texts: tuple[_Text, ...]
    title: str


def _target(board: Board | Mapping[str, Any]) -> _Target:
    if isinstance(board, Mapping) and board.get("type") == "charuco":
        return _charuco_target(_checked_charuco(board))
    if not isinstance(board, Board):
        board = check_board_block(board)
    aruco = _dictionary(board.dictionary)
    black = [_marker_modules(aruco, mid, board.marker_corners(mid)[:, :2]) for mid in board.markers]
    w, h = board.size
    ids = sorted(board.markers)
    block = {
        "dictionary": board.dictionary,
        "marker_length": float(board.marker_length),
        "size": [float(w), float(h)],
        "markers": {str(m): [float(v) for v in board.markers[m]] for m in ids},
    }
    caption = (
        f"{board.dictionary}, {len(ids)} markers of {_mm(board.marker_length)} mm, board "
        f"{_mm(w)} x {_mm(h)} mm between the crop marks; print at 100 % (actual size)"
    )
    return _Target((float(w), float(h)), np.concatenate(black), caption, "board", block)


def _charuco_target(layout: dict[str, Any]) -> _Target:
    """The print of a ChArUco target: its markers' modules (checked against OpenCV's
    board, so the print is what OpenCV's detector expects) and its black squares."""
    board = charuco_board(layout)
    aruco = _dictionary(layout["dictionary"])
    (sx, sy), square, length = layout["squares"], layout["square_length"], layout["marker_length"]
    unit = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])  # TL, TR, BR, BL
    centres = charuco_markers(layout)
    ids = [int(mid) for mid in np.ravel(board.getIds())]
    if ids != list(centres):
        raise RuntimeError(f"OpenCV's ChArUco marker ids {ids} are not {list(centres)}")
    black = []
    for cv_corners, mid in zip(board.getObjPoints(), ids, strict=True):
        cv_corners = np.asarray(cv_corners, float).reshape(4, 3)[:, :2]
        # The same corners in float64 (OpenCV keeps float32), in OpenCV's order.
        corners = centres[mid] - length / 2 + unit * length
        if not np.allclose(corners, cv_corners, rtol=0.0, atol=1e-6):
            raise RuntimeError(f"OpenCV's ChArUco marker {mid} is not where expected: {cv_corners}")
        black.append(_marker_modules(aruco, mid, corners))
    black.append(charuco_black_squares(layout))
    caption = (
        f"ChArUco {sx} x {sy} squares of {_mm(square)} mm, {layout['dictionary']} markers of "
        f"{_mm(layout['marker_length'])} mm, board {_mm(sx * square)} x {_mm(sy * square)} mm; "
        "print at 100 % (actual size)"
    )
    size = (sx * square, sy * square)
    return _Target(size, np.concatenate(black), caption, "geometric_board", dict(layout))


def _marker_modules(aruco: cv2.aruco.Dictionary, marker_id: int, corners: np.ndarray) -> np.ndarray:
    """Black modules (K, 4) of one marker whose corners (4, 2) are TL, TR, BR, BL, metres.

    The marker image's columns run from corner 0 to corner 1 and its rows from
    corner 0 to corner 3 (the detector's corner order); the square is axis-aligned.
    """
    n = aruco.markerSize + 2
    bits = cv2.aruco.generateImageMarker(aruco, int(marker_id), n)  # one pixel per module
    rows, cols = np.nonzero(bits < 128)
    c0 = np.asarray(corners[0], float)
    across, down = (corners[1] - c0) / n, (corners[3] - c0) / n
    a = c0 + cols[:, None] * across + rows[:, None] * down
    b = a + across + down
    return np.column_stack([np.minimum(a, b), np.maximum(a, b)])


def _page(target: _Target) -> _Page:
    """The print: the board at ``PAGE_MARGIN_M`` from the top left, its marks and texts."""
    w, h = target.size
    m = PAGE_MARGIN_M
    size = (w + 2 * m, h + m + PAGE_FOOTER_M)
    g, c, t = _CROP_GAP_M, _CROP_LENGTH_M, _LINE_M / 2
    marks = []
    for x, y, sx, sy in ((0, 0, -1, -1), (w, 0, 1, -1), (w, h, 1, 1), (0, h, -1, 1)):
        ends = sorted((x + sx * g, x + sx * (g + c)))  # along the edge y = const, outside
        marks.append([ends[0], y - t, ends[1], y + t])
        ends = sorted((y + sy * g, y + sy * (g + c)))  # along the edge x = const, outside
        marks.append([x - t, ends[0], x + t, ends[1]])
    bar = next((b for b in _BAR_LENGTHS_M if b + 0.015 <= w + m), _BAR_LENGTHS_M[-1])
    top, bottom = h + _BAR_TOP_M, h + _BAR_TOP_M + _BAR_TICK_M
    marks.append([0.0, bottom - _BAR_THICK_M, bar, bottom])
    for k in range(int(round(bar / 0.01)) + 1):
        x = min(max(k * 0.01, t), bar - t)
        end = k == 0 or abs(k * 0.01 - bar) < 1e-9
        marks.append([x - t, top if end else bottom - _BAR_TICK_M / 2, x + t, bottom])
    em = min(_EM_M, (size[0] - 2 * m) / (_EM_WIDTH * len(target.caption)))
    texts = (
        _Text(m + bar + 0.002, m + bottom, min(_EM_M, em * 1.2), f"{_mm(bar)} mm"),
        _Text(m, m + h + _CAPTION_BASELINE_M, em, target.caption),
    )
    shift = np.array([m, m, m, m])
    return _Page(size, target.black + shift, np.array(marks) + shift, texts, target.caption)


# --------------------------------------------------------------------------------------------
# Raster


def render_board(board: Board | Mapping[str, Any], dpi: float = 600) -> np.ndarray:
    """The board alone (no margin) at true scale, 8-bit grey.

    Parameters
    ----------
    board : Board or dict
        A :class:`~colourhs.capture.Board`, a rig.json ``board`` block
        (:func:`board_layout`) or a ChArUco description (:func:`charuco_layout`).
    dpi : float
        Resolution, dots per inch: ``dpi / 0.0254`` pixels per metre.

    Returns
    -------
    ndarray of uint8, shape (round(height * px_per_m), round(width * px_per_m))
        255 white, 0 black; a pixel on a module's edge has the grey of its white
        share. Pixel (u, v), with (0, 0) the centre of the top-left pixel, shows
        board point ((u + 0.5) / px_per_m, (v + 0.5) / px_per_m) metres.
    """
    target = _target(board)
    return _rasterise(target.black, target.size, _px_per_m(dpi))


def _px_per_m(dpi: float) -> float:
    dpi = float(dpi)
    if not (math.isfinite(dpi) and dpi > 0):
        raise ValueError(f"dpi must be a positive number, got {dpi:g}")
    return dpi / M_PER_INCH


def _rasterise(black: np.ndarray, size: tuple[float, float], px_per_m: float) -> np.ndarray:
    """White image of ``size`` metres with the black rectangles (N, 4) drawn by area coverage.

    A rectangle's coverage of a pixel is the product of its overlaps along x and y,
    so each pixel's grey is its exact white share (the rectangles do not overlap).
    """
    width, height = (int(round(v * px_per_m)) for v in size)
    cover = np.zeros((height, width), np.float32)
    for x0, y0, x1, y1 in np.asarray(black, float) * px_per_m:
        cols, ox = _overlaps(x0, x1, width)
        rows, oy = _overlaps(y0, y1, height)
        if cols.size and rows.size:
            cover[rows[0] : rows[-1] + 1, cols[0] : cols[-1] + 1] += np.outer(oy, ox)
    return np.rint(255.0 * (1.0 - np.clip(cover, 0.0, 1.0))).astype(np.uint8)


def _overlaps(a: float, b: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Pixels (indices in [0, n)) that the interval [a, b] (pixel units) meets, and by how much."""
    idx = np.arange(max(int(math.floor(a)), 0), min(int(math.ceil(b)), n))
    return idx, np.clip(np.minimum(idx + 1, b) - np.maximum(idx, a), 0.0, 1.0)


def _page_image(page: _Page, px_per_m: float) -> np.ndarray:
    image = _rasterise(np.concatenate([page.board, page.marks]), page.size, px_per_m)
    for text in page.texts:
        _put_text(image, text, px_per_m)
    return image


def _put_text(image: np.ndarray, text: _Text, px_per_m: float) -> None:
    """Draw ``text`` (cap height 0.72 em) with OpenCV's Hershey font, in place."""
    font = cv2.FONT_HERSHEY_SIMPLEX
    (width, cap), _ = cv2.getTextSize(text.text, font, 1.0, 1)
    origin = (int(round(text.x * px_per_m)), int(round(text.y * px_per_m)))
    scale = min(0.72 * text.em * px_per_m / cap, (image.shape[1] - origin[0] - 1) / width)
    thickness = max(1, int(round(scale * 1.5)))
    cv2.putText(image, text.text, origin, font, scale, 0, thickness, cv2.LINE_AA)


# --------------------------------------------------------------------------------------------
# Prints


def json_path(out_path: str | Path, board: Board | Mapping[str, Any]) -> Path:
    """Where :func:`write_board` writes the rig.json block of a print ``out_path``.

    ``OUT.board.json`` for a marker board, ``OUT.geometric_board.json`` for a ChArUco
    target (``OUT`` the print's name without its suffix): named after the rig.json key
    the file holds.
    """
    key = "geometric_board" if isinstance(board, Mapping) and board.get("type") else "board"
    out_path = Path(out_path)
    return out_path.with_name(f"{out_path.stem}.{key}.json")


def write_board(
    board: Board | Mapping[str, Any], out_path: str | Path, dpi: float = 600
) -> tuple[Path, Path]:
    """Write a print of a marker board or ChArUco target and its rig.json block.

    The page is the board plus a white margin (:data:`PAGE_MARGIN_M` left, right and
    above, :data:`PAGE_FOOTER_M` below) holding crop marks at the board's corners, a
    scale bar (100 mm where it fits) with its label and a one-line caption; nothing is
    drawn on the board but its markers (and a ChArUco target's squares).

    Parameters
    ----------
    board : Board or dict
        As :func:`render_board` takes.
    out_path : str or Path
        The print: ``.png`` (8-bit grey at ``dpi`` rounded to whole pixels per
        metre, which the file's pHYs chunk records), ``.svg`` (millimetres, one
        rectangle per black module or square) or ``.pdf`` (vector, page size =
        board + margin at true scale).
    dpi : float
        Resolution of a PNG, dots per inch (SVG and PDF are vector).

    Returns
    -------
    (Path, Path)
        The print and the JSON beside it (:func:`json_path`): ``{"board": block}`` or
        ``{"geometric_board": description}``, a fragment of rig.json.

    Raises
    ------
    ValueError
        For another suffix, a non-positive dpi, or a board that is not valid.
    """
    out_path = Path(out_path)
    suffix = out_path.suffix.lower()
    writers = {".png": _write_png, ".svg": _write_svg, ".pdf": _write_pdf}
    if suffix not in writers:
        raise ValueError(f"{out_path}: the print must be a .pdf, .png or .svg file")
    px_per_m = _px_per_m(dpi)
    target = _target(board)
    page = _page(target)
    with atomic_output(out_path) as tmp:
        writers[suffix](page, tmp, px_per_m)
    written = json_path(out_path, target.block)
    with atomic_output(written) as tmp:
        tmp.write_text(_fragment(target.key, target.block), encoding="utf-8")
    return out_path, written


def _fragment(key: str, block: dict[str, Any]) -> str:
    """``{key: block}`` as indented JSON with each list of numbers on one line."""
    text = json.dumps({key: block}, indent=2)
    return re.sub(r"\[[^\[\]{}\"]*\]", lambda m: json.dumps(json.loads(m.group(0))), text) + "\n"


def _write_png(page: _Page, path: Path, px_per_m: float) -> None:
    """The page rendered at whole pixels per metre, the value PNG's pHYs chunk holds."""
    from PIL import Image

    px_per_m = float(max(1, round(px_per_m)))
    dpi = px_per_m * M_PER_INCH
    Image.fromarray(_page_image(page, px_per_m)).save(path, format="PNG", dpi=(dpi, dpi))


def _write_svg(page: _Page, path: Path, _px_per_m: float) -> None:
    path.write_text(_svg(page), encoding="utf-8")


def _svg(page: _Page) -> str:
    """The page as SVG in millimetres: a white sheet, the board's and the marks' rectangles."""
    w, h = (_num(v * 1e3) for v in page.size)
    lines = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}mm" height="{h}mm" '
        f'viewBox="0 0 {w} {h}">',
        f"<title>{_escape(page.title)}</title>",
        f'<rect x="0" y="0" width="{w}" height="{h}" fill="#fff"/>',
    ]
    for name, rects in (("board", page.board), ("marks", page.marks)):
        lines.append(f'<g id="{name}" fill="#000" shape-rendering="crispEdges">')
        lines += [
            f'<rect x="{_num(x0)}" y="{_num(y0)}" '
            f'width="{_num(x1 - x0)}" height="{_num(y1 - y0)}"/>'
            for x0, y0, x1, y1 in np.asarray(rects, float) * 1e3
        ]
        lines.append("</g>")
    lines += [
        f'<text x="{_num(t.x * 1e3)}" y="{_num(t.y * 1e3)}" font-size="{_num(t.em * 1e3)}" '
        f'font-family="DejaVu Sans, Helvetica, Arial, sans-serif">{_escape(t.text)}</text>'
        for t in page.texts
    ]
    lines.append("</svg>")
    return "\n".join(lines) + "\n"


def _write_pdf(page: _Page, path: Path, _px_per_m: float) -> None:
    """The page as a vector PDF of the page's size (matplotlib, 1 data unit = 1 mm)."""
    from matplotlib.collections import PolyCollection
    from matplotlib.figure import Figure

    w, h = (v * 1e3 for v in page.size)
    fig = Figure(figsize=(page.size[0] / M_PER_INCH, page.size[1] / M_PER_INCH))
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    ax.set_axis_off()
    ax.set_xlim(0.0, w)
    ax.set_ylim(h, 0.0)
    rects = np.concatenate([page.board, page.marks]) * 1e3
    x0, y0, x1, y1 = rects.T
    polygons = np.stack([np.c_[x0, y0], np.c_[x1, y0], np.c_[x1, y1], np.c_[x0, y1]], axis=1)
    ax.add_collection(
        PolyCollection(
            polygons, facecolors="black", edgecolors="none", linewidths=0, antialiased=False
        ),
        autolim=False,
    )
    for t in page.texts:
        ax.text(
            t.x * 1e3,
            t.y * 1e3,
            t.text,
            fontsize=t.em / M_PER_INCH * 72.0,
            fontfamily="DejaVu Sans",
            ha="left",
            va="baseline",
        )
    fig.savefig(path, format="pdf", metadata={"Title": page.title, "Creator": "colourhs board"})


def _num(value: float) -> str:
    """A length in millimetres for SVG: up to 6 decimals (1 nm), no trailing zeros."""
    text = f"{value:.6f}".rstrip("0").rstrip(".")
    return "0" if text in ("", "-0") else text


def _escape(text: str) -> str:
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
