"""Randomised rigs and scenes: the presets ``random`` and ``random-tiny``.

Every seed draws a different, plausible colour HS rig and scene set from the
ranges below (U = uniform, N = normal; "per camera" draws are independent
for each camera). This table is the one place the ranges are documented;
:class:`RandomRanges` holds them (``RANGES`` for ``random``, ``TINY_RANGES``
for ``random-tiny``, which differs only where the last column says so).

====================  =================================================  =====================
quantity              range (``random``)                                 ``random-tiny``
====================  =================================================  =====================
working distance D    U(0.5, 1.0) m from the fixation point (the world   same
                      origin, where the optical axes nearly meet); each
                      camera's distance D (1 + U(-0.05, 0.05))
field of view         horizontal U(18, 35) deg for the rig, each camera  same
                      focal length x (1 + U(-0.01, 0.01)); fy/fx 1 +
                      U(-0.003, 0.003)
field size            (D, FOV) pairs are kept only if the field's half-  0.19 to 0.23 m
                      width at D, D tan(FOV/2), is >= 0.17 m (so the
                      boards and objects below fit; this rules out D <
                      0.54 m and FOV < 19.3 deg)
pair angles           each U(15, 30) deg (angle at the fixation point    same
                      between two camera centres), irregular: largest
                      minus smallest >= 3 deg; the triangle centred on
                      the viewing axis (world +z) at a random
                      orientation U(0, 360) deg about it
principal point       (W-1)/2 + U(-0.04, 0.04) W, (H-1)/2 + U(-0.04,     same
                      0.04) H
camera roll           U(-25, 25) deg about the camera's optical axis     same
aim error             aim point N(0, 0.01 D) m per axis off the origin   same
lens distortion       k1 U(-0.15, 0.05), k2 U(-0.05, 0.1), p1, p2 N(0,   same
                      3e-4), k3 = 0 (per camera); ``random-tiny-lens``
                      adds rational k4-k6 U(-0.1, 0.1), thin prism
                      s1-s4 N(0, 1e-3) and a skew K[0, 1] U(-0.01,
                      0.01) f (the camera model's end-to-end test)
camera names          one style of cam1..3, left/right/top (by           same
                      position), C0..C2, A/B/C, cam_a..c, north/east/
                      west-like; rig.json order shuffled; light colours
                      a random permutation
image encoding        8 or 16 bit (p = 0.5 each); black level U(0, 1) x  same
                      16 DN (8 bit) or x 4096 DN (16 bit), rounded;
                      white level 2^bits - 1
exposure              white Lambertian (albedo 0.8) at the origin,       same
                      facing the light, reads U(0.3, 0.6) of full scale
board                 width U(0.20, 0.32) m, height/width U(0.65,        width U(0.22, 0.27)
                      0.85); 4..8 markers (uniform) of DICT_4X4_50,      m, aspect U(0.75,
                      DICT_5X5_100 or DICT_6X6_250, distinct random      0.85), 4 markers of
                      ids, side U(0.03, 0.05) m, placed without overlap  DICT_4X4_50, side
                      (best of 30 random candidates, the one farthest    U(0.06, 0.07) m,
                      from the others), gaps and white border >= 1.5     gaps >= 1 cell
                      cells (cell: side / (bits + 2))
board poses           7 calibration poses + the held-out ``plane``:      slant <= 30 deg,
                      slant U(0, 45) deg about an axis at U(0, 360)      incidence < 55 deg,
                      deg, roll U(-15, 15) deg, centre +-0.25 of the     cells >= 3 px
                      field's half-width in x and y, depth stratified
                      over +-0.1 D; kept if every camera sees the whole
                      board (margin 4 px) from its white side at < 65
                      deg incidence and every marker cell spans >= 2 px
LED profile           cos(tx)^mx cos(ty)^my (1 + sx tx + sy ty): mx      same
                      U(10, 14), my U(6, 9), sx, sy U(-0.4, 0.4) /rad;
                      axis tilted U(0, 8) deg off the optical axis
                      towards U(0, 360) deg; ripple 1 + a cos(2 pi
                      theta / T + phase), a U(0, 0.03), T U(4, 15) deg,
                      phase U(0, 2 pi); lights collocated (offset 0)
vignetting            sigma_c = g_c (1 - k_c r_c^2 / r_corner^2):        same
                      corner loss k U(0.05, 0.2) per camera, k_c = k +
                      U(-0.02, 0.02) per channel; centres: a common
                      offset and one per channel, each uniform in a
                      disc of radius 0.05 r_corner (channels differ by
                      <= 0.1 r_corner); colour shading (spread of the
                      channels' sensitivity ratios over the image) up
                      to ~8 %; gains g_c 1 + U(-g, g), g =
                      Nuisances.gain_spread (default 0.06)
cross-talk            LED matrix: off-diagonals U(0.02, 0.08), diagonal  same
                      1; chromatic filter matrix: each off-diagonal the
                      LED one x U(0.6, 1.4)
sensor                full well U(8000, 20000) e-, read noise U(2, 10)   same
                      e-
masks                 exact (coverage >= 0.5), none (no masks/ folder),  same
                      dilated 1 px or eroded 1 px (3x3), p = 1/4 each
objects               statue and toy: scale U(0.8, 1.2), bounding-box    same
                      centre at U(-0.03, 0.03) m in x and y and
                      U(-0.05, 0.05) m in z, yaw U(-30, 30) deg about
                      the vertical; redrawn until fully inside every
                      camera's view (margin 4 px)
statue material       one of (p = 1/3 each): glossy plaster as today     same
                      (Blinn-Phong ks 0.25, s 30); white dielectric
                      (GGX roughness U(0.1, 0.5), F0 U(0.03, 0.06),
                      white specular); rough diffuse (Oren-Nayar sigma
                      U(0.15, 0.5) rad); dirt as today
toy materials         plastics: coloured diffuse + white GGX (roughness  same
                      U(0.1, 0.5), F0 U(0.03, 0.06)); mirror disc: GGX
                      metal, roughness U(0.1, 0.3), per-band F0 of
                      gold, copper, brass or silver (x (1 + U(-0.03,
                      0.03))), diffuse 0.05
sheet                 4 frames; width U(0.20, 0.30) m (aspect as         same
                      today), tilted U(0, 25) deg about an axis at U(0,
                      360) deg; white (0.7) dielectric, white GGX
                      roughness U(0.1, 0.5), F0 U(0.03, 0.06); all
                      frames fully in view
chromatic light       U(0.3, 0.6) m off the viewing axis at U(0, 360)    same
                      deg, z = -U(0.5, 0.9) D (between rig and scene),
                      aimed at the origin; per-filter profile as today
white reference       facing the rig through the origin, tilted U(0,     same
                      15) deg about an axis at U(0, 360) deg, 6 D
                      tan(FOV/2) wide (fills every view)
====================  =================================================  =====================

Draws come from independent random streams per topic (rig geometry and
scenes, photometric model, encoding), each seeded by the seed and the topic's
name, so the geometry, board, poses, scenes and encoding of a seed do not
depend on which nuisances are switched on: every photometric value is drawn
whatever the switches, and a switched-off effect just drops its values. A
draw whose boards or objects cannot be placed is redrawn as a whole (the
table's ranges are the ranges of every accepted draw).

``exact=True`` forces 16-bit images and exact masks while keeping the rest of
the seed's draw (the black level keeps its drawn fraction of 4096 DN).
"""

