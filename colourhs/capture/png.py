"""PNG images of a dataset: header checks and decoding to normalised R, G, B.

:func:`read_image` decodes a 3-channel capture image to float32 R, G, B in
[0, 1] (black and white levels from the rig's
:class:`~colourhs.capture.rig.ImageSpec`) with its saturation mask;
:func:`read_mask` decodes a silhouette. The header checks (signature, IHDR,
channels, bit depth, size) read only a file's first 33 bytes, so
:func:`colourhs.capture.layout.open_dataset` can check every image quickly.
Re-exported by :mod:`colourhs.capture`.
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path
from typing import NamedTuple

import cv2
import numpy as np

from colourhs.capture.base import CaptureFormatError
from colourhs.capture.rig import ImageSpec

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
