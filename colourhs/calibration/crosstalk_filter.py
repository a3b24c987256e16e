"""The filter mixing from the chromatic white captures: a constant matrix or a smooth field.

Estimate 1 of :mod:`colourhs.calibration.crosstalk` (whose docstring has the model
``I_c(u) = sum_b M[c, b](u) J_b(u)``, section III-E of the paper): the white
reference under one coloured light b at a time gives
``I_c / I_b = M_filter[c, b](u)``. This module holds

- :func:`crosstalk_matrix`: one constant 3x3 M per camera, the median ratio;
- :func:`legendre_basis` and :class:`MixingField`: M(u) as a 2-D Legendre
  polynomial in the pixel coordinates, the form of every spatial calibration
  (the filters' field, and the LEDs' one, ``M_filter * F``);
- :func:`fit_mixing_field`: its fit, robust weighted least squares or the
  maximum likelihood of the integer readings (8-bit images).
"""

from __future__ import annotations

import numpy as np

from colourhs.capture import COLOURS


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
    px = _legendre_1d(uv[..., 0], width, degree)
    py = _legendre_1d(uv[..., 1], height, degree)
    return np.stack([px[..., i] * py[..., j] for i, j in _legendre_terms(degree)], axis=-1)


def _legendre_1d(t: np.ndarray, size: int, degree: int) -> np.ndarray:
    """P_0 .. P_degree (..., degree + 1) at pixel coordinates ``t`` mapped to [-1, 1]."""
    return np.polynomial.legendre.legvander(2.0 * t / max(size - 1, 1) - 1.0, degree)


def _legendre_terms(degree: int) -> list[tuple[int, int]]:
    """(i, j) of each column of :func:`legendre_basis`, in its order."""
    return [(n - j, j) for n in range(degree + 1) for j in range(n + 1)]


def legendre_grid(width: int, height: int, degree: int) -> np.ndarray:
    """:func:`legendre_basis` on every pixel centre, (height, width, nb), the same numbers.

    Beyond the paper (speed). Each column is the outer product of two 1-D
    polynomials, so only those are evaluated, not the recurrences at every
    pixel; the products are the same numbers as :func:`legendre_basis`'s.
    """
    px = _legendre_1d(np.arange(width, dtype=float), width, degree)
    py = _legendre_1d(np.arange(height, dtype=float), height, degree)
    terms = _legendre_terms(degree)
    out = np.empty((height, width, len(terms)))
    for k, (i, j) in enumerate(terms):
        np.multiply(py[:, None, j], px[None, :, i], out=out[..., k])
    return out


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
            phi = legendre_grid(self.width, self.height, self.degree)
            self._dense = np.einsum("...j,cbj->...cb", phi, self.coefficients)
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
        return {
            "basis": "legendre2d",
            "degree": self.degree,
            "width": self.width,
            "height": self.height,
            "coefficients": self.coefficients.tolist(),
        }

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
    step=None,
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
      images, where a leak of a few per cent is a few DN with sub-DN noise,
      and least squares -- or a median of ratios -- are biased by the
      rounding by a sizeable share of the leak): a reading v is
      ``round(mu + noise)``, mu = M I_b, noise Gaussian of variance
      ``s_r^2 + g mu`` (read and shot noise, both fitted), so
      ``P(v) = Phi((v + q/2 - mu) / s) - Phi((v - q/2 - mu) / s)``
      (the lower bound open at 0, where readings below black clip), mixed
      with 0.1 % of outliers. At most ``max_pixels`` pixels (a regular
      subsample) enter this fit.
    - Zero where every reading of the channel is at the black level (a
      camera whose filters pass no measurable leak): that likelihood has no
      maximum (it grows as the leak goes negative).

    ``step``, if given, is called after each light colour's fit (progress).

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
    basis = legendre_grid(W, H, degree).reshape(H * W, -1)  # legendre_basis at every pixel
    nb = basis.shape[1]
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
        phi = basis[lit]
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
            if quantum is not None and not np.any(ic > 0.5 * quantum):
                # Every reading at the black level: the leak is below what the
                # sensor shows (no cross-talk; the likelihood of all-floor
                # readings grows without bound as the leak goes negative).
                a = np.zeros(nb)
                quantised[c, b] = True
            elif quantum is not None and np.sqrt(np.mean(res**2)) < 1.5 * quantum:
                stride = max(1, int(np.ceil(len(ic) / max_pixels)))
                sl = slice(None, None, stride)
                a, s_r = _fit_quantised(ic[sl], ib[sl], phi[sl], a, float(quantum))
                quantised[c, b], noise[c, b] = True, s_r / quantum
            coef[c, b] = a
            rms[c, b] = float(np.sqrt(np.mean((ic / ib - phi @ a) ** 2)))
        if step is not None:
            step()
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