from __future__ import annotations

import hashlib
from dataclasses import asdict, dataclass, field, replace
from functools import lru_cache
from typing import Any

import cv2
import numpy as np
from scipy.spatial import ConvexHull

from colourhs.capture import Camera
from colourhs.geometry import look_at
from colourhs.synth import scenes as sc
from colourhs.synth.brdf import Material
from colourhs.synth.poses import board_poses, in_view
from colourhs.synth.rig import (
    COLOURS,
    CameraModel,
    LightModel,
    Nuisances,
    RigModel,
    _power_for_exposure,
)

__all__ = [
    "MASK_MODES",
    "METALS",
    "NAME_STYLES",
    "RANGES",
    "RANGES_BY_NAME",
    "TINY_RANGES",
    "RandomDraw",
    "RandomRanges",
    "describe",
    "draw_random",
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

DICTIONARY_SIZES = {"DICT_4X4_50": 50, "DICT_5X5_100": 100, "DICT_6X6_250": 250}


@dataclass(frozen=True)
class RandomRanges:
    """The ranges of the module docstring's table (lengths in metres, angles in degrees)."""

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
    black_level_dn: dict = field(default_factory=lambda: {8: 16, 16: 4096})
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
    pose_min_cell_px: float = 2.0
    margin_px: float = 4.0
    led_exponent_x: tuple[float, float] = (10.0, 14.0)
    led_exponent_y: tuple[float, float] = (6.0, 9.0)
    led_skew: float = 0.4
    led_tilt_deg: float = 8.0
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
#: The ranges of each randomised preset, by :attr:`Preset.random_ranges`.
RANGES_BY_NAME = {
    "random": RANGES,
    "random-tiny": TINY_RANGES,
    "random-tiny-lens": replace(TINY_RANGES, rational=0.1, thin_prism_sd=1e-3, skew_rel=0.01),
}


def _stream(seed: int, topic: str) -> np.random.Generator:
    digest = hashlib.sha256(f"colourhs-random-rig:{seed}:{topic}".encode()).digest()
    return np.random.default_rng(int.from_bytes(digest[:8], "little"))


@dataclass(frozen=True)
class _View:
    """The cameras and image size, all that visibility tests need (duck-types RigModel)."""

    cameras: tuple[Camera, ...]
    width: int
    height: int


@dataclass(frozen=True)
class RandomDraw:
    """Everything a seed draws for a randomised dataset.

    Attributes
    ----------
    rig : the rig model (cameras in rig.json order, photometric model, the
        nuisances with the drawn sensor values).
    board : rig.json's board entry.
    poses : board poses (R_b, t_b): 7 calibration poses, then the ``plane``.
    bit_depth, black_level : the image encoding.
    mask_mode : one of :data:`MASK_MODES`.
    builders : ``white``, ``statue``, ``toy`` (callables () -> SceneGeometry) and
        ``sheet`` (callable phase -> SceneGeometry).
    description : JSON-able description of the draw (for ``gt/rig_model.json``).
    """

    rig: RigModel
    board: dict
    poses: list
    bit_depth: int
    black_level: int
    mask_mode: str
    builders: dict
    description: dict


def draw_random(
    seed: int,
    width: int,
    height: int,
    nuisances: Nuisances,
    ranges: RandomRanges = RANGES,
    n_poses: int = 7,
    sheet_frames: int = 4,
    statue_level: int = 6,
    exact: bool = False,
) -> RandomDraw:
    """Draw the rig, board, poses, scenes and encoding of one seed (see the module table).

    Parameters
    ----------
    seed : the dataset's seed.
    width, height : image size, pixels.
    nuisances : the switches (``light_falloff``, ``vignetting``, ``crosstalk``,
        ``noise``, ``quantise``, ``saturate``; ``gain_spread`` and
        ``chromatic_filter_tilt`` as magnitudes, 0 = off). The other
        magnitudes come from ``ranges``; the rig's ``nuisances`` records them.
    ranges : the ranges to draw from.
    n_poses : calibration board poses (the held-out ``plane`` pose comes on top).
    sheet_frames : frames of the dynamic sheet.
    statue_level : icosphere subdivision of the statue.
    exact : force 16-bit images and exact masks (the rest of the draw unchanged).
    """
    rg = ranges
    geo = _draw_geometry(seed, width, height, rg, n_poses, sheet_frames, statue_level)
    enc = _stream(seed, "encoding")
    bits = int(enc.choice([8, 16]))
    black_fraction = float(enc.uniform(0, 1))
    mask_mode = str(enc.choice(MASK_MODES))
    if exact:
        bits, mask_mode = 16, "exact"
    black = int(round(black_fraction * rg.black_level_dn[bits]))
    rig, photometric = _photometric(seed, geo, width, height, nuisances, rg)
    scene_desc = geo["scenes"]
    builders = _builders(scene_desc, geo, statue_level)
    description = {
        "working_distance_m": geo["distance"],
        "hfov_deg": geo["hfov"],
        "pair_angles_deg": geo["pair_angles"],
        "camera_rolls_deg": geo["rolls"],
        "name_style": list(geo["names"]),
        "mask_mode": mask_mode,
        "bit_depth": bits,
        "black_level": black,
        "scenes": _jsonable(scene_desc),
        "photometric": _jsonable(photometric),
    }
    return RandomDraw(
        rig=rig,
        board=geo["board"],
        poses=geo["poses"],
        bit_depth=bits,
        black_level=black,
        mask_mode=mask_mode,
        builders=builders,
        description=description,
    )


# --------------------------------------------------------------------------- geometry
def _draw_geometry(seed, width, height, rg, n_poses, sheet_frames, statue_level) -> dict:
    rng = _stream(seed, "geometry")
    shapes = _object_shapes(statue_level)
    for _ in range(rg.attempts):
        geo = _draw_cameras(rng, width, height, rg)
        view = _View(tuple(geo["cameras"]), width, height)
        board = _draw_board(rng, rg)
        if board is None:
            continue
        poses = _draw_poses(rng, view, board, rg, geo, n_poses)
        if poses is None:
            continue
        scenes = _draw_scenes(rng, view, rg, geo, shapes, sheet_frames)
        if scenes is None:
            continue
        return geo | {"board": board, "poses": poses, "scenes": scenes}
    raise RuntimeError(f"seed {seed}: no rig with placeable boards and objects in {rg.attempts}")


def _pair_angles(rng, rg) -> np.ndarray:
    while True:
        a = rng.uniform(*rg.pair_angle_deg, 3)
        if a.max() - a.min() >= rg.pair_angle_spread_deg:
            return a


def _camera_directions(angles_deg: np.ndarray) -> np.ndarray | None:
    """Unit vectors (3, 3) with the given pairwise angles (12, 13, 23), or None if impossible."""
    a12, a13, a23 = np.deg2rad(angles_deg)
    u1 = np.array([0.0, 0.0, 1.0])
    u2 = np.array([np.sin(a12), 0.0, np.cos(a12)])
    z = np.cos(a13)
    x = (np.cos(a23) - z * np.cos(a12)) / np.sin(a12)
    y2 = 1.0 - x * x - z * z
    if y2 <= 1e-6:
        return None
    return np.stack([u1, u2, np.array([x, np.sqrt(y2), z])])


def _draw_cameras(rng, width, height, rg) -> dict:
    while True:
        D = rng.uniform(*rg.distance_m)
        hfov = rng.uniform(*rg.hfov_deg)
        half = D * np.tan(np.deg2rad(hfov) / 2)
        if rg.field_half_width_m[0] <= half <= rg.field_half_width_m[1]:
            break
    while True:
        angles = _pair_angles(rng, rg)
        u = _camera_directions(angles)
        if u is not None:
            break
    # Centre the triangle on -z (cameras in front of the scene, looking along +z),
    # then turn it about the viewing axis.
    m = u.sum(axis=0)
    m /= np.linalg.norm(m)
    target = np.array([0.0, 0.0, -1.0])
    axis = np.cross(m, target)
    Q = sc.axis_angle(axis, np.arccos(np.clip(m @ target, -1, 1)))
    psi = np.deg2rad(rng.uniform(0, 360))
    Rz = sc.axis_angle([0, 0, 1], psi)
    u = u @ (Rz @ Q).T
    focal = (width / 2) / np.tan(np.deg2rad(hfov) / 2)
    cams, rolls = [], []
    for i in range(3):
        Di = D * (1 + rng.uniform(-rg.camera_distance_rel, rg.camera_distance_rel))
        centre = Di * u[i]
        aim = rng.normal(0, rg.aim_rel * D, 3)
        R0, _ = look_at(centre, aim)
        roll = rng.uniform(-rg.roll_deg, rg.roll_deg)
        R = sc.axis_angle([0, 0, 1], np.deg2rad(roll)) @ R0
        t = -R @ centre
        f = focal * (1 + rng.uniform(-rg.focal_rel, rg.focal_rel))
        K = np.array(
            [
                [f, 0.0, (width - 1) / 2 + rng.uniform(-1, 1) * rg.principal_rel * width],
                [
                    0.0,
                    f * (1 + rng.uniform(-rg.aspect_rel, rg.aspect_rel)),
                    (height - 1) / 2 + rng.uniform(-1, 1) * rg.principal_rel * height,
                ],
                [0.0, 0.0, 1.0],
            ]
        )
        dist = np.array(
            [rng.uniform(*rg.k1), rng.uniform(*rg.k2), *rng.normal(0, rg.tangential_sd, 2), 0.0]
        )
        # No draws without these terms: the other presets' seeds keep their rigs.
        if rg.rational or rg.thin_prism_sd or rg.skew_rel:
            k456 = rng.uniform(-rg.rational, rg.rational, 3)
            dist = np.concatenate([dist, k456, rng.normal(0, rg.thin_prism_sd, 4)])
            K[0, 1] = rng.uniform(-1, 1) * rg.skew_rel * f
        cams.append(Camera(f"_{i}", K, dist, R, t, "red", np.zeros(3)))
        rolls.append(float(roll))
    # Names, colours and the order of rig.json.
    style = NAME_STYLES[int(rng.integers(len(NAME_STYLES)))]
    if style in POSITIONAL_STYLES:
        names = _positional_names(cams, style)
    else:
        names = [style[k] for k in rng.permutation(3)]
    colours = [COLOURS[k] for k in rng.permutation(3)]
    order = [int(k) for k in rng.permutation(3)]
    cams = [
        replace(c, name=n, light_colour=col) for c, n, col in zip(cams, names, colours, strict=True)
    ]
    return {
        "distance": float(D),
        "hfov": float(hfov),
        "focal": float(focal),
        "half_width": float(half),
        "pair_angles": [float(a) for a in angles],
        "cameras": [cams[k] for k in order],
        "rolls": [rolls[k] for k in order],
        "names": style,
    }


def _positional_names(cams, style) -> list[str]:
    """left/right/top-like names: the highest camera is 'top', then left and right by x."""
    c = np.array([cam.centre for cam in cams])
    top = int(np.argmin(c[:, 1]))  # world y points down
    rest = [k for k in range(3) if k != top]
    left, right = sorted(rest, key=lambda k: c[k, 0])
    names = [""] * 3
    names[left], names[right], names[top] = style
    return names


def _draw_board(rng, rg) -> dict | None:
    w = rng.uniform(*rg.board_width_m)
    h = w * rng.uniform(*rg.board_aspect)
    dictionary = str(rng.choice(rg.dictionaries))
    n = int(rng.integers(rg.n_markers[0], rg.n_markers[1] + 1))
    L = rng.uniform(*rg.marker_length_m)
    ids = np.sort(rng.choice(DICTIONARY_SIZES[dictionary], n, replace=False))
    d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary))
    gap = rg.marker_gap_cells * L / (d.markerSize + 2)
    lo = np.array([gap + L / 2, gap + L / 2])
    hi = np.array([w - gap - L / 2, h - gap - L / 2])
    if np.any(hi < lo):
        return None
    centres = None
    for _ in range(20):
        centres = _layout(rng, n, lo, hi, L + gap)
        if centres is not None:
            break
    if centres is None:
        return None
    return {
        "dictionary": dictionary,
        "marker_length": float(L),
        "size": [float(w), float(h)],
        "markers": {
            str(int(i)): [float(x), float(y)] for i, (x, y) in zip(ids, centres, strict=True)
        },
    }


