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
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from colourhs.capture import COLOURS, open_dataset, read_image
from colourhs.io import write_json

OFF_DIAGONAL = tuple((c, b) for c in range(3) for b in range(3) if c != b)


# --------------------------------------------------------------------------- constant matrix
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
        lit = _lit(img, b, None if saturated is None else saturated[colour], min_signal, colour)
        for c in range(3):
            if c == b:
                continue
            r = img[..., c][lit] / img[..., b][lit]
            M[c, b] = np.median(r)
            spread[c, b] = np.median(np.abs(r - M[c, b]))
    return M, spread


def _lit(img, b, saturated, min_signal, colour) -> np.ndarray:
    lit = (img[..., b] > min_signal) & (img[..., b] < 0.98)
    if saturated is not None:
        lit &= ~saturated
    if lit.sum() < 100:
        raise ValueError(f"cross-talk: too few lit pixels under {colour} light ({lit.sum()})")
    return lit


# --------------------------------------------------------------------------- smooth field
def legendre_basis(uv: np.ndarray, width: int, height: int, degree: int) -> np.ndarray:
    """2-D Legendre polynomials P_i(x) P_j(y), i + j <= ``degree``, at pixels ``uv`` (..., 2).

    x, y are the pixel coordinates mapped to [-1, 1] over the image (pixel
    centres 0 .. width - 1 and 0 .. height - 1). Returns (..., nb) with
    nb = (degree + 1)(degree + 2) / 2; column 0 is the constant 1.
    """
    uv = np.asarray(uv, float)
    x = 2.0 * uv[..., 0] / max(width - 1, 1) - 1.0
    y = 2.0 * uv[..., 1] / max(height - 1, 1) - 1.0
    px = np.polynomial.legendre.legvander(x, degree)
    py = np.polynomial.legendre.legvander(y, degree)
    cols = [px[..., i] * py[..., j] for n in range(degree + 1) for j in range(n + 1)
            for i in (n - j,)]  # fmt: skip
    return np.stack(cols, axis=-1)


class MixingField:
    """A camera's spatially varying mixing matrix M(u), smooth over the image.

    ``M[c, b](u) = sum_j coefficients[c, b, j] phi_j(u)`` with phi the 2-D
    Legendre basis of :func:`legendre_basis`; the diagonal is 1. Dense
    matrices and their inverses on the pixel grid are computed once, on first
    use.
    """

    def __init__(self, width: int, height: int, degree: int, coefficients: np.ndarray) -> None:
        self.width, self.height, self.degree = int(width), int(height), int(degree)
        nb = (self.degree + 1) * (self.degree + 2) // 2
        coef = np.array(coefficients, float)
        if coef.shape != (3, 3, nb):
            raise ValueError(f"mixing field: coefficients of shape {coef.shape}, need (3, 3, {nb})")
        coef[np.arange(3), np.arange(3)] = np.eye(nb)[0]
        self.coefficients = coef
        self._dense = None
        self._inverse = None

    @property
    def shape(self) -> tuple[int, int]:
        """(height, width) of the images it applies to."""
        return self.height, self.width

    def at(self, uv: np.ndarray) -> np.ndarray:
        """Mixing matrices (..., 3, 3) at pixel positions ``uv`` (..., 2)."""
        phi = legendre_basis(uv, self.width, self.height, self.degree)
        return np.einsum("...j,cbj->...cb", phi, self.coefficients)

    def dense(self) -> np.ndarray:
        """M on every pixel centre, (height, width, 3, 3)."""
        if self._dense is None:
            v, u = np.mgrid[0 : self.height, 0 : self.width].astype(float)
            self._dense = self.at(np.stack([u, v], axis=-1))
        return self._dense

    def inverse(self) -> np.ndarray:
        """M^-1 on every pixel centre, (height, width, 3, 3)."""
        if self._inverse is None:
            self._inverse = np.linalg.inv(self.dense())
        return self._inverse

    @property
    def median(self) -> np.ndarray:
        """Median over the image of each entry, (3, 3): the best constant matrix."""
        return np.median(self.dense().reshape(-1, 3, 3), axis=0)

    def scaled(self, factor: np.ndarray) -> MixingField:
        """The field times a constant (3, 3) factor, elementwise (``M_filter * F``)."""
        f = np.asarray(factor, float)
        return MixingField(self.width, self.height, self.degree, self.coefficients * f[..., None])

    def to_json(self) -> dict:
        return {"basis": "legendre2d", "degree": self.degree, "width": self.width,
                "height": self.height, "coefficients": self.coefficients.tolist()}  # fmt: skip

    @classmethod
    def from_json(cls, data: dict) -> MixingField:
        if data.get("basis") != "legendre2d":
            raise ValueError(f"mixing field: unknown basis {data.get('basis')!r}")
        return cls(data["width"], data["height"], data["degree"], data["coefficients"])


