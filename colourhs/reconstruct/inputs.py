"""A frame's inputs to colour HS: its images and the calibrations that apply.

:func:`load_frame` reads one frame of a dataset (capture format) with the
cross-talk (unmixing), photometric (mu maps, eq. 6-8), chromaticity (p,
eq. 9) and noise calibrations into a :class:`Frame`, the arrays that the
data term (:mod:`colourhs.reconstruct.dataterm`) and the Bayesian
refinement read.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import h5py
import numpy as np

from colourhs.calibration.crosstalk import load_crosstalk, unmix
from colourhs.calibration.noise import (
    NoiseModel,
    estimate_noise,
    load_noise,
    quantisation_variance,
)
from colourhs.capture import COLOURS, Rig, dataset_of, read_image, read_mask
from colourhs.common.files import note_read
from colourhs.reconstruct.dataterm import pair_arrays


@dataclass(frozen=True)
class CalibrationFiles:
    """The calibration files that apply to a frame (None: that calibration is not used).

    The fields are :func:`load_frame`'s keyword arguments of the same names.
    """

    crosstalk_json: str | Path | None = None  # colourhs crosstalk: the unmixing
    photometric_h5: str | Path | None = None  # colourhs photometric: mu maps (eq. 6-8)
    chromaticity_h5: str | Path | None = None  # colourhs chromaticity: p (eq. 9)
    noise_json: str | Path | None = None  # colourhs noise: the noise model

    def provenance(self) -> dict[str, str | Path | None]:
        """The files by the calibration's name (crosstalk, photometric, chromaticity, noise)."""
        return {
            "crosstalk": self.crosstalk_json,
            "photometric": self.photometric_h5,
            "chromaticity": self.chromaticity_h5,
            "noise": self.noise_json,
        }


@dataclass(frozen=True)
class RayGrid:
    """The reference camera's pixel rays: a hypothesis at z-depth z of pixel p is
    the point ``centre + z rays[p]``."""

    rays: np.ndarray  # (H*W, 3) world directions scaled to unit z-depth, row-major
    centre: np.ndarray  # (3,) the rays' origin, the reference camera's centre, metres
    shape: tuple[int, int]  # (H, W) of the reference image


@dataclass
class Frame:
    """Everything the data term needs of one frame (arrays in camera order)."""

    rig: Rig
    images: np.ndarray  # (C, 3, H, W) float32, unmixed when calibrated
    saturated: np.ndarray  # (C, H, W) bool
    silhouettes: np.ndarray | None  # (C, H, W) bool
    mu: np.ndarray | None  # (P, 2, H, W) float32
    chroma: np.ndarray | None  # (C, 3, H, W) float32
    variance: np.ndarray | None = None  # (C, 3, H, W) noise variance of ``images``
    inputs: list = field(default_factory=list)  # files read, for provenance
    # (P,) 1-sigma of each pair's log ratio mu_a / mu_b (the photometric calibration's
    # jackknife), None where the calibration does not say (no calibration, true maps)
    mu_ratio_sigma: np.ndarray | None = None
    # Whether a camera's missing p takes the reference pixel's: a map tracked away from
    # its chromatic frame, whose holes are mostly where the tracking lost the surface
    # (in the chromatic frame they are the calibration's); see colourhs.reconstruct.dataterm
    chroma_tracked: bool = False
    # A map tracked away from its chromatic frame: its tracking sigma (C, H, W) and each
    # camera's image colour as recorded (C, H, W, 3; chromaticity_tracking.image_colour),
    # for the reference camera's hole fill (fill_reference_holes); None otherwise
    chroma_sigma: np.ndarray | None = None
    chroma_colour: np.ndarray | None = None


