"""The two sides of every reciprocal pair, sampled at 3D points (eq. 5 terms).

A reciprocal pair k of cameras (a, b) gives the eq. (5) row
``w_k = s_a v_a - s_b v_b`` at a point X, with ``s = J / |L - X|^2``, ``J =
mu i / p`` (the Helmholtz camera's calibrated intensity, eqs. 2 and 4) and
``v`` the unit vector from X to the side's light L. :func:`helmholtz_sides`
prepares, per side, J and its noise variance (:mod:`colourhs.calibration.noise`) as
images; :func:`sample_sides` samples them (compiled, the OpenCV camera
model) with their derivatives along a ray; :func:`whitened_cost` is the
per-point ML cost of eq. (5) in noise units (used by ML HS and by the
Bayesian refinement, :mod:`colourhs.reconstruct.bayes.surface`).

Beyond the paper: the noise variance of every sample (the squared
interpolation weights of the pixels' variances: a sample between pixels
averages their noise); cubic-convolution sampling as an option
(:func:`helmholtz_sides`); and, as in the data term
(:mod:`colourhs.reconstruct.dataterm`), a side with no chromaticity p over a
sample's whole footprint takes the p of the reference camera's pixel on the
sample's ray.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numba as nb
import numpy as np
from scipy.ndimage import gaussian_filter

from colourhs.capture import MIN_SIGNAL
from colourhs.common.geometry import model_coefficients
from colourhs.common.sampling import footprint_jit, weights_jit
from colourhs.reconstruct.constraint import hs_row, row_variance
from colourhs.reconstruct.dataterm import to_pixel

BLUR_PX = 1.0  # Gaussian blur of the images before sampling, pixels (see side_maps)
FOOTPRINT_PX = 0.0  # footprint error at the edges of unusable regions, pixels (see side_maps)
"""Why ``FOOTPRINT_PX`` is 0 by default: weighing down the rows at the edges of
unusable regions (``side_maps``) removes the bias that a board's dark markers
give its depth at low signal, but the same edges are the silhouettes of
curved objects and sheets, whose depth they fix, so those lose more than the
boards gain. The depth's error bar
(:mod:`colourhs.reconstruct.bayes.uncertainty`) covers the markers' offset
instead. A rig whose captures are all boards may set it (0.15 pixel:
two views 12-30 degrees apart see a slanted surface foreshortened 10-20 %
differently, so their 1-pixel blur kernels differ by about that much)."""
BLUR_SUPPORT = 0.9  # least share of the blur kernel on usable pixels (see side_maps)
RIM_SUPPORT = 0.999  # the same, for samples clear of every edge (see side_maps)
"""Why ``BLUR_SUPPORT`` and ``RIM_SUPPORT`` hold on any rig: they are shares of
the blur's kernel, in the image's own pixels whatever its size or the rig. A
sample whose kernel reaches unusable pixels (a silhouette, a dark marker, a
saturated patch) mixes the edge: above 0.9 it is still mostly the surface, and
only above 0.999 (about 3 blur sigmas from the edge) is the edge's share below
a thousandth of the sample."""
ORDER = 1  # interpolation of the sides: 1 bilinear, 3 cubic convolution (see helmholtz_sides)


@dataclass
class HelmholtzSides:
    """The two sides of every reciprocal pair, ready to sample (eq. 5).

    For side j (pair j // 2, side j % 2): ``cameras[j]`` and its light
    ``light[j]``, and per pixel a stack ``maps[j]`` (H, W, 2) of J = mu i / p
    (the Helmholtz camera's calibrated intensity) and its noise variance;
    NaN where unusable. With a ``reference`` camera, the stack is (H, W, 4):
    then also mu i and its variance where only p is unknown (NaN elsewhere),
    divided when sampled by ``p_ref[..., bands[j]]`` (H, W, 3: the reference
    camera's p, NaN where unknown) at the sample's pixel in the reference.
    """

    cameras: list
    light: np.ndarray
    maps: list
    blurred: bool = False  # neighbouring pixels' noise correlated (see side_maps)
    order: int = 1  # 1 bilinear, 3 cubic convolution (see helmholtz_sides)
    blur_px: float = 0.0  # the Gaussian blur's sigma, pixels (the noise's correlation)
    reference: object = None  # the camera the samples' rays leave from (a Camera)
    p_ref: np.ndarray | None = None  # (H, W, 3) its chromaticity p
    bands: np.ndarray | None = None  # (2P,) each side's channel

    def __post_init__(self):
        self.stack = np.ascontiguousarray(np.stack(self.maps), dtype=np.float64)
        self.K = np.stack([np.asarray(c.K, float) for c in self.cameras])
        self.dist = np.stack([model_coefficients(c.dist) for c in self.cameras])
        self.R = np.stack([np.asarray(c.R, float) for c in self.cameras])
        self.t = np.stack([np.asarray(c.t, float) for c in self.cameras])
        self.light = np.ascontiguousarray(self.light, dtype=np.float64)
        self.noise_corr = noise_correlation(self.blur_px) if self.blurred else np.zeros(4)
        ref = self.reference if self.reference is not None else self.cameras[0]
        self.ref_proj = (
            np.asarray(ref.K, float),
            model_coefficients(ref.dist),
            np.asarray(ref.R, float),
            np.asarray(ref.t, float),
        )
        if self.p_ref is None:
            self.p_ref = np.full((1, 1, 3), np.nan)
        self.p_ref = np.ascontiguousarray(self.p_ref, dtype=np.float64)
        if self.bands is None:
            self.bands = np.zeros(len(self.cameras), np.int64)
        self.bands = np.asarray(self.bands, np.int64)

    @property
    def pairs(self) -> int:
        return len(self.cameras) // 2


def with_side_scaled(sides: HelmholtzSides, j: int, factor: float) -> HelmholtzSides:
    """The same sides with side ``j``'s J (and its noise) scaled by ``factor``: the
    log ratio mu_a / mu_b of pair ``j // 2`` moved by ``+-log(factor)`` (side a: +)."""
    maps = list(sides.maps)
    maps[j] = maps[j] * np.tile([factor, factor * factor], maps[j].shape[-1] // 2)
    return replace(sides, maps=maps)


def with_pairs(sides: HelmholtzSides, keep) -> HelmholtzSides:
    """The same sides with only the reciprocal pairs ``keep`` (indices), in that order."""
    j = [i for p in keep for i in (2 * p, 2 * p + 1)]
    return replace(
        sides,
        cameras=[sides.cameras[i] for i in j],
        light=sides.light[j],
        maps=[sides.maps[i] for i in j],
        bands=sides.bands[j],
    )


def noise_correlation(blur_px: float, taps: int = 4) -> np.ndarray:
    """Correlation (taps,) of Gaussian-blurred white noise between pixels 0..taps-1 apart.

    Blurring independent pixels with a Gaussian of sigma ``blur_px`` makes
    their noise a stationary field whose autocorrelation is a Gaussian of
    sigma ``blur_px * sqrt(2)``: ``exp(-k^2 / (4 blur_px^2))`` at k pixels, in
    rows and columns alike (separable). :func:`sample_sides` uses it for the
    exact variance of an interpolated sample (beyond the paper): a sample
    between pixels averages partly independent noise, so its variance is
    lower than a pixel's by a factor that depends on the sub-pixel offset.
    """
    k = np.arange(float(taps))
    return np.exp(-(k**2) / (4.0 * float(blur_px) ** 2))


def _blur(values: np.ndarray, sigma: float, min_support: float = BLUR_SUPPORT) -> np.ndarray:
    """NaN-aware Gaussian blur: normalised convolution; NaN where support < ``min_support``."""
    ok = np.isfinite(values)
    support = gaussian_filter(ok.astype(float), sigma)
    out = gaussian_filter(np.where(ok, values, 0.0), sigma) / np.maximum(support, 1e-12)
    return np.where(support >= min_support, out, np.nan)


def side_maps(
    J: np.ndarray,
    var: np.ndarray,
    blur_px: float = BLUR_PX,
    footprint_px: float = FOOTPRINT_PX,
    min_support: float = BLUR_SUPPORT,
) -> np.ndarray:
    """Stack (H, W, 2) of one Helmholtz camera: J and its noise variance.

    Parameters
    ----------
    J : (H, W) calibrated intensity mu i / p, NaN where unusable.
    var : (H, W) its noise variance (same units squared).
    blur_px : Gaussian blur (pixels) of J before sampling; the noise
        variance is scaled by the kernel's sum of squared weights,
        1 / (4 pi sigma^2). Blurred neighbours are correlated, so a sample
        between them has the variance of :func:`sample_sides` (with no blur,
        the squared bilinear weights of the pixels' variances).
    footprint_px : the model error of a sample at the edge of an unusable
        region (beyond the paper): within reach of the blur and the bilinear
        support of an unusable pixel (a dark marker, a shadow, a silhouette,
        a saturated patch; counted as 0) ``(footprint_px |grad J|)^2`` is
        added to the variance (:data:`FOOTPRINT_PX`). The two sides of a
        pair sample such an edge through footprints that do not match, an
        error that does not fall with the sensor noise; without this term
        the robust weights drop such rows only while the noise is small
        against them, so a surface's depth moves with the noise level.
    min_support : least share of the blur's kernel on usable pixels; below it the
        sample is unusable (:data:`BLUR_SUPPORT`; :data:`RIM_SUPPORT` keeps only
        samples clear of every edge,
        :func:`colourhs.reconstruct.bayes.uncertainty.rim_valley_pull`).
    """
    unusable = ~np.isfinite(J)
    if blur_px > 0:
        J = _blur(J, blur_px, min_support)
        var = _blur(var, blur_px, min_support) * min(1.0 / (4.0 * np.pi * blur_px**2), 1.0)
    if footprint_px > 0 and unusable.any():
        from scipy.ndimage import binary_dilation

        # Within reach of the blur (2 sigma) and the bilinear support of an unusable
        # pixel: the edge of a dark, saturated or outside region.
        reach = int(np.ceil(2.0 * blur_px)) + 1
        rim = binary_dilation(unusable, iterations=reach) & ~unusable
        gy, gx = np.gradient(np.where(np.isfinite(J), J, 0.0))
        var = var + np.where(rim, footprint_px**2 * (gx * gx + gy * gy), 0.0)
    return np.stack([J, var], axis=-1)


def helmholtz_sides(
    frame,
    variance: np.ndarray,
    pairs,
    min_signal: float = MIN_SIGNAL,
    blur_px: float | None = None,
    order: int | None = None,
    min_support: float = BLUR_SUPPORT,
    reference: int | None = None,
) -> HelmholtzSides:
    """The sides of every reciprocal pair of a frame (see :class:`HelmholtzSides`).

    ``frame`` is a :class:`colourhs.reconstruct.frame.Frame`; ``variance``
    (C, 3, H, W) the noise variance of its images; ``pairs`` from
    :func:`colourhs.reconstruct.dataterm.pair_arrays`. J is unusable where
    the image is saturated, at or below ``min_signal``, outside the
    silhouette, or mu or p is not positive, as in the data term. ``blur_px``
    (default :data:`BLUR_PX`) and ``min_support``: see :func:`side_maps`.
    ``reference`` (the index of the camera the samples' rays leave from): where
    a side has no p, its sample takes that camera's p at the ray's pixel, as
    in the data term (beyond the paper; the p of the surface point both see).

    ``order`` (default :data:`ORDER`): 1 samples bilinearly, 3 by cubic
    convolution (Keys 1981, a = -1/2; beyond the paper). Bilinear
    interpolation smooths by t (1 - t) / 2 times the image's second derivative
    at a sub-pixel offset t, a bias that differs between the two sides of a
    pair wherever the image curves (they see the surface at other scales and
    offsets); cubic convolution reproduces quadratics, so it has none to that
    order. Bilinear is the default: under noise the worst surfaces come
    out worse with cubic convolution.
    """
    blur_px = BLUR_PX if blur_px is None else float(blur_px)
    order = ORDER if order is None else int(order)
    if order not in (1, 3):
        raise ValueError(f"order must be 1 (bilinear) or 3 (cubic), not {order}")
    pair_cams, pair_ch = pairs
    fallback = frame.chroma is not None and reference is not None
    cams, light, maps = [], [], []
    for p, ((a, b), (ca, cb)) in enumerate(zip(pair_cams, pair_ch, strict=True)):
        for k, (c, ch) in enumerate(((a, ca), (b, cb))):
            i = frame.images[c, ch].astype(float)
            bad = frame.saturated[c] | ~(i > min_signal)
            if frame.silhouettes is not None:
                bad |= ~frame.silhouettes[c].astype(bool)
            scale = np.ones_like(i)
            if frame.mu is not None:
                scale = scale * frame.mu[p, k]
            raw = scale  # mu alone: where only p is unknown (see HelmholtzSides)
            if frame.chroma is not None:
                with np.errstate(invalid="ignore", divide="ignore"):
                    scale = scale / frame.chroma[c, ch]
            bad |= ~np.isfinite(raw) | ~(raw > 0)
            no_p = ~bad & (~np.isfinite(scale) | ~(scale > 0))
            bad |= no_p
            J = np.where(bad, np.nan, i * scale)
            V = np.where(bad, np.nan, variance[c, ch] * scale**2)
            stack = side_maps(J, V, blur_px, min_support=min_support)
            if fallback:
                Jr = np.where(no_p, i * raw, np.nan)
                Vr = np.where(no_p, variance[c, ch] * raw**2, np.nan)
                stack = np.concatenate(
                    [stack, side_maps(Jr, Vr, blur_px, min_support=min_support)], -1
                )
            cam = frame.rig.cameras[c]
            cams.append(cam)
            light.append(cam.light_centre)
            maps.append(stack)
    extra = {}
    if fallback:
        extra = {
            "reference": frame.rig.cameras[reference],
            "p_ref": np.moveaxis(np.asarray(frame.chroma[reference], float), 0, -1),
            "bands": np.asarray(pair_ch, np.int64).ravel(),
        }
    return HelmholtzSides(cams, np.asarray(light), maps, blur_px > 0, order, blur_px, **extra)


@nb.njit(cache=True, inline="always")
def _keys(t):
    """Cubic-convolution weights (Keys, a = -1/2) of taps -1..2 at offset t in [0, 1),
    and their derivatives in t."""
    t2 = t * t
    t3 = t2 * t
    w = (
        (-t3 + 2 * t2 - t) / 2,
        (3 * t3 - 5 * t2 + 2) / 2,
        (-3 * t3 + 4 * t2 + t) / 2,
        (t3 - t2) / 2,
    )
    d = (
        (-3 * t2 + 4 * t - 1) / 2,
        (9 * t2 - 10 * t) / 2,
        (-9 * t2 + 8 * t + 1) / 2,
        (3 * t2 - 2 * t) / 2,
    )
    return w, d


@nb.njit(cache=True, inline="always")
def _correlated_gain(w, corr):
    """Variance of ``sum_a w_a n_a`` over unit-variance noise with correlation
    ``corr[|a - b|]`` between taps a and b (one axis of a separable sample)."""
    n = len(w)
    g = 0.0
    for a in range(n):
        for b in range(n):
            g += w[a] * w[b] * corr[abs(a - b)]
    return g


@nb.njit(cache=True)
def _cubic(maps, j, u, vv, blurred, corr, layer=0):
    """Cubic-convolution sample of side j at pixel (u, vv): J, dJ/du, dJ/dv and the
    noise variance (squared weights; where ``blurred``, the weights times the
    correlated noise's gain, :func:`noise_correlation`); NaN without the full
    4 x 4 support inside the image. ``layer``: J's index in the stack (its
    variance the next)."""
    Hh, Ww = maps.shape[1], maps.shape[2]
    if not (u >= 1.0 and vv >= 1.0 and u < Ww - 2 and vv < Hh - 2):
        return np.nan, np.nan, np.nan, np.nan
    u0 = int(np.floor(u))
    v0 = int(np.floor(vv))
    wu, du = _keys(u - u0)
    wv, dv = _keys(vv - v0)
    J = 0.0
    gu = 0.0
    gv = 0.0
    noise = 0.0
    for a in range(4):
        for b in range(4):
            val = maps[j, v0 - 1 + a, u0 - 1 + b, layer]
            J += wv[a] * wu[b] * val
            gu += wv[a] * du[b] * val
            gv += dv[a] * wu[b] * val
            w = wv[a] * wu[b]
            if not blurred:
                w = w * w
            noise += w * maps[j, v0 - 1 + a, u0 - 1 + b, layer + 1]
    if blurred:
        noise *= _correlated_gain(wu, corr) * _correlated_gain(wv, corr)
    return J, gu, gv, noise


@nb.njit(cache=True, inline="always")
def _bilinear(maps, j, u0, v0, a, b, blurred, corr, layer):
    """Bilinear sample of side j's ``layer`` (J; its variance the next) in the
    footprint at texel (u0, v0) with offsets (a, b): J, dJ/du, dJ/dv and the
    noise variance (see :func:`_sample_kernel`)."""
    w00, w01, w10, w11 = weights_jit(a, b)
    j00, j01 = maps[j, v0, u0, layer], maps[j, v0, u0 + 1, layer]
    j10, j11 = maps[j, v0 + 1, u0, layer], maps[j, v0 + 1, u0 + 1, layer]
    J = w00 * j00 + w01 * j01 + w10 * j10 + w11 * j11
    # the bilinear interpolant's own derivative: the Jacobian of what is sampled
    gu = (1.0 - b) * (j01 - j00) + b * (j11 - j10)
    gv = (1.0 - a) * (j10 - j00) + a * (j11 - j01)
    # The noise of a weighted sum of independent pixels: squared weights
    # (a sample between four pixels averages their noise). Blurred
    # pixels are correlated (corr[1] between neighbours): their
    # variance interpolates, times the gain of the bilinear weights
    # on that correlated noise, per axis t^2 + (1 - t)^2 + 2 t (1 - t)
    # corr[1] (1 at a pixel, (1 + corr[1]) / 2 half-way).
    gain = 1.0
    if blurred:
        gain = (1.0 - 2.0 * a * (1.0 - a) * (1.0 - corr[1])) * (
            1.0 - 2.0 * b * (1.0 - b) * (1.0 - corr[1])
        )
    else:
        w00, w01, w10, w11 = w00 * w00, w01 * w01, w10 * w10, w11 * w11
    noise = gain * (
        w00 * maps[j, v0, u0, layer + 1]
        + w01 * maps[j, v0, u0 + 1, layer + 1]
        + w10 * maps[j, v0 + 1, u0, layer + 1]
        + w11 * maps[j, v0 + 1, u0 + 1, layer + 1]
    )
    return J, gu, gv, noise


@nb.njit(cache=True, inline="always")
def _reference_p(x0, x1, x2, K, dist, R, t, p_ref):
    """The reference camera's p (three floats) at the pixel of point X, bilinear
    (NaN if any texel of the footprint has none; every point of a ray through
    the reference's centre has the same pixel). Scalars: no allocation per point."""
    cx = R[0, 0] * x0 + R[0, 1] * x1 + R[0, 2] * x2 + t[0]
    cy = R[1, 0] * x0 + R[1, 1] * x1 + R[1, 2] * x2 + t[1]
    cz = R[2, 0] * x0 + R[2, 1] * x1 + R[2, 2] * x2 + t[2]
    if cz <= 0.0:
        return np.nan, np.nan, np.nan
    u, vv = to_pixel(cx / cz, cy / cz, K, dist)
    u = np.round(u) if abs(u - np.round(u)) < 1e-6 else u
    vv = np.round(vv) if abs(vv - np.round(vv)) < 1e-6 else vv
    inside, fu0, fv0, a, b = footprint_jit(u, vv, p_ref.shape[1], p_ref.shape[0])
    if not inside:
        return np.nan, np.nan, np.nan
    u0, v0 = int(fu0), int(fv0)
    w00, w01, w10, w11 = weights_jit(a, b)
    return (
        _known_bilinear(p_ref, u0, v0, 0, w00, w01, w10, w11),
        _known_bilinear(p_ref, u0, v0, 1, w00, w01, w10, w11),
        _known_bilinear(p_ref, u0, v0, 2, w00, w01, w10, w11),
    )


@nb.njit(cache=True, inline="always")
def _known_bilinear(p_ref, u0, v0, c, w00, w01, w10, w11):
    """Band c of ``p_ref`` over the footprint; NaN if a texel under a positive
    weight has no p."""
    val = 0.0
    for w, pv in (
        (w00, p_ref[v0, u0, c]),
        (w01, p_ref[v0, u0 + 1, c]),
        (w10, p_ref[v0 + 1, u0, c]),
        (w11, p_ref[v0 + 1, u0 + 1, c]),
    ):
        if w > 0.0:
            val = val + w * pv if pv > 0.0 else np.nan
    return val


@nb.njit(parallel=True, cache=True, fastmath=False)
def _sample_kernel(
    X,
    R,
    Ks,
    dists,
    Rs,
    ts,
    light,
    maps,
    blurred,
    corr,
    order,
    derivatives,
    ref_proj,
    p_ref,
    bands,
    s,
    var,
    v,
    ds,
    dv,
):
    """Project every point into every side's camera (OpenCV model, with the
    derivative of the pixel along the ray where ``derivatives``), sample the
    side's stack bilinearly (``order`` 1) or by cubic convolution (3), and form
    the eq. (5) terms (see :func:`sample_sides`; ``ds`` and ``dv`` are not
    written without ``derivatives``). A stack of 4 layers has mu i where the
    side has no p: divided by the reference pixel's p (``p_ref`` sampled where
    the reference camera, ``ref_proj`` = K, distortion coefficients, R, t,
    sees the point) in the side's band ``bands[j]``; the reference's p is
    constant along the ray, so the derivatives scale by it too."""
    N = X.shape[0]
    nside = Ks.shape[0]
    Hh, Ww = maps.shape[1], maps.shape[2]
    fallback = maps.shape[3] == 4
    rK, rdist, rR, rt = ref_proj
    for i in nb.prange(N):
        x0, x1, x2 = X[i, 0], X[i, 1], X[i, 2]
        r0, r1, r2 = R[i, 0], R[i, 1], R[i, 2]
        # the reference pixel's p, where a side has none
        q0, q1, q2 = np.nan, np.nan, np.nan
        if fallback:
            q0, q1, q2 = _reference_p(x0, x1, x2, rK, rdist, rR, rt, p_ref)
        for j in range(nside):
            p = j // 2
            k = j % 2
            # camera coordinates of X and of dX/dz = R
            cx = Rs[j, 0, 0] * x0 + Rs[j, 0, 1] * x1 + Rs[j, 0, 2] * x2 + ts[j, 0]
            cy = Rs[j, 1, 0] * x0 + Rs[j, 1, 1] * x1 + Rs[j, 1, 2] * x2 + ts[j, 1]
            cz = Rs[j, 2, 0] * x0 + Rs[j, 2, 1] * x1 + Rs[j, 2, 2] * x2 + ts[j, 2]
            dcx = Rs[j, 0, 0] * r0 + Rs[j, 0, 1] * r1 + Rs[j, 0, 2] * r2
            dcy = Rs[j, 1, 0] * r0 + Rs[j, 1, 1] * r1 + Rs[j, 1, 2] * r2
            dcz = Rs[j, 2, 0] * r0 + Rs[j, 2, 1] * r1 + Rs[j, 2, 2] * r2
            nan = np.nan
            u = nan
            vv = nan
            du = 0.0
            dvv = 0.0
            if cz > 0.0:
                u, vv = to_pixel(cx / cz, cy / cz, Ks[j], dists[j])
            if cz > 0.0 and derivatives:
                eps = 1e-6 * cz
                up, vp = to_pixel(
                    (cx + eps * dcx) / (cz + eps * dcz),
                    (cy + eps * dcy) / (cz + eps * dcz),
                    Ks[j],
                    dists[j],
                )
                um, vm = to_pixel(
                    (cx - eps * dcx) / (cz - eps * dcz),
                    (cy - eps * dcy) / (cz - eps * dcz),
                    Ks[j],
                    dists[j],
                )
                du = (up - um) / (2.0 * eps)
                dvv = (vp - vm) / (2.0 * eps)
            J = nan
            noise = nan
            gu = nan
            gv = nan
            inside, fu0, fv0, a, b = footprint_jit(u, vv, Ww, Hh)
            if order == 3:
                J, gu, gv, noise = _cubic(maps, j, u, vv, blurred, corr)
            elif inside:
                J, gu, gv, noise = _bilinear(maps, j, int(fu0), int(fv0), a, b, blurred, corr, 0)
            band = bands[j]
            qb = q0 if band == 0 else (q1 if band == 1 else q2)
            if fallback and not np.isfinite(J) and np.isfinite(qb):
                # No p of the side's own: mu i, by the reference pixel's p.
                if order == 3:
                    Jr, gur, gvr, nr = _cubic(maps, j, u, vv, blurred, corr, 2)
                elif inside:
                    Jr, gur, gvr, nr = _bilinear(
                        maps, j, int(fu0), int(fv0), a, b, blurred, corr, 2
                    )
                else:
                    Jr, gur, gvr, nr = nan, nan, nan, nan
                J, gu, gv, noise = Jr / qb, gur / qb, gvr / qb, nr / (qb * qb)
            Dx = light[j, 0] - x0
            Dy = light[j, 1] - x1
            Dz = light[j, 2] - x2
            d2 = Dx * Dx + Dy * Dy + Dz * Dz
            d = np.sqrt(d2)
            ux, uy, uz = Dx / d, Dy / d, Dz / d
            ur = ux * r0 + uy * r1 + uz * r2
            v[i, p, k, 0] = ux
            v[i, p, k, 1] = uy
            v[i, p, k, 2] = uz
            s[i, p, k] = J / d2
            var[i, p, k] = noise / (d2 * d2)
            if not derivatives:
                continue
            # dD/dz = -R, dd/dz = -u.R, du/dz = (-R + u (u.R)) / d
            dv[i, p, k, 0] = (-r0 + ux * ur) / d
            dv[i, p, k, 1] = (-r1 + uy * ur) / d
            dv[i, p, k, 2] = (-r2 + uz * ur) / d
            ds[i, p, k] = (gu * du + gv * dvv) / d2 + 2.0 * J * ur / (d2 * d)


def sample_sides(sides: HelmholtzSides, X: np.ndarray, R: np.ndarray, derivatives: bool = True):
    """Eq. (5) terms at points ``X`` (N, 3) and their derivative along rays ``R`` (dX/dz).

    Compiled (numba); the projection is the OpenCV model of
    :func:`colourhs.common.geometry.project` (the data term's
    :func:`colourhs.reconstruct.dataterm.to_pixel`).

    Returns
    -------
    s : (N, P, 2) ``J / |L - X|^2`` of each side (the row is s_a v_a - s_b v_b).
    var : (N, P, 2) noise variance of s.
    v : (N, P, 2, 3) unit vectors from X towards each side's light.
    ds, dv : derivatives of s and v with respect to the depth z; None without
        ``derivatives`` (the ML costs: two projections fewer per sample, and
        s, var and v the same to the bit).
    NaN where a point leaves an image or lands on an unusable sample.
    """
    N, P = len(X), sides.pairs
    s = np.empty((N, P, 2))
    var = np.empty((N, P, 2))
    v = np.empty((N, P, 2, 3))
    nd = N if derivatives else 1  # not written without derivatives
    ds = np.empty((nd, P, 2))
    dv = np.empty((nd, P, 2, 3))
    _sample_kernel(
        np.ascontiguousarray(X, float),
        np.ascontiguousarray(R, float),
        sides.K,
        sides.dist,
        sides.R,
        sides.t,
        sides.light,
        sides.stack,
        sides.blurred,
        sides.noise_corr,
        sides.order,
        bool(derivatives),
        sides.ref_proj,
        sides.p_ref,
        sides.bands,
        s,
        var,
        v,
        ds,
        dv,
    )
    return (s, var, v, ds, dv) if derivatives else (s, var, v, None, None)


@nb.njit(cache=True)
def _smallest_singular(u, vt, warm=False):
    """The smallest singular value's right singular vector of the (P, 3) ``u``,
    by one-sided Jacobi rotations of its columns (Hestenes), in place: on
    return the columns of ``u`` are orthogonal and the rows of ``vt`` the
    right singular vectors. Works on W itself, not W^T W, so the small
    singular value keeps its relative accuracy. Returns the index of the
    smallest column.

    ``warm``: ``u`` is already ``A @ vt.T`` for the matrix ``A`` whose SVD is
    wanted and an orthogonal ``vt`` close to its right singular vectors (the
    previous pass's); the rotations continue from there (fewer sweeps) instead
    of from ``vt = I``, ``u = A``."""
    P = u.shape[0]
    if not warm:
        for i in range(3):
            for j in range(3):
                vt[i, j] = 1.0 if i == j else 0.0
    for _ in range(30):
        rotated = False
        for j, k in ((0, 1), (0, 2), (1, 2)):
            alpha = beta = gamma = 0.0
            for p in range(P):
                alpha += u[p, j] * u[p, j]
                beta += u[p, k] * u[p, k]
                gamma += u[p, j] * u[p, k]
            if gamma == 0.0 or abs(gamma) <= 1e-15 * np.sqrt(alpha * beta):
                continue
            rotated = True
            zeta = (beta - alpha) / (2.0 * gamma)
            t = (1.0 if zeta >= 0 else -1.0) / (abs(zeta) + np.sqrt(1.0 + zeta * zeta))
            c = 1.0 / np.sqrt(1.0 + t * t)
            s = c * t
            for p in range(P):
                a, b = u[p, j], u[p, k]
                u[p, j], u[p, k] = c * a - s * b, s * a + c * b
            for p in range(3):
                a, b = vt[j, p], vt[k, p]
                vt[j, p], vt[k, p] = c * a - s * b, s * a + c * b
        if not rotated:
            break
    best, least = 0, np.inf
    for j in range(3):
        norm = 0.0
        for p in range(P):
            norm += u[p, j] * u[p, j]
        if norm < least:
            best, least = j, norm
    return best


@nb.njit(parallel=True, cache=True)
def _whitened_rows(s, var, v, w, ok):
    """The rows ``w = s_a v_a - s_b v_b`` (N, P, 3) of eq. (5) at each point, and
    ``ok`` (N,): every row finite and every variance positive (else its rows are
    0). One compiled pass instead of NumPy's temporaries; the same
    arithmetic, so the same bits."""
    N, P = s.shape[0], s.shape[1]
    for i in nb.prange(N):
        good = True
        for k in range(P):
            vax, vay, vaz = v[i, k, 0, 0], v[i, k, 0, 1], v[i, k, 0, 2]
            vbx, vby, vbz = v[i, k, 1, 0], v[i, k, 1, 1], v[i, k, 1, 2]
            wx, wy, wz = hs_row(s[i, k, 0], s[i, k, 1], vax, vay, vaz, vbx, vby, vbz)
            w[i, k, 0], w[i, k, 1], w[i, k, 2] = wx, wy, wz
            good &= np.isfinite(wx) and np.isfinite(wy) and np.isfinite(wz)
            good &= var[i, k, 0] > 0 and var[i, k, 1] > 0
        ok[i] = good
        if not good:
            w[i] = 0.0


@nb.njit(parallel=True, cache=True)
def _whitened_kernel(w, var, v, ok, R, passes, chi2, normal):
    """:func:`whitened_cost` per point (compiled; see there)."""
    N, P = w.shape[0], w.shape[1]
    for i in nb.prange(N):
        scale = np.ones(P)
        u = np.empty((P, 3))
        vt = np.empty((3, 3))
        nx, ny, nz, lam = 1.0, 0.0, 0.0, 0.0
        for it in range(passes + 1):
            # The reweighted rows in the previous pass's singular basis
            # (u = W' vt^T): that pass's rotations are not repeated.
            for k in range(P):
                for j in range(3):
                    if it == 0:
                        u[k, j] = w[i, k, j] / scale[k]
                    else:
                        u[k, j] = (
                            w[i, k, 0] * vt[j, 0] + w[i, k, 1] * vt[j, 1] + w[i, k, 2] * vt[j, 2]
                        ) / scale[k]
            j = _smallest_singular(u, vt, it > 0)
            nx, ny, nz = vt[j, 0], vt[j, 1], vt[j, 2]
            lam = 0.0
            for k in range(P):  # n' W' W n as a sum of squares: no cancellation
                r = (w[i, k, 0] * nx + w[i, k, 1] * ny + w[i, k, 2] * nz) / scale[k]
                lam += r * r
                if ok[i]:
                    vax, vay, vaz = v[i, k, 0, 0], v[i, k, 0, 1], v[i, k, 0, 2]
                    vbx, vby, vbz = v[i, k, 1, 0], v[i, k, 1, 1], v[i, k, 1, 2]
                    sd2 = row_variance(
                        var[i, k, 0], var[i, k, 1], vax, vay, vaz, vbx, vby, vbz, nx, ny, nz
                    )[0]
                    scale[k] = max(np.sqrt(sd2), 1e-300)
        if nx * R[i, 0] + ny * R[i, 1] + nz * R[i, 2] > 0:
            nx, ny, nz = -nx, -ny, -nz
        chi2[i] = lam if ok[i] else np.nan
        normal[i, 0], normal[i, 1], normal[i, 2] = nx, ny, nz


def whitened_cost(sides: HelmholtzSides, X: np.ndarray, R: np.ndarray, passes: int = 2):
    """Per-point ML cost of eq. (5) in noise units, and its normal.

    The smallest eigenvalue of W^T W after each row of W is divided by its
    predicted noise along the normal (Sampson weights, from the previous
    pass's normal; the first from the unweighted W): a chi-square with one
    degree of freedom at the true depth, 0 on exact data. Unlike
    sigma_3 / sigma_2, a weak row (a dark sample, a black marker) does not
    make the cost small.

    Compiled: the eigenvector is W's smallest right singular vector, by
    Jacobi rotations of W itself (:func:`_smallest_singular`; the
    eigenvalue, the sum of the squared whitened rows along it), where
    numpy's batched ``eigh`` of W^T W squared W's condition number. Each pass
    after the first starts its rotations from the previous pass's singular
    basis (the weights change the rows little, so fewer sweeps are needed;
    only near-ties between hypotheses can come out differently than from a
    cold start).

    Returns
    -------
    chi2 : (N,) NaN where a sample is unusable. normal : (N, 3) towards -R.
    """
    s, var, v, _, _ = sample_sides(sides, X, R, derivatives=False)
    w = np.empty((len(s), sides.pairs, 3))
    ok = np.empty(len(s), bool)
    _whitened_rows(s, var, v, w, ok)
    chi2 = np.empty(len(w))
    normal = np.empty((len(w), 3))
    _whitened_kernel(w, var, v, ok, np.ascontiguousarray(R, float), passes, chi2, normal)
    return chi2, normal