def fit_mixing_field(
    white: dict[str, np.ndarray],
    saturated: dict[str, np.ndarray] | None = None,
    degree: int = 3,
    min_signal: float = 0.1,
    quantum: float | None = None,
    max_pixels: int = 40000,
) -> tuple[MixingField, dict]:
    """Fit M(u) to single-colour white captures: ``I_c(u) = M[c, b](u) I_b(u)`` under light b.

    Each off-diagonal entry is a Legendre polynomial of total ``degree`` in
    the pixel coordinates. The small reading I_c is the dependent variable
    (so its noise does not bias the estimate; the lit channel I_b is large).
    Pixels saturated in any channel, with the lit channel above 0.98 or below
    ``min_signal`` of full scale, are left out.

    - Least squares with weights 1 / (I_b + 0.01) (shot plus read noise of
      I_c) and Huber reweighting at 3 robust standard deviations, when the
      readings' noise exceeds the quantisation step (16-bit images).
    - Maximum likelihood of the integer readings when the noise is below
      about one step ``quantum`` (fraction of full scale per raw value: 8-bit
      images, where a 2-8 % leak is a few DN with sub-DN noise, and least
      squares -- or a median of ratios -- are biased by the rounding by up to
      30 % of the leak): a reading v is ``round(mu + noise)``, mu = M I_b,
      noise Gaussian of variance ``s_r^2 + g mu`` (read and shot noise, both
      fitted), so ``P(v) = Phi((v + q/2 - mu) / s) - Phi((v - q/2 - mu) / s)``
      (the lower bound open at 0, where readings below black clip), mixed
      with 0.1 % of outliers. At most ``max_pixels`` pixels (a regular
      subsample) enter this fit.

    Returns
    -------
    field : the fitted :class:`MixingField`.
    info : ``rms`` (3, 3) RMS of the per-pixel ratio residual I_c / I_b - M,
        ``pixels`` (3,) pixels used per light colour, ``quantised`` (3, 3) bool
        (maximum likelihood used), ``noise`` (3, 3) fitted noise at I_c = 0
        in raw steps (read noise; NaN for least squares).
    """
    first = next(iter(white.values()))
    H, W = first.shape[:2]
    v, u = np.mgrid[0:H, 0:W]
    uv_all = np.stack([u.ravel(), v.ravel()], axis=1).astype(float)
    nb = (degree + 1) * (degree + 2) // 2
    coef = np.zeros((3, 3, nb))
    rms = np.zeros((3, 3))
    quantised = np.zeros((3, 3), bool)
    noise = np.full((3, 3), np.nan)
    pixels = np.zeros(3, int)
    for colour, img in white.items():
        b = COLOURS.index(colour)
        sat = None if saturated is None else saturated[colour]
        lit = _lit(img, b, sat, min_signal, colour).ravel()
        sub = img.reshape(-1, 3)[lit].astype(float)
        phi = legendre_basis(uv_all[lit], W, H, degree)
        pixels[b] = int(lit.sum())
        ib = sub[:, b]
        w0 = 1.0 / (ib + 0.01)
        A = phi * ib[:, None]
        for c in range(3):
            if c == b:
                continue
            ic = sub[:, c]
            w = w0.copy()
            for _ in range(4):
                sw = np.sqrt(w)
                a = np.linalg.lstsq(A * sw[:, None], ic * sw, rcond=None)[0]
                res = ic - A @ a
                z = res * np.sqrt(w0)
                scale = 1.4826 * np.median(np.abs(z)) + 1e-12
                w = w0 * np.minimum(1.0, 3.0 * scale / np.maximum(np.abs(z), 1e-30))
            if quantum is not None and np.sqrt(np.mean(res**2)) < 1.5 * quantum:
                stride = max(1, int(np.ceil(len(ic) / max_pixels)))
                sl = slice(None, None, stride)
                a, s_r = _fit_quantised(ic[sl], ib[sl], phi[sl], a, float(quantum))
                quantised[c, b], noise[c, b] = True, s_r / quantum
            coef[c, b] = a
            rms[c, b] = float(np.sqrt(np.mean((ic / ib - phi @ a) ** 2)))
    info = {"rms": rms, "pixels": pixels, "quantised": quantised, "noise": noise}
    return MixingField(W, H, degree, coef), info


