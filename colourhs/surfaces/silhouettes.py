"""Silhouettes of a frame: one boolean mask per camera, and its signed distance image.

From the scene's ``masks/`` when it has them, otherwise by thresholding the
frame (the rig has no ambient light, :data:`colourhs.capture.LIT_THRESHOLD`).
The visual hull (:mod:`colourhs.surfaces.hull`) carves with them.
"""

from __future__ import annotations

import cv2
import numpy as np

from colourhs.capture import (
    LIT_THRESHOLD,
    CaptureFormatError,
    dataset_of,
    read_image,
    read_mask,
)

DEFAULT_THRESHOLD = LIT_THRESHOLD
"""Silhouette threshold on the largest channel (:data:`colourhs.capture.LIT_THRESHOLD`)."""


def threshold_silhouette(
    image: np.ndarray, threshold: float = DEFAULT_THRESHOLD, min_area_px: int | None = None
) -> np.ndarray:
    """Object silhouette of a frame taken without ambient light.

    The rig lights the object with its own lights only, so the background is
    dark: a pixel is object where its largest channel exceeds ``threshold``.
    A small morphological clean-up follows, in this order:

    1. connected components (8-connected) smaller than ``min_area_px`` are dropped
       (noise, hot pixels);
    2. a closing with a 3 x 3 cross (OpenCV) bridges one-pixel cracks;
    3. holes (background regions not connected to the image border) are filled.

    Steps 2 and 3 only add object pixels: dark spots on the object (shadows,
    black paint, metal reflecting nothing) must not carve the hull. A true
    through-hole of the object is filled too, which keeps the hull conservative.

    Parameters
    ----------
    image : ndarray, shape (H, W, 3) or (H, W)
        Linear image in [0, 1] of full scale above black level
        (:func:`~colourhs.capture.read_image`).
    threshold : float
        Largest-channel level above which a pixel is object, full-scale units.
    min_area_px : int, optional
        Smallest object component kept, pixels; default ``max(4, 1e-4 * H * W)``.

    Returns
    -------
    ndarray of bool, shape (H, W)
    """
    img = np.asarray(image, np.float32)
    raw = (img.max(axis=2) if img.ndim == 3 else img) > threshold
    H, W = raw.shape
    min_area = max(4, round(1e-4 * H * W)) if min_area_px is None else int(min_area_px)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(raw.astype(np.uint8), connectivity=8)
    big = stats[:, cv2.CC_STAT_AREA] >= min_area
    big[0] = False  # label 0 is the background
    sil = big[labels].astype(np.uint8)
    sil = cv2.morphologyEx(sil, cv2.MORPH_CLOSE, cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3)))
    # Fill holes: background components (4-connected) that do not touch the border.
    _, bg = cv2.connectedComponents((sil == 0).astype(np.uint8), connectivity=4)
    border = np.unique(np.concatenate([bg[0], bg[-1], bg[:, 0], bg[:, -1]]))
    hole = (sil == 0) & ~np.isin(bg, border)
    return (sil != 0) | hole


def silhouettes(
    dataset_dir, scene: str, frame: str | int, threshold: float = DEFAULT_THRESHOLD
) -> dict[str, np.ndarray]:
    """Every camera's silhouette of one frame.

    Uses ``scenes/<scene>/masks/<frame>/<camera>.png`` when the scene has masks
    (non-zero = object, used as is); otherwise thresholds the frame image
    itself with :func:`threshold_silhouette` (background is dark: the rig has
    no ambient light).

    Parameters
    ----------
    dataset_dir : str, Path or Dataset
        A dataset in the capture format.
    scene : str
    frame : str or int
        Six-digit frame name or its index.
    threshold : float
        Largest-channel threshold (full-scale units) when there are no masks.

    Returns
    -------
    dict of str to ndarray of bool, shape (H, W)
        Camera name to silhouette, in rig order.

    Raises
    ------
    CaptureFormatError
        A mask or image is missing or malformed, or a silhouette has no object
        pixel (the error names the mask, or the image that was thresholded).
    """
    ds = dataset_of(dataset_dir, scenes=[scene])
    return silhouettes_and_sources(ds, scene, frame, threshold)[0]


def silhouettes_and_sources(ds, scene, frame, threshold):
    """Silhouettes, the files they came from and how ("masks" or "threshold")."""
    spec = ds.rig.image
    out, files = {}, []
    source = "masks" if ds.scene(scene).has_masks else "threshold"
    for cam in ds.rig.cameras:
        if source == "masks":
            path = ds.mask_image(scene, frame, cam.name)
            sil = read_mask(path, spec)
            problem = "silhouette mask has no object pixel (all zero): nothing to carve"
        else:
            path = ds.frame_image(scene, frame, cam.name)
            sil = threshold_silhouette(read_image(path, spec)[0], threshold)
            problem = (
                f"no object pixel: no pixel's largest channel exceeds the silhouette "
                f"threshold {threshold} (and the scene has no masks/)"
            )
        if not sil.any():
            raise CaptureFormatError(path, problem)
        out[cam.name] = sil
        files.append(path)
    return out, files, source


def silhouette_distance(silhouette: np.ndarray) -> np.ndarray:
    """Signed distance (pixels) from each pixel centre to the silhouette's outline.

    Positive outside the silhouette, negative inside. The outline runs along
    pixel edges, half a pixel from the centres on either side of it; the
    distances between pixel centres are exact Euclidean distance transforms
    (OpenCV ``DIST_MASK_PRECISE``). The image border is not an outline: the
    object may continue beyond it.

    Parameters
    ----------
    silhouette : ndarray of bool, shape (H, W)

    Returns
    -------
    ndarray of float32, shape (H, W)
    """
    sil = np.asarray(silhouette, bool)
    out = cv2.distanceTransform((~sil).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    inside = cv2.distanceTransform(sil.astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    return np.where(sil, 0.5 - inside, out - 0.5).astype(np.float32)
