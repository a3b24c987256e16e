"""What every part of the capture reader shares: the format's constants and its errors.

The format's version string (:data:`FORMAT`), the light and channel colours
(:data:`COLOURS`), the name rule of cameras and folders, the two intensity
thresholds that follow from the format's "no ambient light" rule
(:data:`LIT_THRESHOLD`, :data:`MIN_SIGNAL`), and the errors the reader raises:
:class:`CaptureFormatError` (a file breaks the format) and
:class:`UnknownNameError` (a lookup by a name the dataset does not have).
Re-exported by :mod:`colourhs.capture`.
"""

from __future__ import annotations

import re
from pathlib import Path

FORMAT = "colourhs-capture/1"
"""Value of the ``format`` key of rig.json that :mod:`colourhs.capture` reads."""

COLOURS = ("red", "green", "blue")
"""Light / channel colours; the index of a colour is its image channel (R, G, B)."""

_NAME = re.compile(r"[A-Za-z0-9_-]+")


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
