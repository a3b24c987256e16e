"""The refinement's Gauss-Newton matrix ``B^T J^T J B``, assembled in one pass.

Beyond the paper (numerics only). Each Levenberg-Marquardt step of
:mod:`colourhs.reconstruct.bayes.refine` needs ``A = B^T J^T J B``: ``J`` the
Jacobian of the rows of eq. (5) over the pixels' depths (each row has
entries at a pixel and its four neighbours,
:func:`~colourhs.reconstruct.bayes.surface.hs_residuals`),
``B`` the cubic B-spline basis (each pixel a 4 x 4 patch of control points,
:class:`~colourhs.reconstruct.bayes.spline.SplineSurface`). Three general sparse
products (``J^T J``, ``. B``, ``B^T .``) with their symbolic passes and
transposes would be a large share of each step.

Here the pattern of ``A`` is found once per spline (it depends only on the
pixels' links and patches, not on the values), and each step fills its
values in one pass over the pixels: a pixel's rows touch at most a 6 x 6
block of its surface's control grid (its own patch and its neighbours',
which are shifted by at most one control point for a spacing of at least
one pixel, checked), so each pixel adds the Gram matrix of its ``P`` rows,
expressed on that block, to a dense 36 x 36 block per cell (the pixels of
one patch), which is added to ``A``'s values once per cell through a map
from (control point, grid offset within 11 x 11) to the value's index.
Each thread adds into its own copy of the values (no races); the copies
are summed. The result equals the sparse products' to rounding (the sums
run in another order).
"""

from __future__ import annotations

import numba as nb
import numpy as np
import scipy.sparse as sp

SPAN = 11  # control-grid offsets -5 .. 5 in each direction (a 6 x 6 block's differences)
HALF = SPAN // 2


