"""Maximum-likelihood colour HS per pixel (paper section III-A: standard ML HS).

The paper's ML HS picks, per pixel, the depth hypothesis of best data cost
(eq. 5). With three reciprocal pairs that choice is ambiguous even on exact
data: along a ray, det W(z) = 0 has roots besides the surface (several per
pixel within the working range, some with a cost of zero), so the best
hypothesis is often not the surface. Beyond the paper, this module keeps the
paper's per-pixel data but
decides between the roots as Zickler et al.'s original HS does, with a
window: each candidate root of a pixel, with its HS normal, defines a
tangent plane; the candidate whose plane also explains the rows of the
pixel's 8 neighbours (their points on that plane, eq. 5 residuals in noise
units against the plane's normal) wins. On the true surface every
neighbour agrees to second order in the pixel spacing; at a false root the
neighbours' rows disagree with its normal. The depth is the root's
continuous minimum (:func:`refine_ml`): each candidate takes ``PRESELECT``
of its rounds before the window chooses, the chosen one the rest (by then a
candidate is close enough to its minimum for the window to judge it, and
the losers' remaining rounds would change nothing).
"""

from __future__ import annotations

import warnings

import numba as nb
import numpy as np

from colourhs.reconstruct.constraint import hs_row, row_variance
from colourhs.reconstruct.sides import HelmholtzSides, sample_sides, whitened_cost

CANDIDATES = 4  # local minima of the per-pixel cost kept as candidate roots
CONVERGED_STEPS = 1e-3  # refine_ml: a move under this many labels has converged
ROUNDS = 6  # refine_ml's parabola rounds per pixel
PRESELECT = 2  # of them, the rounds before the window chooses among the candidates
WINDOW = ((-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1))


def candidate_labels(
    cost: np.ndarray, max_cost: float, k: int = CANDIDATES, chunk: int = 65536
) -> np.ndarray:
    """(N, k) labels of each pixel's ``k`` best local minima of ``cost`` (N, L); -1 = none.

    A local minimum is a label whose cost is at most its neighbours' and below
    ``max_cost``; the ends of the range count when they are minima too.
    ``chunk`` pixels at a time (bounds the temporaries: a few (chunk, L) arrays).
    """
    out = np.empty((len(cost), min(k, cost.shape[1])), np.int64)
    for s in range(0, len(cost), chunk):
        out[s : s + chunk] = _candidates(cost[s : s + chunk], max_cost, k)
    return out


def _candidates(cost, max_cost, k):
    c = np.asarray(cost, np.float32)
    left = np.concatenate([np.full((len(c), 1), np.inf, np.float32), c[:, :-1]], axis=1)
    right = np.concatenate([c[:, 1:], np.full((len(c), 1), np.inf, np.float32)], axis=1)
    minima = (c <= left) & (c < right) & (c < max_cost)
    score = np.where(minima, c, np.inf)
    k = min(k, c.shape[1])
    idx = np.argpartition(score, k - 1, axis=1)[:, :k]
    best = np.take_along_axis(score, idx, axis=1)
    order = np.argsort(best, axis=1)
    idx = np.take_along_axis(idx, order, axis=1)
    return np.where(np.isfinite(np.take_along_axis(best, order, axis=1)), idx, -1)


