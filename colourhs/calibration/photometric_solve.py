"""The mu maps' control grid and the least squares of eqs. (7)-(8), paper section III-C.

Steps 2-6 of :mod:`colourhs.calibration.photometric` (whose docstring describes them):
the eq. (6) samples of every pair, one row
``lambda_a(u_a) - lambda_b(u_b) + c_ab = log kappa`` each, contain the
eq. (7) transfers and the system of eq. (8); they are solved jointly for the
log-mu control points of all six maps with the two-pair coupling of each
camera through a colour-shading polynomial, its prior, a curvature
regulariser and the gauge. This module holds

- :class:`Grid`: the bilinear control grid over an image;
- :func:`shading_basis` and :func:`shading_coordinates`: the colour-shading
  polynomial in undistorted normalised image coordinates;
- :func:`solve_mu_grids`: the least squares (with its difference operators);
- :func:`coverage` (the calibrated region) and :func:`eq7_residual_rms`
  (the eq. (7) residuals of a solved map).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

from colourhs.calibration.photometric_samples import KappaSamples
from colourhs.capture import Camera
from colourhs.common.geometry import normalised_coordinates, pixel_grid
from colourhs.common.sampling import bilinear_footprint, bilinear_weights


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
        uv = np.asarray(uv, float)
        # Beyond the grid: clamped to its border (the footprint clamps).
        _, x0, y0, fx, fy = bilinear_footprint(
            uv[:, 0] / self.spacing, uv[:, 1] / self.spacing, nx, ny
        )
        x0, y0 = x0.astype(int), y0.astype(int)
        idx = np.stack(
            [y0 * nx + x0, y0 * nx + x0 + 1, (y0 + 1) * nx + x0, (y0 + 1) * nx + x0 + 1], 1
        )
        return idx, np.stack(bilinear_weights(fx, fy), 1)

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


def _second_difference_operator(grid: Grid) -> sp.csr_matrix:
    """Second differences along rows and columns of the node grid (curvature)."""
    ny, nx = grid.shape
    idx = np.arange(grid.size).reshape(ny, nx)
    triples = np.concatenate(
        [
            np.stack([idx[:, :-2].ravel(), idx[:, 1:-1].ravel(), idx[:, 2:].ravel()], 1),
            np.stack([idx[:-2].ravel(), idx[1:-1].ravel(), idx[2:].ravel()], 1),
        ]
    )
    m = len(triples)
    rows = np.repeat(np.arange(m), 3)
    vals = np.tile([1.0, -2.0, 1.0], m)
    return sp.csr_matrix((vals, (rows, triples.ravel())), shape=(m, grid.size))


def _difference_operator(grid: Grid) -> sp.csr_matrix:
    """First differences between horizontally and vertically adjacent nodes."""
    ny, nx = grid.shape
    idx = np.arange(grid.size).reshape(ny, nx)
    pairs = np.concatenate(
        [
            np.stack([idx[:, :-1].ravel(), idx[:, 1:].ravel()], 1),
            np.stack([idx[:-1].ravel(), idx[1:].ravel()], 1),
        ]
    )
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
      pixels in a and b; contains eq. 7 / eq. 8, see the :mod:`colourhs.calibration.photometric`
      docstring);
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
    pin = sp.csr_matrix(
        (np.full(len(gauge), float(max(m_map.values()))), (gauge, gauge)), shape=(total, total)
    )
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


def eq7_noise_rms(
    samples: KappaSamples, grid: Grid, lam_a: np.ndarray, step: int, box: int
) -> float:
    """The eq. (7) residual RMS that the readings' own noise explains (beyond the paper).

    Two samples of one pose ``step`` pixels apart on b's grid differ, once the
    fitted map is removed, by their noise alone (the model is smooth over a
    step; a disagreement shared by a pose cancels). The robust spread of those
    differences (MAD), corrected for the overlap of the two boxes (their noise
    is correlated over ``(box - step) / box`` of a box), gives one sample's
    noise sigma; an eq. (7) residual, a difference of two samples on two poses,
    has sqrt(2) sigma. :func:`eq7_residual_rms` well above it means the poses
    disagree with eq. (6) beyond noise: light eq. (6) does not model
    (interreflections, ambient light), or a glossy board with lights beside the
    lenses. NaN without neighbouring samples.
    """
    p = samples.log_kappa - grid.interpolate(lam_a, samples.uv_a)
    uv = np.rint(samples.uv_b / step).astype(np.int64)
    key = (samples.pose.astype(np.int64) * (1 << 20) + uv[:, 1]) * (1 << 20) + uv[:, 0]
    order = np.argsort(key)
    diffs = []
    for shift in (1, 1 << 20):  # the neighbour one step right, one step down
        j = np.searchsorted(key[order], key + shift)
        j = np.minimum(j, len(key) - 1)
        hit = key[order][j] == key + shift
        diffs.append(p[order][j][hit] - p[hit])
    d = np.concatenate(diffs)
    if len(d) < 10:
        return float("nan")
    mad = 1.4826 * np.median(np.abs(d - np.median(d)))
    overlap = max(box - step, 0) / box
    sample_sigma = mad / np.sqrt(2.0 * (1.0 - overlap))
    return float(np.sqrt(2.0) * sample_sigma)


def pair_ratio_sigma(
    pairs: list[tuple[tuple[str, int], tuple[str, int], KappaSamples]],
    grid: Grid,
    solve,
) -> np.ndarray:
    """1-sigma uncertainty (P,) of each pair's log ratio lambda_a - lambda_b (eq. 6).

    Beyond the paper. The HS constraint (eq. 5) weighs a pair's two sides by
    mu_a and mu_b, and a smooth surface's depth moves far with their ratio
    (:func:`colourhs.reconstruct.bayes.uncertainty.ratio_sensitivity`); an error
    shared by a board pose's samples (its plane's pose, its share of the
    sensor noise) does not average out over them. So the uncertainty is the
    jackknife over the board poses: ``solve(pairs)`` (the grids of
    :func:`solve_mu_grids` as the calibration calls it) once without each
    pose, each pair's ratio averaged over all its samples' pixels, and
    ``(n - 1) / n`` times the sum of the squared deviations from their mean.
    An error shared by every pose (the cross-talk unmixing's) does not show
    in it: a lower bound. NaN with fewer than four poses (too few to tell a
    spread).
    """
    poses = np.unique(np.concatenate([s.pose for _, _, s in pairs]))
    if len(poses) < 4:
        return np.full(len(pairs), np.nan)
    theta = []
    for j in poses:
        grids = solve([(ka, kb, s.subset(s.pose != j)) for ka, kb, s in pairs])
        theta.append(
            [
                np.mean(grid.interpolate(grids[ka], s.uv_a) - grid.interpolate(grids[kb], s.uv_b))
                for ka, kb, s in pairs
            ]
        )
    theta = np.asarray(theta)
    n = len(poses)
    return np.sqrt((n - 1) / n * np.sum((theta - theta.mean(axis=0)) ** 2, axis=0))
