"""Depth of a surface from the agreement of its geometry with eq. (5).

The Bayesian HS of the paper (section III-E) takes a surface's depth from the
depth-normal consistency: the normal that the constraint rows of eq. (5)
give at a hypothesised depth must agree with the geometry there. The
discrete labelling (:mod:`colourhs.reconstruct.mrf`) can only test that
agreement in steps of a label; under sensor noise the per-pixel data cost is
flat on smooth surfaces (its expectation is even slightly lower away from
the true depth), so the labelling cannot fix a smooth surface's depth to
better than a few labels. This module finds the continuous surface that
minimises the consistency energy itself (beyond the paper: its continuous,
noise-weighted form):

    E(z) = sum_p rho( sum_t sum_k (w_k(X_p) . N_t)^2 / var_k(N_t) / T_p )

- ``X_p = c + z_p r_p`` is pixel p's point at depth z_p along its ray.
- ``w_k`` is the eq. (5) row of reciprocal pair k sampled at X_p, and ``N_t``
  the unit normal of triangle t of the depth map around p (p with two
  4-neighbours; ``T_p`` triangles). The normal is the surface's own, not the
  rows' best fit: this is what pins the depth.
- ``var_k(N) = var(s_a) (v_a . N)^2 + var(s_b) (v_b . N)^2`` is the predicted
  variance of ``w_k . N`` from the sensor noise (:mod:`colourhs.noise`) and the
  interpolation error (a Sampson-normalised residual, so noise along the
  rows' own directions does not bias the normal).
- ``rho`` is Geman-McClure: pixels the model cannot explain (interreflection,
  a white highlight on a coloured surface, a mixed pixel) lose their
  weight instead of bending the surface. Its scale is ``ROBUST`` times the
  noise model's, or times the residuals' own median level where that is
  larger (errors of rendering, sampling or calibration beyond the noise).

This module holds E: the surfaces of a depth map (:class:`SurfaceGraph`),
E's residuals and their Jacobian over the depths (:func:`hs_residuals`),
holes filled and normals of the result. :mod:`colourhs.reconstruct.refine`
minimises it.
"""

from __future__ import annotations

import numba as nb
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from colourhs.reconstruct.sides import HelmholtzSides, sample_sides

ROBUST = 3.0  # Geman-McClure scale, in units of the predicted noise per row
EDGE_FOOTPRINTS = 6.0  # depth jump between neighbours that separates surfaces


class SurfaceGraph:
    """The pixels of a depth map, their 4-neighbour triangles and surfaces.

    Neighbours whose initial depths differ by more than ``edge_footprints``
    pixel footprints are not linked (a depth edge); connected linked pixels
    form one surface.
    """

    def __init__(
        self,
        mask: np.ndarray,
        shape,
        z: np.ndarray,
        footprint: np.ndarray,
        edge_footprints: float = EDGE_FOOTPRINTS,
    ):
        H, W = shape
        self.shape = (H, W)
        self.pix = np.flatnonzero(mask)
        n = self.n = len(self.pix)
        idx = np.full(H * W, -1)
        idx[self.pix] = np.arange(n)
        self.rows, self.cols = np.divmod(self.pix, W)
        zz, fp = z[self.pix], footprint[self.pix]

        def neighbour(di, dj):
            i2, j2 = self.rows + di, self.cols + dj
            inside = (i2 >= 0) & (i2 < H) & (j2 >= 0) & (j2 < W)
            out = np.full(n, -1)
            out[inside] = idx[(i2 * W + j2)[inside]]
            has = np.flatnonzero(out >= 0)
            out[has[np.abs(zz[out[has]] - zz[has]) > edge_footprints * fp[has]]] = -1
            return out

        east, west = neighbour(0, 1), neighbour(0, -1)
        south, north = neighbour(1, 0), neighbour(-1, 0)
        # The four triangles around each pixel, counter-clockwise in the image.
        self.triangles = [(east, south), (south, west), (west, north), (north, east)]
        p = np.concatenate([np.flatnonzero(east >= 0), np.flatnonzero(south >= 0)])
        q = np.concatenate([east[east >= 0], south[south >= 0]])
        g = sp.coo_matrix((np.ones(len(p)), (p, q)), shape=(n, n))
        self.n_surfaces, self.surface = connected_components(g, directed=False)


@nb.njit(cache=True, inline="always")
def _cross(ax, ay, az, bx, by, bz):
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


