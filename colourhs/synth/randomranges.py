"""The ranges of the randomised presets, and the seeded random streams they draw from.

:class:`RandomRanges` holds the ranges of the table in
:mod:`colourhs.synth.randomrig`'s docstring (the one place they are
documented): :data:`RANGES` for ``random``, :data:`TINY_RANGES` for
``random-tiny``, :data:`CORNER_RANGES` and :data:`CORNER_TINY_RANGES` for
``corner`` and ``corner-tiny`` (the hard ends of the ranges combined), and
every preset's by name in :data:`RANGES_BY_NAME`; beside
them the discrete choices (camera names, mask modes, metals, marker
dictionaries). :func:`_stream` gives the independent random stream of one
topic of a seed.

:mod:`colourhs.synth.randomrig` re-exports these.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field, replace

import numpy as np

__all__ = [
    "CORNER_RANGES",
    "CORNER_TINY_RANGES",
    "MASK_MODES",
    "METALS",
    "NAME_STYLES",
    "RANGES",
    "RANGES_BY_NAME",
    "TINY_RANGES",
    "RandomRanges",
]

#: Naming styles of the three cameras. "left/right/top" style names go by position.
NAME_STYLES = (
    ("cam1", "cam2", "cam3"),
    ("left", "right", "top"),
    ("C0", "C1", "C2"),
    ("A", "B", "C"),
    ("cam_a", "cam_b", "cam_c"),
    ("west", "east", "north"),
)
POSITIONAL_STYLES = {("left", "right", "top"), ("west", "east", "north")}

MASK_MODES = ("exact", "none", "dilated", "eroded")

#: Schlick F0 per light band (R, G, B) of some metals (linear, approximate).
METALS = {
    "gold": (1.0, 0.71, 0.29),
    "copper": (0.95, 0.64, 0.54),
    "brass": (0.91, 0.78, 0.42),
    "silver": (0.95, 0.93, 0.88),
}

#: Black level's upper end per sensor bit depth, DN: 1/16 of full scale at every
#: depth (16 of 255, 256 of 4095, 4096 of 65535), so the pedestal takes the same
#: share of the range whatever the depth.
BLACK_LEVEL_DN = {8: 16, 12: 256, 16: 4096}

#: The PNG bit depth of each sensor bit depth: PNG has no 12-bit samples, so
#: 12-bit data (0..4095, white level 4095) is written in 16-bit PNGs.
CONTAINER_BITS = {8: 8, 12: 16, 16: 16}

DICTIONARY_SIZES = {"DICT_4X4_50": 50, "DICT_5X5_100": 100, "DICT_6X6_250": 250}


@dataclass(frozen=True)
class RandomRanges:
    """The ranges of the table of :mod:`colourhs.synth.randomrig` (metres, degrees)."""

    distance_m: tuple[float, float] = (0.5, 1.0)
    camera_distance_rel: float = 0.05
    hfov_deg: tuple[float, float] = (18.0, 35.0)
    focal_rel: float = 0.01
    aspect_rel: float = 0.003
    field_half_width_m: tuple[float, float] = (0.17, np.inf)
    pair_angle_deg: tuple[float, float] = (15.0, 30.0)
    pair_angle_spread_deg: float = 3.0
    principal_rel: float = 0.04
    roll_deg: float = 25.0
    aim_rel: float = 0.01
    k1: tuple[float, float] = (-0.15, 0.05)
    k2: tuple[float, float] = (-0.05, 0.1)
    tangential_sd: float = 3e-4
    rational: float = 0.0  # k4, k5, k6 U(-rational, rational); 0 = not drawn
    thin_prism_sd: float = 0.0  # s1..s4 N(0, sd); 0 = not drawn
    skew_rel: float = 0.0  # K[0, 1] U(-1, 1) skew_rel f; 0 = not drawn
    # Sensor bit depths to choose from (p equal); 12 is written in 16-bit PNGs.
    bit_depths: tuple[int, ...] = (8, 16)
    black_level_dn: dict = field(default_factory=lambda: dict(BLACK_LEVEL_DN))
    exposure: tuple[float, float] = (0.3, 0.6)
    board_width_m: tuple[float, float] = (0.20, 0.32)
    board_aspect: tuple[float, float] = (0.65, 0.85)
    n_markers: tuple[int, int] = (4, 8)
    dictionaries: tuple[str, ...] = ("DICT_4X4_50", "DICT_5X5_100", "DICT_6X6_250")
    marker_length_m: tuple[float, float] = (0.03, 0.05)
    marker_gap_cells: float = 1.5
    pose_slant_deg: float = 45.0
    pose_roll_deg: float = 15.0
    pose_offcentre: float = 0.25  # of the field's half-width
    pose_depth_rel: float = 0.1  # of D
    pose_incidence_deg: float = 65.0
    # The held-out plane's slant to the reference camera's line of sight; None: a
    # calibration-like pose (slant to the viewing axis up to pose_slant_deg).
    plane_slant_deg: tuple[float, float] | None = None
    pose_min_cell_px: float = 2.0
    margin_px: float = 4.0
    led_exponent_x: tuple[float, float] = (10.0, 14.0)
    led_exponent_y: tuple[float, float] = (6.0, 9.0)
    led_skew: float = 0.4
    led_tilt_deg: float = 8.0
    # Light centre's distance from the lens, in the camera's x-y plane; (0, 0) = collocated.
    light_offset_m: tuple[float, float] = (0.0, 0.0)
    ripple_amplitude: tuple[float, float] = (0.0, 0.03)
    ripple_period_deg: tuple[float, float] = (4.0, 15.0)
    vignetting_corner: tuple[float, float] = (0.05, 0.2)
    colour_shading: float = 0.02
    vignetting_centre_rel: float = 0.05  # disc radius, of the corner radius
    crosstalk: tuple[float, float] = (0.02, 0.08)
    filter_crosstalk_factor: tuple[float, float] = (0.6, 1.4)
    full_well_e: tuple[float, float] = (8000.0, 20000.0)
    read_noise_e: tuple[float, float] = (2.0, 10.0)
    object_scale: tuple[float, float] = (0.8, 1.2)
    object_lateral_m: float = 0.03
    object_depth_m: float = 0.05
    object_yaw_deg: float = 30.0
    ggx_roughness: tuple[float, float] = (0.1, 0.5)
    dielectric_f0: tuple[float, float] = (0.03, 0.06)
    metal_roughness: tuple[float, float] = (0.1, 0.3)
    metal_f0_jitter: float = 0.03
    oren_nayar_sigma: tuple[float, float] = (0.15, 0.5)
    sheet_width_m: tuple[float, float] = (0.20, 0.30)
    sheet_tilt_deg: float = 25.0
    chromatic_offset_m: tuple[float, float] = (0.3, 0.6)
    chromatic_depth_rel: tuple[float, float] = (0.5, 0.9)
    white_tilt_deg: float = 15.0
    attempts: int = 200


RANGES = RandomRanges()
TINY_RANGES = replace(
    RANGES,
    field_half_width_m=(0.19, 0.23),
    board_width_m=(0.22, 0.27),
    board_aspect=(0.75, 0.85),
    n_markers=(4, 4),
    dictionaries=("DICT_4X4_50",),
    marker_length_m=(0.06, 0.07),
    marker_gap_cells=1.0,
    pose_slant_deg=30.0,
    pose_incidence_deg=55.0,
    pose_min_cell_px=3.0,
)
#: The hard ends of the ranges combined (``corner``): narrow camera triangles,
#: slanted boards and plane, small full well with high read noise, 12-bit
#: data, strong barrel distortion, lights beside the lenses. The table of
#: :mod:`colourhs.synth.randomrig` gives each value and why.
CORNER = {
    "pair_angle_deg": (12.0, 15.0),
    "pair_angle_spread_deg": 1.0,
    "pose_slant_deg": 50.0,
    "pose_incidence_deg": 70.0,
    "plane_slant_deg": (40.0, 50.0),
    "full_well_e": (5000.0, 8000.0),
    "read_noise_e": (8.0, 10.0),
    "bit_depths": (8, 12),
    "k1": (-0.15, -0.12),
    "k2": (0.05, 0.1),
    "light_offset_m": (0.02, 0.04),
}
CORNER_RANGES = replace(RANGES, **CORNER)
CORNER_TINY_RANGES = replace(TINY_RANGES, **CORNER)
#: The ranges of each randomised preset, by :attr:`Preset.random_ranges`.
RANGES_BY_NAME = {
    "random": RANGES,
    "random-tiny": TINY_RANGES,
    "random-tiny-lens": replace(TINY_RANGES, rational=0.1, thin_prism_sd=1e-3, skew_rel=0.01),
    "corner": CORNER_RANGES,
    "corner-tiny": CORNER_TINY_RANGES,
}


def _stream(seed: int, topic: str) -> np.random.Generator:
    digest = hashlib.sha256(f"colourhs-random-rig:{seed}:{topic}".encode()).digest()
    return np.random.default_rng(int.from_bytes(digest[:8], "little"))
