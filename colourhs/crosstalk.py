"""Channel cross-talk: calibration from the chromatic white captures, and unmixing.

The paper names channel cross-talk as an error it does not address (section
III-E). A camera channel c responds to light of colour b with a relative
strength, so with all three lights on each channel mixes the three bands:

    I_c = sum_b M[c, b] J_b,   M[b, b] = 1,

where J_b is what channel b would record with perfectly separated channels
(its own sensitivity, which photometric calibration absorbs into mu). The
chromatic captures of the white reference light the scene with one colour b
at a time, so there ``I_c / I_b = M[c, b]`` at every pixel: the matrix comes
from data the rig already has. Unmixing is ``J = M^-1 I`` per pixel.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from colourhs.capture import COLOURS, open_dataset, read_image
from colourhs.io import write_json


def crosstalk_matrix(
    white: dict[str, np.ndarray],
    saturated: dict[str, np.ndarray] | None = None,
    min_signal: float = 0.1,
) -> tuple[np.ndarray, np.ndarray]:
    """Estimate one camera's mixing matrix M from single-colour white captures.

    Parameters
    ----------
    white : light colour -> (H, W, 3) linear image (R, G, B) of the white
        reference under that colour alone.
    saturated : optional light colour -> (H, W) saturated-pixel mask.
    min_signal : lowest reading (fraction of full scale) of the lit channel
        for a pixel to be used.

    Returns
    -------
    M : (3, 3) with M[c, b] = median over pixels of I_c / I_b under light b
        (unit diagonal).
    spread : (3, 3) median absolute deviation of the per-pixel ratios (the
        spatial variation plus noise, for the record).
    """
    M = np.eye(3)
    spread = np.zeros((3, 3))
    for colour, img in white.items():
        b = COLOURS.index(colour)
        lit = (img[..., b] > min_signal) & (img[..., b] < 0.98)
        if saturated is not None:
            lit &= ~saturated[colour]
        if lit.sum() < 100:
            raise ValueError(f"cross-talk: too few lit pixels under {colour} light ({lit.sum()})")
        for c in range(3):
            if c == b:
                continue
            r = img[..., c][lit] / img[..., b][lit]
            M[c, b] = np.median(r)
            spread[c, b] = np.median(np.abs(r - M[c, b]))
    return M, spread


def unmix(image: np.ndarray, M: np.ndarray) -> np.ndarray:
    """Separate the bands of an image (..., 3): J = M^-1 I per pixel."""
    return np.asarray(image, float) @ np.linalg.inv(M).T


def calibrate_crosstalk(dataset_dir: str | Path, out_json: str | Path | None = None) -> dict:
    """Mixing matrix per camera from ``chromatic/white/<colour>/<camera>.png``.

    Writes (atomically) a JSON file ``{"cameras": {name: {"M": 3x3, "spread":
    3x3}}}`` when ``out_json`` is given and returns the same dict.
    """
    ds = open_dataset(dataset_dir, check_images=False)
    if "white" not in ds.chromatic_objects:
        raise ValueError(f"{ds.root / 'chromatic' / 'white'}: missing (needed for cross-talk)")
    out = {"cameras": {}, "method": "median of I_c / I_b under light b alone (white reference)"}
    for cam in ds.rig.camera_names:
        imgs, sats = {}, {}
        for colour in COLOURS:
            imgs[colour], sats[colour] = read_image(
                ds.chromatic_image("white", colour, cam), ds.rig.image
            )
        M, spread = crosstalk_matrix(imgs, sats)
        out["cameras"][cam] = {"M": M.tolist(), "spread": spread.tolist()}
    if out_json is not None:
        write_json(out_json, out)
    return out


def load_crosstalk(path: str | Path) -> dict[str, np.ndarray]:
    """Camera name -> mixing matrix M from a file written by :func:`calibrate_crosstalk`."""
    data = json.loads(Path(path).read_text())
    return {cam: np.asarray(v["M"], float) for cam, v in data["cameras"].items()}
