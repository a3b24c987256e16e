"""Capture images of a dataset, PNG or TIFF: header checks and decoding to normalised R, G, B.

:func:`read_image` decodes a 3-channel capture image to float32 R, G, B in
[0, 1] (black and white levels from the rig's
:class:`~colourhs.capture.rig.ImageSpec`) with its saturation mask;
:func:`read_mask` decodes a silhouette. A file's suffix names its format
(:data:`~colourhs.capture.base.IMAGE_FORMATS`: ``.png``, ``.tif``, ``.tiff``);
both formats pass the same checks (channels, unsigned samples, bit depth,
size) on their header, which is read without decoding pixels (a PNG's first 33
bytes, a TIFF's first image directory: :mod:`colourhs.capture.tiff`), so
:func:`colourhs.capture.layout.open_dataset` can check every image quickly.
Re-exported by :mod:`colourhs.capture`.
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import cv2
import numpy as np

from colourhs.capture.base import IMAGE_FORMATS, CaptureFormatError, _ImageHeader
from colourhs.capture.rig import ImageSpec
from colourhs.capture.tiff import Reader, is_tiff, parse_tiff_header

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


def _parse_png_header(path: Path, head: bytes) -> _ImageHeader:
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
    channels, kind, allowed = _PNG_COLOUR_TYPES.get(colour_type, (0, "", ()))
    if width == 0 or height == 0 or depth not in allowed:
        raise CaptureFormatError(path, "unreadable PNG: invalid IHDR chunk")
    return _ImageHeader(width, height, depth, channels, kind, "PNG")


def _image_format(path: Path) -> str:
    """``"PNG"`` or ``"TIFF"``, as the file's suffix (any case) names it."""
    fmt = IMAGE_FORMATS.get(path.suffix.lower())
    if fmt is None:
        raise CaptureFormatError(
            path, f"not an image file name: expected a suffix {', '.join(IMAGE_FORMATS)}"
        )
    return fmt


def _parse_header(path: Path, read: Reader) -> _ImageHeader:
    """The header of an image file in the format its suffix names.

    A file holding the other format's data is refused with the name it should have.
    """
    fmt = _image_format(path)
    head = read(0, _PNG_HEADER_BYTES)
    found = "PNG" if head.startswith(_PNG_SIGNATURE) else "TIFF" if is_tiff(head) else fmt
    if found != fmt:
        suffix = next(s for s, f in IMAGE_FORMATS.items() if f == found)
        raise CaptureFormatError(
            path, f"unreadable {fmt}: the file holds {found} data; name it {path.stem}{suffix}"
        )
    return parse_tiff_header(path, read) if fmt == "TIFF" else _parse_png_header(path, head)


def _read_header(path: Path, what: str) -> _ImageHeader:
    """Read only the header of an image file (fast: a few hundred bytes at most)."""
    try:
        with path.open("rb") as file:

            def read(offset: int, size: int) -> bytes:
                file.seek(offset)
                return file.read(size)

            return _parse_header(path, read)
    except FileNotFoundError:
        raise CaptureFormatError(path, f"{what} not found") from None
    except OSError as err:
        raise CaptureFormatError(path, f"cannot read {what}: {err.strerror}") from None


def _check_header(
    path: Path, header: _ImageHeader, spec: ImageSpec, channels: tuple[int, ...], depth: int
) -> None:
    """Refuse an image whose channels, sample format, bit depth or size is not the expected one."""
    wanted = " or ".join(map(str, channels))
    fmt = header.fmt
    if header.kind == "palette":
        raise CaptureFormatError(path, f"wrong channels: palette {fmt}, expected {wanted} channels")
    if header.channels not in channels:
        raise CaptureFormatError(
            path,
            f"wrong channels: {header.channels} channel(s) ({header.kind} {fmt}), "
            f"expected {wanted}",
        )
    if header.sample_format != "unsigned":
        raise CaptureFormatError(
            path,
            f"wrong sample format: {header.bit_depth}-bit {header.sample_format} {fmt}, "
            f"expected unsigned {depth}-bit integers",
        )
    if header.bit_depth != depth:
        raise CaptureFormatError(
            path, f"wrong bit depth: {header.bit_depth}-bit {fmt}, expected {depth}-bit"
        )
    if (header.width, header.height) != (spec.width, spec.height):
        raise CaptureFormatError(
            path,
            f"wrong image size: found {header.width}x{header.height}, expected "
            f"{spec.width}x{spec.height} (width x height)",
        )


