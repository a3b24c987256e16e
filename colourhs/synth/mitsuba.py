"""The marker board rendered by Mitsuba 3: a second, independent renderer.

Mitsuba 3 (``pip install mitsuba``) is an optional dependency, used by
``benchmarks/mitsuba_photometric.py`` and the opt-in tests only, never by the
workflow; this module imports it when a function is called. It renders the
photometric captures' board (paper section III-C) for a synthetic rig
(:class:`~colourhs.synth.simulated_rig.RigModel`) with Mitsuba's own pinhole camera,
point or spot lights, BSDFs, texture lookup, pixel filters and, optionally, a
white floor whose light reaches the board (path tracing), so that the
photometric calibration can be tried on images that
:mod:`colourhs.synth.image_formation` did not make (:class:`BoardRender`,
:func:`photometric_dataset`). What the rig adds after the optics (channel sensitivity sigma_c,
cross-talk X, sensor noise) is applied as in eq. (4) of
:mod:`colourhs.synth.image_formation`.

Mitsuba's perspective camera has no lens distortion, square pixels only and
no skew, and its point light is isotropic: a rig given here must have
``dist`` zero, ``K[0, 0] == K[1, 1]``, ``K[0, 1] == 0`` and lights without an
angular profile (``Nuisances.light_falloff`` off), else :func:`render_board`
refuses it.
"""

from __future__ import annotations

import json
import os
import shutil
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from colourhs.common.geometry import normalised_coordinates, pixel_grid
from colourhs.synth import scenes as sc
from colourhs.synth.simulated_rig import COLOURS, CameraModel, RigModel

# Mitsuba's CPU-vectorised variant (llvm_ad_rgb) compiles kernels with the
# system's LLVM and aborts on some BSDFs, filters and integrators with LLVM 15 or
# older; the scalar variant needs none. COLOURHS_MITSUBA_VARIANT=llvm_ad_rgb, with
# DRJIT_LIBLLVM_PATH at a newer libLLVM, is several times faster.
MITSUBA_VARIANT = os.environ.get("COLOURHS_MITSUBA_VARIANT", "scalar_rgb")
# Mitsuba's camera looks along +z with +x to the left and +y up; OpenCV's has
# +x to the right and +y down.
_CV_TO_MITSUBA = np.diag([-1.0, -1.0, 1.0])


@dataclass(frozen=True)
class BoardRender:
    """How Mitsuba renders the board.

    Attributes
    ----------
    material : ``"diffuse"`` (Lambertian, the board of :mod:`colourhs.synth.scenes`)
        or ``"roughplastic"`` (a white diffuse base under a GGX-rough dielectric
        coating: glossy paper or a laminated board).
    roughness : GGX alpha of the coating (``"roughplastic"`` only).
    pixel_filter : Mitsuba's reconstruction filter: ``"box"`` (a sensor's pixel
        area, as :mod:`colourhs.synth.image_formation`) or ``"gaussian"`` (Mitsuba's
        default, 0.5 px standard deviation: light from a marker spreads about
        2 px into the white).
    samples_per_pixel : stratified samples per pixel.
    spot_cutoff_deg, spot_beam_deg : ``None``: isotropic point lights (the
        rig's own lights, ``light_falloff`` off). Else Mitsuba's spot light
        along each camera's optical axis: full intensity within
        ``spot_beam_deg`` of the axis, falling linearly in angle to zero at
        ``spot_cutoff_deg`` (a profile with a kink, unlike the rig's smooth
        LED profiles; :func:`spot_profile`).
    texel_m : size of a texel of the board's printed texture, metres (a tenth
        of a millimetre is finer than any pixel footprint at working distance).
    floor_m : ``None``: the board alone. Else a white Lambertian floor (2 m
        square, the board's white albedo) this far below the world origin,
        across the first camera's image-down axis, and Mitsuba's path tracer
        with one bounce: light that reaches the board through the floor, which
        eq. (6)'s direct-light kappa does not model.
    """

    material: str = "diffuse"
    roughness: float = 0.2
    pixel_filter: str = "box"
    samples_per_pixel: int = 16
    texel_m: float = 1e-4
    spot_cutoff_deg: float | None = None
    spot_beam_deg: float | None = None
    floor_m: float | None = None


def spot_profile(cos_theta: np.ndarray, cutoff_deg: float, beam_deg: float) -> np.ndarray:
    """Mitsuba's spot light intensity relative to its axis at angle acos(cos_theta).

    1 within ``beam_deg``, then linear in the angle down to 0 at ``cutoff_deg``.
    """
    theta = np.degrees(np.arccos(np.clip(cos_theta, -1.0, 1.0)))
    ramp = (cutoff_deg - theta) / (cutoff_deg - beam_deg)
    return np.where(theta <= beam_deg, 1.0, np.clip(ramp, 0.0, 1.0))


