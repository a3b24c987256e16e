"""TIFF headers of capture images: the first image's tags, read without decoding pixels.

A capture image may be a TIFF (``<camera>.tif`` or ``<camera>.tiff``, capture-format.md),
as scientific cameras often write. :func:`parse_tiff_header` reads the file header and
the first image file directory (IFD), classic TIFF or BigTIFF, either byte order, and
describes the image as an :class:`~colourhs.capture.base._ImageHeader`, like a PNG's,
so that :mod:`colourhs.capture.png` checks channels, sample format, bit depth and size
of both formats in one place. It reads a few hundred bytes wherever the directory lies,
so :func:`colourhs.capture.layout.open_dataset` checks every image quickly.

It refuses what would not be read faithfully: more than one image in the file (a
multi-page TIFF: which page is the capture?), lossy JPEG compression (the format's
values are measurements), separate colour planes (OpenCV does not decode them),
pixels stored in another order than top-left first (the Orientation tag: OpenCV's
unchanged read does not apply it, so the geometry would silently not match the
calibration) and colour models other than RGB, greyscale and palette (a raw Bayer
mosaic, YCbCr, CMYK, ...).
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from pathlib import Path

from colourhs.capture.base import CaptureFormatError, _ImageHeader

#: ``read(offset, size)``: at most ``size`` bytes of the file from ``offset``.
Reader = Callable[[int, int], bytes]

_BYTE_ORDERS = {b"II": "<", b"MM": ">"}
# magic number -> (entry count format, offset format, entry size, offset of the first IFD's offset)
_LAYOUTS = {42: ("H", "I", 12, 4), 43: ("Q", "Q", 20, 8)}  # classic TIFF, BigTIFF
_MAX_ENTRIES = 65535  # a classic IFD's most; real ones hold a few dozen

_WIDTH, _HEIGHT, _BITS, _COMPRESSION, _PHOTOMETRIC = 256, 257, 258, 259, 262
_ORIENTATION, _SAMPLES, _PLANAR, _SAMPLE_FORMAT = 274, 277, 284, 339
_TAGS = (
    _WIDTH,
    _HEIGHT,
    _BITS,
    _COMPRESSION,
    _PHOTOMETRIC,
    _ORIENTATION,
    _SAMPLES,
    _PLANAR,
    _SAMPLE_FORMAT,
)
# TIFF field type -> struct code: BYTE, SHORT, LONG, LONG8 (the types of the tags read here)
_TYPES = {1: "B", 3: "H", 4: "I", 16: "Q"}
_JPEG_COMPRESSIONS = (6, 7)
_PHOTOMETRIC_NAMES = {
    0: "WhiteIsZero greyscale",
    4: "transparency mask",
    5: "CMYK",
    6: "YCbCr",
    8: "CIELab",
    32803: "colour filter array (raw Bayer mosaic)",
    34892: "linear raw",
}
_SAMPLE_FORMATS = {1: "unsigned", 2: "signed", 3: "floating-point", 4: "untyped"}


def is_tiff(head: bytes) -> bool:
    """Whether ``head`` (a file's first bytes, 4 or more) starts a TIFF or BigTIFF file."""
    order = _BYTE_ORDERS.get(head[:2])
    return order is not None and len(head) >= 4 and _unpacked(order + "H", head[2:4]) in _LAYOUTS


def parse_tiff_header(path: Path, read: Reader) -> _ImageHeader:
    """Describe the image of a TIFF file from its first image file directory.

    Parameters
    ----------
    path : Path
        The file, for messages.
    read : Reader
        Reads bytes of the file at an offset (the file itself, or its bytes in memory).

    Returns
    -------
    _ImageHeader
        Size, bit depth, samples per pixel, colour model and sample format.

    Raises
    ------
    CaptureFormatError
        Not a TIFF file, a truncated or malformed directory, or a TIFF the format
        refuses: several images, JPEG compression, separate colour planes, an
        orientation other than top-left,
        samples of different depths, or a colour model other than RGB, greyscale, palette.
    """
    head = read(0, 16)
    if not is_tiff(head):
        raise CaptureFormatError(path, "unreadable TIFF: not a TIFF file")
    order = _BYTE_ORDERS[head[:2]]
    count_fmt, offset_fmt, entry_size, first_at = _LAYOUTS[_unpacked(order + "H", head[2:4])]
    ifd = _field(path, order + offset_fmt, head[first_at:])
    count_size, offset_size = struct.calcsize(count_fmt), struct.calcsize(offset_fmt)
    n = _field(path, order + count_fmt, read(ifd, count_size)) if ifd else 0
    if not 0 < n <= _MAX_ENTRIES:
        raise CaptureFormatError(path, f"unreadable TIFF: image directory of {n} entries")
    body = read(ifd + count_size, n * entry_size + offset_size)
    tags: dict[int, tuple[int, ...]] = {}
    for start in range(0, n * entry_size, entry_size):
        entry = _whole(path, body[start : start + entry_size], entry_size)
        # an entry: tag, field type, value count (offset-sized), value or its offset
        tag, kind, count = struct.unpack(order + "HH" + offset_fmt, entry[: 4 + offset_size])
        if tag in _TAGS:
            value = entry[4 + offset_size :]
            tags[tag] = _tag_values(path, (order, offset_fmt), (tag, kind, count), value, read)
    next_ifd = _field(path, order + offset_fmt, body[n * entry_size :])
    return _describe(path, tags, next_ifd)


def _unpacked(fmt: str, data: bytes) -> int:
    """The one integer ``fmt`` packs at the start of ``data`` (long enough)."""
    return struct.unpack(fmt, data[: struct.calcsize(fmt)])[0]


def _whole(path: Path, data: bytes, size: int) -> bytes:
    """``data``, refused as a truncated header when shorter than ``size`` bytes."""
    if len(data) < size:
        raise CaptureFormatError(path, "unreadable TIFF: truncated header")
    return data[:size]


def _field(path: Path, fmt: str, data: bytes) -> int:
    """The integer ``fmt`` packs at the start of ``data``; a truncated header otherwise."""
    return _unpacked(fmt, _whole(path, data, struct.calcsize(fmt)))


def _tag_values(
    path: Path,
    layout: tuple[str, str],
    entry: tuple[int, int, int],
    value: bytes,
    read: Reader,
) -> tuple[int, ...]:
    """The integers of a directory entry: in its value field, or at the offset it holds.

    ``layout`` is (byte order, offset format), ``entry`` (tag, field type, count).
    """
    order, offset_fmt = layout
    tag, kind, count = entry
    code = _TYPES.get(kind)
    if code is None or not 0 < count <= _MAX_ENTRIES:
        raise CaptureFormatError(
            path, f"unreadable TIFF: tag {tag} holds {count} values of field type {kind}"
        )
    fmt = f"{order}{count}{code}"
    size = struct.calcsize(fmt)
    data = value if size <= len(value) else read(_field(path, order + offset_fmt, value), size)
    return struct.unpack(fmt, _whole(path, data, size))


def _describe(path: Path, tags: dict[int, tuple[int, ...]], next_ifd: int) -> _ImageHeader:
    """The header of the first image from its tags (TIFF 6.0 defaults for absent ones)."""
    for tag, name in ((_WIDTH, "ImageWidth"), (_HEIGHT, "ImageLength")):
        if tag not in tags:
            raise CaptureFormatError(path, f"unreadable TIFF: no {name} tag")
    if _PHOTOMETRIC not in tags:
        raise CaptureFormatError(
            path, "unreadable TIFF: no PhotometricInterpretation tag (RGB or greyscale)"
        )
    if next_ifd:
        raise CaptureFormatError(
            path, "unsupported TIFF: more than one image (multi-page TIFF); save one per file"
        )
    if tags.get(_COMPRESSION, (1,))[0] in _JPEG_COMPRESSIONS:
        raise CaptureFormatError(
            path,
            "unsupported TIFF: lossy JPEG compression; save uncompressed or with a "
            "lossless compression (LZW, Deflate)",
        )
    if tags.get(_PLANAR, (1,))[0] != 1:
        raise CaptureFormatError(
            path,
            "unsupported TIFF: separate colour planes (planar configuration 2); save "
            "the samples of each pixel together (planar configuration 1, contiguous)",
        )
    orientation = tags.get(_ORIENTATION, (1,))[0]
    if orientation != 1:
        raise CaptureFormatError(
            path,
            f"unsupported TIFF: orientation {orientation} (pixels stored rotated or "
            "mirrored); save them top row first, left to right (orientation 1)",
        )
    bits = set(tags.get(_BITS, (1,)))
    formats = set(tags.get(_SAMPLE_FORMAT, (1,)))
    if len(bits) > 1 or len(formats) > 1:
        raise CaptureFormatError(
            path, f"unsupported TIFF: samples of different types (bits {sorted(bits)})"
        )
    photometric = tags[_PHOTOMETRIC][0]
    channels = tags.get(_SAMPLES, (1,))[0]
    kind = _colour_model(photometric, channels)
    if kind is None:
        name = _PHOTOMETRIC_NAMES.get(photometric, f"PhotometricInterpretation {photometric}")
        raise CaptureFormatError(
            path, f"unsupported TIFF colour model: {name} with {channels} sample(s), expected RGB"
        )
    width, height = tags[_WIDTH][0], tags[_HEIGHT][0]
    if width == 0 or height == 0:
        raise CaptureFormatError(path, f"unreadable TIFF: empty image ({width}x{height})")
    (sample_format,) = formats
    return _ImageHeader(
        width,
        height,
        bits.pop(),
        channels,
        kind,
        "TIFF",
        _SAMPLE_FORMATS.get(sample_format, f"SampleFormat {sample_format}"),
    )


def _colour_model(photometric: int, channels: int) -> str | None:
    """The colour model in the words of PNG's colour types; None where the format has none."""
    if photometric == 2 and channels >= 3:
        return {3: "RGB", 4: "RGBA"}.get(channels, f"RGB+{channels - 3} extra")
    if photometric == 1:
        return {1: "greyscale", 2: "greyscale+alpha"}.get(channels, f"greyscale+{channels - 1}")
    if photometric == 3:
        return "palette"
    return None