def _layout(rng, n, lo, hi, pitch) -> list | None:
    """``n`` square centres in the box [lo, hi], at least ``pitch`` apart in x or in y.

    Each centre is the best of 30 random candidates: the one farthest from those placed.
    """
    centres = []
    for _ in range(n):
        cand = rng.uniform(lo, hi, (30, 2))
        if centres:
            c = np.array(centres)
            apart = np.abs(cand[:, None, :] - c[None]) >= pitch  # (30, k, 2)
            ok = np.all(apart.any(axis=-1), axis=1)
            if not ok.any():
                return None
            cand = cand[ok]
            dmin = np.min(np.linalg.norm(cand[:, None] - c[None], axis=-1), axis=1)
            centres.append(cand[int(np.argmax(dmin))])
        else:
            centres.append(cand[0])
    return centres


def _draw_poses(rng, view, board, rg, geo, n_poses):

    try:
        return board_poses(
            view,
            board,
            n_poses + 1,
            rng,
            rg.margin_px,
            depth_m=rg.pose_depth_rel * geo["distance"],
            lateral_m=rg.pose_offcentre * geo["half_width"],
            tilt_deg=rg.pose_slant_deg,
            roll_deg=rg.pose_roll_deg,
            max_incidence_deg=rg.pose_incidence_deg,
            any_direction=True,
            min_cell_px=rg.pose_min_cell_px,
            tries=300,
        )
    except RuntimeError:
        return None