def _mitsuba():
    import mitsuba as mi

    if mi.variant() != MITSUBA_VARIANT:
        mi.set_variant(MITSUBA_VARIANT)
    return mi


def mitsuba_draw(
    preset: str,
    seed: int,
    *,
    light_offset_m: tuple[float, float] = (0.0, 0.0),
    noise: bool = True,
    exact: bool = False,
):
    """A randomised preset's draw restricted to what Mitsuba models (:func:`check_rig`).

    The preset's ranges with no lens distortion, square pixels, no skew and the
    lights ``light_offset_m`` (a range, metres) from the lens centres;
    nuisances with isotropic lights and no cross-talk, sensor noise as
    ``noise``; ``exact`` as :func:`colourhs.synth.randomrig.draw_random`.
    Returns the preset, the ranges, the nuisances and the draw, which
    :func:`colourhs.synth.synthesise.synthesise` (with those ranges and
    nuisances) renders as the same rig.
    """
    from dataclasses import replace

    from colourhs.synth.randomrig import RANGES_BY_NAME, draw_random
    from colourhs.synth.simulated_rig import Nuisances
    from colourhs.synth.synthesise import PRESETS

    p = PRESETS[preset]
    ranges = replace(
        RANGES_BY_NAME[p.random_ranges],
        k1=(0.0, 0.0),
        k2=(0.0, 0.0),
        tangential_sd=0.0,
        rational=0.0,
        thin_prism_sd=0.0,
        skew_rel=0.0,
        aspect_rel=0.0,
        light_offset_m=tuple(light_offset_m),
    )
    nuis = Nuisances(light_falloff=False, crosstalk=False, noise=noise)
    d = draw_random(
        seed,
        p.width,
        p.height,
        nuis,
        ranges,
        n_poses=p.n_poses,
        sheet_frames=p.sheet_frames,
        statue_level=p.statue_level,
        exact=exact,
    )
    return p, ranges, nuis, d


def check_rig(rig: RigModel) -> None:
    """Raise ``ValueError`` naming what of ``rig`` Mitsuba's camera and light cannot model."""
    for cam in rig.cameras:
        K = cam.K
        if np.any(cam.dist != 0):
            raise ValueError(
                f"camera {cam.name}: lens distortion {cam.dist.tolist()} (Mitsuba has none)"
            )
        if abs(K[0, 0] - K[1, 1]) > 1e-9 * K[0, 0] or K[0, 1] != 0:
            raise ValueError(f"camera {cam.name}: non-square pixels or skew (Mitsuba has neither)")
    for li in rig.lights:
        if li.exponent_x or li.exponent_y or any(li.skew) or li.ripple[0]:
            raise ValueError(
                f"{li.colour} light: an angular profile (Mitsuba's point light is isotropic)"
            )


def board_texture(board: dict, texel_m: float) -> np.ndarray:
    """The printed board's reflectance (rows along board y, columns along board x)."""
    w, h = board["size"]
    nx, ny = int(np.ceil(w / texel_m)), int(np.ceil(h / texel_m))
    x = (np.arange(nx) + 0.5) * w / nx
    y = (np.arange(ny) + 0.5) * h / ny
    X, Y = np.meshgrid(x, y)
    xy = np.stack([X.ravel(), Y.ravel()], axis=1)
    return sc.board_reflectance(board, xy).reshape(ny, nx)


def _board_bsdf(mi, board: dict, opts: BoardRender) -> dict:
    tex = board_texture(board, opts.texel_m)
    refl = {
        "type": "bitmap",
        "bitmap": mi.Bitmap(np.repeat(tex[..., None], 3, axis=2).astype(np.float32)),
        "raw": True,
        "filter_type": "nearest",
    }
    if opts.material == "diffuse":
        bsdf = {"type": "diffuse", "reflectance": refl}
    elif opts.material == "roughplastic":
        bsdf = {
            "type": "roughplastic",
            "distribution": "ggx",
            "alpha": float(opts.roughness),
            "diffuse_reflectance": refl,
            "nonlinear": False,
        }
    else:
        raise ValueError(f"unknown board material {opts.material!r}")
    return {"type": "twosided", "bsdf": bsdf}