def chroma_variance(images: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """The variance (as ``images``, (..., 3, H, W)) that a relative error ``sigma`` of p
    ((..., H, W), the same in every channel; NaN: none) adds to each intensity: eq. 3
    divides each intensity by its p, so a relative error of p is one of the intensity
    (beyond the paper)."""
    return (images * np.nan_to_num(sigma, nan=0.0)[..., None, :, :]) ** 2


def fill_reference_holes(frame: Frame, reference: int) -> Frame:
    """``frame`` with the holes of its ``reference`` camera's tracked map filled from a
    near pixel of the same image colour
    (:func:`colourhs.calibration.chromaticity_tracking.fill_from_colour`) and that
    camera's variance widened by the filled pixels' tracking sigma as
    :func:`load_frame` widens it; unchanged without a tracked map (beyond the paper).

    Only the reference camera's: a hole there drops the pixel, while another camera's
    sample without p takes the reference pixel's, the same surface point's, which a
    near pixel's p can only approach.
    """
    needs = (frame.chroma_colour, frame.chroma, frame.chroma_sigma, frame.variance)
    if any(x is None for x in needs):
        return frame
    from colourhs.calibration.chromaticity_tracking import fill_from_colour

    p = frame.chroma[reference].transpose(1, 2, 0)
    before = np.all(np.isfinite(p), axis=-1)
    filled, sigma = fill_from_colour(
        p, frame.chroma_sigma[reference], frame.chroma_colour[reference]
    )
    chroma, chroma_sigma = frame.chroma.copy(), frame.chroma_sigma.copy()
    chroma[reference] = filled.transpose(2, 0, 1)
    chroma_sigma[reference] = sigma
    variance = frame.variance.copy()
    new = np.all(np.isfinite(filled), axis=-1) & ~before
    variance[reference] += chroma_variance(frame.images[reference], np.where(new, sigma, 0.0))
    return replace(frame, chroma=chroma, chroma_sigma=chroma_sigma, variance=variance)


def load_frame(
    dataset_dir,
    scene: str,
    frame: str,
    crosstalk_json=None,
    photometric_h5=None,
    chromaticity_h5=None,
    use_masks: bool = True,
    noise_json=None,
) -> Frame:
    """Read a frame's images and the calibrations that apply to it.

    ``noise_json`` (:func:`colourhs.calibration.noise.calibrate_noise`) gives the images'
    noise variance; without it the noise model is estimated from the frame's
    own images (:func:`colourhs.calibration.noise.estimate_noise`). A chromaticity
    file that carries a 1-sigma of log p per camera (``sigma/<camera>``: a tracked
    map, :mod:`colourhs.calibration.chromaticity_tracking`; not the calibrated map's
    own, :func:`colourhs.calibration.chromaticity.log_sigma`) widens that variance by
    ``(i sigma)^2`` per channel: eq. 3 divides each intensity by its p, so a relative
    error of p is one of the intensity (beyond the paper); and where one camera's
    map, tracked away from the chromatic frame, has no p, the reconstruction takes
    the reference pixel's (``Frame.chroma_tracked``), and the reference camera's own
    holes that of a near pixel of the same colour in its image
    (:func:`fill_reference_holes`).
    """
    ds = dataset_of(dataset_dir, scenes=[scene])
    rig = ds.rig
    mixing = load_crosstalk(crosstalk_json) if crosstalk_json else {}
    imgs, sats, sils, inputs, raw = [], [], [], [], []
    sc = ds.scene(scene)
    for cam in rig.camera_names:
        path = ds.frame_image(scene, frame, cam)
        img, sat = read_image(path, rig.image)
        raw.append(img.transpose(2, 0, 1))
        imgs.append((unmix(img, mixing[cam]) if cam in mixing else img).transpose(2, 0, 1))
        sats.append(sat)
        inputs.append(path)
        if use_masks and sc.has_masks:
            sils.append(read_mask(ds.mask_image(scene, frame, cam), rig.image))
    mu = ratio_sigma = None
    pair_cams, pair_ch = pair_arrays(rig)
    if photometric_h5:
        from colourhs.calibration.photometric import read_mu_maps, read_ratio_sigma

        maps = read_mu_maps(photometric_h5)
        names = rig.camera_names
        keys = [
            (f"{names[a]}/{COLOURS[ca]}", f"{names[b]}/{COLOURS[cb]}")
            for (a, b), (ca, cb) in zip(pair_cams, pair_ch, strict=True)
        ]
        mu = np.stack([[maps[ka], maps[kb]] for ka, kb in keys]).astype(np.float32)
        # The jackknife part only: with the cross-talk term the sigma is too wide
        # (smooth surfaces fall within 1 sigma far more often than 68 % of the time).
        sigmas = read_ratio_sigma(photometric_h5, part="poses")
        if sigmas:
            ratio_sigma = np.array(
                [sigmas.get(f"{ka}~{kb}", sigmas.get(f"{kb}~{ka}", np.nan)) for ka, kb in keys]
            )
    chroma = chroma_sigma = None
    moved = False
    if chromaticity_h5:
        note_read(chromaticity_h5)
        with h5py.File(chromaticity_h5) as f:
            chroma = np.stack([f[cam][()].transpose(2, 0, 1) for cam in rig.camera_names])
            # A tracked map's sigma (its attribute "frame"); the calibration's own
            # (chromaticity.log_sigma) is not weighed in.
            tracked = "frame" in f.attrs
            if tracked and all(f"sigma/{cam}" in f for cam in rig.camera_names):
                chroma_sigma = np.stack([f[f"sigma/{cam}"][()] for cam in rig.camera_names])
                moved = f.attrs.get("frame", "") != f.attrs.get("chromatic_frame", "")
    for extra in (crosstalk_json, photometric_h5, chromaticity_h5, noise_json):
        if extra:
            inputs.append(Path(extra))
    images = np.stack(imgs).astype(np.float32)
    colour = None
    if moved:  # for the reference camera's hole fill (fill_reference_holes)
        from colourhs.calibration.chromaticity_tracking import image_colour

        colour = np.stack([image_colour(r.transpose(1, 2, 0)) for r in raw])
    model = load_noise(noise_json) if noise_json else None
    variance = []
    for c, cam in enumerate(rig.camera_names):
        rgb = images[c].transpose(1, 2, 0)
        if model is None:
            floor = quantisation_variance(rig.image.black_level, rig.image.white_level)
            gain, offset = estimate_noise([rgb], floor)
            variance.append(NoiseModel({cam: gain}, {cam: offset}).variance(cam, rgb))
        else:
            variance.append(model.variance(cam, rgb))
    variance = np.stack(variance).transpose(0, 3, 1, 2).astype(np.float32)
    if chroma_sigma is not None:  # (C, H, W): the same relative error in every channel
        variance += chroma_variance(images, chroma_sigma)
    return Frame(
        rig,
        images,
        np.stack(sats),
        np.stack(sils) if sils else None,
        mu,
        None if chroma is None else chroma.astype(np.float32),
        variance,
        inputs,
        ratio_sigma,
        moved,
        chroma_sigma if moved else None,
        colour,
    )