def _check_image_header(path: Path, header: _ImageHeader, spec: ImageSpec) -> None:
    _check_header(path, header, spec, channels=(3,), depth=spec.bit_depth)


def _check_mask_header(path: Path, header: _ImageHeader, spec: ImageSpec) -> None:
    _check_header(path, header, spec, channels=(1, 3), depth=8)


def _decode(path: Path, fmt: str) -> np.ndarray | None:
    """The pixels of an image file (OpenCV channel order), None where OpenCV cannot decode them.

    A TIFF is decoded from its file, a PNG from its bytes: OpenCV's in-memory TIFF
    decoder fails on tiled 8-bit TIFFs that its file decoder reads.
    """
    try:
        if fmt == "TIFF":
            return cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        return cv2.imdecode(np.frombuffer(path.read_bytes(), np.uint8), cv2.IMREAD_UNCHANGED)
    except cv2.error:
        return None


def _load(path: Path, what: str) -> tuple[_ImageHeader, np.ndarray]:
    """Read a whole image file: its header and its decoded pixels (OpenCV channel order)."""
    header = _read_header(path, what)
    try:
        pixels = _decode(path, header.fmt)
    except OSError as err:
        raise CaptureFormatError(path, f"cannot read {what}: {err.strerror}") from None
    if pixels is None:
        raise CaptureFormatError(path, f"unreadable {header.fmt}: cannot decode the image data")
    return header, pixels


def read_image(path: str | Path, spec: ImageSpec) -> tuple[np.ndarray, np.ndarray]:
    """Read one capture image and normalise it.

    Parameters
    ----------
    path : str or Path
        A 3-channel image of the dataset: PNG (``.png``) or TIFF (``.tif``, ``.tiff``).
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
        Missing file, unreadable PNG or TIFF, not 3 channels, not unsigned integers,
        wrong size or bit depth; a TIFF with several images, JPEG compression or
        rotated pixels (:mod:`colourhs.capture.tiff`).
    """
    path = Path(path)
    header, bgr = _load(path, "image file")
    _check_image_header(path, header, spec)
    if bgr.shape != (spec.height, spec.width, 3) or bgr.dtype != spec.dtype:
        raise CaptureFormatError(
            path,
            f"unreadable {header.fmt}: decoded as {bgr.dtype} {bgr.shape}, expected 3 channels",
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
        An 8-bit PNG or TIFF with 1 or 3 channels, of the rig's image size.
    spec : ImageSpec
        The rig's image encoding (only the size is used).

    Returns
    -------
    ndarray of bool, shape (H, W)
        True on the object: where any channel is non-zero.

    Raises
    ------
    CaptureFormatError
        Missing file, unreadable PNG or TIFF, not 8-bit unsigned, not 1 or 3
        channels, or wrong size.
    """
    path = Path(path)
    header, pixels = _load(path, "mask file")
    _check_mask_header(path, header, spec)
    if pixels.shape[:2] != (spec.height, spec.width) or pixels.dtype != np.uint8:
        raise CaptureFormatError(
            path,
            f"unreadable {header.fmt}: decoded as {pixels.dtype} {pixels.shape}, expected 8-bit",
        )
    return pixels != 0 if pixels.ndim == 2 else np.any(pixels != 0, axis=2)