@nb.njit(cache=True, inline="always")
def _triangle_normal(X, R, p, a, b):
    """Unit normal (towards the camera) of triangle (p, a, b), its edges and 1 / |raw| * sign."""
    e1x, e1y, e1z = X[a, 0] - X[p, 0], X[a, 1] - X[p, 1], X[a, 2] - X[p, 2]
    e2x, e2y, e2z = X[b, 0] - X[p, 0], X[b, 1] - X[p, 1], X[b, 2] - X[p, 2]
    nx, ny, nz = _cross(e1x, e1y, e1z, e2x, e2y, e2z)
    ln = np.sqrt(nx * nx + ny * ny + nz * nz)
    sg = -1.0 if nx * R[p, 0] + ny * R[p, 1] + nz * R[p, 2] > 0.0 else 1.0
    f = sg / ln
    return nx * f, ny * f, nz * f, e1x, e1y, e1z, e2x, e2y, e2z, f


@nb.njit(cache=True, inline="always")
def _sampson(s, var, v, p, k, nx, ny, nz):
    """(w . N) / sqrt(N' C N) of pair k at pixel p, with the pieces of its derivative."""
    vax, vay, vaz = v[p, k, 0, 0], v[p, k, 0, 1], v[p, k, 0, 2]
    vbx, vby, vbz = v[p, k, 1, 0], v[p, k, 1, 1], v[p, k, 1, 2]
    sa, sb = s[p, k, 0], s[p, k, 1]
    ca = vax * nx + vay * ny + vaz * nz
    cb = vbx * nx + vby * ny + vbz * nz
    sd2 = var[p, k, 0] * ca * ca + var[p, k, 1] * cb * cb
    sd = np.sqrt(sd2)
    wx, wy, wz = sa * vax - sb * vbx, sa * vay - sb * vby, sa * vaz - sb * vbz
    r = (wx * nx + wy * ny + wz * nz) / sd
    return r, sd, sd2, ca, cb, wx, wy, wz


@nb.njit(parallel=True, cache=True)
def _triangle_chi2(X, R, s, var, v, valid, nb_a, nb_b, chi2, count):
    """Per pixel: the summed squared Sampson residuals of its triangles, and their number."""
    n = X.shape[0]
    P = s.shape[1]
    for p in nb.prange(n):
        c = 0.0
        m = 0.0
        for t in range(4):
            a, b = nb_a[t, p], nb_b[t, p]
            if not (valid[p] and a >= 0 and b >= 0):
                continue
            nx, ny, nz = _triangle_normal(X, R, p, a, b)[:3]
            for k in range(P):
                r = _sampson(s, var, v, p, k, nx, ny, nz)[0]
                c += r * r
            m += 1.0
        chi2[p] = c
        count[p] = m


@nb.njit(parallel=True, cache=True)
def _triangle_rows(X, R, s, var, v, ds, dv, valid, nb_a, nb_b, weights, count, res, cols, vals):
    """The weighted Sampson residuals of E and their Jacobian entries.

    Row ``(p * 4 + t) * P + k`` is pair k against triangle t of pixel p, with
    entries at the depths of p and of the triangle's other two pixels; rows
    of missing triangles are zero.
    """
    n = X.shape[0]
    P = s.shape[1]
    for p in nb.prange(n):
        wt = np.sqrt(weights[p] / max(count[p], 1.0))
        for t in range(4):
            a, b = nb_a[t, p], nb_b[t, p]
            base = (p * 4 + t) * P
            for k in range(P):
                res[base + k] = 0.0
                for j in range(3):
                    cols[base + k, j] = p
                    vals[base + k, j] = 0.0
            if not (valid[p] and a >= 0 and b >= 0):
                continue
            nx, ny, nz, e1x, e1y, e1z, e2x, e2y, e2z, f = _triangle_normal(X, R, p, a, b)
            # d(unit N) = (I - N N^T) d(raw N) * sign / |raw N|
            qx, qy, qz = _cross(R[p, 0], R[p, 1], R[p, 2], e1x - e2x, e1y - e2y, e1z - e2z)
            pq = qx * nx + qy * ny + qz * nz
            dpx, dpy, dpz = (qx - pq * nx) * f, (qy - pq * ny) * f, (qz - pq * nz) * f
            qx, qy, qz = _cross(R[a, 0], R[a, 1], R[a, 2], e2x, e2y, e2z)
            pq = qx * nx + qy * ny + qz * nz
            dax, day, daz = (qx - pq * nx) * f, (qy - pq * ny) * f, (qz - pq * nz) * f
            qx, qy, qz = _cross(e1x, e1y, e1z, R[b, 0], R[b, 1], R[b, 2])
            pq = qx * nx + qy * ny + qz * nz
            dbx, dby, dbz = (qx - pq * nx) * f, (qy - pq * ny) * f, (qz - pq * nz) * f
            for k in range(P):
                r, sd, sd2, ca, cb, wx, wy, wz = _sampson(s, var, v, p, k, nx, ny, nz)
                # d r / d N of (w . N) / sqrt(N' C N)
                ga, gb = var[p, k, 0] * ca * r / sd2, var[p, k, 1] * cb * r / sd2
                gx = wx / sd - ga * v[p, k, 0, 0] - gb * v[p, k, 1, 0]
                gy = wy / sd - ga * v[p, k, 0, 1] - gb * v[p, k, 1, 1]
                gz = wz / sd - ga * v[p, k, 0, 2] - gb * v[p, k, 1, 2]
                sa, sb, dsa, dsb = s[p, k, 0], s[p, k, 1], ds[p, k, 0], ds[p, k, 1]
                dwx = (
                    dsa * v[p, k, 0, 0]
                    + sa * dv[p, k, 0, 0]
                    - dsb * v[p, k, 1, 0]
                    - sb * dv[p, k, 1, 0]
                )
                dwy = (
                    dsa * v[p, k, 0, 1]
                    + sa * dv[p, k, 0, 1]
                    - dsb * v[p, k, 1, 1]
                    - sb * dv[p, k, 1, 1]
                )
                dwz = (
                    dsa * v[p, k, 0, 2]
                    + sa * dv[p, k, 0, 2]
                    - dsb * v[p, k, 1, 2]
                    - sb * dv[p, k, 1, 2]
                )
                row = base + k
                res[row] = r * wt
                cols[row, 1] = a
                cols[row, 2] = b
                vals[row, 0] = (
                    (dwx * nx + dwy * ny + dwz * nz) / sd + gx * dpx + gy * dpy + gz * dpz
                ) * wt
                vals[row, 1] = (gx * dax + gy * day + gz * daz) * wt
                vals[row, 2] = (gx * dbx + gy * dby + gz * dbz) * wt