def _floor(mi, cam: CameraModel, distance_m: float) -> dict:
    """A 2 m white Lambertian square ``distance_m`` below the origin, facing up."""
    down = cam.R[1]  # the camera's image-down axis in the world
    x_axis = cam.R[0]
    z_axis = np.cross(x_axis, down)
    A = np.eye(4)
    # the rectangle's normal (+z local) points up, towards the board
    A[:3, :3] = np.stack([x_axis, z_axis, -down], axis=1)
    A[:3, 3] = distance_m * down
    return {
        "type": "rectangle",
        "to_world": mi.ScalarTransform4f(A.tolist()),
        "bsdf": {
            "type": "twosided",
            "bsdf": {
                "type": "diffuse",
                "reflectance": {"type": "rgb", "value": [sc.WHITE_ALBEDO] * 3},
            },
        },
    }


def _light(mi, li, cam: CameraModel, opts: BoardRender) -> dict:
    value = np.zeros(3)
    value[COLOURS.index(li.colour)] = li.power
    intensity = {"type": "rgb", "value": value.tolist()}
    pos = np.asarray(li.position, float)
    if opts.spot_cutoff_deg is None:
        return {"type": "point", "position": pos.tolist(), "intensity": intensity}
    axis = cam.R[2]  # the camera's optical axis in the world
    to_world = mi.ScalarTransform4f().look_at(
        origin=pos.tolist(), target=(pos + axis).tolist(), up=(-cam.R[1]).tolist()
    )
    return {
        "type": "spot",
        "to_world": to_world,
        "intensity": intensity,
        "cutoff_angle": float(opts.spot_cutoff_deg),
        "beam_width": float(opts.spot_beam_deg),
    }


def true_mu_maps(rig: RigModel, opts: BoardRender) -> dict[str, np.ndarray]:
    """Ground-truth mu = rho / sigma (eq. 2) of the lights :func:`render_board` uses.

    As :func:`colourhs.synth.groundtruth.true_mu_maps` (same keys, pixel
    centres, the light's direction towards the camera's ray at the camera's
    distance from the world origin), with Mitsuba's spot profile when
    ``opts`` asks for spot lights.
    """
    from colourhs.synth.groundtruth import true_mu_maps as rig_maps
    from colourhs.synth.image_formation import camera_rays

    out = rig_maps(rig)
    if opts.spot_cutoff_deg is None:
        return out
    for i, cam in enumerate(rig.cameras):
        rays = camera_rays(cam, rig.width, rig.height, supersample=1)
        points = rays.origin + float(np.linalg.norm(cam.centre)) * rays.directions
        d = points - rig.lights[i].position
        cos = (d @ cam.R[2]) / np.linalg.norm(d, axis=1)
        prof = spot_profile(cos, opts.spot_cutoff_deg, opts.spot_beam_deg)
        for key in out:
            if key.startswith(f"{cam.name}/"):
                out[key] = (out[key] * prof.reshape(out[key].shape)).astype(np.float32)
    return out


def _sensor(mi, cam: CameraModel, width: int, height: int, opts: BoardRender):
    K = cam.K
    c2w = np.eye(4)
    c2w[:3, :3] = cam.R.T @ _CV_TO_MITSUBA
    c2w[:3, 3] = cam.centre
    # OpenCV puts pixel centres on integers, Mitsuba's film on half-integers;
    # Mitsuba's principal-point offset is a fraction of the film, positive
    # towards its own +x (left) and +y (up).
    return mi.load_dict(
        {
            "type": "perspective",
            "fov": float(np.degrees(2 * np.arctan(width / (2 * K[0, 0])))),
            "fov_axis": "x",
            "principal_point_offset_x": -(K[0, 2] + 0.5 - width / 2) / width,
            "principal_point_offset_y": -(K[1, 2] + 0.5 - height / 2) / height,
            "near_clip": 1e-3,
            "far_clip": 1e3,
            "to_world": mi.ScalarTransform4f(c2w.tolist()),
            "film": {
                "type": "hdrfilm",
                "width": width,
                "height": height,
                "pixel_format": "rgb",
                "rfilter": {"type": opts.pixel_filter},
            },
            "sampler": {"type": "stratified", "sample_count": opts.samples_per_pixel},
        }
    )