# --------------------------------------------------------------------------- scenes
def _hull_points(vertices: np.ndarray) -> np.ndarray:
    return vertices[ConvexHull(vertices).vertices]


@lru_cache(maxsize=4)
def _base_geometry(name: str, statue_level: int) -> sc.SceneGeometry:
    """The statue or toy in its own frame (built once per process; treat as read-only)."""
    return sc.statue(statue_level) if name == "statue" else sc.toy()


@lru_cache(maxsize=4)
def _object_shapes(statue_level: int) -> dict:
    """Convex-hull points and bounding-box centres of the statue and toy, object frame."""
    out = {}
    for name in ("statue", "toy"):
        v = _base_geometry(name, statue_level).vertices
        out[name] = {"hull": _hull_points(v), "centre": (v.min(axis=0) + v.max(axis=0)) / 2}
    return out


def _yaw(deg: float) -> np.ndarray:
    return sc.axis_angle([0.0, 1.0, 0.0], np.deg2rad(deg))


def _place(rng, view, rg, shape, tries=300) -> dict | None:
    for _ in range(tries):
        s = rng.uniform(*rg.object_scale)
        pos = np.array(
            [
                *rng.uniform(-rg.object_lateral_m, rg.object_lateral_m, 2),
                rng.uniform(-rg.object_depth_m, rg.object_depth_m),
            ]
        )
        yaw = rng.uniform(-rg.object_yaw_deg, rg.object_yaw_deg)
        pts = s * (shape["hull"] - shape["centre"]) @ _yaw(yaw).T + pos
        if in_view(view, pts, rg.margin_px):
            return {"scale": s, "position": pos, "yaw_deg": yaw, "origin": shape["centre"]}
    return None


