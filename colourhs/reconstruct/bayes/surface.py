"""Depth of a surface from the agreement of its geometry with eq. (5).

The Bayesian HS of the paper (section III-E) takes a surface's depth from the
depth-normal consistency: the normal that the constraint rows of eq. (5)
give at a hypothesised depth must agree with the geometry there. The
discrete labelling (:mod:`colourhs.reconstruct.bayes.mrf`) can only test that
agreement in steps of a label; under sensor noise the per-pixel data cost is
flat on smooth surfaces (its expectation is even slightly lower away from
the true depth), so the labelling cannot fix a smooth surface's depth to
better than a few labels. This module finds the continuous surface that
minimises the consistency energy itself (beyond the paper: its continuous,
noise-weighted form):

    E(z) = sum_p rho( sum_k (w_k(X_p) . N_p)^2 / var_k(N_p) )

- ``X_p = c + z_p r_p`` is pixel p's point at depth z_p along its ray.
- ``w_k`` is the eq. (5) row of reciprocal pair k sampled at X_p, and ``N_p``
  the unit normal of the depth map at p: the sum of the normals of p's
  triangles with its 4-neighbours, which with all four is the
  central-difference normal ``(X_e - X_w) x (X_s - X_n)`` (one-sided at a
  surface's edge). The normal is the surface's own, not the rows' best
  fit: this is what pins the depth. It must be the normal *at p*, where the
  rows are sampled: each triangle's normal is the surface's normal a third
  of a pixel away, about footprint / (3 r) off on a surface of radius r,
  and comparing the rows with those would leave E a floor that falls as
  the surface flattens, so that E would prefer flatter surfaces nearer the
  camera.
- ``var_k(N) = var(s_a) (v_a . N)^2 + var(s_b) (v_b . N)^2`` is the predicted
  variance of ``w_k . N`` from the sensor noise (:mod:`colourhs.calibration.noise`) and the
  interpolation error (a Sampson-normalised residual, so noise along the
  rows' own directions does not bias the normal).
- ``rho`` is Geman-McClure: pixels the model cannot explain (interreflection,
  a white highlight on a coloured surface, a mixed pixel) lose their
  weight instead of bending the surface. Its scale is ``ROBUST`` times the
  noise model's, or times the residuals' own median level where that is
  larger (errors of rendering, sampling or calibration beyond the noise).

This module holds E: the surfaces of a depth map (:class:`SurfaceGraph`),
E's residuals and their Jacobian over the depths (:func:`hs_residuals`),
holes filled and normals of the result. :mod:`colourhs.reconstruct.bayes.refine`
minimises it.
"""

from __future__ import annotations

import numba as nb
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from colourhs.reconstruct.constraint import hs_row, row_variance
from colourhs.reconstruct.sides import HelmholtzSides, sample_sides

ROBUST = 3.0  # Geman-McClure scale, in units of the predicted noise per row
EDGE_FOOTPRINTS = 6.0  # depth jump between neighbours that separates surfaces