def render_board(
    rig: RigModel, board: dict, R_b: np.ndarray, t_b: np.ndarray, opts: BoardRender | None = None
) -> dict[str, np.ndarray]:
    """Per-band light transport of the board at pose (R_b, t_b), seen by every camera.

    Parameters
    ----------
    rig : the synthetic rig (cameras, lights with their power).
    board : rig.json's board entry.
    R_b, t_b : the board's pose, world X = R_b X_board + t_b (metres).
    opts : how to render (default :class:`BoardRender`).

    Returns
    -------
    dict
        Camera name -> (height, width, 3) image whose band b holds the radiance
        reaching the camera from the light of colour b (``COLOURS`` order), in
        the rig's full-scale units: ``rho_l f_b (n . v_l) / d_l^2`` of eq. (4)
        before the camera's sigma_c and cross-talk.
    """
    mi = _mitsuba()
    opts = BoardRender() if opts is None else opts
    check_rig(rig)
    w, h = board["size"]
    # Mitsuba's rectangle spans [-1, 1]^2 in its local xy plane; uv = (x + 1) / 2, (y + 1) / 2.
    A = np.eye(4)
    A[:3, :3] = np.asarray(R_b, float) @ np.diag([w / 2, h / 2, 1.0])
    A[:3, 3] = np.asarray(R_b, float) @ np.array([w / 2, h / 2, 0.0]) + np.asarray(t_b, float)
    board_shape = {
        "type": "rectangle",
        "to_world": mi.ScalarTransform4f(A.tolist()),
        "bsdf": _board_bsdf(mi, board, opts),
    }
    # One scene per light: Mitsuba's direct integrator picks one emitter per
    # sample, which would add noise between the bands.
    shapes = {"board": board_shape}
    integrator = {"type": "direct"}
    if opts.floor_m is not None:
        shapes["floor"] = _floor(mi, rig.cameras[0], opts.floor_m)
        integrator = {"type": "path", "max_depth": 3}
    scenes = []
    for li, cam in zip(rig.lights, rig.cameras, strict=True):
        scenes.append(
            mi.load_dict(
                {"type": "scene", "integrator": integrator, "light": _light(mi, li, cam, opts)}
                | shapes
            )
        )
    out = {}
    for cam in rig.cameras:
        sensor = _sensor(mi, cam, rig.width, rig.height, opts)
        images = [mi.render(s, sensor=sensor, spp=opts.samples_per_pixel) for s in scenes]
        out[cam.name] = sum(np.array(img, dtype=np.float64) for img in images)
    return out


def camera_signal(
    cam: CameraModel, transport: np.ndarray, crosstalk: np.ndarray | None = None
) -> np.ndarray:
    """Eq. (4)'s camera side: signal_c = sigma_c(v) sum_b X[c, b] transport_b.

    ``transport`` is one camera's :func:`render_board` image; sigma_c is taken
    at the pixel centres. Returns the (height, width, 3) signal in fractions of
    full scale, as :func:`colourhs.synth.image_formation.channel_signal`.
    """
    H, W = transport.shape[:2]
    X = cam.crosstalk if crosstalk is None else np.asarray(crosstalk, float)
    xy = normalised_coordinates(pixel_grid(W, H).reshape(-1, 2), cam.K, cam.dist)
    sens = cam.sensitivity(xy).reshape(H, W, 3)
    return np.einsum("cb,hwb->hwc", X, transport) * sens


def photometric_dataset(
    out: str | Path, ours: str | Path, rig: RigModel, board: dict, poses, seed: int, opts
) -> Path:
    """A copy of dataset ``ours`` whose ``photometric/`` board captures Mitsuba rendered.

    ``ours`` is a dataset that :func:`colourhs.synth.synthesise.synthesise` wrote for
    ``rig`` (its ``rig.json`` and ``gt/`` are copied; ``gt/photometric.h5``
    becomes :func:`true_mu_maps` of ``opts``' lights); ``poses`` are its board
    poses (R, t), the held-out plane last, as ``draw_random`` gives them. Each
    image gets the rig's sensor noise with the draw ``ours`` used for the same
    file. Written to a sibling folder and moved into place: no partial dataset.
    """
    from colourhs.synth.simulated_rig import sensor
    from colourhs.synth.synthesise import _image_rng, write_png

    out, ours = Path(out), Path(ours)
    tmp = out.with_name(out.name + ".partial")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    try:
        shutil.copy(ours / "rig.json", tmp / "rig.json")
        shutil.copytree(ours / "gt", tmp / "gt")
        with h5py.File(tmp / "gt" / "photometric.h5", "w") as f:
            f.attrs["note"] = "mu = rho / sigma (eq. 2) of Mitsuba's lights, on pixel centres"
            for key, mu in true_mu_maps(rig, opts).items():
                f.create_dataset(key, data=mu, compression="gzip")
        image = json.loads((ours / "rig.json").read_text())["image"]
        for k, (R, t) in enumerate(poses[:-1]):
            transport = render_board(rig, board, R, t, opts)
            for cam in rig.cameras:
                rel = f"photometric/pose{k:02d}/{cam.name}.png"
                dn = sensor(
                    camera_signal(cam, transport[cam.name]),
                    _image_rng(seed, rel),
                    rig.nuisances,
                    image["bit_depth"],
                    image["black_level"],
                    image["white_level"],
                )
                write_png(tmp / rel, dn)
        shutil.rmtree(out, ignore_errors=True)
        tmp.rename(out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out
