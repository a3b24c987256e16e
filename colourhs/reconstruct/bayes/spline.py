"""Cubic B-spline depth maps, one control grid per surface (beyond the paper).

The Bayesian refinement (:mod:`colourhs.reconstruct.bayes.surface`) represents
each connected surface's depth map by a uniform cubic B-spline over the
image: few free depth modes, so the estimate cannot chase the noise of
individual samples (a per-pixel surface can, and then drifts).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp


def default_spacing(width: int) -> float:
    """Spline control spacing in pixels: 1/120 of the image width (at least 4).

    Beyond the paper (its Bayesian HS has no spline). The spacing trades the
    detail a spline can hold for the number of free depth modes the noise
    can exploit. A fraction of the width is a fixed field angle, so the same
    detail of an object at any resolution, and more pixels per control point
    (less noise per mode) as the resolution grows; 4 px is the floor under
    which a control point is no longer constrained by the pixels around it
    (at 480 px wide and less the floor applies). A coarser grid cannot hold
    a statue's detail, a finer one gives the noise more modes to bend.
    """
    return max(4.0, width / 120.0)


def cubic_weights(t: np.ndarray) -> np.ndarray:
    """Uniform cubic B-spline weights (N, 4) at fractional positions t in [0, 1)."""
    t2, t3 = t * t, t * t * t
    return (
        np.stack([(1 - t) ** 3, 3 * t3 - 6 * t2 + 4, -3 * t3 + 3 * t2 + 3 * t + 1, t3], axis=-1)
        / 6.0
    )


class SplineSurface:
    """Cubic B-spline depth maps, one control grid per surface.

    Surface k's control points sit every ``spacing_px`` pixels from the top
    left of its pixels' bounding box; only those that some pixel of the
    surface uses are unknowns, numbered surface by surface
    (``surface_of[j]`` is control point j's surface).

    Parameters
    ----------
    rows, cols : (n,) pixel coordinates of the surfaces' pixels.
    surface : (n,) each pixel's surface, 0 .. n_surfaces - 1.
    spacing_px : control point spacing, pixels.
    """

    def __init__(self, rows, cols, surface, spacing_px: float):
        self.spacing = float(spacing_px)
        self.grids = []  # (row0, col0, ni, nj, remap) per surface
        owner, coords = [], []
        m = 0
        for k in range(int(surface.max()) + 1 if len(surface) else 0):
            sel = surface == k
            r0, c0 = int(rows[sel].min()), int(cols[sel].min())
            ki = np.floor((rows[sel] - r0) / self.spacing).astype(int)
            kj = np.floor((cols[sel] - c0) / self.spacing).astype(int)
            ni, nj = int(ki.max()) + 4, int(kj.max()) + 4
            used = np.zeros(ni * nj, bool)
            for a in range(4):
                for b in range(4):
                    used[(ki + a) * nj + (kj + b)] = True
            remap = np.full(ni * nj, -1)
            remap[used] = m + np.arange(used.sum())
            self.grids.append((r0, c0, ni, nj, remap))
            owner.append(np.full(int(used.sum()), k))
            coords.append(np.divmod(np.flatnonzero(used), nj))
            m += int(used.sum())
        self.size = m
        self.surface_of = np.concatenate(owner) if owner else np.zeros(0, int)
        #: (2, m) each control point's row and column in its surface's grid.
        self.grid_coords = np.concatenate(coords, axis=1) if coords else np.zeros((2, 0), int)
        self.basis = self.rows_for(rows, cols, surface)[0]

    def rows_for(self, rows, cols, surfaces) -> tuple[sp.csr_matrix, np.ndarray]:
        """Basis rows (N, m) of pixels (rows, cols) on the given surfaces.

        Returns the sparse basis and whether each pixel lies on its surface's
        control grid (rows of pixels that do not are empty).
        """
        n = len(rows)
        R, C, V = [], [], []
        inside = np.zeros(n, bool)
        for surface, (r0, c0, ni, nj, remap) in enumerate(self.grids):
            sel = np.flatnonzero(surfaces == surface)
            if not len(sel):
                continue
            gi = (rows[sel] - r0) / self.spacing
            gj = (cols[sel] - c0) / self.spacing
            ki, kj = np.floor(gi).astype(int), np.floor(gj).astype(int)
            ok = (ki >= 0) & (kj >= 0) & (ki + 3 < ni) & (kj + 3 < nj)
            ids = [np.where(ok, (ki + a) * nj + (kj + b), 0) for a in range(4) for b in range(4)]
            for cid in ids:
                ok &= remap[cid] >= 0
            wi, wj = cubic_weights(gi - ki), cubic_weights(gj - kj)
            for (a, b), cid in zip(((a, b) for a in range(4) for b in range(4)), ids, strict=True):
                R.append(sel[ok])
                C.append(remap[cid[ok]])
                V.append((wi[:, a] * wj[:, b])[ok])
            inside[sel[ok]] = True
        if not R:
            return sp.csr_matrix((n, self.size)), inside
        B = sp.csr_matrix(
            (np.concatenate(V), (np.concatenate(R), np.concatenate(C))), shape=(n, self.size)
        )
        return B, inside

    def second_differences(self) -> tuple[sp.csr_matrix, np.ndarray]:
        """D (k, m): second differences of neighbouring control points along rows and
        columns, and each row's surface (k,)."""
        R, C, V, S = [], [], [], []
        k = 0
        for surface, (_, _, ni, nj, remap) in enumerate(self.grids):
            grid = remap.reshape(ni, nj)
            for c0, c1, c2 in (
                (grid[:, :-2], grid[:, 1:-1], grid[:, 2:]),
                (grid[:-2], grid[1:-1], grid[2:]),
            ):
                ok = (c0 >= 0) & (c1 >= 0) & (c2 >= 0)
                r = k + np.arange(ok.sum())
                for c, coef in ((c0, 1.0), (c1, -2.0), (c2, 1.0)):
                    R.append(r)
                    C.append(c[ok])
                    V.append(np.full(ok.sum(), coef))
                S.append(np.full(ok.sum(), surface))
                k += int(ok.sum())
        if not R:
            return sp.csr_matrix((0, self.size)), np.zeros(0, int)
        D = sp.csr_matrix(
            (np.concatenate(V), (np.concatenate(R), np.concatenate(C))), shape=(k, self.size)
        )
        return D, np.concatenate(S)