def _tilt(rng, max_deg) -> tuple[float, float]:
    """A tilt angle U(0, max) and the direction of its axis U(0, 360), degrees."""
    return float(rng.uniform(0, max_deg)), float(rng.uniform(0, 360))


def _tilt_matrix(angle_deg, axis_deg) -> np.ndarray:
    a = np.deg2rad(axis_deg)
    return sc.axis_angle([np.cos(a), np.sin(a), 0.0], np.deg2rad(angle_deg))


def _draw_scenes(rng, view, rg, geo, shapes, sheet_frames) -> dict | None:
    statue = _place(rng, view, rg, shapes["statue"])
    if statue is None:
        return None
    toy = _place(rng, view, rg, shapes["toy"])
    if toy is None:
        return None
    kind = str(rng.choice(["plaster", "dielectric", "rough_diffuse"]))
    statue["material"] = kind
    statue["roughness"] = float(rng.uniform(*rg.ggx_roughness))
    statue["f0"] = float(rng.uniform(*rg.dielectric_f0))
    statue["sigma"] = float(rng.uniform(*rg.oren_nayar_sigma))
    metal = str(rng.choice(sorted(METALS)))
    toy["plastic_roughness"] = float(rng.uniform(*rg.ggx_roughness))
    toy["plastic_f0"] = float(rng.uniform(*rg.dielectric_f0))
    toy["metal"] = metal
    toy["metal_roughness"] = float(rng.uniform(*rg.metal_roughness))
    jitter = 1 + rng.uniform(-rg.metal_f0_jitter, rg.metal_f0_jitter, 3)
    toy["metal_f0_rgb"] = np.clip(np.array(METALS[metal]) * jitter, 0, 1)
    sheet = None
    for _ in range(100):
        width = rng.uniform(*rg.sheet_width_m)
        tilt, axis = _tilt(rng, rg.sheet_tilt_deg)
        cand = {"size": [width, width * 0.2 / 0.26], "tilt_deg": tilt, "tilt_axis_deg": axis}
        frames = [
            _sheet(cand, f / max(sheet_frames - 1, 1), material=None) for f in range(sheet_frames)
        ]
        if all(in_view(view, _hull_points(g.vertices), rg.margin_px) for g in frames):
            sheet = cand
            break
    if sheet is None:
        return None
    sheet["roughness"] = float(rng.uniform(*rg.ggx_roughness))
    sheet["f0"] = float(rng.uniform(*rg.dielectric_f0))
    sheet["frames"] = sheet_frames
    rho = rng.uniform(*rg.chromatic_offset_m)
    az = np.deg2rad(rng.uniform(0, 360))
    z = -rng.uniform(*rg.chromatic_depth_rel) * geo["distance"]
    chromatic = np.array([rho * np.cos(az), rho * np.sin(az), z])
    white_tilt, white_axis = _tilt(rng, rg.white_tilt_deg)
    return {
        "statue": statue,
        "toy": toy,
        "sheet": sheet,
        "chromatic_light": chromatic,
        "white": {
            "tilt_deg": white_tilt,
            "tilt_axis_deg": white_axis,
            "size_m": 6 * geo["half_width"],
        },
    }


