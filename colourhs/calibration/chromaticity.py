"""Surface chromaticity calibration, section III-D of the paper (equations 9-12).

For every camera and pixel this measures the triplet ``p = (p_R, p_G, p_B)``: the reflectance
of the surface seen through the pixel in the red, green and blue light bands, relative to the
white reference. Inputs are the chromatic captures of the capture format
(``capture-format.md``): the white reference ``chromatic/white/<colour>/<camera>.png`` and the
object ``chromatic/<object>/<colour>/<camera>.png``, each lit by the single chromatic light
through its red, green and blue filter in turn.

Measurement
-----------
Under light of colour ``b`` only the camera channel of the same colour is used (the camera's
red channel under red light, and so on). Its intensity is ``i_b = rho_b sigma_b p_b G`` (eq. 9)
with ``rho_b sigma_b`` the light-camera product of that band (cross-talk gain included) and
``G`` the geometry and BRDF shape, the same for the three bands. The white reference gives
``i_b^w = rho_b sigma_b p^w G^w`` with ``p^w`` the same in every band (eq. 10), so

    p_R / p_G = (i_r i_g^w) / (i_g i_r^w)                                   (eq. 12)

and likewise ``p_R / p_B`` and ``p_G / p_B``. Per pixel, the three ratio equations
``p_R - r_RG p_G = 0``, ``p_R - r_RB p_B = 0``, ``p_G - r_GB p_B = 0`` (each row scaled to unit
norm) and the normalisation row are solved in least squares, vectorised over pixels.

Normalisation
-------------
White is ``(1, 1, 1)``: every triplet is scaled so that ``p_R + p_G + p_B = 3``. The scale
between the object's and the white reference's geometry, ``G / G^w``, is unknown per pixel
(they are different surfaces), so only the direction of the triplet is measured. Compare with a
ground truth after giving it the same normalisation (:func:`normalise`).

Masking (NaN in the maps)
-------------------------
A pixel is NaN where

* it is off the object: outside the silhouette ``scenes/<scene>/masks/<frame>/<camera>.png``
  (the chromatic frame's) of the first scene, by name, whose scene.json names this
  chromatic object and that has masks; without such a scene, where the mean of the
  object's three matching-channel intensities is below ``object_threshold`` (default 0.02
  of full scale: the rig has no ambient light, so the background reads black);
* it is too dark to measure: the matching channel of any of the three object captures, or of
  the three white captures, is below ``min_signal`` (default 0.01 of full scale; with the
  synthetic rig's 15000 e- full well the shot noise there is about 8 % of the signal, so the
  ratio of equation 12 is still within a few per cent);
* any channel of any of the six captures is saturated (at ``white_level``).

Colour indices follow :data:`colourhs.capture.COLOURS` (red, green, blue).
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
from pathlib import Path
from typing import NamedTuple

import h5py
import numpy as np

from colourhs.capture import (
    COLOURS,
    LIT_THRESHOLD,
    MIN_SIGNAL,
    CaptureFormatError,
    Dataset,
    dataset_of,
    read_image,
    read_mask,
)
from colourhs.common.progress import bar, stage

log = logging.getLogger(__name__)

__all__ = [
    "MIN_SIGNAL",
    "NORMALISATION",
    "OBJECT_THRESHOLD",
    "RATIO_PAIRS",
    "chromaticity_error",
    "log_ratio_rms",
    "log_sigma",
    "log_sigma_coverage",
    "map_log_sigma",
    "chromaticity_map",
    "chromaticity_maps",
    "chromaticity_ratios",
    "normalise",
    "object_silhouette",
    "read_chromatic_captures",
    "signal_mask",
    "solve_chromaticity",
]

OBJECT_THRESHOLD = LIT_THRESHOLD
"""Default object threshold on the mean of the three matching channels (no silhouette)."""

NORMALISATION = "sum: p_R + p_G + p_B = 3 (white = (1, 1, 1)); only the direction is measured"
"""The normalisation of every triplet, as written into the HDF5 attributes."""

RATIO_PAIRS = ((0, 1), (0, 2), (1, 2))
"""Channel index pairs (numerator, denominator) of the ratios: R/G, R/B, G/B."""

_NORM_SUM = 3.0


# --------------------------------------------------------------------------------------------
# Pure functions over arrays


def _stack(intensities: dict[str, np.ndarray], what: str) -> np.ndarray:
    missing = [c for c in COLOURS if c not in intensities]
    if missing:
        raise ValueError(f"{what}: missing intensity of colour(s) {', '.join(missing)}")
    arrays = [np.asarray(intensities[c], dtype=np.float64) for c in COLOURS]
    if any(a.shape != arrays[0].shape for a in arrays):
        shapes = ", ".join(f"{c} {a.shape}" for c, a in zip(COLOURS, arrays, strict=True))
        raise ValueError(f"{what}: intensities differ in shape: {shapes}")
    return np.stack(arrays, axis=-1)


def chromaticity_ratios(obj: dict[str, np.ndarray], white: dict[str, np.ndarray]) -> np.ndarray:
    """Ratios of chromaticity components, equation (12).

    Parameters
    ----------
    obj, white : dict of str to ndarray, shape (H, W)
        Colour (``"red"``, ``"green"``, ``"blue"``) to the matching-channel intensity of the
        object, respectively of the white reference, under light of that colour.

    Returns
    -------
    ndarray of float64, shape (H, W, 3)
        ``(p_R/p_G, p_R/p_B, p_G/p_B)`` (see :data:`RATIO_PAIRS`), e.g.
        ``p_R/p_G = (i_r i_g^w) / (i_g i_r^w)``; NaN where any of the intensities involved is
        not finite and positive.

    Raises
    ------
    ValueError
        A colour is missing or the arrays differ in shape.
    """
    i = _stack(obj, "object")
    w = _stack(white, "white reference")
    if i.shape != w.shape:
        raise ValueError(f"object intensities {i.shape[:-1]} and white {w.shape[:-1]} differ")
    with np.errstate(divide="ignore", invalid="ignore"):
        q = i / w  # p_b up to the per-pixel geometric scale
        q[~((i > 0) & (w > 0) & np.isfinite(i) & np.isfinite(w))] = np.nan
        return np.stack([q[..., a] / q[..., b] for a, b in RATIO_PAIRS], axis=-1)


def solve_chromaticity(ratios: np.ndarray, valid: np.ndarray | None = None) -> np.ndarray:
    """Chromaticity triplets from component ratios, per pixel in least squares.

    Per pixel the rows ``p_a - r_ab p_b = 0`` for the three ratios of :data:`RATIO_PAIRS`, each
    scaled to unit norm, and the normalisation row ``p_R + p_G + p_B = 3`` form a 4x3 system,
    solved through its normal equations (batched over pixels). The solution is then rescaled so
    that its sum is exactly 3 (a no-op when the three ratios are consistent, as those of
    :func:`chromaticity_ratios` are).

    Parameters
    ----------
    ratios : ndarray, shape (..., 3)
        ``(p_R/p_G, p_R/p_B, p_G/p_B)``.
    valid : ndarray of bool, shape (...), optional
        Pixels to solve; the others are NaN.

    Returns
    -------
    ndarray of float32, shape (..., 3)
        ``(p_R, p_G, p_B)`` with sum 3; NaN where masked, where a ratio is not finite and
        positive, or where the solution has a non-positive component.
    """
    ratios = np.asarray(ratios, dtype=np.float64)
    if ratios.ndim < 1 or ratios.shape[-1] != 3:
        raise ValueError(f"ratios must have shape (..., 3), got {ratios.shape}")
    shape = ratios.shape[:-1]
    ok = np.all(np.isfinite(ratios) & (ratios > 0), axis=-1)
    if valid is not None:
        valid = np.asarray(valid, dtype=bool)
        if valid.shape != shape:
            raise ValueError(f"valid has shape {valid.shape}, expected {shape}")
        ok &= valid
    out = np.full(shape + (3,), np.nan, dtype=np.float32)
    r = ratios[ok]  # (N, 3)
    n = len(r)
    if n == 0:
        return out
    A = np.zeros((n, 4, 3))
    for row, (a, b) in enumerate(RATIO_PAIRS):
        scale = 1.0 / np.sqrt(1.0 + r[:, row] ** 2)
        A[:, row, a] = scale
        A[:, row, b] = -r[:, row] * scale
    A[:, 3, :] = 1.0
    rhs = np.zeros((n, 4))
    rhs[:, 3] = _NORM_SUM
    AtA = np.einsum("nki,nkj->nij", A, A)
    Atb = np.einsum("nki,nk->ni", A, rhs)
    p = np.linalg.solve(AtA, Atb[..., None])[..., 0]
    total = p.sum(axis=1, keepdims=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        p = p * (_NORM_SUM / total)
    p[~np.all(np.isfinite(p) & (p > 0), axis=1)] = np.nan
    out[ok] = p
    return out


def signal_mask(
    obj: dict[str, np.ndarray], white: dict[str, np.ndarray], min_signal: float = MIN_SIGNAL
) -> np.ndarray:
    """Pixels bright enough to measure: every matching channel of object and white >= min_signal.

    Parameters
    ----------
    obj, white : dict of str to ndarray, shape (H, W)
        As for :func:`chromaticity_ratios`, fractions of full scale.
    min_signal : float
        Smallest usable intensity, fraction of full scale.

    Returns
    -------
    ndarray of bool, shape (H, W)
    """
    i = _stack(obj, "object")
    w = _stack(white, "white reference")
    return np.all((i >= min_signal) & (w >= min_signal), axis=-1)


def normalise(p: np.ndarray) -> np.ndarray:
    """Scale triplets ``(..., 3)`` to sum 3 (white = (1, 1, 1)); NaN where the sum is not > 0."""
    p = np.asarray(p, dtype=np.float64)
    total = p.sum(axis=-1, keepdims=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(total > 0, p * (_NORM_SUM / total), np.nan)


def log_sigma(
    p: np.ndarray,
    obj: dict[str, np.ndarray],
    white: dict[str, np.ndarray],
    obj_var: dict[str, np.ndarray],
    white_var: dict[str, np.ndarray],
) -> np.ndarray:
    """1-sigma of each band's log p (..., 3) under the sensor noise of eq. (12)'s intensities.

    Beyond the paper, which gives p no uncertainty. Each band's ratio ``q_b = i_b /
    i_b^w`` of two independent captures has the relative variance ``v_b = var(i_b) /
    i_b^2 + var(i_b^w) / (i_b^w)^2``; the map is ``q`` scaled to sum 3 (the ratios of
    eq. 12 are consistent, so the least squares of :func:`solve_chromaticity` returns
    ``p_b = 3 q_b / sum q``), whose log changes by ``d log p_b = sum_c (delta_bc - p_c /
    3) d log q_c``, so ``var(log p_b) = sum_c (delta_bc - p_c / 3)^2 v_c`` to first order.
    A pure colour's dark bands carry the largest sigma.

    Parameters
    ----------
    p : ndarray, shape (..., 3)
        The map (:func:`solve_chromaticity`), NaN where unknown.
    obj, white : dict of str to ndarray, shape (...)
        The matching-channel intensities, as for :func:`chromaticity_ratios`.
    obj_var, white_var : dict of str to ndarray, shape (...)
        Their variances (the noise model's, :class:`colourhs.calibration.noise.NoiseModel`),
        fractions of full scale squared.

    Returns
    -------
    ndarray of float32, shape (..., 3)
        NaN where ``p`` is.
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        v = _stack(obj_var, "object variance") / _stack(obj, "object") ** 2
        v = v + _stack(white_var, "white variance") / _stack(white, "white reference") ** 2
    w = np.asarray(p, np.float64) / _NORM_SUM
    var = np.zeros(w.shape)
    for b in range(3):
        d = -w
        d[..., b] += 1.0
        var[..., b] = np.sum(d * d * v, axis=-1)
    return np.where(np.isfinite(p), np.sqrt(var), np.nan).astype(np.float32)


def chromaticity_error(estimate: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Per-pixel relative error ``||p_est - p_gt|| / ||p_gt||`` after normalising both to sum 3.

    Parameters
    ----------
    estimate, truth : ndarray, shape (H, W, 3)
        NaN where unknown.

    Returns
    -------
    ndarray of float64, shape (H, W)
        NaN where either is unknown.
    """
    e = normalise(estimate)
    t = normalise(truth)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.linalg.norm(e - t, axis=-1) / np.linalg.norm(t, axis=-1)


def log_ratio_rms(estimate: np.ndarray, truth: np.ndarray) -> float:
    """RMS of the log ratios of two chromaticity maps over the pixels where both are known:
    per pixel and channel ``log(p_est / p_gt)``, less the pixel's mean over the channels
    (what a common scale of the triplet does, which eq. 12 cannot measure), squared and
    averaged over channels and pixels. 0 for maps equal up to a scale per pixel; NaN
    where no pixel is known in both.

    Parameters
    ----------
    estimate, truth : ndarray, shape (H, W, 3)
        NaN (or <= 0) where unknown.
    """
    d, ok = _centred_log_difference(estimate, truth)
    if not ok.any():
        return float("nan")
    return float(np.sqrt(np.mean(d**2)))


def _centred_log_difference(estimate, truth) -> tuple[np.ndarray, np.ndarray]:
    """``log(p_est / p_gt)`` less its mean over the channels (n, 3), at the pixels (...)
    where both are known (finite and > 0), and those pixels."""
    e, t = np.asarray(estimate, np.float64), np.asarray(truth, np.float64)
    ok = np.all(np.isfinite(e) & np.isfinite(t) & (e > 0) & (t > 0), axis=-1)
    d = np.log(e[ok]) - np.log(t[ok])
    return d - d.mean(axis=1, keepdims=True), ok


def log_sigma_coverage(
    estimate: np.ndarray, truth: np.ndarray, sigma: np.ndarray, ks=(1, 2, 3)
) -> tuple[float, list[float]] | None:
    """How well a map's 1-sigma of log p covers its error against a truth.

    Over the pixels where the map, the truth and ``sigma`` are known: the median sigma
    and, for each k of ``ks``, the share of the (pixel, band) differences
    ``log p_b - log t_b`` within k of their sigma, the truth ``t`` scaled to the map's
    own sum first. Only p's direction is measured, and its error bar is that of the map
    as it is normalised (:func:`log_sigma`: sum 3, where a pure colour's dark band
    carries most of the error and its bright bands little), so the truth is compared in
    that gauge; a centred log ratio would hand each bright band a third of the dark
    band's error, beyond its own bar. An honest Gaussian error bar gives 0.68, 0.95 and
    0.997 within 1, 2 and 3. None where no pixel has all three.

    Parameters
    ----------
    estimate, truth : ndarray, shape (..., 3)
        NaN (or <= 0) where unknown.
    sigma : ndarray, shape (..., 3) per band, or (...) the same in every band
        The 1-sigma of log p (:func:`log_sigma`, or a tracked map's).
    """
    e = np.asarray(estimate, np.float64)
    t = np.asarray(truth, np.float64)
    s = np.asarray(sigma, np.float64).reshape(e.shape[:-1] + (-1,))
    s = np.broadcast_to(s, e.shape)
    ok = np.all(np.isfinite(e) & np.isfinite(t) & (e > 0) & (t > 0) & np.isfinite(s), axis=-1)
    if not ok.any():
        return None
    e, t, s = e[ok], t[ok], s[ok]
    d = np.log(e) - np.log(t * e.sum(axis=1, keepdims=True) / t.sum(axis=1, keepdims=True))
    within = np.abs(d) / s
    return float(np.median(s)), [float(np.mean(within <= k)) for k in ks]


def map_log_sigma(f: h5py.File, camera: str) -> np.ndarray | None:
    """A chromaticity file's error bar of ``camera``'s map, its 1-sigma of log p: a
    tracked map's ``p_sigma/<camera>`` (H, W, 3;
    :func:`colourhs.calibration.chromaticity_tracking.tracked_log_sigma`), else the
    file's ``sigma/<camera>`` (the calibrated map's, (H, W, 3), :func:`log_sigma`; or
    a tracked map's match residual alone, (H, W), where its calibration had no error
    bar); None without either."""
    for name in (f"p_sigma/{camera}", f"sigma/{camera}"):
        if name in f:
            return f[name][()]
    return None


# --------------------------------------------------------------------------------------------
# Files


def object_silhouette(dataset: Dataset, obj: str, camera: str) -> Path | None:
    """The silhouette of chromatic object ``obj`` in ``camera``, or None.

    The mask of the chromatic frame (scene.json's ``chromatic_frame``: the pose the
    chromatic captures show; by default the first frame) of the first scene (by name)
    whose scene.json names ``obj`` as its chromatic object and that has masks.
    """
    for name, scene in sorted(dataset.scenes.items()):
        if scene.chromatic == obj and scene.has_masks:
            return dataset.mask_image(name, scene.chromatic_frame, camera)
    return None


def _check_object(dataset: Dataset, obj: str) -> None:
    if obj not in dataset.chromatic_objects:
        known = ", ".join(o for o in dataset.chromatic_objects if o != "white") or "none"
        raise CaptureFormatError(
            dataset.root / "chromatic" / obj,
            f"chromatic object {obj!r} not in the dataset (objects: {known})",
        )
    if "white" not in dataset.chromatic_objects:
        raise CaptureFormatError(
            dataset.root / "chromatic" / "white", "missing white reference folder"
        )


def read_chromatic_captures(
    dataset: Dataset, obj: str, camera: str
) -> tuple[dict[str, np.ndarray], np.ndarray, list[Path]]:
    """Matching-channel intensities of ``obj`` (or ``"white"``) under each light colour.

    Returns
    -------
    intensities : dict of str to ndarray of float32, shape (H, W)
        Colour to the camera's channel of that colour under light of that colour.
    saturated : ndarray of bool, shape (H, W)
        Saturated in any channel of any of the three captures.
    paths : list of Path
        The files read.

    Raises
    ------
    CaptureFormatError
        A capture is missing or malformed (the message names the file), or the object is not in
        the dataset.
    """
    _check_object(dataset, obj)
    spec = dataset.rig.image
    intensities, paths = {}, []
    saturated = np.zeros((spec.height, spec.width), dtype=bool)
    for k, colour in enumerate(COLOURS):
        path = dataset.chromatic_image(obj, colour, camera)
        if not path.is_file():
            raise CaptureFormatError(
                path, f"missing capture of chromatic object {obj!r} under {colour} light"
            )
        image, sat = read_image(path, spec)
        intensities[colour] = image[..., k]
        saturated |= sat
        paths.append(path)
    return intensities, saturated, paths


def _matching_variance(noise, camera: str, intensities: dict[str, np.ndarray]) -> dict:
    """The noise model's variance of each colour's matching-channel intensity (H, W)."""
    return {
        colour: noise.variance(camera, intensities[colour], channel=k)
        for k, colour in enumerate(COLOURS)
    }


def _chromaticity_map(
    dataset: Dataset,
    obj: str,
    camera: str,
    min_signal: float,
    object_threshold: float,
    noise=None,
) -> tuple[np.ndarray, dict]:
    """The map and what went into it (paths, mask source, intensity image; with a
    :class:`~colourhs.calibration.noise.NoiseModel` ``noise``, ``sigma``: :func:`log_sigma`)."""
    dataset.rig.camera(camera)
    obj_i, obj_sat, obj_paths = read_chromatic_captures(dataset, obj, camera)
    white_i, white_sat, white_paths = read_chromatic_captures(dataset, "white", camera)
    silhouette = object_silhouette(dataset, obj, camera)
    if silhouette is not None:
        on_object = read_mask(silhouette, dataset.rig.image)
        mask_source = str(silhouette.relative_to(dataset.root))
    else:
        mean = np.mean(np.stack([obj_i[c] for c in COLOURS]), axis=0)
        on_object = mean >= object_threshold
        mask_source = f"threshold: mean matching intensity >= {object_threshold}"
    valid = on_object & signal_mask(obj_i, white_i, min_signal) & ~obj_sat & ~white_sat
    where = f"{dataset.root / 'chromatic' / obj}: camera {camera!r}"
    if not valid.any():
        raise ValueError(
            f"{where}: all samples masked (on object: {int(on_object.sum())} pixels; none "
            f"unsaturated with every matching channel >= {min_signal} of full scale)"
        )
    p = solve_chromaticity(chromaticity_ratios(obj_i, white_i), valid)
    if not np.isfinite(p).any():
        raise ValueError(f"{where}: all samples masked (no solvable pixel)")
    sigma = None
    if noise is not None:
        obj_var = _matching_variance(noise, camera, obj_i)
        white_var = _matching_variance(noise, camera, white_i)
        sigma = log_sigma(p, obj_i, white_i, obj_var, white_var)
    info = {
        "sigma": sigma,
        "paths": obj_paths + white_paths + ([silhouette] if silhouette is not None else []),
        "mask_source": mask_source,
        "intensity": sum(obj_i[c] for c in COLOURS),
        "valid_pixels": int(np.isfinite(p[..., 0]).sum()),
    }
    return p, info


def chromaticity_map(
    dataset: Dataset,
    obj: str,
    camera: str,
    min_signal: float = MIN_SIGNAL,
    object_threshold: float = OBJECT_THRESHOLD,
) -> np.ndarray:
    """Chromaticity map of chromatic object ``obj`` seen by ``camera``.

    Parameters
    ----------
    dataset : Dataset
        An opened dataset (:func:`colourhs.capture.open_dataset`).
    obj : str
        A folder under ``chromatic/`` other than the reference (e.g. ``"toy"``).
    camera : str
        Camera name.
    min_signal : float
        Smallest usable matching-channel intensity (object and white), fraction of full scale.
    object_threshold : float
        Object threshold on the mean matching intensity, used only without a silhouette.

    Returns
    -------
    ndarray of float32, shape (H, W, 3)
        ``(p_R, p_G, p_B)`` with sum 3, NaN where masked (see the module docstring).

    Raises
    ------
    CaptureFormatError
        Unknown object, or a missing or malformed capture (naming the file).
    KeyError
        Unknown camera.
    ValueError
        Every pixel is masked ("all samples masked").
    """
    return _chromaticity_map(dataset, obj, camera, min_signal, object_threshold)[0]


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


class ObjectChromaticity(NamedTuple):
    """What :func:`chromaticity_maps` computed for one object."""

    maps: dict[str, np.ndarray]  # camera -> (H, W, 3) chromaticity p, NaN where unknown
    intensity: np.ndarray  # (H, W) the object's intensity in ``camera`` (for the figure)
    camera: str


def chromaticity_maps(
    dataset_dir: str | Path | Dataset,
    obj: str,
    out_h5: str | Path,
    min_signal: float = MIN_SIGNAL,
    object_threshold: float = OBJECT_THRESHOLD,
    noise_json: str | Path | None = None,
) -> ObjectChromaticity:
    """Chromaticity maps of ``obj`` for every camera, written to HDF5.

    The HDF5 file (results contract: ``results/NAME/calib/chromaticity/<object>.h5``) holds one
    float32 dataset ``"<camera>"`` of shape (H, W, 3) per camera, ``(p_R, p_G, p_B)``, NaN where
    unknown; each with attributes ``mask`` (silhouette file or threshold) and ``valid_pixels``.
    File attributes: ``object``, ``dataset``, ``cameras``, ``normalisation``, ``min_signal``,
    ``object_threshold``, ``inputs`` (JSON: input file relative to the dataset -> sha256) and
    ``inputs_sha256`` (sha256 of the sorted ``"path sha256"`` lines). With ``noise_json``
    also ``sigma/<camera>`` (H, W, 3) float32, each band's 1-sigma of log p under the
    captures' sensor noise (:func:`log_sigma`: the map's error bar, which
    :func:`colourhs.reconstruct.inputs.load_frame` does not weigh the channels by), and
    the attribute ``noise_model`` (the file and its sha256). Written to a temporary
    name and renamed at the end: nothing is left behind on error. The figure (the paper's
    Figure 6, :func:`colourhs.report.figures.chromaticity_figure`) is the command's to draw, from
    what this returns: calibration modules do not import the figures. Shows a bar over the
    cameras and logs a line at INFO before the writing (:mod:`colourhs.common.progress`).

    Parameters
    ----------
    dataset_dir : str, Path or Dataset
        The dataset (capture format); validated by :func:`colourhs.capture.open_dataset`.
    obj : str
        The chromatic object.
    out_h5 : str or Path
        HDF5 file to write.
    min_signal, object_threshold : float
        See :func:`chromaticity_map`.
    noise_json : str or Path, optional
        The rig's noise model (:func:`colourhs.calibration.noise.calibrate_noise`).

    Returns
    -------
    ObjectChromaticity
        ``maps``: camera name to its map; ``intensity``: the first camera's intensity
        image of the object (the figure's), ``camera``: that camera's name.
    """
    # The images it decodes are checked as they are read (read_image), not every header.
    dataset = dataset_of(dataset_dir)
    _check_object(dataset, obj)
    noise = None
    if noise_json is not None:
        from colourhs.calibration.noise import load_noise

        noise = load_noise(noise_json)
    maps, infos = {}, {}
    cams = bar(dataset.rig.camera_names, f"chromaticity {obj}", unit="camera")
    for camera in cams:
        maps[camera], infos[camera] = _chromaticity_map(
            dataset, obj, camera, min_signal, object_threshold, noise
        )
    inputs = {
        str(p.relative_to(dataset.root)): _sha256(p)
        for info in infos.values()
        for p in dict.fromkeys(info["paths"])
    }
    lines = "".join(f"{k} {v}\n" for k, v in sorted(inputs.items()))
    out_h5 = Path(out_h5)
    stage(log, f"chromaticity {obj}: writing {out_h5.name}")
    out_h5.parent.mkdir(parents=True, exist_ok=True)
    tmp_h5 = out_h5.with_name(f".{out_h5.name}.{os.getpid()}.tmp")
    try:
        with h5py.File(tmp_h5, "w") as f:
            f.attrs["object"] = obj
            f.attrs["dataset"] = str(dataset.root.resolve())
            f.attrs["cameras"] = json.dumps(list(maps))
            f.attrs["channels"] = "p_R, p_G, p_B (reflectance in the red, green, blue bands)"
            f.attrs["normalisation"] = NORMALISATION
            f.attrs["min_signal"] = float(min_signal)
            f.attrs["object_threshold"] = float(object_threshold)
            f.attrs["inputs"] = json.dumps(inputs, sort_keys=True)
            f.attrs["inputs_sha256"] = hashlib.sha256(lines.encode()).hexdigest()
            if noise_json is not None:
                f.attrs["noise_model"] = f"{noise_json} {_sha256(Path(noise_json))}"
            for camera, p in maps.items():
                d = f.create_dataset(camera, data=p, compression="gzip")
                d.attrs["mask"] = infos[camera]["mask_source"]
                d.attrs["valid_pixels"] = infos[camera]["valid_pixels"]
                if infos[camera]["sigma"] is not None:
                    f.create_dataset(f"sigma/{camera}", data=infos[camera]["sigma"])
        os.replace(tmp_h5, out_h5)
    finally:
        if tmp_h5.exists():
            tmp_h5.unlink()
    first = dataset.rig.camera_names[0]
    return ObjectChromaticity(maps, infos[first]["intensity"], first)