def _fit_quantised(ic, ib, phi, a0, q, outliers=1e-3):
    """Maximum-likelihood a of ``round(I_b phi a + noise)`` readings (see fit_mixing_field).

    Returns the coefficients and the fitted read noise (fraction of full scale).
    """
    from scipy.optimize import minimize
    from scipy.special import ndtr

    nb = phi.shape[1]
    floor = ic <= 0  # clipped at black: only the upper bound is known
    root2pi = np.sqrt(2 * np.pi)

    def nll(p):
        a, lsr, lg = p[:nb], p[nb], p[nb + 1]
        mu = ib * (phi @ a)
        pos = mu > 0
        var = np.exp(2 * lsr) + np.exp(lg) * np.where(pos, mu, 0.0)
        sg = np.sqrt(var)
        zh = (ic + q / 2 - mu) / sg
        zl = np.where(floor, 0.0, (ic - q / 2 - mu) / sg)
        ph = np.exp(-0.5 * zh**2) / root2pi
        pl = np.where(floor, 0.0, np.exp(-0.5 * zl**2) / root2pi)
        L = ndtr(zh) - np.where(floor, 0.0, ndtr(zl))
        Lm = (1 - outliers) * L + outliers * q
        gL = -(1 - outliers) / Lm
        dL_dmu = (pl - ph) / sg
        dL_dvar = (-zh * ph + zl * pl) / sg * (0.5 / sg)
        gmu = gL * (dL_dmu + dL_dvar * np.exp(lg) * pos)
        grad = np.concatenate(
            [
                phi.T @ (gmu * ib),
                [np.sum(gL * dL_dvar * 2 * np.exp(2 * lsr))],
                [np.sum(gL * dL_dvar * np.exp(lg) * np.where(pos, mu, 0.0))],
            ]
        )
        return -np.sum(np.log(Lm)), grad

    p0 = np.concatenate([a0, [np.log(0.3 * q), np.log((0.3 * q) ** 2 / 0.01)]])
    res = minimize(nll, p0, jac=True, method="L-BFGS-B", options={"maxiter": 500})
    return res.x[:nb], float(np.exp(res.x[nb]))


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
    dataset_dir: str | Path,
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
    ...}``. "M" is always a constant matrix (today's, or the median over the
    image of the final field), so readers of the first format still work; a
    spatial calibration adds "filter_M" (today's matrix), "field"
    (:meth:`MixingField.to_json`), "field_rms" and "field_quantised"; with the
    board "field" becomes the LED mixing, "filter_field" keeps the filters',
    and "led_factor" (F), "led_factor_sd" and "led_mixing_sd" (its standard
    errors, and those of M) join, with "led_fit" (the fit's diagnostics) at the
    top level.
    """
    ds = open_dataset(dataset_dir, check_images=False)
    if "white" not in ds.chromatic_objects:
        raise ValueError(f"{ds.root / 'chromatic' / 'white'}: missing (needed for cross-talk)")
    spatial = (poses_csv is not None) if spatial is None else bool(spatial)
    out = {"cameras": {}, "method": "median of I_c / I_b under light b alone (white reference)"}
    fields = {}
    for cam in ds.rig.camera_names:
        imgs, sats = {}, {}
        for colour in COLOURS:
            imgs[colour], sats[colour] = read_image(
                ds.chromatic_image("white", colour, cam), ds.rig.image
            )
        M, spread = crosstalk_matrix(imgs, sats)
        out["cameras"][cam] = {"M": M.tolist(), "spread": spread.tolist()}
        if spatial:
            quantum = 1.0 / (ds.rig.image.white_level - ds.rig.image.black_level)
            field, info = fit_mixing_field(imgs, sats, degree=degree, quantum=quantum)
            fields[cam] = field
            out["cameras"][cam] |= {"M": field.median.tolist(), "filter_M": M.tolist(),
                                    "field": field.to_json(),
                                    "field_rms": info["rms"].tolist(),
                                    "field_quantised": info["quantised"].tolist()}  # fmt: skip
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
        out["method"] += "; times the LED factor from the board captures (own-light and "
        out["method"] += "same-light pose invariance, eq. 1)"
        out["led_fit"] = result["diagnostics"]
    if out_json is not None:
        write_json(out_json, out)
    return out


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


# --------------------------------------------------------------------------- LED factor
@dataclass(frozen=True)
class BoardShot:
    """One board pose with its all-lights-on images (raw, not unmixed)."""

    name: str
    R: np.ndarray  # board to world rotation
    t: np.ndarray  # board to world translation, metres
    images: dict  # camera name -> (H, W, 3) linear image
    saturated: dict  # camera name -> (H, W) bool

    @property
    def normal(self) -> np.ndarray:
        """Unit normal of the white face (towards the cameras), world frame."""
        return self.R @ np.array([0.0, 0.0, -1.0])


LED_DEFAULTS = {"step_px": None, "margin_m": 0.002, "min_cos": 0.3, "min_signal": 0.03,
                "sigma_degree": 4, "pose_refinement": False, "iterations": 10,
                "huber": 3.0, "constraints": ("own", "same_light"), "shrink": True}  # fmt: skip


def _inv3(M: np.ndarray) -> np.ndarray:
    """Inverses of (N, 3, 3) matrices by cofactors (much faster than a batched LU)."""
    a, b, c = M[:, 0, 0], M[:, 0, 1], M[:, 0, 2]
    d, e, f = M[:, 1, 0], M[:, 1, 1], M[:, 1, 2]
    g, h, i = M[:, 2, 0], M[:, 2, 1], M[:, 2, 2]
    co = np.stack(
        [e * i - f * h, c * h - b * i, b * f - c * e,
         f * g - d * i, a * i - c * g, c * d - a * f,
         d * h - e * g, b * g - a * h, a * e - b * d], axis=1
    ).reshape(-1, 3, 3)  # fmt: skip
    det = a * co[:, 0, 0] + b * co[:, 1, 0] + c * co[:, 2, 0]
    return co / det[:, None, None]


def _unmix_rows(readings, Mf, Minv, ch):
    """Channel ``ch`` of T = M^-1 readings per row, and d log T_ch / d F[c, b] (N, 6).

    M = Mf * F; for an off-diagonal (c, b), dT/dF[c, b] = -M^-1 (dM/dF[c, b]) T
    = -Mf[c, b] T_b M^-1[:, c].
    """
    r = np.arange(len(readings))
    T = np.einsum("ncb,nb->nc", Minv, readings)
    t = T[r, ch]
    D = np.empty((len(readings), len(OFF_DIAGONAL)))
    with np.errstate(divide="ignore", invalid="ignore"):
        for q, (c, b) in enumerate(OFF_DIAGONAL):
            D[:, q] = -Mf[:, c, b] * T[:, b] * Minv[r, ch, c] / t
    return t, D


class _LedProblem:
    """The rows of the LED-factor fit (see :func:`led_factor`).

    Per row: the box-filtered readings ``Y`` of one or two cameras (the
    measurement), the readings ``Q`` of a ring around the same footprint
    (independent noise: they give the Jacobian and the weights, so the
    Gauss-Newton normal equations are an instrumental-variables estimator,
    unbiased by the noise of ``Y``), the filter mixing there, the geometry
    term, the nuisance design ``Z`` and the pixel group of the free h(u).
    """

    def __init__(self, rows: dict, nc: int, ncols: int):
        for k, v in rows.items():
            setattr(self, k, v)
        self.nc = nc
        self.N = len(self.group)
        self.ng = int(self.group.max()) + 1 if self.N else 0
        self.nth = nc * len(OFF_DIAGONAL)
        self.two = self.cam2 >= 0
        self.ncols = ncols

    def factors(self, theta) -> np.ndarray:
        F = np.ones((self.nc, 3, 3))
        for kk in range(self.nc):
            for q, (c, b) in enumerate(OFF_DIAGONAL):
                F[kk, c, b] = theta[kk * len(OFF_DIAGONAL) + q]
        return F

    def evaluate(self, theta):
        """y (N,) at factors theta, its Jacobian (N, nth) and noise weights, from the ring."""
        nq, N = len(OFF_DIAGONAL), self.N
        F = self.factors(theta)
        Minv = _inv3(self.M1 * F[self.cam])
        t1, _ = _unmix_rows(self.Y1, self.M1, Minv, self.ch)
        q1, d1 = _unmix_rows(self.Q1, self.M1, Minv, self.ch)
        with np.errstate(divide="ignore", invalid="ignore"):
            y = np.log(t1) - self.logG
        J = np.zeros((N, self.nth))
        np.put_along_axis(J, self.cam[:, None] * nq + np.arange(nq), d1, axis=1)
        var = 1.0 / q1
        i2 = np.flatnonzero(self.two)
        if len(i2):
            M2, c2, ch2 = self.M2[i2], self.cam2[i2], self.ch[i2]
            Minv2 = _inv3(M2 * F[c2])
            t2, _ = _unmix_rows(self.Y2[i2], M2, Minv2, ch2)
            q2, d2 = _unmix_rows(self.Q2[i2], M2, Minv2, ch2)
            with np.errstate(divide="ignore", invalid="ignore"):
                y[i2] -= np.log(t2)
            J2 = np.zeros((len(i2), self.nth))
            np.put_along_axis(J2, c2[:, None] * nq + np.arange(nq), -d2, axis=1)
            J[i2] += J2
            var[i2] += 1.0 / q2
        with np.errstate(divide="ignore", invalid="ignore"):
            w = np.where(np.isfinite(y) & (var > 0), 1.0 / var, 0.0)
        return np.nan_to_num(y), np.nan_to_num(J), F, np.nan_to_num(w)

    def design(self, J):
        """The sparse design [J, -Z] (each row touches one or two cameras' blocks)."""
        import scipy.sparse as sp

        if getattr(self, "_Zs", None) is None:
            self._Zs = -sp.csr_matrix(self.Z)
        return sp.hstack([sp.csr_matrix(J), self._Zs], format="csr")

    def normal_equations(self, X, y, w):
        """X^T W X and X^T W y of the rows with each pixel group's weighted mean removed."""
        import scipy.sparse as sp

        S = sp.csr_matrix((w, (self.group, np.arange(self.N))), shape=(self.ng, self.N))
        sw = np.asarray(S.sum(axis=1)).ravel()
        sw = np.where(sw > 0, sw, 1.0)
        Sx, Sy = S @ X, S @ y
        XtX = (X.T @ sp.diags(w) @ X).toarray() - (Sx.T @ sp.diags(1.0 / sw) @ Sx).toarray()
        Xty = X.T @ (w * y) - Sx.T @ (Sy / sw)
        return XtX, np.asarray(Xty).ravel()

    def demean(self, a, w):
        """``a`` minus its weighted mean over each pixel group (eliminates h(u))."""
        g, ng = self.group, self.ng
        sw = np.bincount(g, weights=w, minlength=ng)
        sw = np.where(sw > 0, sw, 1.0)
        if a.ndim == 1:
            return a - (np.bincount(g, weights=w * a, minlength=ng) / sw)[g]
        out = np.empty_like(a)
        for col in range(a.shape[1]):
            m = np.bincount(g, weights=w * a[:, col], minlength=ng) / sw
            out[:, col] = a[:, col] - m[g]
        return out


def _box_images(rig, shots, k: int, K: int, margin_m: float) -> list[dict]:
    """Per shot and camera: k x k box means, ring means, and where both are usable.

    A pixel is valid when its centre sees the board's white surface at least
    ``margin_m`` (and 1.5 pixels) from markers and edges and is not saturated. The box mean
    needs every pixel of its box valid; the ring (the K x K box less the
    k x k one) averages its valid pixels and needs a third of them.
    """
    import cv2

    from colourhs.geometry import backproject, pixel_grid, ray_plane_intersection

    W, H = rig.image.width, rig.image.height
    grid = pixel_grid(W, H).reshape(-1, 2)
    rays = {c.name: backproject(grid, c.K, c.dist, c.R, c.t) for c in rig.cameras}

    def bsum(a, size):
        return cv2.boxFilter(a, -1, (size, size), normalize=False, borderType=cv2.BORDER_CONSTANT)

    out = []
    for shot in shots:
        per = {}
        for cam in rig.cameras:
            name = cam.name
            origin, d = rays[name]
            x, t = ray_plane_intersection(origin, d, shot.t, shot.normal)
            xy = ((x - shot.t) @ shot.R)[:, :2]
            with np.errstate(invalid="ignore", divide="ignore"):
                # at least 1.5 pixels clear of a marker or edge, wherever the pixel lies
                pixel_m = t / (cam.K[0, 0] * np.abs(d @ shot.normal))
                margin = np.maximum(margin_m, 1.5 * np.nan_to_num(pixel_m, nan=np.inf))
                valid = (t > 0) & rig.board.white(xy, margin)
            valid = valid.reshape(H, W) & ~shot.saturated[name]
            v = valid.astype(np.float32)
            img = np.ascontiguousarray(shot.images[name], np.float32) * v[..., None]
            n_small, n_big = bsum(v, k), bsum(v, K)
            s_small, s_big = bsum(img, k), bsum(img, K)
            ring_n = n_big - n_small
            ok = (n_small > k * k - 0.5) & (ring_n >= (K * K - k * k) / 3)
            with np.errstate(invalid="ignore", divide="ignore"):
                ring = (s_big - s_small) / ring_n[..., None]
            per[name] = (s_small / (k * k), np.where(ok[..., None], ring, 0.0), ok)
        out.append(per)
    return out


POSE_STEP = (1e-3, 1e-3, 1e-3)  # m of depth, rad of tilt: the units of the pose corrections


def _pose_derivatives(shot, board, origin, d, cam) -> np.ndarray:
    """d log((n . v) / |c - x|^2) / d(plane depth, two tilts) for rays ``d`` of ``cam`` (N, 3).

    The board plane moved along its normal, or turned about its two in-plane
    axes through the board's centre; finite differences of the exact geometry.
    """
    from colourhs.geometry import ray_plane_intersection

    def log_g(R, t):
        n = R @ np.array([0.0, 0.0, -1.0])
        x, _ = ray_plane_intersection(origin, d, t, n)
        v = cam.light_centre - x
        d2 = np.sum(v**2, axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.log((v @ n) / np.sqrt(d2) / d2)

    base = log_g(shot.R, shot.t)
    centre = shot.R @ np.array([board.size[0] / 2, board.size[1] / 2, 0.0]) + shot.t
    out = np.empty((len(d), 3))
    eps = 1e-5
    out[:, 0] = (log_g(shot.R, shot.t + eps * shot.normal) - base) / eps * POSE_STEP[0]
    for k, axis in enumerate((shot.R[:, 0], shot.R[:, 1])):
        Q = _rotation(axis, eps)
        R = Q @ shot.R
        out[:, k + 1] = (log_g(R, centre - Q @ (centre - shot.t)) - base) / eps * POSE_STEP[k + 1]
    return np.nan_to_num(out)


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation matrix by ``angle`` (rad) about unit ``axis`` (Rodrigues)."""
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def _build_led_problem(rig, shots, fields, opts) -> _LedProblem:
    from colourhs.geometry import backproject, project, ray_plane_intersection
    from colourhs.helmholtz import sample_bilinear

    W, H = rig.image.width, rig.image.height
    step = int(opts["step_px"])
    k = 2 * (step // 2) + 1  # odd box, centred on the sample
    K = k + 4  # ring of width 2 around it
    cams = rig.cameras
    nc, npose = len(cams), len(shots)
    sdeg = int(opts["sigma_degree"])
    nbs = (sdeg + 1) * (sdeg + 2) // 2 - 1
    n_pose_cols = 3 * npose if opts["pose_refinement"] else 0
    ncols = n_pose_cols + nc * nbs
    half = K // 2 + 1
    us = np.arange(half, W - half, step, dtype=float)
    vs = np.arange(half, H - half, step, dtype=float)
    gu, gv = np.meshgrid(us, vs)
    uv = np.stack([gu.ravel(), gv.ravel()], axis=1)
    npx = len(uv)
    iu, iv = uv[:, 0].astype(int), uv[:, 1].astype(int)
    boxes = _box_images(rig, shots, k, K, opts["margin_m"])
    parts = []
    for a, A in enumerate(cams):
        origin, d = backproject(uv, A.K, A.dist, A.R, A.t)
        MA = fields[A.name].at(uv)
        # the light's rays: the camera's model moved to the light centre
        collocated = bool(np.allclose(A.light_offset, 0.0))
        l_origin, l_dir = origin, d
        if not collocated:
            l_origin, l_dir = backproject(uv, A.K, A.dist, A.R, -A.R @ A.light_centre)
        for j, shot in enumerate(shots):
            n = shot.normal
            x, s = ray_plane_intersection(origin, d, shot.t, n)
            yA, qA, okA = (v[iv, iu] for v in boxes[j][A.name])
            with np.errstate(invalid="ignore", divide="ignore"):
                vc = A.centre - x
                cos_c = (vc @ n) / np.linalg.norm(vc, axis=1)
                ok = (s > 0) & (cos_c > opts["min_cos"]) & okA
            # (a) the camera's own channel against the geometry of its own light, on a
            # grid of the light's directions (the camera's own grid when collocated)
            o = A.light_channel
            if collocated:
                xo, so, uo, yo, qo, oko = x, s, uv, yA, qA, okA
            else:
                xo, so = ray_plane_intersection(l_origin, l_dir, shot.t, n)
                uo = project(xo, A.K, A.dist, A.R, A.t)
                box, ring, okimg = boxes[j][A.name]
                yo, qo = sample_bilinear(box, uo), sample_bilinear(ring, uo)
                with np.errstate(invalid="ignore"):
                    oko = sample_bilinear(okimg.astype(np.float32), uo) > 1 - 1e-6
                    oko &= (uo[:, 0] >= half) & (uo[:, 0] <= W - 1 - half)
                    oko &= (uo[:, 1] >= half) & (uo[:, 1] <= H - 1 - half)
            vl = A.light_centre - xo
            dl2 = np.sum(vl**2, axis=1)
            vco = A.centre - xo
            with np.errstate(invalid="ignore", divide="ignore"):
                cos_l = (vl @ n) / np.sqrt(dl2)
                own = (so > 0) & oko & (cos_l > opts["min_cos"]) & (yo[:, o] > opts["min_signal"])
                own &= (vco @ n) / np.linalg.norm(vco, axis=1) > opts["min_cos"]
            idx = np.flatnonzero(own) if "own" in opts["constraints"] else np.zeros(0, int)
            z = np.zeros((len(idx), ncols))
            if n_pose_cols:
                # the markers stage's plane error (depth, two tilts), shared by the cameras
                dz = _pose_derivatives(shot, rig.board, l_origin, l_dir[idx], A)
                z[:, 3 * j : 3 * j + 3] = dz
            if not collocated:
                # the camera's own-channel vignetting at its pixel, S_a, as in (b)
                base = n_pose_cols + a * nbs
                z[:, base : base + nbs] = legendre_basis(uo[idx], W, H, sdeg)[:, 1:]
            parts.append({"kind": np.zeros(len(idx), int), "cam": np.full(len(idx), a),
                          "cam2": np.full(len(idx), -1), "ch": np.full(len(idx), o),
                          "Y1": yo[idx], "Q1": qo[idx],
                          "M1": MA[idx] if collocated else fields[A.name].at(uo[idx]),
                          "Y2": np.ones((len(idx), 3)), "Q2": np.ones((len(idx), 3)),
                          "M2": np.broadcast_to(np.eye(3), (len(idx), 3, 3)),
                          "logG": np.log(cos_l[idx] / dl2[idx]), "Z": z,
                          "group": a * npx + idx, "u1": uv[idx],
                          "u2": np.full((len(idx), 2), np.nan) if collocated else uo[idx],
                          "pose": np.full(len(idx), j)})  # fmt: skip
            # (b) the light of camera m seen by camera a and by camera m itself
            for m, B in enumerate(cams):
                if m == a or "same_light" not in opts["constraints"]:
                    continue
                oB = B.light_channel
                uB = project(x, B.K, B.dist, B.R, B.t)
                vb = B.light_centre - x
                vcb = B.centre - x
                with np.errstate(invalid="ignore", divide="ignore"):
                    okb = ok & ((vcb @ n) / np.linalg.norm(vcb, axis=1) > opts["min_cos"])
                    okb &= (vb @ n) / np.linalg.norm(vb, axis=1) > opts["min_cos"]
                    okb &= (uB[:, 0] >= half) & (uB[:, 0] <= W - 1 - half)
                    okb &= (uB[:, 1] >= half) & (uB[:, 1] <= H - 1 - half)
                idx = np.flatnonzero(okb)
                ub = uB[idx]
                box_B, ring_B, ok_B = boxes[j][B.name]
                usable = sample_bilinear(ok_B.astype(np.float32), ub) > 1 - 1e-6
                yB = sample_bilinear(box_B, ub)
                qB = sample_bilinear(ring_B, ub)
                with np.errstate(invalid="ignore"):
                    keep = usable & (yA[idx, oB] > opts["min_signal"])
                    keep &= yB[:, oB] > opts["min_signal"]
                idx, ub, yB, qB = idx[keep], ub[keep], yB[keep], qB[keep]
                z = np.zeros((len(idx), ncols))
                base = n_pose_cols + m * nbs
                z[:, base : base + nbs] = -legendre_basis(ub, W, H, sdeg)[:, 1:]
                parts.append({"kind": np.ones(len(idx), int), "cam": np.full(len(idx), a),
                              "cam2": np.full(len(idx), m), "ch": np.full(len(idx), oB),
                              "Y1": yA[idx], "Q1": qA[idx], "M1": MA[idx], "Y2": yB, "Q2": qB,
                              "M2": fields[B.name].at(ub), "logG": np.zeros(len(idx)), "Z": z,
                              "group": nc * npx + (a * nc + m) * npx + idx, "u1": uv[idx],
                              "u2": ub, "pose": np.full(len(idx), j)})  # fmt: skip
    rows = {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}
    block = np.floor(rows["u1"] / (8 * step)).astype(int)
    rows["cluster"] = np.stack([rows["kind"], rows["cam"], rows["cam2"], rows["pose"],
                                block[:, 0], block[:, 1]], axis=1)  # fmt: skip
    # a pixel seen in a single pose carries nothing once its h(u) is eliminated
    _, inv, counts = np.unique(rows["group"], return_inverse=True, return_counts=True)
    keep = counts[inv] >= 2
    rows = {key: v[keep] for key, v in rows.items()}
    rows["group"] = np.unique(rows["group"], return_inverse=True)[1]
    rows["cluster"] = np.unique(rows["cluster"], axis=0, return_inverse=True)[1].ravel()
    if len(rows["group"]) < 100:
        raise ValueError(f"LED factor: too few usable board samples ({len(rows['group'])})")
    prob = _LedProblem(rows, nc, ncols)
    prob.step, prob.box = step, k
    return prob


def _solve_led_problem(prob: _LedProblem, theta, iterations: int, huber: float):
    """IV Gauss-Newton with Huber reweighting; returns theta, its covariance, diagnostics."""
    nth = prob.nth
    robust = np.ones(prob.N)
    steps = []
    for it in range(max(int(iterations), 1) + 1):
        y, J, F, wn = prob.evaluate(theta)
        w = wn * robust
        X = prob.design(J)
        XtX, Xty = prob.normal_equations(X, y, w)
        sol = np.linalg.lstsq(XtX, -Xty, rcond=1e-13)[0]
        r = prob.demean(y + X @ sol, w)
        if it == max(int(iterations), 1) or (steps and steps[-1] < 1e-5):
            break  # the last pass only evaluates (for the covariance)
        theta = theta + sol[:nth]
        z = r * np.sqrt(wn)
        scale = 1.4826 * np.median(np.abs(z[w > 0])) + 1e-15
        robust = np.minimum(1.0, huber * scale / np.maximum(np.abs(z), 1e-30))
        steps.append(float(np.max(np.abs(sol[:nth]))))
    # sandwich covariance of theta, nuisances eliminated, with the score summed over
    # clusters of nearby rows (residuals of neighbouring samples are correlated:
    # shared pixels of the partner camera, small model errors)
    import scipy.sparse as sp

    Xt = prob.demean(X.toarray(), w)
    Hi = np.linalg.pinv(XtX, rcond=1e-13)
    _, cl = np.unique(prob.cluster, return_inverse=True)
    C = sp.csr_matrix((w * r, (cl, np.arange(prob.N))), shape=(int(cl.max()) + 1, prob.N))
    score = C @ Xt
    cov = (Hi @ (score.T @ score) @ Hi)[:nth, :nth]
    # identifiability of theta: the Schur complement with the nuisances eliminated
    red = np.linalg.pinv(Hi[:nth, :nth], rcond=1e-15)
    sv = np.linalg.svd(red / np.abs(red).max(), compute_uv=False)
    diag = {"iterations": len(steps), "last_step": steps[-1],
            "rms_log_residual": float(np.sqrt(np.sum(w * r**2) / np.sum(w)
                                              / np.mean(wn[w > 0]))),
            "singular_values": [float(v) for v in sv]}  # fmt: skip
    return theta, cov, diag


def shrink_towards_filter(theta, cov) -> tuple[np.ndarray, np.ndarray, float]:
    """Empirical-Bayes estimate of the LED factors given their fit and its covariance.

    Prior: F = 1 + N(0, tau^2) for every off-diagonal (the filters chosen to
    match the LEDs' colours); tau maximises the marginal likelihood of the fit,
    ``theta - 1 ~ N(0, cov + tau^2 I)``. Returns the posterior mean, its
    covariance and tau. Where the fit is no better than its noise (LEDs
    and filters alike, or too few board pixels) tau -> 0 and F -> 1: the
    filter mixing, never worse than ignoring the board.
    """
    from scipy.optimize import minimize_scalar

    d = np.asarray(theta, float) - 1.0
    C = 0.5 * (cov + cov.T)
    eye = np.eye(len(d))

    def nll(log_tau):
        A = C + np.exp(2 * log_tau) * eye
        sign, logdet = np.linalg.slogdet(A)
        return 0.5 * (logdet + d @ np.linalg.solve(A, d)) if sign > 0 else np.inf

    res = minimize_scalar(nll, bounds=(np.log(1e-4), np.log(2.0)), method="bounded")
    tau2 = float(np.exp(2 * res.x))
    if nll(np.log(1e-4)) <= res.fun:
        tau2 = 0.0
    A = C + tau2 * eye
    gain = tau2 * np.linalg.inv(A)
    return 1.0 + gain @ d, tau2 * eye - tau2 * gain, float(np.sqrt(tau2))


def led_factor(rig, shots: list[BoardShot], fields: dict, **params) -> dict:
    """The constant LED factor F per camera, ``M_LED(u) = M_filter(u) * F``, from the board.

    Constraints (module docstring; eq. 1 with a Lambertian board), at samples
    on a grid of step ``step_px`` (default width / 160) of each camera a, for
    every board pose where the sample sees the white surface (``margin_m``
    clear of markers and edges, incidence cosines above ``min_cos``,
    unsaturated, readings above ``min_signal``):

    - (a) own channel o of camera a:
      ``log T_{a<-a} - log((n . v_a) / |c_a - x|^2) = h(u)``, h free per pixel
      (it is log(sigma rho) of the camera's own Helmholtz camera);
    - (b) each other light m: ``log T_{a<-m}(u) - log T_{m<-m}(u_m) = h'(u) -
      S_m(u_m)``, u_m the board point's pixel in camera m, h' free per pixel,
      S_m (log sigma of camera m's own channel) a Legendre polynomial of
      degree ``sigma_degree``.

    Readings are means over an odd box of about ``step_px`` pixels (as much
    information as every pixel, far fewer rows); the Jacobian and the noise
    weights come from the ring around each box (an instrumental variable:
    Jacobians from the sample's own noisy readings bias F by many standard
    errors). The 18 off-diagonals of F are solved by Gauss-Newton with the
    per-pixel constants eliminated (variable projection) and the
    polynomials solved jointly, with Huber weights at ``huber`` robust
    deviations.

    Only (a) depends on the board poses, through the geometry: a depth error
    dz of the markers stage shifts log G by about 2 dz / d, which F absorbs as
    a leak (0.02 mm, as on the synthetic 640x480 rigs: F off by ~0.005; 0.05-0.09
    mm at 160x120: ~0.05). ``pose_refinement`` adds a depth and two tilt
    corrections per pose, shared by the cameras; it removes that bias on
    noise-free images but is nearly degenerate with F and multiplies its
    noise errors about tenfold, so it is off by default. ``constraints``
    chooses the kinds of rows, ``("own", "same_light")``; without "own" the
    fit has six null directions (the mixing common to all cameras, module
    docstring), visible as six vanishing ``singular_values``.

    With ``shrink`` (default) the fitted factors are shrunk towards 1 by
    :func:`shrink_towards_filter` (empirical Bayes, one prior spread for the
    18 numbers, from their fit and its sandwich covariance): LEDs that match
    the filters, or a fit too noisy to tell, give F = 1, i.e. the filter field.

    Parameters
    ----------
    rig : the dataset's :class:`~colourhs.capture.Rig`.
    shots : board poses with their raw images.
    fields : camera name -> filter :class:`MixingField` (chromatic captures).

    Returns
    -------
    dict with ``factor`` (camera -> (3, 3) F, unit diagonal), ``sd`` (camera ->
    (3, 3) standard errors: sandwich estimate over 8 x 8 blocks of samples,
    posterior with ``shrink``), ``diagnostics``
    (JSON-able: rows per kind, iterations, RMS residual, singular values of
    the normal matrix of F with the nuisances eliminated, parameters).
    """
    opts = LED_DEFAULTS | {k: v for k, v in params.items() if v is not None}
    opts["step_px"] = int(opts["step_px"] or max(1, round(rig.image.width / 160)))
    prob = _build_led_problem(rig, shots, fields, opts)
    theta0 = np.ones(prob.nth) if opts.get("initial") is None else np.asarray(opts["initial"])
    if opts.get("return_problem"):
        return prob
    theta, cov, diag = _solve_led_problem(prob, theta0, opts["iterations"], opts["huber"])
    fit_sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    if opts["shrink"]:
        fit = theta
        theta, cov, tau = shrink_towards_filter(theta, cov)
        diag |= {"prior_sd": tau, "unshrunk": [float(v) for v in fit]}
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    diag["fit_sd"] = [float(v) for v in fit_sd]
    F = prob.factors(theta)
    factor, sds = {}, {}
    for kk, name in enumerate(rig.camera_names):
        factor[name] = F[kk]
        S = np.zeros((3, 3))
        for q, (c, b) in enumerate(OFF_DIAGONAL):
            S[c, b] = sd[kk * len(OFF_DIAGONAL) + q]
        sds[name] = S
    diag = {"rows_own": int(np.sum(prob.kind == 0)), "rows_same_light": int(np.sum(prob.kind == 1)),
            "box_px": prob.box} | diag | {"params": {k: v for k, v in opts.items()
                                                     if k in LED_DEFAULTS}}  # fmt: skip
    return {"factor": factor, "sd": sds, "diagnostics": diag}


def read_board_shots(ds, poses_csv) -> list[BoardShot]:
    """The board poses of a marker poses table with their raw images."""
    import pandas as pd

    table = pd.read_csv(poses_csv, dtype={"pose": str}, keep_default_na=False)
    shots = []
    for _, row in table.iterrows():
        pose = str(row["pose"])
        R = np.array([[float(row[f"R{i}{j}"]) for j in range(3)] for i in range(3)])
        t = np.array([float(row["t_x"]), float(row["t_y"]), float(row["t_z"])])
        images, saturated = {}, {}
        for cam in ds.rig.camera_names:
            images[cam], saturated[cam] = read_image(ds.photometric_image(pose, cam), ds.rig.image)
        shots.append(BoardShot(pose, R, t, images, saturated))
    if len(shots) < 2:
        raise ValueError(f"{poses_csv}: {len(shots)} board poses, the LED factor needs >= 2")
    return shots


def led_factor_from_dataset(ds, poses_csv, fields: dict, **params) -> dict:
    """:func:`led_factor` on a dataset's board captures and a marker poses table."""
    return led_factor(ds.rig, read_board_shots(ds, poses_csv), fields, **params)