def robust_energy(chi2, usable, scale):
    """Geman-McClure rho(chi2) = chi2 / (1 + chi2 / scale) per pixel, NaN where unusable."""
    return np.where(usable, chi2 / (1.0 + chi2 / scale), np.nan)


def hs_residuals(
    z,
    graph: SurfaceGraph,
    R,
    sides: HelmholtzSides,
    c_ref,
    robust: float = ROBUST,
    weights=None,
    jacobian: bool = True,
    scale: float | None = None,
):
    """Residuals of E (see the module docstring) and their Jacobian over the depths.

    Parameters
    ----------
    z : (n,) depths of the graph's pixels, metres.
    R : (n, 3) their rays (unit z-depth). c_ref : (3,) the rays' origin.
    robust : Geman-McClure scale, in units of the noise per row.
    weights : per-pixel IRLS weights to use instead of rho'(chi2).
    jacobian : with False, J is None and the second value is each pixel's
        robust energy rho(chi2), NaN where its samples are unusable.
    scale : the Geman-McClure scale in chi2 units; default from the
        residuals (``robust^2 P`` times the larger of 1 and their median
        over its noise-only value), returned in ``info`` so that energies
        of several depth maps can be compared at one scale.

    Returns
    -------
    J : sparse (M, n) Jacobian, r : (M,) IRLS-weighted residuals (r . r is
    the quadratic model of the robust energy), info : dict with ``valid``
    (n,) rows usable, ``weights`` (n,), ``chi2`` (n,) mean squared
    normalised residual per triangle, ``scale``.
    """
    n = graph.n
    X = c_ref + R * z[:, None]
    s, var, v, ds, dv = sample_sides(sides, X, R)
    P = s.shape[1]
    valid = np.all(np.isfinite(s), axis=(1, 2)) & np.all(np.isfinite(ds), axis=(1, 2))
    valid &= np.all(var > 0, axis=(1, 2))
    nb_a = np.stack([a for a, _ in graph.triangles])
    nb_b = np.stack([b for _, b in graph.triangles])
    chi2 = np.empty(n)
    count = np.empty(n)
    _triangle_chi2(X, R, s, var, v, valid, nb_a, nb_b, chi2, count)
    chi2 = chi2 / np.maximum(count, 1)
    usable = valid & (count > 0)
    if scale is None:
        # The robust scale: the noise model's, or the residuals' own where the
        # model (rendering, sampling, calibration) leaves more than the noise:
        # the median of a chi-square with P degrees of freedom is about P - 2/3.
        used = chi2[usable]
        level = max(1.0, float(np.median(used)) / (P - 2.0 / 3.0)) if len(used) else 1.0
        scale = level * robust**2 * P
    if not jacobian:
        return (
            None,
            robust_energy(chi2, usable, scale),
            {"valid": usable, "chi2": chi2, "scale": scale},
        )
    if weights is None:
        weights = 1.0 / (1.0 + chi2 / scale) ** 2  # rho'(chi2): IRLS
    w = np.ascontiguousarray(weights, float)
    res = np.empty(n * 4 * P)
    cols = np.empty((n * 4 * P, 3), np.int64)
    vals = np.empty((n * 4 * P, 3))
    _triangle_rows(X, R, s, var, v, ds, dv, valid, nb_a, nb_b, w, count, res, cols, vals)
    indptr = np.arange(0, 3 * len(res) + 1, 3)
    J = sp.csr_matrix((vals.ravel(), cols.ravel(), indptr), shape=(len(res), n))
    info = {"valid": usable, "weights": w, "chi2": chi2, "scale": scale}
    return J, res, info