class SurfaceGraph:
    """The pixels of a depth map, their linked 4-neighbours and surfaces.

    Neighbours whose initial depths differ by more than ``edge_footprints``
    pixel footprints are not linked (a depth edge); connected linked pixels
    form one surface. ``neighbours`` (4, n): each pixel's linked east, south,
    west and north neighbour (its index among the graph's pixels, -1 where
    none), counter-clockwise in the image: consecutive ones span p's
    triangles (:func:`_pixel_normal`).
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

        # West and north are the inverse links of east and south, so that every
        # link goes both ways: judged from each end with its own footprint, a
        # pair at the threshold could be linked one way only, and a one-way
        # link joins two surfaces (whose splines would then share a pixel's rows).
        east, south = neighbour(0, 1), neighbour(1, 0)
        west, north = np.full(n, -1), np.full(n, -1)
        for fwd, back in ((east, west), (south, north)):
            has = np.flatnonzero(fwd >= 0)
            back[fwd[has]] = has
        self.neighbours = np.stack([east, south, west, north])
        p = np.concatenate([np.flatnonzero(east >= 0), np.flatnonzero(south >= 0)])
        q = np.concatenate([east[east >= 0], south[south >= 0]])
        g = sp.coo_matrix((np.ones(len(p)), (p, q)), shape=(n, n))
        self.n_surfaces, self.surface = connected_components(g, directed=False)
        self.index = np.arange(n)  # each pixel's index in the graph this one was cut from

    def subset(self, keep: np.ndarray) -> SurfaceGraph:
        """The graph of the surfaces ``keep`` (n_surfaces,) bool alone.

        Their pixels and links are unchanged (a link never joins two
        surfaces); the surfaces are numbered in their order here, and
        ``index`` gives each kept pixel's index in this graph.
        """
        import copy

        sel = keep[self.surface]
        out = copy.copy(self)
        idx = np.full(self.n, -1)
        idx[sel] = np.arange(int(sel.sum()))
        out.pix, out.rows, out.cols = self.pix[sel], self.rows[sel], self.cols[sel]
        out.n = int(sel.sum())
        nbr = self.neighbours[:, sel]
        # C order, as the constructor's: the compiled kernels that read it are then
        # compiled for one layout only (the mask's indexing returns Fortran order).
        out.neighbours = np.ascontiguousarray(np.where(nbr >= 0, idx[np.maximum(nbr, 0)], -1))
        out.surface = (np.cumsum(keep) - 1)[self.surface[sel]]
        out.n_surfaces = int(np.count_nonzero(keep))
        out.index = np.flatnonzero(sel)
        return out


@nb.njit(cache=True, inline="always")
def _cross(ax, ay, az, bx, by, bz):
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


@nb.njit(cache=True, inline="always")
def _pixel_normal(X, R, nbr, p, d):
    """Unit normal (towards the camera) of the depth map at pixel p, and its derivatives.

    The normal is the sum of the raw normals of p's triangles with its
    4-neighbours ``nbr[:, p]`` (east, south, west, north; -1 where missing):
    with all four, ``(X_e - X_w) x (X_s - X_n)``, the central-difference
    normal at p itself. ``d`` (5, 3) receives the derivatives of the unit
    normal with respect to the depths of p, east, south, west and north.
    Returns the normal, and the number of triangles (0: no normal).
    """
    rx, ry, rz = 0.0, 0.0, 0.0
    for j in range(5):
        d[j, 0] = 0.0
        d[j, 1] = 0.0
        d[j, 2] = 0.0
    m = 0
    for t in range(4):
        a, b = nbr[t, p], nbr[(t + 1) % 4, p]
        if a < 0 or b < 0:
            continue
        e1x, e1y, e1z = X[a, 0] - X[p, 0], X[a, 1] - X[p, 1], X[a, 2] - X[p, 2]
        e2x, e2y, e2z = X[b, 0] - X[p, 0], X[b, 1] - X[p, 1], X[b, 2] - X[p, 2]
        cx, cy, cz = _cross(e1x, e1y, e1z, e2x, e2y, e2z)
        rx, ry, rz = rx + cx, ry + cy, rz + cz
        # d(e1 x e2)/dz_p = R_p x (e1 - e2); /dz_a = R_a x e2; /dz_b = e1 x R_b
        qx, qy, qz = _cross(R[p, 0], R[p, 1], R[p, 2], e1x - e2x, e1y - e2y, e1z - e2z)
        d[0, 0] += qx
        d[0, 1] += qy
        d[0, 2] += qz
        qx, qy, qz = _cross(R[a, 0], R[a, 1], R[a, 2], e2x, e2y, e2z)
        d[1 + t, 0] += qx
        d[1 + t, 1] += qy
        d[1 + t, 2] += qz
        qx, qy, qz = _cross(e1x, e1y, e1z, R[b, 0], R[b, 1], R[b, 2])
        u = 1 + (t + 1) % 4
        d[u, 0] += qx
        d[u, 1] += qy
        d[u, 2] += qz
        m += 1
    ln = np.sqrt(rx * rx + ry * ry + rz * rz)
    if m == 0 or ln == 0.0:
        return 0.0, 0.0, 0.0, 0
    sg = -1.0 if rx * R[p, 0] + ry * R[p, 1] + rz * R[p, 2] > 0.0 else 1.0
    f = sg / ln
    nx, ny, nz = rx * f, ry * f, rz * f
    # d(unit N) = (I - N N^T) d(raw N) * sign / |raw N|
    for j in range(5):
        pq = d[j, 0] * nx + d[j, 1] * ny + d[j, 2] * nz
        d[j, 0] = (d[j, 0] - pq * nx) * f
        d[j, 1] = (d[j, 1] - pq * ny) * f
        d[j, 2] = (d[j, 2] - pq * nz) * f
    return nx, ny, nz, m


@nb.njit(cache=True, inline="always")
def _sampson(s, var, v, p, k, nx, ny, nz):
    """(w . N) / sqrt(N' C N) of pair k at pixel p, with the pieces of its derivative."""
    vax, vay, vaz = v[p, k, 0, 0], v[p, k, 0, 1], v[p, k, 0, 2]
    vbx, vby, vbz = v[p, k, 1, 0], v[p, k, 1, 1], v[p, k, 1, 2]
    sd2, ca, cb = row_variance(var[p, k, 0], var[p, k, 1], vax, vay, vaz, vbx, vby, vbz, nx, ny, nz)
    sd = np.sqrt(sd2)
    wx, wy, wz = hs_row(s[p, k, 0], s[p, k, 1], vax, vay, vaz, vbx, vby, vbz)
    r = (wx * nx + wy * ny + wz * nz) / sd
    return r, sd, sd2, ca, cb, wx, wy, wz


@nb.njit(parallel=True, cache=True)
def _pixel_chi2(X, R, s, var, v, valid, nbr, idx, chi2, count):
    """For each pixel ``p = idx[i]``: the summed squared Sampson residuals of its
    rows against its normal (:func:`_pixel_normal`), and the number of
    triangles that gave it, into ``chi2[p]`` and ``count[p]``. Its samples are
    row i of ``s``, ``var`` and ``v`` (read only where ``valid[p]``)."""
    P = s.shape[1]
    for i in nb.prange(len(idx)):
        p = idx[i]
        d = np.empty((5, 3))
        c = 0.0
        if not valid[p]:
            chi2[p] = 0.0
            count[p] = 0
            continue
        nx, ny, nz, m = _pixel_normal(X, R, nbr, p, d)
        if m > 0:
            for k in range(P):
                r = _sampson(s, var, v, i, k, nx, ny, nz)[0]
                c += r * r
        else:
            m = 0
        chi2[p] = c
        count[p] = m


@nb.njit(parallel=True, cache=True)
def _pixel_rows(X, R, s, var, v, ds, dv, valid, nbr, idx, weights, res, cols, vals):
    """The weighted Sampson residuals of E and their Jacobian entries.

    Row ``i * P + k`` is pair k against the normal of pixel ``p = idx[i]``,
    with entries at the depths of p and of its four neighbours (east, south,
    west, north; a missing one's entry is 0 at column p); rows of pixels
    without a normal are zero. Pixel p's samples are row i of ``s``, ``var``,
    ``v``, ``ds`` and ``dv`` (read only where ``valid[p]``).
    """
    P = s.shape[1]
    for i in nb.prange(len(idx)):
        p = idx[i]
        d = np.empty((5, 3))
        wt = np.sqrt(weights[p])
        for k in range(P):
            row = i * P + k
            res[row] = 0.0
            cols[row, 0] = p
            vals[row, 0] = 0.0
            for j in range(4):
                q = nbr[j, p]
                cols[row, 1 + j] = q if q >= 0 else p
                vals[row, 1 + j] = 0.0
        if not valid[p]:
            continue
        nx, ny, nz, m = _pixel_normal(X, R, nbr, p, d)
        if m == 0:
            continue
        for k in range(P):
            r, sd, sd2, ca, cb, wx, wy, wz = _sampson(s, var, v, i, k, nx, ny, nz)
            # d r / d N of (w . N) / sqrt(N' C N)
            ga, gb = var[i, k, 0] * ca * r / sd2, var[i, k, 1] * cb * r / sd2
            gx = wx / sd - ga * v[i, k, 0, 0] - gb * v[i, k, 1, 0]
            gy = wy / sd - ga * v[i, k, 0, 1] - gb * v[i, k, 1, 1]
            gz = wz / sd - ga * v[i, k, 0, 2] - gb * v[i, k, 1, 2]
            sa, sb, dsa, dsb = s[i, k, 0], s[i, k, 1], ds[i, k, 0], ds[i, k, 1]
            dwx = (
                dsa * v[i, k, 0, 0]
                + sa * dv[i, k, 0, 0]
                - dsb * v[i, k, 1, 0]
                - sb * dv[i, k, 1, 0]
            )
            dwy = (
                dsa * v[i, k, 0, 1]
                + sa * dv[i, k, 0, 1]
                - dsb * v[i, k, 1, 1]
                - sb * dv[i, k, 1, 1]
            )
            dwz = (
                dsa * v[i, k, 0, 2]
                + sa * dv[i, k, 0, 2]
                - dsb * v[i, k, 1, 2]
                - sb * dv[i, k, 1, 2]
            )
            row = i * P + k
            res[row] = r * wt
            vals[row, 0] = (
                (dwx * nx + dwy * ny + dwz * nz) / sd + gx * d[0, 0] + gy * d[0, 1] + gz * d[0, 2]
            ) * wt
            for j in range(4):
                if nbr[j, p] >= 0:
                    vals[row, 1 + j] = (gx * d[1 + j, 0] + gy * d[1 + j, 1] + gz * d[1 + j, 2]) * wt


def _usable_samples(s, var, ds) -> np.ndarray:
    """(N,) points whose every side's sample, derivative and variance are usable."""
    ok = np.all(np.isfinite(s), axis=(1, 2)) & np.all(np.isfinite(ds), axis=(1, 2))
    return ok & np.all(var > 0, axis=(1, 2))


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
    active: np.ndarray | None = None,
):
    """Residuals of E (see the module docstring) and their Jacobian over the depths.

    Parameters
    ----------
    z : (n,) depths of the graph's pixels, metres.
    R : (n, 3) their rays (unit z-depth). c_ref : (3,) the rays' origin.
    robust : Geman-McClure scale, in units of the noise per row.
    weights : per-pixel IRLS weights to use instead of rho'(chi2).
    jacobian : with False, J is None, the second value is each pixel's
        robust energy rho(chi2), NaN where its samples are unusable, and
        ``info["samples"]`` holds the sides E read, ``(s, var, v)`` of
        :func:`colourhs.reconstruct.sides.sample_sides` at the evaluated
        pixels (the active ones, in pixel order), for a caller that needs them
        without sampling the images again (the Jacobian's callers keep their
        rows for a whole step, and would keep these with them).
    scale : the Geman-McClure scale in chi2 units; default from the
        residuals (``robust^2 P`` times the larger of 1 and their median
        over its noise-only value), returned in ``info`` so that energies
        of several depth maps can be compared at one scale.
    active : (n,) bool, the pixels whose rows are evaluated (default all):
        J, r and ``jacobian_values`` hold their rows only, in pixel order
        (M = P times their number; the depth search's subsample, whose
        other pixels' rows would otherwise be zeros filling most of every
        array); the others are unusable (their depths still give the active
        pixels' normals).

    Returns
    -------
    J : sparse (M, n) Jacobian, r : (M,) IRLS-weighted residuals (r . r is
    the quadratic model of the robust energy), info : dict with ``valid``
    (n,) rows usable, ``weights`` (n,) (also without the Jacobian),
    ``chi2`` (n,) summed squared normalised residual of the pixel's P rows,
    ``scale`` and, with the Jacobian, ``jacobian_values`` (M, 5): row
    ``i P + k``'s entries at the i-th evaluated pixel p and its east, south,
    west and north neighbours (J's values in that order).
    """
    n = graph.n
    X = c_ref + R * z[:, None]
    if active is None:
        s, var, v, ds, dv = sample_sides(sides, X, R)
        valid = _usable_samples(s, var, ds)
        idx = np.arange(n)
    else:  # the active pixels' samples and rows only
        idx = np.flatnonzero(active)
        s, var, v, ds, dv = sample_sides(sides, X[idx], R[idx])
        valid = np.zeros(n, bool)
        valid[idx] = _usable_samples(s, var, ds)
    P = s.shape[1]
    nbr = graph.neighbours
    chi2 = np.zeros(n)
    count = np.zeros(n)
    _pixel_chi2(X, R, s, var, v, valid, nbr, idx, chi2, count)
    usable = valid & (count > 0)
    if scale is None:
        # The robust scale: the noise model's, or the residuals' own where the
        # model (rendering, sampling, calibration) leaves more than the noise:
        # the median of a chi-square with P degrees of freedom is about P - 2/3.
        used = chi2[usable]
        level = max(1.0, float(np.median(used)) / (P - 2.0 / 3.0)) if len(used) else 1.0
        scale = level * robust**2 * P
    if weights is None:
        weights = 1.0 / (1.0 + chi2 / scale) ** 2  # rho'(chi2): IRLS
    w = np.ascontiguousarray(weights, float)
    info = {"valid": usable, "weights": w, "chi2": chi2, "scale": scale}
    if not jacobian:
        info["samples"] = (s, var, v)
        return None, robust_energy(chi2, usable, scale), info
    res = np.empty(len(idx) * P)
    # 32-bit indices: scipy keeps them as they are, where 64-bit ones are
    # checked and copied down to 32 bits on every call.
    index = np.int32 if 5 * len(res) < np.iinfo(np.int32).max and n < 2**31 else np.int64
    cols = np.empty((len(res), 5), index)
    vals = np.empty((len(res), 5))
    _pixel_rows(X, R, s, var, v, ds, dv, valid, nbr, idx, w, res, cols, vals)
    indptr = np.arange(0, 5 * len(res) + 1, 5, dtype=index)
    J = sp.csr_matrix((vals.ravel(), cols.ravel(), indptr), shape=(len(res), n))
    info["jacobian_values"] = vals
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