@nb.njit(parallel=True, cache=True)
def _fill(vals, rows, nbr, bcols, bvals, gi, gj, order, starts, row_of, pos, out, cols):
    """Add each pixel's rows' Gram matrix into ``out`` (chunks, nnz): A's values.

    ``rows`` is any tuple of length P (the rows per pixel): a tuple's length
    is part of its numba type, so P is a compile-time constant and the
    loops over the rows unroll (one compiled kernel per P, cached): faster
    than P passed as an integer, with the same values to the bit. ``vals``
    (M P, 5): row ``row_of[p] P + k``'s entries at pixel p and
    its east, south, west and north neighbours (``nbr`` (4, n), -1 = none); ``bcols``,
    ``bvals`` (n, 16): each pixel's control points, row by row of its 4 x 4
    patch from the top left, and basis weights; ``gi``, ``gj`` (m,): each
    control point's coordinates in its surface's grid. ``order`` lists the
    pixels cell by cell (the pixels of one patch together), cell c being
    ``order[starts[c]:starts[c + 1]]``: a cell's pixels add into one dense
    36 x 36 block (its 6 x 6 control points), added to A once per cell at
    ``pos`` (m, SPAN^2): the index in A's values of control point a's
    neighbour at each grid offset. With ``cols`` (m, SPAN^2) not empty it is
    the pattern pass instead: ``cols`` receives the column (control point)
    of every slot touched.
    """
    P = len(rows)
    chunks = out.shape[0]
    n_cells = len(starts) - 1
    pattern = cols.shape[0] > 0
    for t in nb.prange(chunks):
        L = np.zeros((36, P))
        v = np.empty(P)
        acc = np.zeros((36, 36))
        ids = np.full(36, -1, np.int64)
        used = np.zeros(36, np.bool_)
        lst = np.empty(36, np.int64)
        for cell in range(t * n_cells // chunks, (t + 1) * n_cells // chunks):
            first = bcols[order[starts[cell]], 0]
            bi = gi[first] - 1
            bj = gj[first] - 1
            for i in range(starts[cell], starts[cell + 1]):
                p = order[i]
                for j in range(5):
                    q = p if j == 0 else nbr[j - 1, p]
                    if q < 0:
                        continue
                    for k in range(P):
                        v[k] = vals[row_of[p] * P + k, j]
                    top = bcols[q, 0]
                    loc0 = (gi[top] - bi) * 6 + (gj[top] - bj)
                    for a in range(4):
                        for b in range(4):
                            loc = loc0 + a * 6 + b
                            ids[loc] = bcols[q, a * 4 + b]
                            used[loc] = True
                            w = bvals[q, a * 4 + b]
                            for k in range(P):
                                L[loc, k] += v[k] * w
                cnt = 0
                for loc in range(36):
                    if used[loc]:
                        lst[cnt] = loc
                        cnt += 1
                        used[loc] = False
                for a in range(cnt):
                    la = lst[a]
                    for b in range(a, cnt):
                        lb = lst[b]
                        s = 0.0
                        for k in range(P):
                            s += L[la, k] * L[lb, k]
                        acc[la, lb] += s
                for a in range(cnt):
                    for k in range(P):
                        L[lst[a], k] = 0.0
            for la in range(36):
                ca = ids[la]
                if ca < 0:
                    continue
                for lb in range(la, 36):
                    cb = ids[lb]
                    if cb < 0:
                        continue
                    s = acc[la, lb]
                    acc[la, lb] = 0.0
                    fwd = (gi[cb] - gi[ca] + HALF) * SPAN + gj[cb] - gj[ca] + HALF
                    back = SPAN * SPAN - 1 - fwd
                    if pattern:
                        cols[ca, fwd] = cb
                        cols[cb, back] = ca
                    else:
                        out[t, pos[ca, fwd]] += s
                        if lb != la:
                            out[t, pos[cb, back]] += s
            ids[:] = -1


def check_links(bcols, gi, gj, neighbours) -> None:
    """Refuse a pixel graph whose rows :func:`_fill` cannot place in a 6 x 6 block.

    Every link must join two pixels of one surface whose patches are shifted
    by at most one control point (a spacing of at least one pixel). Two such
    4 x 4 patches share the control point at the larger of their first rows
    and columns; a link into another surface (its own control grid, perhaps
    at the same grid coordinates) shares none, so it shows as two different
    columns there.

    Parameters
    ----------
    bcols : (n, 16) each pixel's patch columns, in row-major grid order.
    gi, gj : (m,) each control point's row and column in its surface's grid.
    neighbours : (4, n) the pixel graph's links (-1: none).

    Raises
    ------
    ValueError
        Naming the problem: a spacing under one pixel, or a link between two
        surfaces (a pixel graph whose links are not symmetric, for example).
    """
    kind, bad = _bad_link(bcols, gi, gj, neighbours)
    if kind == 1:
        raise ValueError("spline control spacing under one pixel: use 1 px or more")
    if kind == 2:
        raise ValueError(
            f"pixel graph links pixel {bad} to another surface's pixel: every link "
            "must join two pixels of one surface, both ways"
        )


@nb.njit(cache=True)
def _bad_link(bcols, gi, gj, neighbours):
    """The first link :func:`check_links` refuses: (kind, pixel), kind 0 for
    none, 1 for patches more than one control point apart, 2 for patches
    that do not share their common control point."""
    for j in range(neighbours.shape[0]):
        for i in range(neighbours.shape[1]):
            q = neighbours[j, i]
            if q < 0:
                continue
            a, b = bcols[i, 0], bcols[q, 0]
            di, dj = gi[b] - gi[a], gj[b] - gj[a]
            if abs(di) > 1 or abs(dj) > 1:
                return 1, i
            # The shared control point's place in each patch (row-major 4 x 4).
            own = 4 * max(di, 0) + max(dj, 0)
            other = 4 * max(-di, 0) + max(-dj, 0)
            if bcols[i, own] != bcols[q, other]:
                return 2, i
    return 0, -1


class SplineGram:
    """``A = B^T J^T J B`` for one spline and pixel graph (see the module docstring).

    Parameters
    ----------
    B : (n, m) sparse basis, 16 entries per row (every pixel on its grid), of a
        spline whose control spacing is at least one pixel (ValueError otherwise).
    grid_coords : (2, m) each control point's row and column in its
        surface's control grid.
    neighbours : (4, n) the pixel graph's east, south, west, north links.
    pairs : P, the rows per pixel.
    pixels : (n,) bool, the pixels whose rows count (default all; the
        others' rows are taken as zero). :meth:`matrix`'s ``vals`` then
        hold their rows only, in pixel order (as
        :func:`~colourhs.reconstruct.bayes.surface.hs_residuals` gives them with ``active``).
    """

    def __init__(self, B: sp.csr_matrix, grid_coords, neighbours, pairs: int, pixels=None):
        B = sp.csr_matrix(B)
        B.sort_indices()
        n, m = B.shape
        if not np.all(np.diff(B.indptr) == 16):
            raise ValueError("every pixel needs its full 4 x 4 spline patch")
        self.bcols = B.indices.reshape(n, 16).astype(np.int64)
        self.bvals = np.ascontiguousarray(B.data.reshape(n, 16), float)
        self.gi, self.gj = (np.ascontiguousarray(g, np.int64) for g in grid_coords)
        self.nbr = np.ascontiguousarray(neighbours, np.int64)
        self.P, self.m = int(pairs), m
        # The 6 x 6 block holds a pixel's rows only if its neighbours' patches are
        # shifted by at most one control point (a spacing of at least one pixel);
        # the kernel does not check its indices, so refuse anything else here.
        check_links(self.bcols, self.gi, self.gj, self.nbr)
        # The pixels cell by cell: a pixel's cell is its patch's first control point.
        sel = np.arange(n) if pixels is None else np.flatnonzero(pixels)
        self.row_of = np.zeros(n, np.int64)  # pixel p's rows in vals: row_of[p] P + k
        self.row_of[sel] = np.arange(len(sel))
        self.order = sel[np.argsort(self.bcols[sel, 0], kind="stable")]
        cell_of = self.bcols[self.order, 0]
        self.starts = np.flatnonzero(np.r_[True, cell_of[1:] != cell_of[:-1], True])
        if len(sel) == 0:
            self.starts = np.zeros(1, np.int64)
        cols = np.full((m, SPAN * SPAN), -1, np.int64)
        self.pos = np.zeros((0, SPAN * SPAN), np.int64)
        self._run(np.zeros((len(sel) * self.P, 5)), np.zeros((1, 0)), cols)
        has = cols >= 0
        self.pos = np.full((m, SPAN * SPAN), -1, np.int64)
        self.pos[has] = np.arange(int(has.sum()))
        self.indices = cols[has]  # row by row, in increasing grid (and so column) order
        self.indptr = np.concatenate([[0], np.cumsum(has.sum(axis=1))])

    def _run(self, vals, out, cols):
        _fill(
            np.ascontiguousarray(vals, float),
            (0,) * self.P,
            self.nbr,
            self.bcols,
            self.bvals,
            self.gi,
            self.gj,
            self.order,
            self.starts,
            self.row_of,
            self.pos,
            out,
            cols,
        )

    def matrix(self, vals: np.ndarray) -> sp.csr_matrix:
        """``B^T J^T J B`` (m, m) for the Jacobian entries ``vals`` (M P, 5) of the
        pixels whose rows count (all n, or ``pixels``), in pixel order."""
        out = np.zeros((nb.get_num_threads(), len(self.indices)))
        self._run(vals, out, np.empty((0, SPAN * SPAN), np.int64))
        return sp.csr_matrix((out.sum(axis=0), self.indices, self.indptr), shape=(self.m,) * 2)
