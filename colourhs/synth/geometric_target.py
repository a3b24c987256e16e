"""The geometric captures of a synthetic dataset: a ChArUco target sized to the rig.

Every preset, fixed or randomised, renders ``geometric/<pose>/<camera>.png``
(the capture format's optional folder, for a geometric calibration of the
cameras): a matte ChArUco target (black squares and markers on white) under the
rig's three lights, seen through each camera's lens distortion, with the
dataset's nuisances. The rules below depend on the rig only, so they hold for
every rig the presets draw:

====================  ======================================================================
quantity              rule
====================  ======================================================================
target                DICT_4X4_50 markers of 0.75 of the square (:func:`target_for_rig`);
                      :data:`FIELD_FRACTION` of the field's width at the working distance
                      D, or wider where the squares would span less than
                      :data:`MIN_SQUARE_PX`; squares across: that width over
                      :data:`MIN_SQUARE_PX`, within :data:`SQUARES_ACROSS`; down: 0.75 of
                      those across, rounded (640 px wide images: 10 x 8 squares of 32 px
                      at D; 160 px: 8 x 6 of 18 px)
poses                 :data:`N_POSES` by default (``Preset.geometric_poses``); slant up to
                      :data:`SLANT_DEG` about an axis in any direction, roll +-
                      :data:`ROLL_DEG`, depth stratified over +-:data:`DEPTH_REL` D; the
                      centre aimed in turn at the field's corners, centre and edges
                      (:data:`AIMS`, :data:`AIM_REL` of its half-width and half-height
                      out), +-:data:`JITTER_REL` of its half-width in x and y around it
acceptance            at least :data:`MIN_CAMERAS` cameras each see at least
                      :data:`MIN_SHARE` of the interior corners (4 px inside the image)
                      from the printed side at less than :data:`MAX_INCIDENCE_DEG`: a pose
                      may leave part of the target out of a view, so that corners reach
                      the image borders (where the distortion is strongest)
random stream         the seed's own (:func:`geometric_rng`): adding these captures changes
                      no draw of the other parts
====================  ======================================================================

The true poses are ``gt/geometric_poses.json`` (pose -> R, t with world X =
R X_target + t, the target frame of :mod:`colourhs.capture.targets`).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

from colourhs.capture.rig import cameras_fixation_point
from colourhs.capture.targets import CHARUCO_MARKER_FRACTION, charuco_corners, charuco_layout
from colourhs.synth.poses import PoseAcceptance, PoseRanges, board_poses

DICTIONARY = "DICT_4X4_50"
"""The markers' dictionary: the fewest bits (largest cells) with an id for up to 50 markers."""

FIELD_FRACTION = 0.5
"""The target's width over the field's width at the working distance: a pose can
then sit well inside every view or reach past an image border."""

MIN_SQUARE_PX = 18.0
"""Least side of a square at the working distance, fronto-parallel, pixels: its
marker's cells (0.75 of it over the 6 cells of a 4x4 marker with its border) span
2.25 px, about the least OpenCV's detector reads through a 40-degree slant."""

SQUARES_ACROSS = (8, 10)
"""Least and most squares across: 8 x 6 gives 35 interior corners, so that a view
with part of the target out of the image or undetected still holds 8 or more (what
a view needs to calibrate); 10 x 8 gives 63 corners and 40 markers (DICT_4X4_50
has 50 ids). On a small image the least count makes the target wider than
:data:`FIELD_FRACTION` of the field."""

SQUARES_ASPECT = 0.75
"""Squares down over squares across (the images' 4:3)."""

N_POSES = 15
"""Poses of a dataset (10 to 30 calibrate a camera; ``Preset.geometric_poses``)."""

SLANT_DEG = 40.0
"""Largest slant of the target, degrees: wider than the photometric board's (25),
as a geometric calibration needs foreshortened views to fix the focal length."""

ROLL_DEG = 20.0
"""Largest roll about the target's normal, degrees."""

AIM_REL = 0.6
"""The poses aim in turn at the field's four corners, its centre and its four edges'
midpoints (:data:`AIMS`), this fraction of the field's half-width (x) and
half-height (y) from its centre: with the target half the field wide, a pose aimed
at a corner puts target corners near that image corner."""

AIMS = ((-1, -1), (1, -1), (1, 1), (-1, 1), (0, 0), (0, -1), (1, 0), (0, 1), (-1, 0))
"""The aims' directions (x, y) in units of :data:`AIM_REL`: corners first, so that
fewer poses than aims still reach every image corner."""

JITTER_REL = 0.15
"""The target's centre moves up to this fraction of the field's half-width in x and
in y around its aim."""

DEPTH_REL = 0.1
"""Depths are stratified over +- this fraction of the working distance."""

MIN_CAMERAS = 2
"""Cameras that must see a pose (a camera pair ties the cameras' poses together)."""

MIN_SHARE = 0.3
"""Share of the interior corners a camera must see for the pose to count for it."""

MAX_INCIDENCE_DEG = 65.0
"""A camera sees the target only at less than this incidence at its centre, degrees."""

MARGIN_PX = 4.0
"""A corner is in view at least this far inside the image, pixels."""