def fill_holes(
    z: np.ndarray,
    graph: SurfaceGraph,
    fill: np.ndarray,
    rays: np.ndarray,
    ring_px: int = 3,
    surfaces: np.ndarray | None = None,
) -> np.ndarray:
    """Depths (H*W,) of the holes enclosed by each surface (NaN elsewhere).

    Beyond the paper. A hole (a black marker, a dark spot, pixels whose rows
    were unusable) inside ``fill`` takes the least-squares quadric of the
    inverse depth over a ring of ``ring_px`` pixels of its surface around
    it: 1 / z of a plane is linear in the ray r (X = c + z r), so the six
    monomials r_i r_j (which span every quadratic in the image plane, the
    linear ones among them since r . axis = 1) fill a planar surface exactly
    and a curved one to second order. ``surfaces`` (n_surfaces,) bool: only
    these surfaces' holes are filled (default all).
    """
    from scipy.ndimage import binary_dilation, binary_fill_holes, find_objects, label

    H, W = graph.shape
    out = np.full(H * W, np.nan)
    inv = np.zeros(H * W)
    inv[graph.pix] = 1.0 / z
    pad = ring_px + 1
    for surface in range(graph.n_surfaces):
        sel = graph.surface == surface
        if sel.sum() < 16 or (surfaces is not None and not surfaces[surface]):
            continue
        rows, cols = graph.rows[sel], graph.cols[sel]
        r0, c0 = max(rows.min() - pad, 0), max(cols.min() - pad, 0)
        r1, c1 = min(rows.max() + 1 + pad, H), min(cols.max() + 1 + pad, W)
        m = np.zeros((r1 - r0, c1 - c0), bool)
        m[rows - r0, cols - c0] = True
        holes, n = label(binary_fill_holes(m) & ~m)
        for k, box in enumerate(find_objects(holes), start=1):
            sl = tuple(slice(max(b.start - pad, 0), b.stop + pad) for b in box)
            hole = holes[sl] == k
            ring = binary_dilation(hole, iterations=ring_px) & m[sl]
            hi, hj = np.nonzero(hole)
            ri, rj = np.nonzero(ring)
            at_h = (hi + sl[0].start + r0) * W + (hj + sl[1].start + c0)
            at_r = (ri + sl[0].start + r0) * W + (rj + sl[1].start + c0)
            at_h = at_h[fill[at_h]]
            if len(at_h) == 0 or len(at_r) < 12:
                continue
            A = _quadric(rays[at_r])
            coef, *_ = np.linalg.lstsq(A, inv[at_r], rcond=None)
            out[at_h] = 1.0 / (_quadric(rays[at_h]) @ coef)
    return out


def _quadric(r: np.ndarray) -> np.ndarray:
    """The six monomials r_i r_j (i <= j) of rays (N, 3)."""
    return np.stack([r[:, i] * r[:, j] for i in range(3) for j in range(i, 3)], axis=1)


def surface_normals(z: np.ndarray, rays, c_ref, shape, pix) -> np.ndarray:
    """Unit normals (towards the camera) of depth map ``z`` at ``pix``.

    Central differences, one-sided where a neighbour has no depth (NaN where
    neither side has).
    """
    H, W = shape
    X = c_ref + rays * z[:, None]
    r, c = np.divmod(pix, W)

    def side(i, j):
        i, j = np.clip(i, 0, H - 1), np.clip(j, 0, W - 1)
        q = i * W + j
        return np.where(np.isfinite(z[q]), q, pix)

    du = X[side(r, c + 1)] - X[side(r, c - 1)]
    dv = X[side(r + 1, c)] - X[side(r - 1, c)]
    N = np.cross(du, dv)
    with np.errstate(invalid="ignore", divide="ignore"):  # isolated pixels: NaN
        N /= np.linalg.norm(N, axis=1, keepdims=True)
    return N * np.where(np.sum(N * rays[pix], axis=1) > 0, -1.0, 1.0)[:, None]