def surface_normals(graph: SurfaceGraph, z: np.ndarray, rays, c_ref) -> np.ndarray:
    """Unit normals (towards the camera) of a depth map at the graph's pixels.

    The normal E compares each pixel's eq. (5) rows with (:func:`_pixel_normal`):
    central differences over the pixel's linked neighbours, one-sided at a
    surface's edge, never across a depth edge. ``z`` (graph.n,) z-depths,
    metres, along ``rays`` (H*W, 3, unit z-depth) from ``c_ref``. NaN rows
    where a pixel has no two consecutive linked neighbours (no triangle).
    """
    R = np.ascontiguousarray(rays[graph.pix], float)
    return pixel_normals(graph, c_ref + R * np.asarray(z, float)[:, None], R)


def pixel_normals(graph: SurfaceGraph, X: np.ndarray, R: np.ndarray) -> np.ndarray:
    """:func:`surface_normals` of the graph's points ``X`` (graph.n, 3) on their rays
    ``R`` (graph.n, 3): unit normals towards the camera, NaN where none."""
    out = np.empty((graph.n, 3))
    _pixel_normals(
        np.ascontiguousarray(X, float), np.ascontiguousarray(R, float), graph.neighbours, out
    )
    return out


@nb.njit(parallel=True, cache=True)
def _pixel_normals(X, R, nbr, out):
    """:func:`_pixel_normal` of every pixel into ``out`` (n, 3); NaN where none."""
    for p in nb.prange(X.shape[0]):
        d = np.empty((5, 3))
        nx, ny, nz, m = _pixel_normal(X, R, nbr, p, d)
        if m == 0:
            nx, ny, nz = np.nan, np.nan, np.nan
        out[p, 0] = nx
        out[p, 1] = ny
        out[p, 2] = nz