def _sheet(desc, phase, material):
    return sc.sheet(
        phase,
        size=tuple(desc["size"]),
        tilt_rad=np.deg2rad(desc["tilt_deg"]),
        tilt_axis_rad=np.deg2rad(desc["tilt_axis_deg"]),
        material=material,
    )


def _statue_material(d) -> Material:
    if d["material"] == "plaster":
        return Material(kd=1.0, specular="blinn_phong", ks=0.25, shininess=30.0)
    if d["material"] == "dielectric":
        return Material(
            kd=1.0, specular="ggx", ks=1.0, roughness=d["roughness"], f0=d["f0"], tint="white"
        )
    return Material(kd=1.0, diffuse="oren_nayar", sigma=d["sigma"])


def _builders(desc: dict, geo: dict, statue_level: int) -> dict:
    st, ty, sh, wh = desc["statue"], desc["toy"], desc["sheet"], desc["white"]

    def statue():
        g = sc.with_materials(_base_geometry("statue", statue_level), [_statue_material(st)])
        return sc.transformed(g, st["scale"], _yaw(st["yaw_deg"]), st["position"], st["origin"])

    def toy():
        plastic = Material(
            kd=1.0,
            specular="ggx",
            ks=1.0,
            roughness=ty["plastic_roughness"],
            f0=ty["plastic_f0"],
            tint="white",
        )
        metal = Material(
            kd=0.05,
            specular="ggx",
            ks=1.0,
            roughness=ty["metal_roughness"],
            tint="fresnel",
            f0_rgb=tuple(ty["metal_f0_rgb"]),
        )
        g = sc.with_materials(_base_geometry("toy", statue_level), [plastic, metal])
        return sc.transformed(g, ty["scale"], _yaw(ty["yaw_deg"]), ty["position"], ty["origin"])

    sheet_material = Material(
        kd=1.0, specular="ggx", ks=1.0, roughness=sh["roughness"], f0=sh["f0"], tint="white"
    )

    def sheet(phase):
        return _sheet(sh, phase, sheet_material)

    def white():
        return sc.white_reference(
            wh["size_m"], 0.0, _tilt_matrix(wh["tilt_deg"], wh["tilt_axis_deg"])
        )

    return {"white": white, "statue": statue, "toy": toy, "sheet": sheet}


