"""What every part of the capture reader shares: the format's constants and its errors.

The format's version string (:data:`FORMAT`), the light and channel colours
(:data:`COLOURS`), the name rule of cameras and folders, the image file
suffixes (:data:`IMAGE_FORMATS`) and what a decoder-free look at an image file
tells (:class:`_ImageHeader`, shared by the PNG and TIFF readers), the two intensity
thresholds that follow from the format's "no ambient light" rule
(:data:`LIT_THRESHOLD`, :data:`MIN_SIGNAL`), and the errors the reader raises:
:class:`CaptureFormatError` (a file breaks the format) and
:class:`UnknownNameError` (a lookup by a name the dataset does not have).
Re-exported by :mod:`colourhs.capture`.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import NamedTuple

FORMAT = "colourhs-capture/1"
"""Value of the ``format`` key of rig.json that :mod:`colourhs.capture` reads."""

COLOURS = ("red", "green", "blue")
"""Light / channel colours; the index of a colour is its image channel (R, G, B)."""

_NAME = re.compile(r"[A-Za-z0-9_-]+")

IMAGE_FORMATS = {".png": "PNG", ".tif": "TIFF", ".tiff": "TIFF"}
"""Suffix of a capture image file -> its format. A capture of camera ``cam1`` is
``cam1.png``, ``cam1.tif`` or ``cam1.tiff`` (lower case), exactly one of them;
the first of this order is the name a missing capture is reported under."""


class _ImageHeader(NamedTuple):
    """What an image file's header says, whatever its format (read without decoding pixels).

    Attributes
    ----------
    width, height : int
        Size in pixels.
    bit_depth : int
        Bits per sample (every sample of the file has the same).
    channels : int
        Samples per pixel (a palette image counts 1 for TIFF, 3 for PNG).
    kind : str
        Colour model in words: ``"RGB"``, ``"RGBA"``, ``"greyscale"``,
        ``"greyscale+alpha"`` or ``"palette"``.
    fmt : str
        ``"PNG"`` or ``"TIFF"``, for messages.
    sample_format : str
        ``"unsigned"`` (integers; PNG's only one), ``"signed"``, ``"floating-point"``, ...
    """

    width: int
    height: int
    bit_depth: int
    channels: int
    kind: str
    fmt: str
    sample_format: str = "unsigned"


# --------------------------------------------------------------------------------------------
# Intensity thresholds


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


# --------------------------------------------------------------------------------------------
# Errors


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


class CaptureFormatProblems(CaptureFormatError):
    """Several files of a dataset break the capture format: every one of them.

    A :class:`CaptureFormatError` naming the dataset folder, whose message lists
    each problem (file and reason) on a line of its own; ``problems`` holds them.
    """

    def __init__(self, root: str | Path, problems: list[CaptureFormatError]) -> None:
        self.problems = list(problems)
        lines = "\n".join(f"  {p}" for p in self.problems)
        super().__init__(root, f"{len(self.problems)} problems:\n{lines}")

    def __reduce__(self):
        return (type(self), (self.path, self.problems))


class UnknownNameError(KeyError):
    """A scene, frame, camera, object, pose or marker the dataset does not have.

    A KeyError (lookups by name), whose message names what exists; ``str()``
    is the message itself, not KeyError's quoted repr.
    """

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""
