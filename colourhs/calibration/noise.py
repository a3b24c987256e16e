"""Sensor noise model of each camera channel, estimated from the captures.

Beyond the paper: the Bayesian refinement (:mod:`colourhs.reconstruct.bayes.surface`)
weighs every constraint row of eq. (5) by its predicted noise, so that the
energy is in units of the sensor's own noise on any rig. A camera pixel
collects photo-electrons (Poisson) and read noise; in fractions of full
scale its variance is affine in the signal,

    var(i) = gain * i + offset,

``gain`` = 1 / (full well in electrons) and ``offset`` = (read noise /
full well)^2 plus the quantisation step^2 / 12. Both are estimated per
camera and channel from images the dataset already has (the white board
poses and the chromatic white captures), with no noise parameter in the
capture format:

1. Each pixel's residual against the mean of its 4 neighbours,
   ``r = i - (i_N + i_S + i_E + i_W) / 4``, is pure noise wherever the image
   is locally linear (smooth shading), with ``var(r) = 1.25 var(i)``.
2. Pixels are binned by signal level (no bin spans more than
   :data:`LEVEL_RATIO` in level); in every bin the robust variance
   ``(1.4826 MAD(r))^2 / 1.25`` ignores a minority of pixels on edges.
   A pixel's level is the mean of its four diagonal neighbours
   (:func:`neighbour_level`), which share no noise with ``r``: binned on its own
   noisy value, a bin at the edge of the levels present (a dark channel's
   cross-talk, a dim corner) selects the pixels whose noise pushed them in, and
   its spread of ``r`` reads a fraction of the noise's.
3. ``gain`` and ``offset`` are the non-negative weighted least-squares fit
   of the bins' variances against their median signal, the rounding to the raw
   values (:func:`quantisation_variance`, known from the rig's black and white
   levels) taken off before the fit and added to the offset after it: the
   offset is never below the rounding's, whatever few dark bins there are.
4. Beyond a minority: on a small image a board's markers, its outline and
   silhouettes are edges in a large share of the lit pixels, and the MAD of
   step 2 then grows with them. So the fit is repeated :data:`STRUCTURE_ROUNDS`
   times without the pixels near image structure (:func:`structure_mask`):
   where the residual of the image smoothed over :data:`STRUCTURE_SCALE_PX`
   exceeds :data:`STRUCTURE_K` of its own noise under the last fit.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from colourhs.capture import COLOURS, dataset_of, read_image
from colourhs.common.files import write_json
from colourhs.common.progress import bar

MAD_TO_SIGMA = 1.4826  # MAD of a normal distribution is 0.6745 sigma
RESIDUAL_VARIANCE = 1.25  # var(i - mean of 4 independent neighbours) / var(i)
MIN_SIGNAL = 0.02  # bins below this are biased by clipping at the black level
N_BINS = 24  # signal bins at most
MIN_BIN = 100  # pixels a bin needs for a stable MAD (its relative error ~ 1 / sqrt(N))

LEVEL_RATIO = 1.25
"""Widest span of a signal bin, as the ratio of its upper to its lower level: a bin's
variance stands for its median level only where the variance changes little across
it, and an affine variance changes by at most this ratio over it, whatever the rig's
levels (a quantile bin alone can span the gap between dark and lit pixels)."""

STRUCTURE_SCALE_PX = 1.5
"""Gaussian scale (pixels) at which :func:`structure_mask` looks for image structure.
The smoothing divides the noise of the neighbour residual about forty-fold
(:func:`smoothed_residual_gain`) but keeps much of a step's, so an edge stands out several times
more clearly than in the pixel's own residual; in pixels, since an edge's footprint in an
image is a pixel or two on any rig (the optics blur about a pixel)."""

STRUCTURE_K = 4.0
"""Noise sigmas of the smoothed residual beyond which a pixel is structure: noise alone
passes it at 0.006 % of the pixels (a Gaussian's two-sided 4-sigma tail), so the pixels
kept are the sensor's whatever its noise level."""

STRUCTURE_ROUNDS = 2
"""Refits without the structure of the last fit: the first fit (all pixels) sets the
threshold too wide, the second from a fit already free of most of the structure."""

MIN_KEPT_SHARE = 0.1
"""Least share of the lit pixels a refit must keep to replace the fit before it. The
mask takes the pixels near structure, up to about half of a small board image's; where it
leaves less than a tenth, the image is structure throughout (a textured scene's own
frame, a noise-free render, whose residuals are rounding and shading rather than a
sensor's noise) and the few pixels left stand for nothing. A share, so it holds on any
rig and at any image size."""


@dataclass(frozen=True)
class NoiseModel:
    """Affine noise model per camera: var(i) = gain[c] * i + offset[c] (full scale^2).

    Attributes
    ----------
    gain : dict camera name -> (3,) per channel R, G, B (1 / electrons at full scale).
    offset : dict camera name -> (3,) per channel (signal-independent variance).
    """

    gain: dict
    offset: dict

    def variance(self, camera: str, image: np.ndarray, channel: int | None = None) -> np.ndarray:
        """Predicted variance (H, W, 3) of a linear image (H, W, 3) of ``camera``; with
        ``channel`` (0-2), that of one channel's intensities (any shape)."""
        g = np.asarray(self.gain[camera], float)
        o = np.asarray(self.offset[camera], float)
        if channel is not None:
            g, o = g[channel], o[channel]
        return np.clip(np.asarray(image, float), 0.0, None) * g + o


def neighbour_level(channel: np.ndarray) -> np.ndarray:
    """The level (H-2, W-2) of each pixel of :func:`neighbour_residuals`: the mean of its
    four diagonal neighbours, the pixel's own level wherever the image is locally linear,
    and independent of the residual's noise (step 2 of the module; beyond the paper)."""
    c = np.asarray(channel, float)
    return (c[:-2, :-2] + c[:-2, 2:] + c[2:, :-2] + c[2:, 2:]) / 4.0


def neighbour_residuals(channel: np.ndarray) -> np.ndarray:
    """``i - mean(4 neighbours)`` (H-2, W-2) of one channel (H, W): noise where locally linear."""
    c = np.asarray(channel, float)
    mean4 = (c[:-2, 1:-1] + c[2:, 1:-1] + c[1:-1, :-2] + c[1:-1, 2:]) / 4.0
    return c[1:-1, 1:-1] - mean4


def fit_affine_noise(
    signal: np.ndarray, residual: np.ndarray, floor: float = 0.0
) -> tuple[float, float]:
    """Fit ``var = gain * signal + offset`` to neighbour residuals, robustly.

    Parameters
    ----------
    signal : (N,) signal level of each pixel (fraction of full scale), independent of
        its residual's noise (:func:`neighbour_level`).
    residual : (N,) its :func:`neighbour_residuals`.
    floor : least variance a bin can have (full scale^2): the quantisation's
        (:func:`quantisation_variance`), the least offset too (step 3 of the
        module). Without it an evenly lit capture
        without noise (a synthetic one with noise, vignetting and light
        fall-off off) has bins of variance 0 and no fit. It also gives the
        raw step, ``sqrt(12 floor)``: a residual is a multiple of a quarter
        step, and on 8-bit data a MAD of such values moves by whole quarter
        steps (a bin's variance by a factor of 2 either way). So each
        residual is spread uniformly over its quarter step (a fixed seed:
        the same images give the same fit) and that spread's variance,
        ``(step / 4)^2 / 12``, taken off its bin's.

    Returns
    -------
    gain, offset : non-negative floats (full scale, full scale^2).

    With pixels for a single bin only, the offset is taken as ``floor`` (shot noise).

    Raises
    ------
    ValueError
        Fewer than ``MIN_BIN`` usable pixels.
    """
    s = np.asarray(signal, float)
    r = np.asarray(residual, float)
    ok = np.isfinite(s) & np.isfinite(r) & (s > MIN_SIGNAL) & (s < 0.98)
    s, r = s[ok], r[ok]
    quantum = np.sqrt(12.0 * floor) / 4.0
    if quantum > 0:
        r = r + quantum * (np.random.default_rng(0).random(len(r)) - 0.5)
    if len(s) < MIN_BIN:
        raise ValueError(f"noise estimate: only {len(s)} usable pixels (need {MIN_BIN})")
    bins = int(np.clip(len(s) // (2 * MIN_BIN), 1, N_BINS))
    edges = np.quantile(s, np.linspace(0, 1, bins + 1))
    steps = int(np.ceil(np.log(s.max() / s.min()) / np.log(LEVEL_RATIO)))
    edges = np.unique(np.concatenate([edges, s.min() * LEVEL_RATIO ** np.arange(1, steps)]))
    level, var, count, silent = [], [], [], 0
    which = np.clip(np.searchsorted(edges, s, side="right") - 1, 0, len(edges) - 2)
    for k in range(len(edges) - 1):
        sel = which == k
        if sel.sum() < MIN_BIN:
            continue
        rk = r[sel]
        mad = np.median(np.abs(rk - np.median(rk)))
        v = max(((MAD_TO_SIGMA * mad) ** 2 - quantum**2 / 12.0) / RESIDUAL_VARIANCE, floor)
        if v <= 0:
            silent += sel.sum()
            continue
        level.append(np.median(s[sel]))
        var.append(v)
        count.append(sel.sum())
    if not level or silent > sum(count):
        # Most pixels without spread: a noise-free image, whose few bins with one are
        # its edges (their diagonal level between two flat parts), not noise.
        raise ValueError("noise estimate: no measurable noise (most bins' spread is 0)")
    if len(level) == 1:
        return float((var[0] - floor) / level[0]), float(floor)
    level, var, w = np.array(level), np.array(var), np.array(count, float)
    from scipy.optimize import nnls

    A = np.stack([level, np.ones_like(level)], axis=1) * np.sqrt(w)[:, None] / var[:, None]
    gain, offset = nnls(A, np.sqrt(w) * (var - floor) / var)[0]
    return float(gain), float(offset + floor)


def quantisation_variance(black_level: float, white_level: float) -> float:
    """Variance (full scale^2) of rounding to the raw values: one raw step
    ``1 / (white - black)`` of full scale, uniform error, so step^2 / 12."""
    return 1.0 / (12.0 * (float(white_level) - float(black_level)) ** 2)


def smoothed_residual_gain(scale_px: float = STRUCTURE_SCALE_PX) -> float:
    """Standard deviation of :func:`neighbour_residuals` of independent unit noise
    smoothed by a Gaussian of ``scale_px``: the root sum of squares of the two
    filters' combined kernel."""
    half = int(np.ceil(4 * scale_px)) + 2
    delta = np.zeros((2 * half + 1, 2 * half + 1))
    delta[half, half] = 1.0
    kernel = neighbour_residuals(cv2.GaussianBlur(delta, (0, 0), scale_px))
    return float(np.sqrt(np.sum(kernel**2)))


_SMOOTHED_GAIN = smoothed_residual_gain()


def structure_mask(channel: np.ndarray, gain: float, offset: float) -> np.ndarray:
    """Pixels (H-2, W-2, as :func:`neighbour_residuals`) of one channel (H, W) near
    image structure under the noise ``var = gain * i + offset``: within a pixel of one
    where the residual of the channel smoothed over :data:`STRUCTURE_SCALE_PX` exceeds
    :data:`STRUCTURE_K` of that residual's noise (:func:`smoothed_residual_gain`
    times the pixel's predicted sigma). Beyond the paper (step 4 of the module)."""
    c = np.asarray(channel, np.float64)
    smooth = neighbour_residuals(cv2.GaussianBlur(c, (0, 0), STRUCTURE_SCALE_PX))
    sigma = np.sqrt(np.clip(c[1:-1, 1:-1], 0.0, None) * gain + offset)
    found = np.abs(smooth) > STRUCTURE_K * _SMOOTHED_GAIN * sigma
    return cv2.dilate(found.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)


def estimate_noise(images: list[np.ndarray], floor: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Per-channel ``gain`` and ``offset`` (3,) from images (H, W, 3) of one camera;
    ``floor``: see :func:`fit_affine_noise`. The fit of every pixel, then
    :data:`STRUCTURE_ROUNDS` fits without those near structure (:func:`structure_mask`,
    step 4 of the module); a refit with too few pixels left (fewer than
    :data:`MIN_KEPT_SHARE` of the lit ones, or too few for a fit) keeps the fit before it."""
    gain, offset = np.zeros(3), np.zeros(3)
    for ch in range(3):
        sig = [neighbour_level(im[..., ch]) for im in images]
        res = [neighbour_residuals(im[..., ch]) for im in images]
        gain[ch], offset[ch] = fit_affine_noise(
            np.concatenate([a.ravel() for a in sig]),
            np.concatenate([r.ravel() for r in res]),
            floor,
        )
        lit = sum(int(np.count_nonzero(a > MIN_SIGNAL)) for a in sig)
        for _ in range(STRUCTURE_ROUNDS):
            keep = [~structure_mask(im[..., ch], gain[ch], offset[ch]) for im in images]
            kept = sum(
                int(np.count_nonzero(k & (a > MIN_SIGNAL))) for a, k in zip(sig, keep, strict=True)
            )
            if kept < MIN_KEPT_SHARE * lit:
                break
            try:
                gain[ch], offset[ch] = fit_affine_noise(
                    np.concatenate([a[k] for a, k in zip(sig, keep, strict=True)]),
                    np.concatenate([r[k] for r, k in zip(res, keep, strict=True)]),
                    floor,
                )
            except ValueError:
                break
    return gain, offset


def calibrate_noise(dataset_dir, out_json=None) -> NoiseModel:
    """Noise model of every camera from the board poses and chromatic white captures.

    Writes ``{"cameras": {name: {"gain": [3], "offset": [3]}}, ...}``
    atomically when ``out_json`` is given. The raw images are used (before
    cross-talk unmixing, which changes the variance by well under 1 %). Shows a
    bar over the images read (:func:`colourhs.common.progress.bar`).
    """
    ds = dataset_of(dataset_dir, scenes=())
    gains, offsets, out = {}, {}, {"cameras": {}, "units": "full scale; var = gain * i + offset"}
    paths = {
        cam: [ds.photometric_image(p, cam) for p in ds.poses]
        + (
            [ds.chromatic_image("white", colour, cam) for colour in COLOURS]
            if "white" in ds.chromatic_objects
            else []
        )
        for cam in ds.rig.camera_names
    }
    total = sum(map(len, paths.values()))
    with bar(desc="noise model", total=total, unit="image") as shown:
        for cam in ds.rig.camera_names:
            images = []
            for path in paths[cam]:
                images.append(read_image(path, ds.rig.image)[0])
                shown.update()
            try:
                floor = quantisation_variance(ds.rig.image.black_level, ds.rig.image.white_level)
                gains[cam], offsets[cam] = estimate_noise(images, floor)
            except ValueError as err:
                raise ValueError(f"{ds.root / 'photometric'}: camera {cam}: {err}") from None
            full_well = [1.0 / g if g > 0 else None for g in gains[cam]]
            out["cameras"][cam] = {
                "gain": gains[cam].tolist(),
                "offset": offsets[cam].tolist(),
                "full_well_e": full_well,
            }
    if out_json is not None:
        write_json(out_json, out)
    return NoiseModel(gains, offsets)


def load_noise(path: str | Path) -> NoiseModel:
    """The :class:`NoiseModel` of a file written by :func:`calibrate_noise`."""
    data = json.loads(Path(path).read_text())["cameras"]
    return NoiseModel(
        {c: np.asarray(v["gain"], float) for c, v in data.items()},
        {c: np.asarray(v["offset"], float) for c, v in data.items()},
    )