# --------------------------------------------------------------------------- photometric
def _photometric(seed, geo, width, height, nuisances, rg) -> tuple[RigModel, dict]:
    """The photometric model: every value drawn whatever the switches, then switched."""
    rng = _stream(seed, "photometric")
    n = nuisances
    exposure = rng.uniform(*rg.exposure)
    full_well = rng.uniform(*rg.full_well_e)
    read_noise = rng.uniform(*rg.read_noise_e)
    cams, lights, per_camera = [], [], []
    for cam in geo["cameras"]:
        gains_u = rng.uniform(-1, 1, 3)
        k = rng.uniform(*rg.vignetting_corner)
        k_c = k + rng.uniform(-rg.colour_shading, rg.colour_shading, 3)
        centre = _disc(rng, 1) + _disc(rng, 3)  # (3, 2), units of the disc radius
        off = rng.uniform(*rg.crosstalk, (3, 3))
        factor = rng.uniform(*rg.filter_crosstalk_factor, (3, 3))
        mx = rng.uniform(*rg.led_exponent_x)
        my = rng.uniform(*rg.led_exponent_y)
        skew = rng.uniform(-rg.led_skew, rg.led_skew, 2)
        tilt = rng.uniform(0, rg.led_tilt_deg)
        tilt_dir = rng.uniform(0, 360)
        ripple = (
            rng.uniform(*rg.ripple_amplitude),
            np.deg2rad(rng.uniform(*rg.ripple_period_deg)),
            rng.uniform(0, 2 * np.pi),
        )
        corner = np.hypot(width / 2, height / 2) / cam.K[0, 0]
        gains = 1 + gains_u * n.gain_spread if n.gain_spread else np.ones(3)
        vig = k_c if n.vignetting else np.zeros(3)
        X = np.eye(3)
        Xc = np.eye(3)
        if n.crosstalk:
            X = X + (1 - np.eye(3)) * off
            Xc = np.eye(3) + (1 - np.eye(3)) * off * factor
        model = CameraModel(
            name=cam.name,
            K=cam.K,
            dist=cam.dist,
            R=cam.R,
            t=cam.t,
            light_colour=cam.light_colour,
            light_offset=np.zeros(3),
            gains=gains,
            vignetting=vig,
            vignetting_centre=centre * rg.vignetting_centre_rel * corner,
            crosstalk=X,
            corner_radius=corner,
            chromatic_crosstalk=Xc,
        )
        cams.append(model)
        if n.light_falloff:
            R_led = _tilt_matrix(tilt, tilt_dir) @ cam.R
            led = LightModel(
                model.light_centre, R_led, cam.light_colour, 1.0, mx, my, tuple(skew), ripple
            )
        else:
            led = LightModel(model.light_centre, cam.R, cam.light_colour, 1.0)
        lights.append(led)
        per_camera.append({"name": cam.name, "led_axis_tilt_deg": float(tilt)})
    lights = [
        replace(li, power=_power_for_exposure(li, cams, exposure, sc.WHITE_ALBEDO, profile=True))
        for li in lights
    ]
    pos = np.asarray(geo["scenes"]["chromatic_light"], float)
    Rc, _ = look_at(pos, np.zeros(3))
    chrom = {}
    for k, colour in enumerate(COLOURS):
        tilt = (n.chromatic_filter_tilt * (k - 1), -n.chromatic_filter_tilt * (k - 1) / 2)
        m = 2.0 if n.light_falloff else 0.0
        li = LightModel(pos, Rc, colour, 1.0, m, m, tilt)
        chrom[colour] = replace(
            li, power=_power_for_exposure(li, cams, exposure, sc.WHITE_ALBEDO, own=True)
        )
    recorded = replace(
        n,
        light_exponent_x=rg.led_exponent_x,
        light_exponent_y=rg.led_exponent_y,
        light_skew=rg.led_skew,
        vignetting_corner=rg.vignetting_corner,
        colour_shading=rg.colour_shading,
        crosstalk_range=rg.crosstalk,
        full_well_e=float(full_well),
        read_noise_e=float(read_noise),
        exposure=float(exposure),
    )
    rig = RigModel(tuple(cams), tuple(lights), chrom, width, height, recorded)
    return rig, {"exposure": exposure, "cameras": per_camera}


def _disc(rng, k: int) -> np.ndarray:
    """``k`` points (k, 2) uniform in the unit disc."""
    r = np.sqrt(rng.uniform(0, 1, k))
    a = rng.uniform(0, 2 * np.pi, k)
    return np.stack([r * np.cos(a), r * np.sin(a)], axis=1)


def _jsonable(v: Any) -> Any:
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, dict):
        return {k: _jsonable(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [_jsonable(x) for x in v]
    return v


def describe(draw: RandomDraw) -> dict:
    """The draw as JSON-able data (rig model aside)."""
    return _jsonable(draw.description | {"board": draw.board}) | {
        "nuisances": _jsonable(asdict(draw.rig.nuisances))
    }
