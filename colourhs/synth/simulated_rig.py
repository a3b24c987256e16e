"""The synthetic colour HS rig: geometry, photometric model and sensor.

Every effect that later stages must calibrate away is a field of
:class:`Nuisances`, with a realistic default and a switch, and this module is
the one place that documents them:

=====================  =====================================================  ==================
effect                 model                                                  default
=====================  =====================================================  ==================
light falloff          anisotropic LED-like radiance of each point light,     exponents 10..14
                       rho(theta) = P cos(theta_x)^m_x cos(theta_y)^m_y        (x) and 6..9 (y),
                       (1 + s_x theta_x + s_y theta_y), angles off the        skew +-0.4/rad
                       light's axis (its camera's optical axis)
vignetting             per-channel camera sensitivity                         8..16 % at the
                       sigma_c = g_c (1 - k_c r^2 / r_corner^2): a lens       corner, +-2 %
                       falloff k common to the channels plus a per-channel    colour shading,
                       colour shading, centre shifted per channel, gains g_c  gains +-6 %
                       differ per camera
cross-talk             3x3 matrix X[channel, light colour] per camera,        off-diagonal
                       diagonal 1; includes the camera's own light leaking    3..8 %; the
                       from its own-colour channel into the other two; a      same matrix for
                       second matrix for the chromatic light's filters        the filters
                       (``CameraModel.chromatic_crosstalk``)
chromatic filters      the chromatic light's profile differs per filter       +-5 %/rad tilt
sensor noise           shot noise (Poisson, full well in electrons) plus      15000 e-, 3 e-
                       Gaussian read noise
exposure               light powers set so a white (albedo 0.8) Lambertian    0.5 of full scale
                       surface at the working distance reads this value
quantisation           integer DN at the dataset's bit depth                  16 bit
saturation             values at or above full scale clip to white_level      on
=====================  =====================================================  ==================

With every switch off the images follow the paper's equation (4) exactly,
with the ground-truth mu of equation (2) written to ``gt/photometric.h5``.

These are the fixed presets' (tiny, demo, paper) values. The randomised
presets draw the magnitudes per seed and add effects (LED axes tilted off
the optical axes, a ripple in the LED profiles, distinct filter cross-talk):
their ranges are the table of :mod:`colourhs.synth.randomrig`.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np

from colourhs.capture import Camera
from colourhs.common.geometry import look_at

COLOURS = ("red", "green", "blue")


@dataclass(frozen=True)
class Nuisances:
    """Switches and magnitudes of every non-ideal effect of the synthetic rig."""

    light_falloff: bool = True
    light_exponent_x: tuple[float, float] = (10.0, 14.0)
    light_exponent_y: tuple[float, float] = (6.0, 9.0)
    light_skew: float = 0.4  # 1/rad, linear asymmetry of the beam
    vignetting: bool = True
    vignetting_corner: tuple[float, float] = (0.08, 0.16)  # fractional loss at the corner
    colour_shading: float = 0.02  # per-channel deviation of that loss
    gain_spread: float = 0.06  # per-camera, per-channel sensitivity spread
    crosstalk: bool = True
    crosstalk_range: tuple[float, float] = (0.03, 0.08)
    chromatic_filter_tilt: float = 0.05  # 1/rad, per-filter change of the chromatic light
    noise: bool = True
    full_well_e: float = 15000.0
    read_noise_e: float = 3.0
    exposure: float = 0.5
    quantise: bool = True
    saturate: bool = True

    def without(self, *names: str) -> Nuisances:
        """A copy with the named switches off (e.g. ``without("noise", "crosstalk")``)."""
        return replace(self, **{n: False for n in names})

    @classmethod
    def none(cls) -> Nuisances:
        """Every effect off but quantisation: equation (4) exactly."""
        return cls(
            light_falloff=False,
            vignetting=False,
            gain_spread=0.0,
            crosstalk=False,
            chromatic_filter_tilt=0.0,
            noise=False,
            saturate=False,
        )


@dataclass(frozen=True)
class LightModel:
    """A point light: position, colour, power and radiance profile.

    The profile's frame is ``R`` (world to light coordinates; the light looks
    along its +z axis, which need not be its camera's optical axis).
    """

    position: np.ndarray  # (3,) world, metres
    R: np.ndarray  # (3, 3)
    colour: str
    power: float  # radiant intensity on the axis, full-scale units x m^2
    exponent_x: float = 0.0
    exponent_y: float = 0.0
    skew: tuple[float, float] = (0.0, 0.0)
    ripple: tuple[float, float, float] = (0.0, 0.0, 0.0)  # amplitude, period (rad), phase (rad)

    def radiance(self, points: np.ndarray) -> np.ndarray:
        """Radiance rho(v) of the light towards world ``points`` (..., 3), eq. (1).

        Returns power x profile; the profile is 1 on the light's axis (up to the ripple).
        """
        d = (np.asarray(points, float) - self.position) @ self.R.T
        prof = light_profile(d, self.exponent_x, self.exponent_y, self.skew, self.ripple)
        return self.power * prof


def light_profile(
    d_light: np.ndarray, mx: float, my: float, skew=(0.0, 0.0), ripple=(0.0, 0.0, 0.0)
) -> np.ndarray:
    """Anisotropic LED-like angular profile for directions ``d_light`` (..., 3).

    ``cos(theta_x)^mx cos(theta_y)^my (1 + s_x theta_x + s_y theta_y)`` with
    theta_x = atan2(d_x, d_z) and theta_y = atan2(d_y, d_z) in radians, times
    the ripple ``1 + a cos(2 pi theta / T + phase)`` in the angle theta off the
    axis when ``ripple = (a, T, phase)`` has a > 0; zero behind the light.
    """
    tx = np.arctan2(d_light[..., 0], d_light[..., 2])
    ty = np.arctan2(d_light[..., 1], d_light[..., 2])
    prof = np.cos(tx) ** mx * np.cos(ty) ** my * (1.0 + skew[0] * tx + skew[1] * ty)
    amp, period, phase = ripple
    if amp:
        theta = np.arctan2(np.hypot(d_light[..., 0], d_light[..., 1]), d_light[..., 2])
        prof = prof * (1.0 + amp * np.cos(2 * np.pi * theta / period + phase))
    return np.where(d_light[..., 2] > 0, np.clip(prof, 0.0, None), 0.0)


@dataclass(frozen=True, eq=False)
class CameraModel(Camera):
    """A camera of the rig (geometry as in rig.json) and its photometric model.

    ``crosstalk`` is the channel response to the rig's LEDs (it also gives the
    true mu, eq. 2); ``chromatic_crosstalk`` the response to the chromatic
    light's filters, used for the chromatic captures.
    """

    gains: np.ndarray  # (3,) channel gains g_c
    vignetting: np.ndarray  # (3,) fractional loss k_c at the image corner
    vignetting_centre: np.ndarray  # (3, 2) per-channel centre offset, normalised coords
    crosstalk: np.ndarray  # (3, 3) X[channel, light colour] for the rig's LEDs
    corner_radius: float  # normalised radius of the image corner
    # (3, 3) the same for the chromatic light's three filters (their spectra differ
    # from the LEDs'); None: the LED matrix.
    chromatic_crosstalk: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.chromatic_crosstalk is None:
            object.__setattr__(self, "chromatic_crosstalk", self.crosstalk)

    def sensitivity(self, xy: np.ndarray) -> np.ndarray:
        """Per-channel sensitivity sigma_c (..., 3) at normalised image coordinates ``xy``."""
        xy = np.asarray(xy, float)[..., None, :]
        r2 = np.sum((xy - self.vignetting_centre) ** 2, axis=-1) / self.corner_radius**2
        return self.gains * np.clip(1.0 - self.vignetting * r2, 0.05, None)

    def to_json(self) -> dict:
        """The camera's entry of rig.json (capture format, version 1)."""
        return {
            "name": self.name,
            "K": self.K.tolist(),
            "dist": self.dist.tolist(),
            "R": self.R.tolist(),
            "t": self.t.tolist(),
            "light": {"colour": self.light_colour, "offset": self.light_offset.tolist()},
        }


