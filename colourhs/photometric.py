"""Photometric calibration of the Helmholtz cameras, paper section III-C.

Each camera's channel that records another camera's light, together with the
camera's own collocated light, is a Helmholtz camera with a
radiance/sensitivity ratio map mu = rho / sigma (eq. 2); three cameras give
six. The board poses of ``photometric/`` calibrate them. What each step
implements:

1. **kappa, eq. (6).** For a reciprocal pair (a, b) and a point x of the
   white board on plane Pi_j, ``kappa = p_ba mu_a(v_a) / (p_ab mu_b(v_b))``
   is measured from the two reciprocal intensities (:func:`kappa`). Samples
   are taken on a regular pixel grid of each of the two cameras
   (:func:`kappa_samples`), on every pose.
2. **Transfer, eq. (7), and the system of eq. (8).** The paper transfers a
   point along the partner's ray v_b to another pose and divides two kappas,
   so that mu_b cancels and ``mu_a(v_a) / mu_a(v_a')`` remains; the log
   constraints on bilinear control points form the least squares of eq. (8),
   solved per map, and the partner's map is then obtained "by transfer via
   (6)". Here the same least squares is solved *jointly* for the two maps of
   a pair from the eq. (6) samples themselves: every sample is one row
   ``lambda_a(u_a) - lambda_b(u_b) + c_ab = log kappa`` (lambda = log mu on
   the control grid, c_ab = log(p_ab / p_ba), one unknown per pair). Two rows
   that share the partner's pixel u_b on two poses difference to exactly the
   eq. (7) row, so the eq. (8) constraints are all in this system; beyond
   the paper, the rows also tie mu_a to mu_b at every point instead of
   through one transfer, and each measurement enters once (eq. 7 rows of all
   pose pairs re-use each kappa n_poses - 1 times, with correlated errors).
3. **Two pairs per camera (paper: "a Helmholtz camera must be observed in at
   least two Helmholtz camera pairs").** eq. (6) cannot see a factor that
   is constant on each epipolar plane of a pair: it multiplies mu_a and
   mu_b alike and cancels in kappa (and in the HS constraint of eq. 5, where
   it scales a row of W). What fixes it is the other pair of each camera:
   the two maps of camera a are ``rho_a / sigma_{a,c1}`` and
   ``rho_a / sigma_{a,c2}``, so their log difference is the camera's colour
   shading ``log(sigma_{a,c2} / sigma_{a,c1})``. The paper (and this module
   before) took it as constant. Real lenses and sensors shade each colour
   channel differently (per-channel vignetting with its own centre: a few
   per cent, smooth), so here the coupling lets a polynomial of total degree
   ``shading_order`` (default 2) in the camera's undistorted normalised image
   coordinates be free: the penalty is on the gradient of
   ``lambda_{a,c1} - lambda_{a,c2} - P beta_a`` (P the monomials, beta_a the
   camera's shading coefficients), beyond the paper.
4. **What the data cannot tell, fixed by a prior.** Shading and the
   epipolar factors of step 3 overlap: a factor linear (or quadratic) in the
   epipolar angle looks, in each camera, like a linear (quadratic) shading.
   Three pairs bring three such factors per order against six linear and nine
   quadratic shading coefficients, so the data fix most of the shading but
   not all; a free polynomial alone would leave the maps tilted at random
   (measured: 4-13 % RMS error). A weak ridge (``shading_prior``) on beta
   takes, among the explanations the data allow, the one with the smallest
   colour shading; it is too weak to bias what the data do determine.
5. **Regulariser.** A weak curvature (second-difference) penalty on every
   map (the paper uses first differences; beyond the paper): where data end
   it extends a map linearly instead of flat, and it leaves linear terms,
   hence the gauge of step 4, to the shading prior alone.
6. **Gauge.** Each map is known up to one constant per pair (the pair's
   free scale); eq. (6) fixes the relative scale of its two maps (c_ab,
   applied to mu_b and reported as the pair's offset); the first map of each
   pair has mean log mu 0 over the control points.

Images are unmixed (see :mod:`colourhs.crosstalk`) before calibration when a
cross-talk calibration is given. :func:`mu_map_errors` (each map against the
truth, up to one scale per pair) and :func:`pair_ratio_errors` (the ratio
``mu_a / mu_b`` at points seen by both cameras, what the HS constraint uses)
measure a result against ground truth.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np
import pandas as pd
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

from colourhs.capture import COLOURS, Board, Camera, Rig, open_dataset, read_image
from colourhs.crosstalk import load_crosstalk, unmix
from colourhs.geometry import (
    backproject,
    normalised_coordinates,
    pixel_grid,
    project,
    ray_plane_intersection,
)
from colourhs.helmholtz import sample_bilinear
from colourhs.io import atomic_output, sha256_files


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
class Grid:
    """Regular grid of control points over an image, bilinear in between.

    Nodes sit at pixel positions (i * spacing, j * spacing) for
    i < nx, j < ny, covering [0, width - 1] x [0, height - 1].
    """

    width: int
    height: int
    spacing: float

    @property
    def shape(self) -> tuple[int, int]:
        """(ny, nx) node counts."""
        return (
            int(np.ceil((self.height - 1) / self.spacing)) + 1,
            int(np.ceil((self.width - 1) / self.spacing)) + 1,
        )

    @property
    def size(self) -> int:
        ny, nx = self.shape
        return ny * nx

    @property
    def nodes(self) -> np.ndarray:
        """(size, 2) pixel positions (u, v) of the nodes, row-major like the values."""
        ny, nx = self.shape
        v, u = np.mgrid[0:ny, 0:nx] * self.spacing
        return np.stack([u.ravel(), v.ravel()], axis=1).astype(float)

    def weights(self, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Bilinear interpolation: node indices (N, 4) and weights (N, 4) of pixels ``uv``."""
        ny, nx = self.shape
        gx = np.clip(np.asarray(uv[:, 0], float) / self.spacing, 0, nx - 1)
        gy = np.clip(np.asarray(uv[:, 1], float) / self.spacing, 0, ny - 1)
        x0 = np.minimum(np.floor(gx).astype(int), nx - 2)
        y0 = np.minimum(np.floor(gy).astype(int), ny - 2)
        fx, fy = gx - x0, gy - y0
        idx = np.stack(
            [y0 * nx + x0, y0 * nx + x0 + 1, (y0 + 1) * nx + x0, (y0 + 1) * nx + x0 + 1], 1
        )
        w = np.stack([(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy], 1)
        return idx, w

    def matrix(self, uv: np.ndarray) -> sp.csr_matrix:
        """(N, size) sparse bilinear interpolation matrix of pixels ``uv``."""
        idx, w = self.weights(uv)
        rows = np.repeat(np.arange(len(idx)), 4)
        return sp.csr_matrix((w.ravel(), (rows, idx.ravel())), shape=(len(idx), self.size))

    def interpolate(self, values: np.ndarray, uv: np.ndarray) -> np.ndarray:
        """Values of the bilinear surface through node ``values`` (ny, nx) at ``uv`` (N, 2)."""
        idx, w = self.weights(uv)
        return np.sum(values.ravel()[idx] * w, axis=1)

    def dense(self, values: np.ndarray) -> np.ndarray:
        """The bilinear surface on every pixel centre, (height, width)."""
        uv = pixel_grid(self.width, self.height).reshape(-1, 2)
        return self.interpolate(values, uv).reshape(self.height, self.width)


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


def _log_kappa_at(view: PoseView, board: Board, a: Camera, b: Camera, ch_a, ch_b, uv_b, opts):
    """log kappa (eq. 6) at the board points seen by pixels ``uv_b`` of b; NaN if unusable."""
    origin, d = backproject(uv_b, b.K, b.dist, b.R, b.t)
    n = view.normal
    x, s = ray_plane_intersection(origin, d, view.t, n)
    xy = ((x - view.t) @ view.R)[:, :2]
    if opts.get("margin_m") is not None:
        margin = float(opts["margin_m"])
    else:
        with np.errstate(invalid="ignore"):
            foot = np.maximum(pixel_footprint_m(x, n, a), pixel_footprint_m(x, n, b))
        margin = opts["margin_px"] * np.nan_to_num(foot, nan=np.inf)
    with np.errstate(invalid="ignore"):
        ok = (s > 0) & board.white(xy, margin)
    uv_a = project(x, a.K, a.dist, a.R, a.t)
    i_a = sample_bilinear(view.images[a.name][..., ch_a], uv_a)
    i_b = sample_bilinear(view.images[b.name][..., ch_b], uv_b)
    sat = sample_bilinear(view.saturated[a.name].astype(float), uv_a) > 0
    sat |= sample_bilinear(view.saturated[b.name].astype(float), uv_b) > 0
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
    (or ``margin_m``), see :data:`DEFAULTS`. Camera a's channel is the one of
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


def eq7_residual_rms(samples: KappaSamples, grid: Grid, lam_a: np.ndarray) -> float:
    """RMS of the eq. (7) residuals of map a: samples sharing b's pixel on two poses.

    The residual of poses j, k seeing the same pixel ``uv_b`` of b is
    ``log kappa_j - log kappa_k - (lambda_a(u_a^j) - lambda_a(u_a^k))``; over
    every such pair of samples (as :func:`kappa_samples` makes them, on b's
    pixel grid). NaN when no pixel is seen on two poses.
    """
    p = samples.log_kappa - grid.interpolate(lam_a, samples.uv_a)
    _, g = np.unique(samples.uv_b, axis=0, return_inverse=True)
    g = g.ravel()
    n = np.bincount(g).astype(float)
    mean = np.bincount(g, weights=p) / n
    ss = np.bincount(g, weights=(p - mean[g]) ** 2)
    # sum over pairs j < k of (p_j - p_k)^2 = n * sum_j (p_j - mean)^2 per pixel
    pairs = np.sum(n * (n - 1) / 2)
    return float(np.sqrt(np.sum(n * ss) / pairs)) if pairs else float("nan")


def _second_difference_operator(grid: Grid) -> sp.csr_matrix:
    """Second differences along rows and columns of the node grid (curvature)."""
    ny, nx = grid.shape
    idx = np.arange(grid.size).reshape(ny, nx)
    triples = np.concatenate(
        [np.stack([idx[:, :-2].ravel(), idx[:, 1:-1].ravel(), idx[:, 2:].ravel()], 1),
         np.stack([idx[:-2].ravel(), idx[1:-1].ravel(), idx[2:].ravel()], 1)]
    )  # fmt: skip
    m = len(triples)
    rows = np.repeat(np.arange(m), 3)
    vals = np.tile([1.0, -2.0, 1.0], m)
    return sp.csr_matrix((vals, (rows, triples.ravel())), shape=(m, grid.size))


def _difference_operator(grid: Grid) -> sp.csr_matrix:
    """First differences between horizontally and vertically adjacent nodes."""
    ny, nx = grid.shape
    idx = np.arange(grid.size).reshape(ny, nx)
    pairs = np.concatenate(
        [np.stack([idx[:, :-1].ravel(), idx[:, 1:].ravel()], 1),
         np.stack([idx[:-1].ravel(), idx[1:].ravel()], 1)]
    )  # fmt: skip
    m = len(pairs)
    rows = np.repeat(np.arange(m), 2)
    vals = np.tile([1.0, -1.0], m)
    return sp.csr_matrix((vals, (rows, pairs.ravel())), shape=(m, grid.size))


def shading_basis(xy: np.ndarray, order: int) -> np.ndarray:
    """Monomials x^i y^j, 1 <= i + j <= ``order``, of coordinates ``xy`` (N, 2): (N, terms).

    The constant is left out (the coupling penalises gradients, so it is free anyway).
    """
    x, y = xy[:, 0], xy[:, 1]
    cols = [x**i * y ** (d - i) for d in range(1, order + 1) for i in range(d, -1, -1)]
    return np.stack(cols, axis=1) if cols else np.zeros((len(xy), 0))


def shading_coordinates(cam: Camera, uv: np.ndarray, width: int, height: int) -> np.ndarray:
    """Undistorted normalised image coordinates of pixels ``uv``, over the corner radius.

    Vignetting and colour shading are functions of the field angle (of the
    ray, not of the distorted pixel), so the shading polynomial lives in
    these coordinates; dividing by the largest corner radius makes the
    coefficients the shading at the image corner, whatever the focal length.
    """
    corners = np.array([[0, 0], [width - 1, 0], [0, height - 1], [width - 1, height - 1]], float)
    centre = cam.K[:2, 2]
    xy0 = normalised_coordinates(centre[None], cam.K, cam.dist)[0]
    rc = np.max(np.linalg.norm(normalised_coordinates(corners, cam.K, cam.dist) - xy0, axis=1))
    return (normalised_coordinates(uv, cam.K, cam.dist) - xy0) / rc


def _place(D: sp.spmatrix, offset: int, total: int) -> sp.csr_matrix:
    """Operator D acting on the columns offset .. offset + D.shape[1] of a vector of ``total``."""
    D = sp.coo_matrix(D)
    return sp.csr_matrix((D.data, (D.row, D.col + offset)), shape=(D.shape[0], total))


def solve_mu_grids(
    pairs: list[tuple[tuple[str, int], tuple[str, int], KappaSamples]],
    grid: Grid,
    bases: dict[str, np.ndarray],
    smoothness: float,
    coupling: float,
    shading_prior: float,
) -> tuple[dict, dict, dict]:
    """Least squares of eqs. (6)-(8) for every Helmholtz camera's log-mu control points.

    Minimises, with lambda_h the log-mu node values of map h (bilinear in
    between) and m_h the number of eq. (6) rows that involve map h:

    - ``sum ((A lambda_a - B lambda_b + c_ab) - log kappa)^2`` over the eq. (6)
      samples of every pair (A, B: bilinear interpolation at the samples'
      pixels in a and b; contains eq. 7 / eq. 8, see the module docstring);
    - ``smoothness^2 m_h sum (D2 lambda_h)^2 (W / s)^2`` per map (D2: second
      differences of adjacent nodes, W the image width and s the node
      spacing in pixels, so that the sum approximates the integral of the
      squared curvature over an image one unit wide: the same for any grid
      spacing and resolution);
    - ``coupling^2 m sum (D (lambda_h1 - lambda_h2 - P beta))^2`` for the two
      maps h1, h2 of one camera (D: first differences of adjacent nodes, whose
      squared sum approximates the Dirichlet energy, itself independent of the
      grid and the resolution; P: the camera's shading basis at the nodes;
      m = m_h1 + m_h2);
    - ``shading_prior^2 m |beta|^2`` per camera.

    Parameters
    ----------
    pairs : (key_a, key_b, samples) per reciprocal pair; keys are (camera, channel).
    grid : the control grid (shared by all maps).
    bases : camera -> (grid.size, terms) shading basis at the nodes
        (:func:`shading_basis` of :func:`shading_coordinates`).
    smoothness, coupling, shading_prior : weights relative to one eq. (6) row.

    Returns
    -------
    grids : (camera, channel) -> (ny, nx) log mu at the control points, with
        the pair's eq. (6) constant applied to the second map of each pair
        and mean 0 over the first map's nodes.
    shading : camera -> (terms,) beta (log shading of the map of the lower
        channel index over the other's, at the image corner).
    offsets : pair index -> c_ab, the eq. (6) relative log scale.
    """
    keys = sorted({k for ka, kb, _ in pairs for k in (ka, kb)})
    n = grid.size
    cams = sorted({k[0] for k in keys if sum(q[0] == k[0] for q in keys) == 2})
    col = {k: h * n for h, k in enumerate(keys)}
    total = n * len(keys)
    for c in cams:
        col[c] = total
        total += bases[c].shape[1]
    for p in range(len(pairs)):
        col[p] = total
        total += 1
    normal = sp.csr_matrix((total, total))
    rhs = np.zeros(total)
    m_map = dict.fromkeys(keys, 0)
    for p, (ka, kb, s) in enumerate(pairs):
        m = len(s.log_kappa)
        M = (
            _place(grid.matrix(s.uv_a), col[ka], total)
            - _place(grid.matrix(s.uv_b), col[kb], total)
            + _place(sp.csr_matrix(np.ones((m, 1))), col[p], total)
        )
        normal = normal + M.T @ M
        rhs += M.T @ s.log_kappa
        m_map[ka] += m
        m_map[kb] += m
    D2 = _second_difference_operator(grid) * (grid.width / grid.spacing)
    D1 = _difference_operator(grid)
    gauge = []
    for k in keys:
        S = _place(D2, col[k], total)
        normal = normal + smoothness**2 * m_map[k] * (S.T @ S)
    for c in cams:
        k1, k2 = (k for k in keys if k[0] == c)
        E = (
            _place(D1, col[k1], total)
            - _place(D1, col[k2], total)
            - _place(sp.csr_matrix(D1 @ bases[c]), col[c], total)
        )
        m = m_map[k1] + m_map[k2]
        normal = normal + coupling**2 * m * (E.T @ E)
        nb = bases[c].shape[1]
        ridge = sp.csr_matrix(
            (np.full(nb, shading_prior**2 * m), (np.arange(nb) + col[c],) * 2),
            shape=(total, total),
        )
        normal = normal + ridge
    # Gauge: pin one node of each map (the null space is one constant per map
    # pair member); the constants are set properly below.
    for k in keys:
        node = col[k] + n // 2
        gauge.append(node)
    pin = sp.csr_matrix((np.full(len(gauge), float(max(m_map.values()))), (gauge, gauge)),
                        shape=(total, total))  # fmt: skip
    lam = spsolve((normal + pin).tocsc(), rhs)
    grids = {k: lam[col[k] : col[k] + n].reshape(grid.shape) for k in keys}
    offsets = {}
    for p, (ka, kb, _) in enumerate(pairs):
        offsets[p] = float(lam[col[p]])
        grids[kb] = grids[kb] - offsets[p]
        mean = grids[ka].mean()
        grids[ka] = grids[ka] - mean
        grids[kb] = grids[kb] - mean
    shading = {c: lam[col[c] : col[c] + bases[c].shape[1]] for c in cams}
    return grids, shading, offsets


def coverage(grid: Grid, uv: np.ndarray, min_support: float) -> np.ndarray:
    """Calibrated region (height, width): pixels whose 4 control points all have data.

    A node's support is the sum of the bilinear weights of the samples at
    ``uv`` (N, 2) on it; a node has data when its support is at least
    ``min_support`` times the median support of the nodes that have any.
    """
    idx, w = grid.weights(uv)
    support = np.bincount(idx.ravel(), weights=w.ravel(), minlength=grid.size)
    ref = np.median(support[support > 0]) if np.any(support > 0) else 0.0
    has = (support >= max(min_support * ref, 1e-12)).astype(float).reshape(grid.shape)
    return grid.dense(has) > 0.999


DEFAULTS = {
    "grid_spacing_px": None,
    "grid_angle_deg": 1.0,
    "min_grid_px": 8.0,
    "step_px": None,
    "samples_per_cell": 7,
    "margin_m": None,
    "margin_px": 2.0,
    "min_cos": 0.3,
    "min_signal": 0.05,
    "smoothness": 1e-4,
    "coupling": 0.1,
    "shading_order": 2,
    "shading_prior": 0.01,
    "min_support": 0.05,
}
"""Default parameters of :func:`calibrate`; why each value holds on any rig:

- ``grid_spacing_px`` None: the pixels that ``grid_angle_deg`` of field
  angle spans (mean focal length x angle), at least ``min_grid_px``.
- ``grid_angle_deg`` 1.0: mu = rho / sigma is a function of the ray's
  direction (eq. 2): LED profiles and vignetting change over degrees
  (the random presets' LED ripple has periods of 4-15 deg); nodes 1 deg
  apart keep the bilinear surface within ~0.1 % RMS of such maps (measured
  on the random rigs), whatever the focal length and image size.
- ``min_grid_px`` 8: a cell holds at least 64 pixels of each pose, so a node
  averages the pixel noise of hundreds of samples even on small images.
- ``step_px`` None: ``grid_spacing_px / samples_per_cell`` rounded, at
  least 1; ``samples_per_cell`` 7: about 50 samples per cell and pose per
  direction, so the sample count per node does not depend on the resolution.
- ``margin_m`` None: ``margin_px`` 2 pixel footprints (the larger of the two
  cameras', :func:`pixel_footprint_m`) around markers and board edges:
  edges blur over a pixel or two in any camera, so the margin is set in
  pixels, not metres (a metric margin is several pixels on a close rig and
  less than one on a far one). A number (metres) overrides it.
- ``min_cos`` 0.3: grazing limit (cosine between the plane's normal and the
  light direction, eq. 6): an error of the board's normal of e radians
  changes cos by e tan(theta), 3e at cos 0.3; beyond, a 0.1 deg normal error
  would cost more than half a per cent. A cosine is the same on any rig.
- ``min_signal`` 0.05 of full scale: darkest usable reading. At 5 % an 8-bit
  pixel has 12 DN, so quantisation and black-level errors (a fraction of a
  DN) stay below ~2 % per sample, which the least squares averages; full
  scale is the sensor's own unit, so it holds for any exposure and depth.
- ``smoothness`` 1e-4: curvature weight relative to one eq. (6) row, for an
  image one unit wide (see :func:`solve_mu_grids`): it only decides nodes at
  the edge of the data, where it continues a map linearly.
- ``coupling`` 0.1: weight of the shading-corrected difference of one
  camera's two maps; only what neither data nor the shading polynomial
  explain competes with it, so any value well above ``smoothness`` works
  (measured flat from 0.1 to 100).
- ``shading_order`` 2: colour shading is per-channel vignetting, radial
  about slightly different centres: to second order a constant, a linear
  term (the centre shift) and a quadratic one (the strength difference);
  higher terms are below 0.1 % on the calibrated field.
- ``shading_prior`` 0.01: a shading coefficient beta (at the image corner)
  costs like a misfit of 0.01 beta on every eq. (6) row: 100 times below a
  per-cent noise, so it cannot bias what the data determine, while it picks
  the smallest shading where they cannot (measured flat from 0.003 to 0.03).
- ``min_support`` 0.05: a node needs 5 % of the median node's sample weight
  to count as calibrated (a relative count, so the same on any number of
  samples); below, a node is decided by the regulariser alone.
"""


def load_views(dataset_dir, poses_csv, crosstalk_json=None) -> tuple[Rig, list[PoseView]]:
    """Read every usable board pose (from the marker poses table) and its images."""
    ds = open_dataset(dataset_dir, check_images=False)
    table = pd.read_csv(poses_csv)
    mixing = load_crosstalk(crosstalk_json) if crosstalk_json else {}
    views = []
    for _, row in table.iterrows():
        pose = str(row["pose"])
        R = np.array([[row[f"R{i}{j}"] for j in range(3)] for i in range(3)], float)
        t = np.array([row["t_x"], row["t_y"], row["t_z"]], float)
        images, saturated = {}, {}
        for cam in ds.rig.camera_names:
            img, sat = read_image(ds.photometric_image(pose, cam), ds.rig.image)
            images[cam] = unmix(img, mixing[cam]) if cam in mixing else img
            saturated[cam] = sat
        views.append(PoseView(pose, R, t, images, saturated))
    if len(views) < 3:
        raise ValueError(f"{poses_csv}: {len(views)} usable board poses, need at least 3")
    return ds.rig, views


def resolve_params(rig: Rig, **params) -> dict:
    """:data:`DEFAULTS` overridden by ``params`` (None = default), rig-dependent ones resolved."""
    unknown = set(params) - set(DEFAULTS)
    if unknown:
        raise TypeError(f"unknown photometric parameter(s) {sorted(unknown)}")
    opts = DEFAULTS | {k: v for k, v in params.items() if v is not None}
    if opts["grid_spacing_px"] is None:
        f = np.mean([0.5 * (c.K[0, 0] + c.K[1, 1]) for c in rig.cameras])
        spacing = f * np.tan(np.radians(opts["grid_angle_deg"]))
        opts["grid_spacing_px"] = float(max(spacing, opts["min_grid_px"]))
    opts["grid_spacing_px"] = float(opts["grid_spacing_px"])
    if opts["step_px"] is None:
        opts["step_px"] = max(1, round(opts["grid_spacing_px"] / opts["samples_per_cell"]))
    opts["step_px"] = int(opts["step_px"])
    opts["shading_order"] = int(opts["shading_order"])
    return opts


def calibrate(rig: Rig, views: list[PoseView], **params) -> dict:
    """Photometric calibration of every Helmholtz camera (eqs. 6-8, module docstring).

    Parameters (keyword, see :data:`DEFAULTS` for each value and why it
    holds on any rig): ``grid_spacing_px`` control point spacing,
    ``step_px`` sample spacing, ``margin_px`` / ``margin_m`` white-area
    margin around markers and board edges, ``min_cos`` grazing limit,
    ``min_signal`` darkest usable intensity, ``smoothness``, ``coupling``
    and ``shading_prior`` weights and ``shading_order`` (see
    :func:`solve_mu_grids`; ``shading_order=0`` is the paper's coupling,
    the two maps of a camera equal up to a constant), ``min_support``
    calibrated-region threshold.

    Returns a dict with ``maps`` ("<camera>/<colour>" -> (H, W) float32 mu),
    ``grids`` (same keys -> (ny, nx) log mu control points), ``calibrated``
    (same keys -> (H, W) bool calibrated region), ``offsets`` (pair ->
    eq. 6 relative log scale applied), ``counts`` (eq. 6 samples per map),
    ``residual_rms`` (RMS of the eq. 7 residuals per map, log units),
    ``shading`` (camera -> {"maps": [the two keys], "order", "coefficients"}:
    the fitted log colour shading, first map over second, at the image
    corner), ``grid`` and ``params``.
    """
    opts = resolve_params(rig, **params)
    W, H = rig.image.width, rig.image.height
    grid = Grid(W, H, opts["grid_spacing_px"])
    pairs, own = [], {}
    for pr in rig.reciprocal_pairs():
        ka, kb = (pr.cam_a, pr.channel_a), (pr.cam_b, pr.channel_b)
        s_ab = kappa_samples(views, rig, pr.cam_a, pr.cam_b, opts)  # on b's pixels: map a
        s_ba = kappa_samples(views, rig, pr.cam_b, pr.cam_a, opts)  # on a's pixels: map b
        for key, s in ((ka, s_ab), (kb, s_ba)):
            if len(s.log_kappa) == 0:
                raise ValueError(
                    f"photometric calibration: no usable samples for {key[0]}/{COLOURS[key[1]]} "
                    "(every board sample masked: markers, saturation, grazing or dark)"
                )
        own[ka], own[kb] = s_ab, s_ba
        pairs.append((ka, kb, KappaSamples.concatenate([s_ab, s_ba.swapped()])))
    order = opts["shading_order"]
    bases = {
        c.name: shading_basis(shading_coordinates(c, grid.nodes, W, H), order) for c in rig.cameras
    }
    grids, shading, offs = solve_mu_grids(
        pairs, grid, bases, opts["smoothness"], opts["coupling"], opts["shading_prior"]
    )
    out = {"maps": {}, "grids": {}, "calibrated": {}, "offsets": {}, "counts": {},
           "residual_rms": {}, "shading": {}}  # fmt: skip
    for p, (ka, kb, s) in enumerate(pairs):
        name = f"{ka[0]}/{COLOURS[ka[1]]}~{kb[0]}/{COLOURS[kb[1]]}"
        out["offsets"][name] = offs[p]
        for key in (ka, kb):
            k = f"{key[0]}/{COLOURS[key[1]]}"
            g = grids[key]
            out["maps"][k] = np.exp(grid.dense(g)).astype(np.float32)
            out["grids"][k] = g
            # calibrated where eq. (7) constrains the map: a pixel seen on two poses
            t = own[key].transferred()
            out["calibrated"][k] = coverage(grid, own[key].uv_a[t], opts["min_support"])
            out["counts"][k] = len(s.log_kappa)
            out["residual_rms"][k] = eq7_residual_rms(own[key], grid, g)
    for cam, beta in shading.items():
        k1, k2 = sorted(k for k in grids if k[0] == cam)
        out["shading"][cam] = {
            "maps": [f"{cam}/{COLOURS[k1[1]]}", f"{cam}/{COLOURS[k2[1]]}"],
            "order": order,
            "coefficients": [float(b) for b in beta],
        }
    out["grid"] = grid
    out["params"] = opts
    return out


def mu_map_errors(result: dict, truth: dict[str, np.ndarray], rig: Rig) -> pd.DataFrame:
    """RMS log error of recovered mu maps against ground truth, up to one scale per pair.

    For each reciprocal pair, one constant (the pair's free scale) is removed
    from the log maps of both its Helmholtz cameras jointly, over their
    calibrated regions. The row "no calibration" does the same for mu = 1.
    """
    rows = []
    for pr in rig.reciprocal_pairs():
        keys = [f"{pr.cam_a}/{COLOURS[pr.channel_a]}", f"{pr.cam_b}/{COLOURS[pr.channel_b]}"]
        for method in ("calibrated", "no calibration"):
            errs = []
            for key in keys:
                m = result["calibrated"][key]
                est = np.log(result["maps"][key][m]) if method == "calibrated" else 0.0
                errs.append(est - np.log(truth[key][m]))
            shift = np.mean(np.concatenate(errs))
            for key, e in zip(keys, errs, strict=True):
                rms = float(np.sqrt(np.mean((e - shift) ** 2)))
                frac = float(result["calibrated"][key].mean())
                rows.append(
                    {
                        "map": key,
                        "method": method,
                        "rms_log_error": rms,
                        "calibrated_fraction": frac,
                    }
                )
    return pd.DataFrame(rows)


def board_points(board: Board, poses, spacing_m: float = 0.002) -> np.ndarray:
    """World points (N, 3) of the white surface of the board at each pose.

    ``poses``: iterable of (R, t) board-to-world poses; points on a square
    grid of ``spacing_m`` in the board frame, markers and edges (one
    spacing) left out.
    """
    w, h = board.size
    gx, gy = np.meshgrid(np.arange(spacing_m, w, spacing_m), np.arange(spacing_m, h, spacing_m))
    xy = np.stack([gx.ravel(), gy.ravel()], axis=1)
    xy = xy[board.white(xy, spacing_m)]
    pts = np.concatenate([xy, np.zeros((len(xy), 1))], axis=1)
    return np.concatenate([pts @ np.asarray(R, float).T + np.asarray(t, float) for R, t in poses])


def pair_ratio_errors(
    result: dict, truth: dict[str, np.ndarray], rig: Rig, points: np.ndarray
) -> pd.DataFrame:
    """RMS error of ``log(mu_a(u_a) / mu_b(u_b))`` per reciprocal pair at world ``points``.

    This is what the HS constraint (eq. 5) uses of the calibration: the
    ratio of the pair's two maps at the two pixels that see one point. A
    factor constant on each epipolar plane of the pair multiplies both maps
    and cancels here (it scales a row of W), as does the pair's free scale
    (one constant per pair is removed). Points (N, 3), metres, that fall in
    both cameras' images and calibrated regions count; the row
    "no calibration" does the same for mu = 1.

    Returns a DataFrame with ``pair``, ``method``, ``rms_log_error``,
    ``points`` (how many counted).
    """
    rows = []
    for pr in rig.reciprocal_pairs():
        A, B = rig.camera(pr.cam_a), rig.camera(pr.cam_b)
        ka, kb = f"{A.name}/{COLOURS[pr.channel_a]}", f"{B.name}/{COLOURS[pr.channel_b]}"
        uv_a = project(points, A.K, A.dist, A.R, A.t)
        uv_b = project(points, B.K, B.dist, B.R, B.t)
        ok = (sample_bilinear(result["calibrated"][ka].astype(float), uv_a) > 0.999) & (
            sample_bilinear(result["calibrated"][kb].astype(float), uv_b) > 0.999
        )
        true = np.log(sample_bilinear(truth[ka], uv_a[ok])) - np.log(
            sample_bilinear(truth[kb], uv_b[ok])
        )
        est = np.log(sample_bilinear(result["maps"][ka], uv_a[ok])) - np.log(
            sample_bilinear(result["maps"][kb], uv_b[ok])
        )
        for method, e in (("calibrated", est - true), ("no calibration", -true)):
            rms = float(np.sqrt(np.mean((e - e.mean()) ** 2))) if ok.any() else float("nan")
            rows.append(
                {"pair": f"{ka}~{kb}", "method": method, "rms_log_error": rms,
                 "points": int(ok.sum())}
            )  # fmt: skip
    return pd.DataFrame(rows)


def photometric_maps(
    dataset_dir, poses_csv, out_h5, crosstalk_json=None, figure_png=None, **params
) -> dict:
    """Calibrate and write ``photometric.h5`` (results contract) and a Figure-3-like PNG.

    The HDF5 file holds one float32 (H, W) mu map per Helmholtz camera at
    ``<camera>/<colour>``, its control grid at ``grid/<camera>/<colour>``
    (log mu), the calibrated region at ``calibrated/<camera>/<colour>``, and
    as attributes the parameters, the pair offsets, the fitted colour
    shading per camera and a hash of the inputs. Written atomically: no
    partial file on error.
    """
    rig, views = load_views(dataset_dir, poses_csv, crosstalk_json)
    result = calibrate(rig, views, **params)
    ds = open_dataset(dataset_dir, check_images=False)
    inputs = [ds.photometric_image(v.name, c) for v in views for c in rig.camera_names]
    inputs += [Path(poses_csv)] + ([Path(crosstalk_json)] if crosstalk_json else [])
    with atomic_output(out_h5) as tmp, h5py.File(tmp, "w") as f:
        for key, mu in result["maps"].items():
            f.create_dataset(key, data=mu, compression="gzip")
            f.create_dataset(f"grid/{key}", data=result["grids"][key].astype(np.float32))
            f.create_dataset(
                f"calibrated/{key}", data=result["calibrated"][key], compression="gzip"
            )
        f.attrs["equations"] = (
            "kappa eq. (6); eqs. (7)-(8) as one least squares over the eq. (6) samples of "
            "each pair; two-pair coupling with a free colour-shading polynomial"
        )
        f.attrs["params"] = json.dumps(result["params"])
        f.attrs["pair_offsets"] = json.dumps(result["offsets"])
        f.attrs["constraints"] = json.dumps(result["counts"])
        f.attrs["residual_rms_log"] = json.dumps(result["residual_rms"])
        f.attrs["colour_shading"] = json.dumps(result["shading"])
        f.attrs["poses"] = json.dumps([v.name for v in views])
        f.attrs["inputs_sha256"] = sha256_files(inputs)
        f.attrs["crosstalk_unmixed"] = bool(crosstalk_json)
    if figure_png is not None:
        from colourhs.figures import mu_maps_figure

        mu_maps_figure(result["maps"], result["calibrated"], figure_png)
    return result


def read_mu_maps(path: str | Path) -> dict[str, np.ndarray]:
    """``"<camera>/<colour>"`` -> (H, W) mu from a photometric.h5 (ours or ground truth)."""
    with h5py.File(path) as f:
        return {
            f"{cam}/{colour}": f[cam][colour][()]
            for cam in f
            if cam not in ("grid", "calibrated")
            for colour in f[cam]
        }
