"""Randomised rigs and scenes: the presets ``random``, ``random-tiny`` and ``corner``.

Every seed draws a different, plausible colour HS rig and scene set from the
ranges below (U = uniform, N = normal; "per camera" draws are independent
for each camera). These tables are the one place the ranges are documented;
:class:`RandomRanges` holds them (``RANGES`` for ``random``, ``TINY_RANGES``
for ``random-tiny``, which differs only where the last column says so;
``CORNER_RANGES`` and ``CORNER_TINY_RANGES`` for ``corner`` and
``corner-tiny``, which differ from ``random`` and ``random-tiny`` only as the
second table says).

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
                      white level 2^bits - 1; 12-bit data (``corner``)
                      in 16-bit PNGs, black level U(0, 1) x 256 DN,
                      white level 4095
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
                      deg incidence and every marker cell spans >= 2
                      px; the ``plane`` drawn as the others
                      (``corner``: at a slant to the reference camera)
ChArUco target        sized to the drawn rig and posed from the seed's   same
                      own stream, as in every preset (``geometric/``:
                      :mod:`colourhs.synth.geometric_target`)
LED profile           cos(tx)^mx cos(ty)^my (1 + sx tx + sy ty): mx      same
                      U(10, 14), my U(6, 9), sx, sy U(-0.4, 0.4) /rad;
                      axis tilted U(0, 8) deg off the optical axis
                      towards U(0, 360) deg; ripple 1 + a cos(2 pi
                      theta / T + phase), a U(0, 0.03), T U(4, 15) deg,
                      phase U(0, 2 pi); lights collocated (offset 0;
                      ``corner``: beside the lens, below)
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
statue material       one of (p = 1/3 each): glossy plaster as in the    same
                      fixed presets (Blinn-Phong ks 0.25, s 30); white
                      dielectric (GGX roughness U(0.1, 0.5), F0 U(0.03,
                      0.06), white specular); rough diffuse (Oren-Nayar
                      sigma U(0.15, 0.5) rad); dirt as in the fixed
                      presets
toy materials         plastics: coloured diffuse + white GGX (roughness  same
                      U(0.1, 0.5), F0 U(0.03, 0.06)); mirror disc: GGX
                      metal, roughness U(0.1, 0.3), per-band F0 of
                      gold, copper, brass or silver (x (1 + U(-0.03,
                      0.03))), diffuse 0.05
sheet                 4 frames; width U(0.20, 0.30) m (aspect as in the  same
                      fixed presets), tilted U(0, 25) deg about an axis
                      at U(0, 360) deg; white (0.7) dielectric, white
                      GGX roughness U(0.1, 0.5), F0 U(0.03, 0.06); all
                      frames fully in view
chromatic light       U(0.3, 0.6) m off the viewing axis at U(0, 360)    same
                      deg, z = -U(0.5, 0.9) D (between rig and scene),
                      aimed at the origin; per-filter profile as in the
                      fixed presets
white reference       facing the rig through the origin, tilted U(0,     same
                      15) deg about an axis at U(0, 360) deg, 6 D
                      tan(FOV/2) wide (fills every view)
====================  =================================================  =====================

The ``corner`` presets combine the hard ends of the ranges (the rest as
``random`` and ``random-tiny``); each is drawable at both sizes (a draw that
does not fit is redrawn as a whole), so none is relaxed:

====================  ============================  ================================================
quantity              ``corner`` presets            why
====================  ============================  ================================================
pair angles           each U(12, 15) deg, largest   the narrowest triangle: the shortest baselines
                      minus smallest >= 1 deg       give the weakest depth (3 deg spread does not
                                                    fit a 3 deg range)
board poses           slant U(0, 50) deg,           the most foreshortened markers a calibration
                      incidence < 70 deg (cells >=  takes; 70 deg so that 50 deg slants fit the
                      2 px, 3 px for                other cameras too
                      ``corner-tiny``)
held-out plane        its normal U(40, 50) deg      a steep plane: depth changes fastest across the
                      from the line of sight of     reference view, and the other cameras see it at
                      the reference camera (the     up to ~65 deg; placed and kept as a calibration
                      first in rig.json) to the     pose (centre, roll, rules), the normal tilted
                      board's centre                from that line towards U(0, 360) deg
sensor                full well U(5000, 8000) e-,   the noisiest sensor: shot noise 1.1-1.4 %, read
                      read noise U(8, 10) e-        noise 0.1-0.2 % of full scale
image encoding        8 or 12 bit (p = 0.5 each)    the coarsest (8) and the 12-bit data of many
                                                    machine-vision sensors, in 16-bit PNGs with
                                                    white level 4095 (not 2^16 - 1)
lens distortion       k1 U(-0.15, -0.12), k2        the barrel end of ``random``'s k1 range, k2 of
                      U(0.05, 0.1)                  the opposite sign in the upper half of its
                                                    range: the corners of a 640x480 image move 2-9
                                                    px (FOV 18-35 deg)
light offset          U(0.02, 0.04) m from the      lights on a ring beside the lens, as built rigs
                      lens, in the camera's x-y     have them: the collocated-light assumption is
                      plane, towards U(0, 360) deg  off by 1-5 deg at 0.5-1 m
                      (per camera)
====================  ============================  ================================================

The ``random-dynamic`` presets draw the rig, board, poses, encoding and sheet
from the ranges of ``random`` and ``random-tiny`` (12 sheet frames, all in
view), the ``corner-dynamic`` presets from those of ``corner`` and
``corner-tiny``, and their moving objects as :mod:`colourhs.synth.dynamicscenes`
says.

Draws come from independent random streams per topic (rig geometry and
scenes, photometric model, encoding, light offsets), each seeded by the seed
and the topic's name, so the geometry, board, poses, scenes and encoding of
a seed do not depend on which nuisances are switched on: every photometric value is drawn
whatever the switches, and a switched-off effect just drops its values. A
draw whose boards or objects cannot be placed is redrawn as a whole (the
table's ranges are the ranges of every accepted draw).

``exact=True`` forces 16-bit images (white level 65535, also where the
ranges draw 12-bit data) and exact masks while keeping the rest of the
seed's draw (the black level keeps its drawn fraction of 4096 DN).

:func:`draw_random` assembles the draw: the ranges and the seeded streams are
:mod:`colourhs.synth.randomranges`, the cameras, board and poses
:mod:`colourhs.synth.randomgeometry`, the scenes
:mod:`colourhs.synth.randomscenes`; the image encoding, the lights' offsets and the
photometric model are drawn here.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace

import numpy as np

from colourhs.synth import scenes as sc
from colourhs.synth.randomgeometry import _draw_geometry
from colourhs.synth.randomranges import (
    CONTAINER_BITS,
    CORNER_RANGES,
    CORNER_TINY_RANGES,
    MASK_MODES,
    METALS,
    NAME_STYLES,
    RANGES,
    RANGES_BY_NAME,
    TINY_RANGES,
    RandomRanges,
    _stream,
)
from colourhs.synth.randomscenes import _builders, _tilt_matrix
from colourhs.synth.simulated_rig import (
    CameraModel,
    LightModel,
    Nuisances,
    RigModel,
    _power_for_exposure,
    chromatic_lights,
    jsonable,
)

__all__ = [
    "CORNER_RANGES",
    "CORNER_TINY_RANGES",
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


@dataclass(frozen=True)
class RandomDraw:
    """Everything a seed draws for a randomised dataset.

    Attributes
    ----------
    rig : the rig model (cameras in rig.json order, photometric model, the
        nuisances with the drawn sensor values).
    board : rig.json's board entry.
    poses : board poses (R_b, t_b): 7 calibration poses, then the ``plane``.
    bit_depth, black_level, white_level : the image encoding (``bit_depth`` the
        PNG's: 12-bit data has 16 and ``white_level`` 4095).
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
    white_level: int
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
    exact : force 16-bit images (white level 65535) and exact masks (the rest of the
        draw unchanged).
    """
    rg = ranges
    geo = _draw_geometry(seed, width, height, rg, n_poses, sheet_frames, statue_level)
    enc = _stream(seed, "encoding")
    sensor_bits = int(enc.choice(list(rg.bit_depths)))
    black_fraction = float(enc.uniform(0, 1))
    mask_mode = str(enc.choice(MASK_MODES))
    if exact:
        sensor_bits, mask_mode = 16, "exact"
    black = int(round(black_fraction * rg.black_level_dn[sensor_bits]))
    bits, white = CONTAINER_BITS[sensor_bits], 2**sensor_bits - 1
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
        "scenes": jsonable(scene_desc),
        "photometric": jsonable(photometric),
    }
    # Only where a range draws them: the other presets' descriptions stay as they were.
    if white != 2**bits - 1:
        description["white_level"] = white
    if rg.plane_slant_deg is not None:
        description["plane_slant_deg"] = _plane_slant(geo)
    return RandomDraw(
        rig=rig,
        board=geo["board"],
        poses=geo["poses"],
        bit_depth=bits,
        black_level=black,
        white_level=white,
        mask_mode=mask_mode,
        builders=builders,
        description=description,
    )


# --------------------------------------------------------------------------- photometric
def _photometric(seed, geo, width, height, nuisances, rg) -> tuple[RigModel, dict]:
    """The photometric model: every value drawn whatever the switches, then switched."""
    rng = _stream(seed, "photometric")
    n = nuisances
    exposure = rng.uniform(*rg.exposure)
    full_well = rng.uniform(*rg.full_well_e)
    read_noise = rng.uniform(*rg.read_noise_e)
    offsets = _light_offsets(seed, rg, len(geo["cameras"]))
    cams, lights, per_camera = [], [], []
    for cam, offset in zip(geo["cameras"], offsets, strict=True):
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
            light_offset=offset,
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
    chrom = chromatic_lights(geo["scenes"]["chromatic_light"], cams, exposure, sc.WHITE_ALBEDO, n)
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


def _light_offsets(seed, rg, n: int) -> np.ndarray:
    """Each camera's light offset (n, 3), camera coordinates, metres.

    Magnitude U(``rg.light_offset_m``) in a direction U(0, 360) deg in the
    camera's x-y plane (beside the lens), from the seed's ``light-offset``
    stream; zeros, drawing nothing, when the range's upper end is 0.
    """
    out = np.zeros((n, 3))
    if rg.light_offset_m[1] <= 0:
        return out
    rng = _stream(seed, "light-offset")
    r = rng.uniform(*rg.light_offset_m, n)
    a = rng.uniform(0, 2 * np.pi, n)
    out[:, 0], out[:, 1] = r * np.cos(a), r * np.sin(a)
    return out


def _plane_slant(geo) -> float:
    """The held-out plane's slant to the reference camera's line of sight, degrees."""
    R, t = geo["poses"][-1]
    centre = R @ sc.board_corners(geo["board"]["size"]).mean(axis=0) + t
    sight = geo["cameras"][0].centre - centre
    cos = (R @ [0.0, 0.0, -1.0]) @ sight / np.linalg.norm(sight)
    return float(np.rad2deg(np.arccos(np.clip(cos, -1.0, 1.0))))


def _disc(rng, k: int) -> np.ndarray:
    """``k`` points (k, 2) uniform in the unit disc."""
    r = np.sqrt(rng.uniform(0, 1, k))
    a = rng.uniform(0, 2 * np.pi, k)
    return np.stack([r * np.cos(a), r * np.sin(a)], axis=1)


def describe(draw: RandomDraw) -> dict:
    """The draw as JSON-able data (rig model aside)."""
    return jsonable(draw.description | {"board": draw.board}) | {
        "nuisances": jsonable(asdict(draw.rig.nuisances))
    }
