"""The rig's types: image encoding, cameras with their lights, the board, reciprocal pairs.

:class:`Rig` is the contents of a validated rig.json (read by
:func:`colourhs.capture.rigjson.load_rig`): its :class:`Camera` objects (each a
calibrated pinhole camera with its collocated light), the :class:`ImageSpec`
shared by all images, the calibration :class:`Board`, the optional ChArUco
target of the geometric captures (``Rig.geometric_board``) and the Helmholtz
:class:`ReciprocalPair` of every two cameras (camera i records camera j's light
in the channel of j's light colour). Geometry follows OpenCV (``x_cam = R X + t``),
lengths in metres. Re-exported by :mod:`colourhs.capture`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from colourhs.capture.base import COLOURS, UnknownNameError
from colourhs.common.geometry import camera_centre, fixation_point, half_vector_defect, light_centre

RECIPROCITY_DEFECT_TOLERANCE_DEG = 0.01
"""Largest half-vector defect of a reciprocal pair (:meth:`Rig.reciprocity_defect`,
degrees) that :func:`light_offset_warning` lets pass. Why it holds on any rig: an
angle, so scaled by the rig (a light's offset over its distance); at it the two
readings of a glossy lobe (GGX, roughness 0.1) differ by about 1 %, a mid-scale
reading's sensor noise, so beyond it a glossy surface's rows carry an error the
noise model does not have."""

RECIPROCITY_DEFECT_LIMIT_DEG = 5.0
"""Largest half-vector defect at the rig's fixation point that validation accepts
(:func:`light_offset_problem`, degrees). Why it holds on any rig: an angle, scaled by
the rig; around it a glossy surface's two readings no longer belong to one
reciprocal configuration: on random rigs its depth error grows faster than the angle
(``benchmarks/light_offset.py``) to tens of times its error bar, while matte
surfaces stay exact, so beyond it the rig is not a Helmholtz rig but two cameras
with lamps beside them."""


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
        Camera name; also the image file stem (``<name>.png``, ``.tif`` or ``.tiff``).
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
    geometric_board : dict or None
        The ChArUco target of the ``geometric/`` captures, rig.json's optional
        ``geometric_board`` block as :func:`colourhs.capture.targets.charuco_layout`
        returns it (``type``, ``dictionary``, ``squares`` [x, y], ``square_length``
        and ``marker_length`` in metres; do not modify it); None when rig.json has none.
    """

    cameras: tuple[Camera, ...]
    image: ImageSpec
    board: Board
    chromatic_light: np.ndarray
    path: Path
    geometric_board: dict | None = None

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

    def fixation_point(self) -> np.ndarray:
        """The point nearest (least squares) to every camera's optical axis, metres (3,):
        the rig's working point (:func:`cameras_fixation_point`)."""
        return cameras_fixation_point(self.cameras)

    def reciprocity_defect(self, X: np.ndarray) -> np.ndarray:
        """Per reciprocal pair (rig order), the half-vector angle between the pair's two
        readings at world points ``X`` (..., 3): shape (P, ...), radians, 0 with
        collocated lights (:func:`colourhs.common.geometry.half_vector_defect`)."""
        out = []
        for p in self.reciprocal_pairs():
            a, b = self.camera(p.cam_a), self.camera(p.cam_b)
            out.append(half_vector_defect(X, a.centre, a.light_centre, b.centre, b.light_centre))
        return np.stack(out)


def cameras_fixation_point(cameras) -> np.ndarray:
    """The point nearest (least squares) to the optical axes of ``cameras`` (the third
    row of each R), metres (3,). ValueError with fewer than two cameras or (nearly)
    parallel axes (:func:`colourhs.common.geometry.fixation_point`)."""
    axes = [np.asarray(c.R, float)[2] for c in cameras]
    return fixation_point(axes, [c.centre for c in cameras])


def _lights_beyond(rig: Rig, limit_deg: float) -> tuple[float, float] | None:
    """(the defect at the fixation point, degrees; the largest light offset, metres)
    where the defect exceeds ``limit_deg``, else None."""
    defect = reciprocity_defect_deg(rig)
    if defect is None or defect <= limit_deg:
        return None
    return defect, max(float(np.linalg.norm(c.light_offset)) for c in rig.cameras)


def light_offset_warning(rig: Rig, tolerance_deg: float | None = None) -> str | None:
    """A warning where the rig's lights sit beside its lenses far enough to matter, else None.

    Beyond the paper. The largest :meth:`Rig.reciprocity_defect` over the
    reciprocal pairs at the rig's fixation point, against ``tolerance_deg``
    (default :data:`RECIPROCITY_DEFECT_TOLERANCE_DEG`). Helmholtz reciprocity
    (eq. 3) then holds for matte surfaces only; the depth of a glossy one can
    be off by more than its ``depth_sigma``, which covers the defect only where
    it differs between the pairs (the jackknife over the pairs,
    :func:`colourhs.reconstruct.bayes.uncertainty.pair_jackknife`).
    """
    tolerance = RECIPROCITY_DEFECT_TOLERANCE_DEG if tolerance_deg is None else tolerance_deg
    beyond = _lights_beyond(rig, tolerance)
    if beyond is None:
        return None
    defect, offset = beyond
    return (
        f"{rig.path}: the lights sit up to {offset * 1e3:.0f} mm beside the lenses; at the "
        f"rig's fixation point a reciprocal pair's two readings see the surface at "
        f"half-vectors up to {defect:.2f} degrees apart (over {tolerance:g}). Helmholtz "
        "reciprocity then holds for matte surfaces only: the depth of a glossy surface can "
        "be off by more than its depth_sigma. Put each light at its lens centre (or a ring "
        "of lights around the lens)."
    )


def light_offset_problem(rig: Rig, limit_deg: float | None = None) -> str | None:
    """Why the rig's lights sit too far beside their lenses for colour HS, else None.

    Beyond the paper. The largest :meth:`Rig.reciprocity_defect` at the rig's
    fixation point against ``limit_deg`` (default
    :data:`RECIPROCITY_DEFECT_LIMIT_DEG`): validation refuses a rig beyond it.
    """
    limit = RECIPROCITY_DEFECT_LIMIT_DEG if limit_deg is None else limit_deg
    beyond = _lights_beyond(rig, limit)
    if beyond is None:
        return None
    defect, offset = beyond
    return (
        f"the lights sit up to {offset * 1e3:.0f} mm beside the lenses: at the rig's "
        f"fixation point a reciprocal pair's two readings see the surface at half-vectors "
        f"{defect:.1f} degrees apart (limit {limit:g}). Helmholtz reciprocity (eq. 3) no "
        "longer pairs them: a glossy surface's depth would be off by many times its "
        "error bar. Mount each light at its lens (or a ring of lights around it), or check "
        "light.offset (metres, in the camera's coordinates)"
    )


def reciprocity_defect_deg(rig: Rig) -> float | None:
    """The largest :meth:`Rig.reciprocity_defect` over the reciprocal pairs at the rig's
    fixation point, degrees; None where the optical axes do not converge."""
    try:
        point = rig.fixation_point()
    except ValueError:
        return None
    return float(np.degrees(rig.reciprocity_defect(point).max()))


def _square_corners(centre: np.ndarray, side: float) -> np.ndarray:
    """Corners (TL, TR, BR, BL) of an axis-aligned square in the board plane, shape (4, 3)."""
    h = side / 2.0
    offsets = np.array([[-h, -h], [h, -h], [h, h], [-h, h]])
    return np.column_stack([centre + offsets, np.zeros(4)])
