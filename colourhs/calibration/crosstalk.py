"""Channel cross-talk: calibration from the chromatic white and board captures, and unmixing.

The paper names channel cross-talk as an error it does not address (section
III-E). A camera channel c responds to light of colour b with a relative
strength, so with all three lights on each channel mixes the three bands:

    I_c(u) = sum_b M[c, b](u) J_b(u),   M[b, b] = 1,

where J_b is what channel b would record from light b alone with perfectly
separated channels (its own sensitivity, which photometric calibration
absorbs into mu). With a channel's sensitivity sigma_c(u) (vignetting, gain)
and X[c, b] the response of channel c to the spectrum of light b relative to
channel b's, ``M[c, b](u) = X[c, b] sigma_c(u) / sigma_b(u)``: the mixing
varies over the image with the colour shading of the vignetting.

Two estimates, from data the capture format has:

1. **Filter mixing field** (``chromatic/white/<colour>/<camera>.png``): the
   white reference under one coloured light b at a time gives
   ``I_c / I_b = M_filter[c, b](u)`` per pixel; a smooth 2-D Legendre
   polynomial (total degree 3) in the pixel coordinates is fitted to
   ``I_c = M[c, b](u) I_b`` (:func:`fit_mixing_field`: robust weighted least
   squares, or, where the noise is below one raw step as in 8-bit images,
   the maximum likelihood of the integer readings). These are the chromatic
   light's *filters*, whose spectra differ from the rig's LEDs: X_filter !=
   X_LED. The spatial factor sigma_c / sigma_b is the sensor's, the same for
   both, so ``M_LED(u) = M_filter(u) * F`` elementwise, with F a constant 3x3
   factor per camera (unit diagonal) that the chromatic captures cannot see.
2. **LED factor F** (``photometric/<pose>/<camera>.png``, all lights on, the
   board pose of each from the markers stage): see :func:`led_factor`. On
   the flat white Lambertian board, eq. (1) with a constant BRDF says that
   the correctly unmixed signal of camera k in the channel of light l's
   colour is

       T_{k<-l}(x) = sigma_{k,l}(u_k) rho_l(v_l) (n . v_l) / |c_l - x|^2,

   a sensor factor of camera k's pixel, the radiance of light l along its
   ray and the known geometry. Two pose invariances follow, at a fixed pixel
   across the board poses:

   (a) own channel: light l sits at camera l, so rho_l(v_l) is a function of
       camera l's pixel u_l, and ``T_{l<-l}(x) |c_l - x|^2 / (n . v_l)`` depends
       on u_l only (1 / mu of eq. 2 for the camera's own colour);
   (b) same light, two cameras: ``T_{k<-l}(x) / T_{l<-l}(x) =
       sigma_{k,l}(u_k) / sigma_{l,l}(u_l)``: rho_l and the geometry cancel,
       leaving camera k's pixel (free per pixel) and a smooth vignetting
       function of camera l's pixel (a low-order polynomial).

   Wrong unmixing leaves leaks ``e J_m`` of the other lights, whose ratio
   J_m / J_l to the signal changes with the pose at a fixed pixel, so the
   18 numbers of F (6 per camera) are fitted to make (a) and (b) pose
   invariant (Gauss-Newton with the per-pixel constants eliminated,
   Jacobians from independent neighbouring pixels, robust weights), then
   shrunk towards 1 by empirical Bayes.

   Why (a) is needed: every constraint that divides the lights' fields out
   entirely -- (b), or the Helmholtz reciprocity ratio
   ``T_{a<-b} T_{b<-a} / (T_{a<-a} T_{b<-b}) = s_a(u_a) s_b(u_b)`` (a product
   of two (b) ratios) -- is blind to a mixing common to all cameras:
   unmixing with ``M_k diag(sigma_k) A diag(sigma_k)^-1`` for any constant A
   (unit diagonal up to per-channel scales) gives ``T_k = diag(sigma_k)
   A^-1 g`` with g the lights' fields, again "sensor times some field", and
   such M_k are of the form M_filter * F'; so 6 of the 18 numbers stay free.
   Only the geometry of the lights (a) tells a light's own field from a
   mixture of fields.

Unmixing is ``J = M(u)^-1 I`` per pixel (:func:`unmix`).

The pieces: :mod:`colourhs.calibration.crosstalk_filter` (estimate 1: the constant matrix,
the :class:`MixingField` and its fit) and :mod:`colourhs.calibration.crosstalk_led`
(estimate 2: the LED factor, the rows of its fit and the fit); this module
unmixes, writes and reads the calibration file, and re-exports the public
names of the others.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from colourhs.calibration.crosstalk_filter import (
    MixingField,
    crosstalk_matrix,
    fit_mixing_field,
    legendre_basis,
)
from colourhs.calibration.crosstalk_led import (
    LED_DEFAULTS,
    OFF_DIAGONAL,
    POSE_STEP,
    BoardShot,
    led_factor,
    led_factor_from_dataset,
    read_board_shots,
    shrink_towards_filter,
)
from colourhs.capture import COLOURS, Dataset, dataset_of, read_image
from colourhs.common.files import write_json
from colourhs.common.progress import bar

__all__ = [
    "LED_DEFAULTS",
    "OFF_DIAGONAL",
    "POSE_STEP",
    "BoardShot",
    "MixingField",
    "calibrate_crosstalk",
    "crosstalk_matrix",
    "fit_mixing_field",
    "led_factor",
    "led_factor_from_dataset",
    "legendre_basis",
    "load_crosstalk",
    "read_board_shots",
    "shrink_towards_filter",
    "unmix",
]


# --------------------------------------------------------------------------- unmixing
def unmix(image: np.ndarray, M, uv: np.ndarray | None = None) -> np.ndarray:
    """Separate the bands of an image: J = M^-1 I per pixel.

    Parameters
    ----------
    image : (..., 3) linear values (R, G, B); with a spatially varying ``M``
        and no ``uv``, a whole (height, width, 3) image.
    M : a (3, 3) matrix (the same everywhere), an (H, W, 3, 3) field of
        per-pixel matrices, or a :class:`MixingField` (what
        :func:`load_crosstalk` returns for a spatial calibration).
    uv : with a :class:`MixingField`, the pixel positions (..., 2) of the
        values in ``image`` (samples rather than a whole image).

    Returns
    -------
    float64 array of the shape of ``image``.
    """
    img = np.asarray(image, float)
    if isinstance(M, MixingField):
        if uv is not None:
            return np.linalg.solve(M.at(uv), img[..., None])[..., 0]
        if img.shape != (*M.shape, 3):
            raise ValueError(
                f"unmix: image of shape {img.shape}, the mixing field is for "
                f"{M.shape[1]}x{M.shape[0]} images"
            )
        return np.einsum("hwcb,hwb->hwc", M.inverse(), img)
    M = np.asarray(M, float)
    if M.shape == (3, 3):
        return img @ np.linalg.inv(M).T
    if M.ndim == img.ndim + 1 and M.shape[-2:] == (3, 3) and M.shape[:-2] == img.shape[:-1]:
        return np.linalg.solve(M, img[..., None])[..., 0]
    raise ValueError(f"unmix: mixing of shape {M.shape} does not fit an image of {img.shape}")


# --------------------------------------------------------------------------- calibration files
def calibrate_crosstalk(
    dataset_dir: str | Path | Dataset,
    out_json: str | Path | None = None,
    poses_csv: str | Path | None = None,
    spatial: bool | None = None,
    degree: int = 3,
    **led_params,
) -> dict:
    """Mixing per camera from ``chromatic/white/<colour>/<camera>.png`` (and the board).

    Without ``poses_csv`` (and ``spatial`` not set): one constant matrix per
    camera, the median of I_c / I_b under the chromatic light's filters
    (:func:`crosstalk_matrix`). With ``spatial``: the smooth filter mixing
    field (:func:`fit_mixing_field`). With ``poses_csv`` (the markers stage's
    board poses; implies ``spatial``): that field times the LED factor F of
    :func:`led_factor`, from the board captures under the rig's own LEDs
    (``led_params``: its keyword parameters).

    Writes (atomically) a JSON file when ``out_json`` is given and returns the
    same dict: ``{"cameras": {name: {"M": 3x3, "spread": 3x3, ...}}, "method":
    ...}``. "M" is always a constant matrix (:func:`crosstalk_matrix`'s, or the
    median over the image of the final field), so a reader that needs only a
    constant matrix works on every such file; a spatial calibration adds
    "filter_M" (:func:`crosstalk_matrix`'s), "field"
    (:meth:`MixingField.to_json`), "field_rms" and "field_quantised"; with the
    board "field" becomes the LED mixing, "filter_field" keeps the filters',
    and "led_factor" (F), "led_factor_sd" and "led_mixing_sd" (its standard
    errors, and those of M) join, with "led_fit" (the fit's diagnostics) and
    "led_mixing_cov" (the full covariance of M_LED's off-diagonals, which the
    fit correlates between cameras) at the top level.

    Shows bars over the filter fields' fits (camera and light colour), the
    board captures read and the board poses, and logs a line at INFO per stage
    of the LED factor (:mod:`colourhs.common.progress`).
    """
    ds = dataset_of(dataset_dir, scenes=())
    if "white" not in ds.chromatic_objects:
        raise ValueError(f"{ds.root / 'chromatic' / 'white'}: missing (needed for cross-talk)")
    spatial = (poses_csv is not None) if spatial is None else bool(spatial)
    out = {"cameras": {}, "method": "median of I_c / I_b under light b alone (white reference)"}
    fields = {}
    label = "cross-talk: filter mixing field"
    cams = ds.rig.camera_names
    with bar(desc=label, total=3 * len(cams), disable=not spatial, unit="fit") as shown:
        for cam in cams:
            imgs, sats = {}, {}
            for colour in COLOURS:
                imgs[colour], sats[colour] = read_image(
                    ds.chromatic_image("white", colour, cam), ds.rig.image
                )
            M, spread = crosstalk_matrix(imgs, sats)
            out["cameras"][cam] = {"M": M.tolist(), "spread": spread.tolist()}
            if spatial:
                quantum = 1.0 / (ds.rig.image.white_level - ds.rig.image.black_level)
                field, info = fit_mixing_field(
                    imgs, sats, degree=degree, quantum=quantum, step=shown.update
                )
                fields[cam] = field
                out["cameras"][cam] |= {
                    "M": field.median.tolist(),
                    "filter_M": M.tolist(),
                    "field": field.to_json(),
                    "field_rms": info["rms"].tolist(),
                    "field_quantised": info["quantised"].tolist(),
                }
    if spatial:
        out["method"] = (
            f"per-pixel I_c / I_b under light b alone (white reference), Legendre degree {degree}"
        )
    if poses_csv is not None:
        result = led_factor_from_dataset(ds, poses_csv, fields, **led_params)
        for cam, F in result["factor"].items():
            field = fields[cam].scaled(F)
            out["cameras"][cam] |= {
                "M": field.median.tolist(),
                "field": field.to_json(),
                "filter_field": fields[cam].to_json(),
                "led_factor": F.tolist(),
                "led_factor_sd": result["sd"][cam].tolist(),
                # standard error of M_LED from F's noise, at the field's median
                "led_mixing_sd": (result["sd"][cam] * np.abs(fields[cam].median)).tolist(),
            }
        # covariance of M_LED's off-diagonals from F's: M_LED = M_filter * F elementwise
        scale = np.array([abs(fields[cam].median[c, b]) for cam, c, b in result["order"]])
        out["led_mixing_cov"] = {
            "order": [list(o) for o in result["order"]],
            "matrix": (result["cov"] * np.outer(scale, scale)).tolist(),
        }
        out["method"] += "; times the LED factor from the board captures (own-light and "
        out["method"] += "same-light pose invariance, eq. 1)"
        out["led_fit"] = result["diagnostics"]
    if out_json is not None:
        write_json(out_json, out)
    return out


def load_mixing_sd(path: str | Path) -> dict[str, np.ndarray]:
    """Camera name -> (3, 3) standard errors of the LED mixing M (``led_mixing_sd``).

    Empty when the file has none (a constant or filter-only calibration, whose
    error against the LEDs is not known).
    """
    data = json.loads(Path(path).read_text())
    return {
        cam: np.asarray(v["led_mixing_sd"], float)
        for cam, v in data["cameras"].items()
        if "led_mixing_sd" in v
    }


def load_mixing_cov(path: str | Path) -> tuple[list[tuple[str, int, int]], np.ndarray] | None:
    """The LED mixing's off-diagonals' full covariance (``led_mixing_cov``): their order,
    (camera, channel, light) each, and the matrix; None when the file has none."""
    data = json.loads(Path(path).read_text())
    cov = data.get("led_mixing_cov")
    if cov is None:
        return None
    return [tuple(o) for o in cov["order"]], np.asarray(cov["matrix"], float)


def load_crosstalk(path: str | Path, light: str = "led") -> dict:
    """Camera name -> mixing from a file written by :func:`calibrate_crosstalk`.

    A (3, 3) ndarray for a constant calibration (the first format), a
    :class:`MixingField` for a spatial one; :func:`unmix` takes either.
    ``light="led"`` (default): the mixing of the rig's own lights, for the
    all-lights-on images (board poses, scene frames). ``light="filter"``: the
    mixing of the chromatic light's filters, for the chromatic captures (the
    two differ by the LED factor).
    """
    if light not in ("led", "filter"):
        raise ValueError(f"load_crosstalk: light must be 'led' or 'filter', not {light!r}")
    data = json.loads(Path(path).read_text())
    out = {}
    for cam, v in data["cameras"].items():
        if light == "filter" and "filter_field" in v:
            out[cam] = MixingField.from_json(v["filter_field"])
        elif light == "filter" and "led_factor" not in v and "field" in v:
            out[cam] = MixingField.from_json(v["field"])  # a field without the board
        elif light == "filter":
            out[cam] = np.asarray(v.get("filter_M", v["M"]), float)
        elif "field" in v:
            out[cam] = MixingField.from_json(v["field"])
        else:
            out[cam] = np.asarray(v["M"], float)
    return out
