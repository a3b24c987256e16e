"""Read and validate datasets in the Colour HS capture format, version 1.

The format is specified in ``capture-format.md`` (the contract between a
capture rig or the synthetic renderer and the pipeline). This package is the
pipeline's only reader of that layout: :func:`open_dataset` validates a whole
dataset and :func:`load_rig`, :func:`read_image` and :func:`read_mask` read its
parts. Anything malformed is refused with a :class:`CaptureFormatError` whose
message starts with the offending file's path, then ``": "`` and the problem.

Conventions (all from the format): lengths are in metres, geometry follows
OpenCV (a world point X maps to camera coordinates ``R X + t``), images are
R, G, B in that order, and channel indices follow :data:`COLOURS`.

Modules (everything public is re-exported here; import from ``colourhs.capture``):

- :mod:`~colourhs.capture.base`: the format's constants, the intensity thresholds
  and the errors;
- :mod:`~colourhs.capture.rig`: the rig's types (:class:`ImageSpec`,
  :class:`Camera`, :class:`Board`, :class:`ReciprocalPair`, :class:`Rig`);
- :mod:`~colourhs.capture.dataset`: :class:`Scene` and :class:`Dataset`;
- :mod:`~colourhs.capture.rigjson`: reading and validating rig.json (its JSON Schema,
  ``rig.schema.json``, is :func:`rig_schema`);
- :mod:`~colourhs.capture.targets`: the ChArUco target of rig.json's optional
  ``geometric_board`` (its description, checks and geometry; import it from there);
- :mod:`~colourhs.capture.jsonvalues`: JSON reading, schema and value checks;
- :mod:`~colourhs.capture.png`: capture images (PNG or TIFF, :mod:`~colourhs.capture.tiff`
  the TIFF header): header checks, :func:`read_image`, :func:`read_mask`;
- :mod:`~colourhs.capture.layout`: the dataset folder, :func:`open_dataset`, :func:`validate`.

Only :mod:`~colourhs.capture.base` (the standard library) is imported with the
package; every other name loads its module on first use (PEP 562), so that
``from colourhs.capture import MIN_SIGNAL`` (the command line's defaults) does
not import numpy, cv2 and jsonschema.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

from colourhs.capture.base import (
    COLOURS,
    FORMAT,
    LIT_THRESHOLD,
    MIN_SIGNAL,
    CaptureFormatError,
    CaptureFormatProblems,
    UnknownNameError,
)

if TYPE_CHECKING:  # the names _LAZY loads, for type checkers (and the import graph)
    from colourhs.capture.dataset import Dataset, Scene
    from colourhs.capture.layout import all_images, dataset_of, open_dataset, validate
    from colourhs.capture.png import read_image, read_mask
    from colourhs.capture.rig import Board, Camera, ImageSpec, ReciprocalPair, Rig
    from colourhs.capture.rigjson import (
        DIST_LENGTHS,
        ROTATION_TOLERANCE,
        load_rig,
        rig_from_dict,
        rig_schema,
    )

#: Submodule -> the public names it holds, imported on first use (:func:`__getattr__`).
_LAZY = {
    "dataset": ("Dataset", "Scene"),
    "layout": ("all_images", "dataset_of", "open_dataset", "validate"),
    "png": ("read_image", "read_mask"),
    "rig": ("Board", "Camera", "ImageSpec", "ReciprocalPair", "Rig"),
    "rigjson": ("DIST_LENGTHS", "ROTATION_TOLERANCE", "load_rig", "rig_from_dict", "rig_schema"),
}
_MODULE_OF = {name: module for module, names in _LAZY.items() for name in names}

__all__ = [
    "COLOURS",
    "DIST_LENGTHS",
    "FORMAT",
    "LIT_THRESHOLD",
    "MIN_SIGNAL",
    "ROTATION_TOLERANCE",
    "Board",
    "Camera",
    "CaptureFormatError",
    "CaptureFormatProblems",
    "Dataset",
    "ImageSpec",
    "ReciprocalPair",
    "Rig",
    "Scene",
    "UnknownNameError",
    "all_images",
    "dataset_of",
    "load_rig",
    "open_dataset",
    "read_image",
    "read_mask",
    "rig_from_dict",
    "rig_schema",
    "validate",
]


def __getattr__(name: str):
    """A public name of a submodule (:data:`_LAZY`), imported on first use and kept."""
    if name not in _MODULE_OF:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{_MODULE_OF[name]}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
