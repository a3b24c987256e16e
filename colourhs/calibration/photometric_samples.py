"""The eq. (6) samples of the photometric calibration, paper section III-C.

Step 1 of :mod:`colourhs.calibration.photometric` (whose docstring describes every step):
for a reciprocal pair (a, b) and a point x of the white board on plane Pi_j,
``kappa = p_ba mu_a(v_a) / (p_ab mu_b(v_b))`` is measured from the two
reciprocal intensities. This module holds

- :func:`kappa`: eq. (6) itself;
- :class:`PoseView`: one board pose with its (unmixed) images;
- :class:`KappaSamples` and :func:`kappa_samples`: the log kappa of a pair
  at the usable board points seen by a regular pixel grid of one camera, on
  every pose (markers, board edges -- :func:`pixel_footprint_m` --,
  saturation, grazing and dark readings left out).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from colourhs.capture import Board, Camera, Rig
from colourhs.common.geometry import backproject, project, ray_plane_intersection
from colourhs.common.sampling import sample_bilinear


def kappa(
    x: np.ndarray,
    n: np.ndarray,
    c_a: np.ndarray,
    c_b: np.ndarray,
    i_a: np.ndarray,
    i_b: np.ndarray,
) -> np.ndarray:
    """kappa(v_a, v_b | Pi) of equation (6).

    ``kappa = (n . v_b) |c_a - x|^2 i_b / ((n . v_a) |c_b - x|^2 i_a)``,
    which equals ``p_ba mu_a(v_a) / (p_ab mu_b(v_b))``.

    Parameters
    ----------
    x : (..., 3) board points, metres.
    n : (3,) or (..., 3) unit plane normal.
    c_a, c_b : (3,) Helmholtz camera centres (collocated light), metres.
    i_a : (...,) intensity of camera a lit by b's light.
    i_b : (...,) intensity of camera b lit by a's light.

    Returns
    -------
    (...,) dimensionless ratio.
    """
    da = np.asarray(c_a, float) - x
    db = np.asarray(c_b, float) - x
    ra2 = np.sum(da**2, axis=-1)
    rb2 = np.sum(db**2, axis=-1)
    cos_a = np.sum(da * n, axis=-1) / np.sqrt(ra2)
    cos_b = np.sum(db * n, axis=-1) / np.sqrt(rb2)
    return cos_b * ra2 * i_b / (cos_a * rb2 * i_a)


@dataclass(frozen=True)
class PoseView:
    """One board pose as the calibration needs it: plane, board pose, images."""

    name: str
    R: np.ndarray  # board to world rotation
    t: np.ndarray  # board to world translation, metres
    images: dict  # camera name -> (H, W, 3) unmixed linear image
    saturated: dict  # camera name -> (H, W) bool

    @property
    def normal(self) -> np.ndarray:
        """Unit normal of the white face (towards the cameras), world frame."""
        return self.R @ np.array([0.0, 0.0, -1.0])


@dataclass(frozen=True)
class KappaSamples:
    """eq. (6) samples of a reciprocal pair (a, b): ``log kappa = log mu_a(uv_a) - log mu_b(uv_b)``

    (up to the pair's constant log(p_ba / p_ab)), one per usable board point.
    """

    uv_a: np.ndarray  # (N, 2) pixel of camera a
    uv_b: np.ndarray  # (N, 2) pixel of camera b
    log_kappa: np.ndarray  # (N,)
    pose: np.ndarray  # (N,) index of the board pose

    def transferred(self) -> np.ndarray:
        """(N,) bool: samples whose pixel ``uv_b`` is seen on another pose too (an eq. 7 row)."""
        _, g = np.unique(self.uv_b, axis=0, return_inverse=True)
        return np.bincount(g.ravel())[g.ravel()] > 1

    def subset(self, keep: np.ndarray) -> KappaSamples:
        """The samples where ``keep`` (N,) bool is true."""
        return KappaSamples(*(getattr(self, f)[keep] for f in KappaSamples.__annotations__))

    def swapped(self) -> KappaSamples:
        """The same samples as seen from b: ``log kappa_ba = -log kappa_ab``."""
        return KappaSamples(self.uv_b, self.uv_a, -self.log_kappa, self.pose)

    @staticmethod
    def concatenate(parts: list[KappaSamples]) -> KappaSamples:
        return KappaSamples(
            *(np.concatenate([getattr(p, f) for p in parts]) for f in KappaSamples.__annotations__)
        )


def pixel_footprint_m(x: np.ndarray, n: np.ndarray, cam: Camera) -> np.ndarray:
    """Size (metres) of one pixel of ``cam`` on the plane with normal ``n`` at points ``x``.

    Distance over focal length, stretched by the slant (the long axis of the
    pixel's footprint on the plane).
    """
    d = x - cam.centre
    r = np.linalg.norm(d, axis=-1)
    cos = np.abs(d @ n) / r
    f = 0.5 * (cam.K[0, 0] + cam.K[1, 1])
    return r / (f * np.maximum(cos, 1e-6))


def box_means(view: PoseView, camera: str, channel: int, box: int) -> tuple[np.ndarray, np.ndarray]:
    """One channel of a pose image averaged over ``box`` x ``box`` pixels, and where the box
    holds a saturated pixel.

    Beyond the paper: a sample of eq. (6) reads the mean of the box around its
    pixel instead of the pixel alone, so that samples ``box`` pixels apart use
    every pixel's reading (the noise variance of a sample falls by box^2)
    without more rows in the least squares. The board's intensity is smooth
    away from markers and edges (which the margin keeps out), so the box mean
    equals the centre value to second order in the box size.
    """
    img = np.ascontiguousarray(view.images[camera][..., channel], dtype=np.float32)
    sat = view.saturated[camera].astype(np.float32)
    if box <= 1:
        return img, sat > 0
    size = (box, box)
    mean = cv2.blur(img, size, borderType=cv2.BORDER_REFLECT)
    return mean, cv2.blur(sat, size, borderType=cv2.BORDER_REFLECT) > 0


def _log_kappa_at(view: PoseView, board: Board, a: Camera, b: Camera, ch_a, ch_b, uv_b, opts):
    """log kappa (eq. 6) at the board points seen by pixels ``uv_b`` of b; NaN if unusable."""
    box = int(opts.get("box_px") or 1)
    origin, d = backproject(uv_b, b.K, b.dist, b.R, b.t)
    n = view.normal
    x, s = ray_plane_intersection(origin, d, view.t, n)
    xy = ((x - view.t) @ view.R)[:, :2]
    if opts.get("margin_m") is not None:
        margin = float(opts["margin_m"])
    else:
        with np.errstate(invalid="ignore"):
            foot = np.maximum(pixel_footprint_m(x, n, a), pixel_footprint_m(x, n, b))
        # the box's half-width on top: no box reaches a marker or the board's edge
        margin = (opts["margin_px"] + box // 2) * np.nan_to_num(foot, nan=np.inf)
    with np.errstate(invalid="ignore"):
        ok = (s > 0) & board.white(xy, margin)
    uv_a = project(x, a.K, a.dist, a.R, a.t)
    img_a, sat_a = box_means(view, a.name, ch_a, box)
    img_b, sat_b = box_means(view, b.name, ch_b, box)
    i_a = sample_bilinear(img_a, uv_a)
    i_b = sample_bilinear(img_b, uv_b)
    sat = sample_bilinear(sat_a.astype(float), uv_a) > 0
    sat |= sample_bilinear(sat_b.astype(float), uv_b) > 0
    for c in (a, b):
        v = c.light_centre - x
        with np.errstate(invalid="ignore"):
            ok &= (v @ n) / np.linalg.norm(v, axis=1) > opts["min_cos"]
    with np.errstate(invalid="ignore"):
        ok &= ~sat & (i_a > opts["min_signal"]) & (i_b > opts["min_signal"])
    lk = np.full(len(uv_b), np.nan)
    lk[ok] = np.log(kappa(x[ok], n, a.light_centre, b.light_centre, i_a[ok], i_b[ok]))
    return lk, uv_a


def kappa_samples(views: list[PoseView], rig: Rig, a: str, b: str, opts: dict) -> KappaSamples:
    """eq. (6) samples of the pair (a, b) at pixels of b on a grid of step ``opts["step_px"]``.

    ``opts`` needs ``step_px``, ``min_cos``, ``min_signal`` and ``margin_px``
    (or ``margin_m``), and takes ``box_px`` (each reading the mean of a box
    of that many pixels square, :func:`box_means`; default 1, the pixel), see
    :data:`colourhs.calibration.photometric.DEFAULTS`. Camera a's channel is the one of
    b's light and vice versa.
    """
    A, B = rig.camera(a), rig.camera(b)
    ch_a, ch_b = B.light_channel, A.light_channel
    W, H = rig.image.width, rig.image.height
    step = opts["step_px"]
    u, v = np.meshgrid(np.arange(0, W, step, dtype=float), np.arange(0, H, step, dtype=float))
    uv_b = np.stack([u.ravel(), v.ravel()], axis=1)
    parts = []
    for j, view in enumerate(views):
        lk, uv_a = _log_kappa_at(view, rig.board, A, B, ch_a, ch_b, uv_b, opts)
        ok = np.isfinite(lk)
        parts.append(KappaSamples(uv_a[ok], uv_b[ok], lk[ok], np.full(ok.sum(), j)))
    return KappaSamples.concatenate(parts)


def crosstalk_ratio_sigma(
    samples: KappaSamples,
    views: list[PoseView],
    a: Camera,
    b: Camera,
    mixing_sd: dict[str, np.ndarray],
    mixing_cov: tuple[list, np.ndarray] | None = None,
) -> float:
    """1-sigma of a pair's log ratio mu_a / mu_b from the unmixing's error (beyond the paper).

    The board images are unmixed as J = M^-1 I (:mod:`colourhs.calibration.crosstalk`); an
    error dM of camera k's mixing leaves ``d log J_c = -sum_m dM[c, m] J_m / J_c``
    in its channel c (to first order, M near the identity). Every sample of
    eq. (6) reads camera a's channel c_b of b's light and camera b's channel
    c_a of a's light, so log kappa moves by ``g . dM`` with ``g = +mean(J_m /
    J_c_b)`` on a's entries (c_b, m) and ``-mean(J_m / J_c_a)`` on b's (c_a,
    m), means over the pair's samples, and the pair's ratio (fitted to the
    samples' mean, its constant c_ab included) with it. The same dM on every
    pose: the jackknife over poses cannot see it. ``sigma^2 = g^T C g`` with
    ``C`` the mixing's covariance ``mixing_cov`` (the cross-talk calibration's
    ``led_mixing_cov``: the LED-factor fit correlates the cameras' errors, and
    a mixing common to them, where the fit is weakest, largely cancels
    between a pair's two sides), else the standard errors ``mixing_sd`` taken
    as independent (an overstatement where the errors correlate).

    Parameters
    ----------
    samples : the pair's eq. (6) samples (``uv_a`` in camera a, ``uv_b`` in b).
    views : the board poses the samples index, with unmixed images.
    a, b : the pair's cameras.
    mixing_sd : camera name -> (3, 3) standard errors of M; a camera absent
        contributes nothing.
    mixing_cov : (order, matrix): the off-diagonals' (camera, channel, light)
        order and their covariance (:func:`colourhs.calibration.crosstalk.load_mixing_cov`).

    Returns
    -------
    float, log units; 0 when neither camera has standard errors.
    """
    grad = {}
    for cam, partner, uv, sign in ((a, b, samples.uv_a, 1.0), (b, a, samples.uv_b, -1.0)):
        if (mixing_cov is None and cam.name not in mixing_sd) or len(uv) == 0:
            continue
        c = partner.light_channel
        ratios = np.zeros((len(uv), 3))
        for j, view in enumerate(views):
            on = samples.pose == j
            if not on.any():
                continue
            img = view.images[cam.name]
            J = np.stack([sample_bilinear(img[..., k], uv[on]) for k in range(3)], axis=1)
            ratios[on] = J / J[:, c : c + 1]
        mean = ratios.mean(axis=0)
        for m in range(3):
            if m != c:
                grad[(cam.name, c, m)] = sign * mean[m]
    if mixing_cov is not None:
        order, C = mixing_cov
        g = np.array([grad.get(tuple(o), 0.0) for o in order])
        return float(np.sqrt(max(g @ C @ g, 0.0)))
    var = sum((mixing_sd[k][c, m] * v) ** 2 for (k, c, m), v in grad.items())
    return float(np.sqrt(var))