@dataclass(frozen=True)
class RigModel:
    """The whole synthetic rig: cameras, their lights, the chromatic light."""

    cameras: tuple[CameraModel, ...]
    lights: tuple[LightModel, ...]  # one per camera, same order
    chromatic_lights: dict  # colour -> LightModel (one position, three filters)
    width: int
    height: int
    nuisances: Nuisances = field(default_factory=Nuisances)

    def helmholtz_mu(self, cam: int, channel: int, xy: np.ndarray, points: np.ndarray):
        """Ground-truth mu = rho / sigma of a Helmholtz camera, eq. (2).

        Camera ``cam``'s channel ``channel`` as a sensor, its collocated light
        as the source; ``xy`` are normalised image coordinates of the rays and
        ``points`` world points along them (the profile depends on direction
        only, so with a collocated light any point on the ray gives the same
        value; with a light beside the lens, the value at those points).
        """
        c = self.cameras[cam]
        sigma = c.sensitivity(xy)[..., channel] * c.crosstalk[channel, channel]
        return self.lights[cam].radiance(points) / sigma

    def to_json(self) -> dict:
        """Everything about the rig, for ``gt/rig_model.json``."""

        return {
            "cameras": [jsonable(asdict(c)) for c in self.cameras],
            "lights": [jsonable(asdict(li)) for li in self.lights],
            "chromatic_lights": {k: jsonable(asdict(v)) for k, v in self.chromatic_lights.items()},
            "nuisances": jsonable(asdict(self.nuisances)),
        }