@dataclass(frozen=True)
class RigScale:
    """How large a rig's field is where its optical axes meet.

    Attributes
    ----------
    distance_m : mean distance of the camera centres from the fixation point, metres.
    half_width_m : mean half-width of the cameras' fields at that distance, metres.
    width_px, height_px : image size, pixels.
    """

    distance_m: float
    half_width_m: float
    width_px: int
    height_px: int

    @property
    def half_height_m(self) -> float:
        """Half-height of the field at the working distance, metres (square pixels)."""
        return self.half_width_m * self.height_px / self.width_px


def rig_scale(rig) -> RigScale:
    """The :class:`RigScale` of ``rig`` (``cameras`` with K, R, t; ``width``, ``height``): the
    fixation point of the optical axes (:func:`colourhs.capture.rig.cameras_fixation_point`)
    and each camera's field at the mean distance (width / 2 over fx)."""
    point = cameras_fixation_point(rig.cameras)
    distance = float(np.mean([np.linalg.norm(c.centre - point) for c in rig.cameras]))
    half = float(np.mean([distance * (rig.width / 2) / c.K[0, 0] for c in rig.cameras]))
    return RigScale(distance, half, int(rig.width), int(rig.height))


def target_for_rig(rig) -> dict:
    """The ChArUco description (rig.json's ``geometric_board``) of ``rig``'s target.

    :data:`FIELD_FRACTION` of the field's width wide, or :data:`MIN_SQUARE_PX` per
    square where that is wider; as many squares across as fit at
    :data:`MIN_SQUARE_PX` (within :data:`SQUARES_ACROSS`), :data:`SQUARES_ASPECT` of
    them down; the square length rounded to 0.1 mm, the marker
    :data:`~colourhs.capture.targets.CHARUCO_MARKER_FRACTION` of it (to 1 um).
    """
    scale = rig_scale(rig)
    px_per_m = scale.width_px / (2 * scale.half_width_m)
    width_px = FIELD_FRACTION * scale.width_px
    across = int(np.clip(width_px // MIN_SQUARE_PX, *SQUARES_ACROSS))
    down = max(2, int(round(across * SQUARES_ASPECT)))
    square = round(max(width_px / across, MIN_SQUARE_PX) / px_per_m, 4)
    marker = round(CHARUCO_MARKER_FRACTION * square, 6)
    return charuco_layout(across, down, square, marker, DICTIONARY)


def pose_rules(rig) -> tuple[PoseRanges, PoseAcceptance]:
    """Where :func:`~colourhs.synth.poses.board_poses` draws ``rig``'s target poses and
    which it keeps (the module's table), scaled by :func:`rig_scale`."""
    scale = rig_scale(rig)
    reach = (AIM_REL * scale.half_width_m, AIM_REL * scale.half_height_m)
    ranges = PoseRanges(
        depth_m=DEPTH_REL * scale.distance_m,
        lateral_m=JITTER_REL * scale.half_width_m,
        tilt_deg=SLANT_DEG,
        roll_deg=ROLL_DEG,
        any_direction=True,
        aims=tuple((x * reach[0], y * reach[1]) for x, y in AIMS),
    )
    acceptance = PoseAcceptance(
        margin_px=MARGIN_PX,
        max_incidence_deg=MAX_INCIDENCE_DEG,
        min_cameras=MIN_CAMERAS,
        min_share=MIN_SHARE,
    )
    return ranges, acceptance


def geometric_rng(seed: int) -> np.random.Generator:
    """The random stream of a seed's target poses, apart from every other draw."""
    digest = hashlib.sha256(f"colourhs-geometric-poses:{seed}".encode()).digest()
    return np.random.default_rng(int.from_bytes(digest[:8], "little"))


@dataclass(frozen=True)
class GeometricCaptures:
    """What a dataset's ``geometric/`` shows.

    Attributes
    ----------
    target : the ChArUco description, rig.json's ``geometric_board`` (:func:`target_for_rig`).
    poses : the target's poses (R, t), world X = R X_target + t, metres
        (:func:`geometric_poses`); written as ``geometric/pose00``, ``pose01``, ...
    """

    target: dict
    poses: list

    @property
    def names(self) -> list[str]:
        """The poses' folder names under ``geometric/``."""
        return [f"pose{k:02d}" for k in range(len(self.poses))]


def geometric_captures(rig, n: int, seed: int) -> GeometricCaptures:
    """The target of ``rig`` (:func:`target_for_rig`) and its ``n`` poses drawn from
    ``seed`` (:func:`geometric_poses`)."""
    target = target_for_rig(rig)
    return GeometricCaptures(target, geometric_poses(rig, target, n, seed))


def geometric_poses(rig, target: dict, n: int, seed: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """``n`` poses (R, t) of the ChArUco ``target`` for ``rig``: world X = R X_target + t.

    Drawn by :func:`~colourhs.synth.poses.board_poses` with :func:`pose_rules` from
    :func:`geometric_rng`, the interior corners as the check points.

    Raises
    ------
    RuntimeError
        If some pose cannot be placed.
    """
    ranges, acceptance = pose_rules(rig)
    rng = geometric_rng(seed)
    points = charuco_corners(target)
    return board_poses(rig, target, n, rng, ranges, acceptance, points=points)