def refine_ml(
    z: np.ndarray,
    cost,
    step_m: float,
    iterations: int = ROUNDS,
    tol: float = CONVERGED_STEPS,
    h: np.ndarray | None = None,
    say=None,
) -> tuple[np.ndarray, np.ndarray]:
    """Continuous per-pixel ML depth: the minimum of each pixel's own cost near ``z``.

    Beyond the paper (whose ML HS picks the best hypothesis): ``cost`` is the
    noise-weighted per-pixel cost of eq. (5) (:func:`whitened_cost`); near
    its minimum it is a parabola in the depth (0 at the true depth on exact
    data), so three evaluations at z - h, z, z + h give the vertex, and
    ``iterations`` Newton-like rounds from h = half a label converge to it.

    Also beyond the paper, for speed: a pixel leaves the rounds once its cost
    is unusable at its own depth (it could never move again) or once a
    parabola's vertex moved it by at most ``tol`` labels (the rounds converge
    fast, so most pixels settle early), and later rounds evaluate the cost
    only where it still changes anything.

    Parameters
    ----------
    z : (N,) starting depths (a candidate label plus its parabola), metres.
    cost : callable (depths (M,), pixels (M,) indices into z) -> (M,) cost
        of those pixels at those depths (NaN where unusable).
    step_m : the label spacing, metres.
    tol : the move, in labels, under which a pixel has converged.
    h : (N,) half-widths to start from (default half a label), e.g. those
        an earlier call returned, to go on where it stopped.
    say : called with a line of text before each round (progress: a round
        takes seconds at high resolution), if given.

    Returns
    -------
    z : (N,) depths, metres; h : (N,) the half-widths the next round would use.
    """
    z = np.array(z, float)
    h = np.full(len(z), step_m / 2.0) if h is None else np.array(h, float)
    todo = np.arange(len(z))
    for i in range(iterations):
        if not len(todo):
            break
        if say is not None:
            say(f"ml: parabola round {i + 1} of {iterations} ({len(todo)} pixels)")
        zt, ht = z[todo], h[todo]
        c = cost(np.concatenate([zt - ht, zt, zt + ht]), np.tile(todo, 3))
        cm, c0, cp = c.reshape(3, -1)
        ok = np.isfinite(cm) & np.isfinite(c0) & np.isfinite(cp)
        den = np.where(ok, cm - 2 * c0 + cp, 0.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            off = np.where(den > 0, 0.5 * (cm - cp) / den, 0.0)
        # The vertex of a parabola through the cost; at most two half-widths per
        # step, and the next half-width follows the step (a Newton iteration).
        off = np.clip(np.nan_to_num(off), -2.0, 2.0)
        z[todo] = np.where(ok, zt + off * ht, zt)
        h[todo] = np.clip(np.abs(off) * ht, ht / 8.0, ht)
        settled = ok & (den > 0) & (np.abs(off) * ht <= tol * step_m)
        todo = todo[~(settled | np.isnan(c0))]
    return z, h


def plane_chi2(sides: HelmholtzSides, X: np.ndarray, R: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Eq. (5) residuals of points ``X`` (N, 3) against normals ``n`` (N, 3), in noise units.

    Sum over the pairs of ``(w_k . n)^2 / (var_a (v_a . n)^2 + var_b (v_b . n)^2)``
    (the Sampson form); NaN where a sample is unusable. Compiled, one pass
    per point (:func:`_plane_chi2`).
    """
    s, var, v, _, _ = sample_sides(sides, X, R, derivatives=False)
    out = np.empty(len(s))
    _plane_chi2(s, var, v, np.ascontiguousarray(n, float), out)
    return out


@nb.njit(parallel=True, cache=True, error_model="numpy")
def _plane_chi2(s, var, v, n, out):
    """:func:`plane_chi2` per point, into ``out`` (N,).

    Beyond the paper (speed): replaces NumPy's five (N, P, 3) temporaries and
    three einsums. The dot products sum x, y, z in order, where einsum sums
    (x + z) + y, so values may differ from NumPy's in the last bits, far
    below anything the window's median tells apart. Division as NumPy's
    (``error_model="numpy"``): x / 0 is inf or NaN, not an error.
    """
    P = s.shape[1]
    for i in nb.prange(s.shape[0]):
        nx, ny, nz = n[i, 0], n[i, 1], n[i, 2]
        total = 0.0
        for k in range(P):
            vax, vay, vaz = v[i, k, 0, 0], v[i, k, 0, 1], v[i, k, 0, 2]
            vbx, vby, vbz = v[i, k, 1, 0], v[i, k, 1, 1], v[i, k, 1, 2]
            wx, wy, wz = hs_row(s[i, k, 0], s[i, k, 1], vax, vay, vaz, vbx, vby, vbz)
            sd2 = row_variance(
                var[i, k, 0], var[i, k, 1], vax, vay, vaz, vbx, vby, vbz, nx, ny, nz
            )[0]
            r = wx * nx + wy * ny + wz * nz
            total += r * r / sd2
        out[i] = total


def window_score(
    sides: HelmholtzSides,
    c_ref: np.ndarray,
    rays: np.ndarray,
    pix: np.ndarray,
    z: np.ndarray,
    n: np.ndarray,
    shape: tuple[int, int],
) -> np.ndarray:
    """Median over a pixel's 8 neighbours of their eq. (5) chi2 on its tangent plane.

    Parameters
    ----------
    rays : (H*W, 3) rays with unit z-depth; pix : (N,) pixels; z : (N,)
    candidate depths; n : (N, 3) candidate normals (unit); shape : (H, W).

    Returns (N,) scores (inf where fewer than 4 neighbours are usable). The
    median keeps a neighbour across a depth edge from vetoing a good
    candidate.
    """
    H, W = shape
    rows, cols = np.divmod(pix, W)
    X = c_ref + rays[pix] * z[:, None]
    d = np.einsum("nk,nk->n", n, X - c_ref)
    out = np.full((len(pix), len(WINDOW)), np.nan)
    for j, (di, dj) in enumerate(WINDOW):
        i2, j2 = rows + di, cols + dj
        inside = (i2 >= 0) & (i2 < H) & (j2 >= 0) & (j2 < W)
        q = np.where(inside, i2 * W + j2, pix)
        rq = rays[q]
        with np.errstate(invalid="ignore", divide="ignore"):
            t = d / np.einsum("nk,nk->n", n, rq)
        ok = inside & np.isfinite(t) & (t > 0)
        Xq = c_ref + rq * np.where(ok, t, z)[:, None]
        chi2 = plane_chi2(sides, Xq, rq, n)
        out[:, j] = np.where(ok, chi2, np.nan)
    usable = np.sum(np.isfinite(out), axis=1)
    with warnings.catch_warnings():  # all-NaN rows (fewer than 4 usable) are expected
        warnings.simplefilter("ignore", RuntimeWarning)
        med = np.nanmedian(np.where(usable[:, None] >= 4, out, np.nan), axis=1)
    return np.where(usable >= 4, med, np.inf)


def ml_depth(
    cost: np.ndarray,
    depths: np.ndarray,
    pix: np.ndarray,
    rays: np.ndarray,
    c_ref: np.ndarray,
    sides: HelmholtzSides,
    shape: tuple[int, int],
    max_cost: float,
    say=None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ML HS depth, normal and validity of the pixels ``pix`` (module docstring).

    Parameters
    ----------
    cost : (N, L) the data term over the hypotheses ``depths`` (L,), metres.
    rays : (H*W, 3) rays with unit z-depth from ``c_ref``.
    max_cost : hypotheses costing more are no candidates.
    say : called with a line of text per candidate, per parabola round and
        before each candidate's window scores (progress), if given.

    Returns
    -------
    z : (N,) depths (metres), normal : (N, 3), valid : (N,) bool.
    """
    labels = candidate_labels(cost, max_cost)
    step = float(depths[1] - depths[0])
    R = rays[pix]
    N, K = labels.shape
    best_z = np.full(N, np.nan)
    best_h = np.full(N, np.nan)
    best_s = np.full(N, np.inf)

    def own_cost(at):
        """refine_ml's cost of the pixels ``at`` (indices into pix)."""

        def cost_of(depth, i):
            Ri = R[at[i]]
            return whitened_cost(sides, c_ref + Ri * depth[:, None], Ri)[0]

        return cost_of

    for k in range(K):
        on = np.flatnonzero(labels[:, k] >= 0)
        if not len(on):
            break
        if say is not None:
            say(f"ml: candidate {k + 1} of {K} ({len(on)} pixels)")
        lab = labels[on, k]
        lm = np.clip(lab - 1, 0, len(depths) - 1)
        lp = np.clip(lab + 1, 0, len(depths) - 1)
        cm, c0, cp = cost[on, lm], cost[on, lab], cost[on, lp]
        den = cm - 2 * c0 + cp
        with np.errstate(invalid="ignore", divide="ignore"):
            off = np.where(den > 0, 0.5 * (cm - cp) / den, 0.0)
        z0 = depths[lab] + np.clip(np.nan_to_num(off), -0.5, 0.5) * step
        z, h = refine_ml(z0, own_cost(on), step, PRESELECT, say=say)
        if say is not None:
            say(f"ml: candidate {k + 1}: its tangent-plane window scores")
        chi2, n = whitened_cost(sides, c_ref + R[on] * z[:, None], R[on])
        score = window_score(sides, c_ref, rays, pix[on], z, n, shape)
        score = np.where(np.isfinite(chi2), score, np.inf)
        take = score < best_s[on]
        best_z[on[take]], best_h[on[take]], best_s[on[take]] = z[take], h[take], score[take]
    # Beyond the paper, for speed: the window chooses after PRESELECT rounds
    # (a candidate is then within a small fraction of a label of its minimum),
    # and only the chosen candidate takes the remaining rounds.
    win = np.flatnonzero(np.isfinite(best_s))
    best_n = np.full((N, 3), np.nan)
    valid = np.zeros(N, bool)
    if not len(win):
        return best_z, best_n, valid
    if say is not None:
        say(f"ml: {ROUNDS - PRESELECT} more rounds on the {len(win)} chosen roots")
    z, _ = refine_ml(best_z[win], own_cost(win), step, ROUNDS - PRESELECT, h=best_h[win], say=say)
    chi2, n = whitened_cost(sides, c_ref + R[win] * z[:, None], R[win])
    best_z[win] = z
    best_n[win] = n
    valid[win] = np.isfinite(chi2)
    return best_z, best_n, valid