def jsonable(v: Any) -> Any:
    """``v`` with numpy arrays and scalars as lists and Python numbers, dicts and
    sequences converted throughout (tuples become lists), for ``json.dump``."""
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, dict):
        return {k: jsonable(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [jsonable(x) for x in v]
    return v


def make_rig(
    width: int,
    height: int,
    focal_px: float,
    rng: np.random.Generator,
    nuisances: Nuisances = Nuisances(),  # noqa: B008 (frozen dataclass)
    distance_m: float = 0.8,
    circumradius_m: float = 0.25,
    chromatic_light_m=(0.0, -0.3, -0.6),
    light_colours=("blue", "red", "green"),
    white_albedo: float = 0.8,
) -> RigModel:
    """Three cameras at the corners of a triangle around the viewing axis.

    The working volume is centred on the world origin; the cameras sit about
    ``distance_m`` from it, on a circle of radius ``circumradius_m`` around the
    world z axis (the viewing axis), at 90, 210 and 330 degrees, so their
    centres are never collinear. Small random perturbations of pose and
    intrinsics make the rig as imperfect as a built one. Each camera carries a
    collocated light of the colour ``light_colours[i]`` (blue, red, green as in
    the paper).
    """
    n = nuisances
    cams, lights = [], []
    depth = np.sqrt(distance_m**2 - circumradius_m**2)
    corner = np.hypot(width / 2, height / 2) / focal_px
    for i, ang in enumerate(np.deg2rad([90.0, 210.0, 330.0])):
        centre = np.array(
            [circumradius_m * np.cos(ang), circumradius_m * np.sin(ang), -depth]
        ) + rng.normal(0, 0.005, 3)
        R, t = look_at(centre, rng.normal(0, 0.008, 3))
        f = focal_px * (1 + rng.normal(0, 0.01))
        K = np.array(
            [
                [f, 0.0, (width - 1) / 2 + rng.normal(0, width / 200)],
                [
                    0.0,
                    f * (1 + rng.normal(0, 0.002)),
                    (height - 1) / 2 + rng.normal(0, height / 200),
                ],
                [0.0, 0.0, 1.0],
            ]
        )
        dist = np.array(
            [rng.uniform(-0.12, -0.04), rng.uniform(0.02, 0.1), *rng.normal(0, 2e-4, 2), 0.0]
        )
        X = np.eye(3)
        if n.crosstalk:
            X = X + (1 - np.eye(3)) * rng.uniform(*n.crosstalk_range, (3, 3))
        gains = 1 + rng.uniform(-n.gain_spread, n.gain_spread, 3) if n.gain_spread else np.ones(3)
        vig = np.zeros(3)
        if n.vignetting:
            vig = rng.uniform(*n.vignetting_corner) + rng.uniform(-1, 1, 3) * n.colour_shading
        cams.append(
            CameraModel(
                name=f"cam{i + 1}",
                K=K,
                dist=dist,
                R=R,
                t=t,
                light_colour=light_colours[i],
                light_offset=np.zeros(3),
                gains=gains,
                vignetting=vig,
                vignetting_centre=rng.normal(0, 0.01, (3, 2)),
                crosstalk=X,
                corner_radius=corner,
            )
        )
        mx, my, skew = 0.0, 0.0, (0.0, 0.0)
        if n.light_falloff:
            mx = rng.uniform(*n.light_exponent_x)
            my = rng.uniform(*n.light_exponent_y)
            skew = tuple(rng.uniform(-n.light_skew, n.light_skew, 2))
        lights.append(LightModel(cams[-1].light_centre, R, light_colours[i], 1.0, mx, my, skew))
    # Exposure: a white Lambertian surface at the origin, facing the light,
    # reads `exposure` of full scale in the channels that record each light.
    lights = [
        replace(li, power=_power_for_exposure(li, cams, n.exposure, white_albedo)) for li in lights
    ]
    chrom = chromatic_lights(chromatic_light_m, cams, n.exposure, white_albedo, n)
    return RigModel(tuple(cams), tuple(lights), chrom, width, height, n)


def chromatic_lights(position_m, cams, exposure, albedo, nuisances) -> dict[str, LightModel]:
    """The chromaticity captures' lights: one of each colour at ``position_m``, aimed at
    the origin.

    Parameters
    ----------
    position_m : array_like, shape (3,)
        The lights' position, world metres.
    cams : sequence of CameraModel
        The rig's cameras (the exposure is their mean reading).
    exposure : float
        Reading of a white Lambertian surface of ``albedo`` at the origin facing the
        light, fraction of full scale, in the channel of the light's colour.
    albedo : float
        That white surface's albedo.
    nuisances : Nuisances
        Colour k (0, 1, 2 = red, green, blue) has the profile skew
        (t (k - 1), -t (k - 1) / 2), t = ``chromatic_filter_tilt`` (1/rad), and the
        profile exponents 2 with ``light_falloff`` (else 0).

    Returns
    -------
    dict
        Colour name -> LightModel.
    """
    n = nuisances
    pos = np.asarray(position_m, float)
    Rc, _ = look_at(pos, np.zeros(3))
    chrom = {}
    for k, colour in enumerate(COLOURS):
        tilt = (n.chromatic_filter_tilt * (k - 1), -n.chromatic_filter_tilt * (k - 1) / 2)
        m = 2.0 if n.light_falloff else 0.0
        li = LightModel(pos, Rc, colour, 1.0, m, m, tilt)
        chrom[colour] = replace(li, power=_power_for_exposure(li, cams, exposure, albedo, own=True))
    return chrom


def _power_for_exposure(light, cams, exposure, albedo, own=False, profile=False) -> float:
    """Light power giving reading ``exposure`` on white at the origin (mean of cameras).

    The white surface faces the light. With ``profile`` the light's angular
    profile towards the origin counts too (a light whose axis misses the origin).
    """
    c = COLOURS.index(light.colour)
    d2 = float(np.sum(light.position**2))
    readings = [
        cam.gains[c] * cam.crosstalk[c, c] * albedo / np.pi / d2
        for cam in cams
        if own or cam.light_colour != light.colour
    ]
    scale = 1.0
    if profile:
        scale = float(replace(light, power=1.0).radiance(np.zeros(3)))
    return exposure / float(np.mean(readings)) / scale


def sensor(
    signal: np.ndarray,
    rng: np.random.Generator,
    nuisances: Nuisances,
    bit_depth: int = 16,
    black_level: int = 0,
    white_level: int | None = None,
) -> np.ndarray:
    """Turn a linear signal (fractions of full scale) into raw sensor values.

    Shot noise is Poisson in electrons (``full_well_e`` electrons at full
    scale), read noise Gaussian (``read_noise_e`` electrons); the result is
    scaled to [black_level, white_level], rounded and clipped. ``white_level``
    defaults to ``2**bit_depth - 1``; 12-bit data in 16-bit images has 4095.

    Returns
    -------
    ndarray of uint8 or uint16, same shape as ``signal``; float64 values
    (unrounded, and unclipped when ``saturate`` is off) when ``quantise`` is off.
    """
    n = nuisances
    if white_level is None:
        white_level = 2**bit_depth - 1
    s = np.clip(np.asarray(signal, float), 0.0, None)
    if n.noise:
        electrons = rng.poisson(s * n.full_well_e) + rng.normal(0, n.read_noise_e, s.shape)
        s = electrons / n.full_well_e
    dn = black_level + s * (white_level - black_level)
    if n.saturate:
        dn = np.clip(dn, 0, white_level)
    if not n.quantise:
        return dn
    dn = np.clip(np.rint(dn), 0, 2**bit_depth - 1)
    return dn.astype(np.uint16 if bit_depth == 16 else np.uint8)
