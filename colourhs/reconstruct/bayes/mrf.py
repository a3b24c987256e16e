"""Semi-global MRF optimisation for Bayesian Helmholtz stereopsis.

The paper (section III-E) adopts the Bayesian HS formulation of Roubtsova and
Guillemaut [8]: a depth labelling of the reference camera minimises

    E = alpha * E_data + (1 - alpha) * E_prior,

where ``E_prior`` is the *depth-normal consistency* prior: the normal
hypothesised with a depth at one pixel must agree with the depths chosen at
its neighbours. This module minimises that energy approximately with
semi-global matching (SGM, H. Hirschmueller, "Stereo Processing by
Semiglobal Matching and Mutual Information", TPAMI 30(2), 2008), replacing
SGM's constant P1/P2 smoothness penalty by the depth-normal prior below.

Prior
-----
Pixel ``p`` with label ``k`` (depth ``depths[k]``) and hypothesised unit normal
``n = normals[p, k]`` defines the tangent plane through
``X_p(k) = c + depths[k] * r_p``. The ray of a neighbour ``q`` meets that plane
at depth ``z_hat = depths[k] * (n . r_p) / (n . r_q)`` (``c`` cancels), i.e. at
the fractional label ``j_hat = (z_hat - depths[0]) / dz``, with ``dz`` the
(uniform) label spacing. The pairwise cost of ``q`` taking label ``k'`` is::

    V(p, k; q, k') = min(|k' - j_hat|, tau)

and ``V = tau`` for every ``k'`` when the prediction is uninformative
(``|n . r_q| <= 1e-12`` or ``j_hat`` not finite).

SGM recursion
-------------
Along each path direction ``r`` (the predecessor of ``p`` is ``p - r``)::

    L_r(p, k) = alpha * cost[p, k]
                + min_k' (L_r(p - r, k') + (1 - alpha) * V(p, k; p - r, k'))
                - min_k' L_r(p - r, k')

``S(p, k) = sum_r L_r(p, k)`` and ``labels = argmin_k S``. The inner minimum is
``O(K)`` per pixel: ``D = `` the L1 distance transform (slope ``w = 1 - alpha``)
of ``L_r(p - r, .)`` by the two-pass algorithm, evaluated exactly at the
fractional ``j_hat`` as ``min(D[f] + w * t, D[f + 1] + w * (1 - t))``
(``f = floor(j_hat)``, ``t = j_hat - f``: every cone has slope ``w``, so this is
the lower envelope itself, not an approximation), with ``j_hat`` clamped to
``[0, K - 1]`` and ``w`` times the clamped-off distance added (again exact),
then truncated at ``min_k' L_r(p - r, k') + w * tau``.

Implementation: numba, three sweeps over the image that read the cost and
normal volumes once each -- top-to-bottom (the three downward directions
together, columns in parallel per row), bottom-to-top (the three upward
ones), and a horizontal sweep (rows in parallel, left-to-right and
right-to-left interleaved) that also takes the arg-min. Besides ``S`` only
``O(W * K)`` path buffers are allocated.
"""

from __future__ import annotations

import numba
import numpy as np
from numba import njit, prange, types
from numba.extending import overload

__all__ = ["labelling_energy", "sgm_depth_normal"]

# fastmath without the "nnan"/"ninf" flags: the prior tests j_hat for NaN/inf,
# which those flags would allow LLVM to fold away; and without "reassoc" and
# "contract": with them a kernel compiled afresh and the same kernel loaded
# from numba's cache may sum S in different orders, enough to move a refined
# depth, so a fresh checkout's first run would disagree with every later one.
# Without them the two agree to the bit, at the same speed.
_FASTMATH = {"nsz", "arcp", "afn"}
_DEN_EPS = 1e-12  # |n . r_q| at or below this: prediction uninformative
_JH_MAX = 1e6  # |j_hat| beyond this: treated as uninformative (V = tau either way)


# ----------------------------------------------------------------------------------------------
# float16 normals: numba has no CPU float16 type, so they are read as their uint16 bits.

# 2**(e - 25) for each exponent field e of a normal float16 (1 <= e <= 30): times the
# 11-bit significand, exact in float32.
_HALF_SCALE = np.ldexp(np.float32(1.0), np.arange(32) - 25).astype(np.float32)


SWEEP_BANDS = 4  # progress only: a vertical sweep runs as this many bands of rows, same numbers


@njit(cache=True)
def _half_to_f32(h):
    """Exact float16 (given as its uint16 bits) to float32 conversion, in
    arithmetic (plain numba: no bit cast)."""
    b = np.int64(h) & 0xFFFF
    e = (b >> 10) & 0x1F
    m = b & 0x3FF
    if e == 0:  # zero or subnormal: m * 2**-24
        f = np.float32(m) * np.float32(5.9604644775390625e-08)
    elif e == 31:
        f = np.float32(np.inf) if m == 0 else np.float32(np.nan)
    else:
        f = np.float32(m | 0x400) * _HALF_SCALE[e]
    return -f if b & 0x8000 else f


def _to_f32(x):  # pragma: no cover - replaced by the overload inside numba
    return np.float32(x)


@overload(_to_f32, inline="always")
def _to_f32_impl(x):
    if x == types.uint16:
        return lambda x: _half_to_f32(x)
    if isinstance(x, types.Float):
        return lambda x: np.float32(x)
    return None


# ----------------------------------------------------------------------------------------------
# The O(K) inner minimum.


@njit(cache=True, fastmath=_FASTMATH)
def _distance_transform_l1(a, w):
    """In-place lower envelope ``D(j) = min_k a[k] + w * |j - k|`` (two passes)."""
    K = a.shape[0]
    for k in range(1, K):
        v = a[k - 1] + w
        if v < a[k]:
            a[k] = v
    for k in range(K - 2, -1, -1):
        v = a[k + 1] + w
        if v < a[k]:
            a[k] = v


@njit(cache=True, fastmath=_FASTMATH)
def _eval_prior(D, min_prev, jh, w, wtau):
    """``min_k' prev[k'] + w * min(|k' - jh|, tau)`` from ``D = DT(prev)``.

    ``min_prev = min(prev)``, ``wtau = w * tau``. Exact (see module docstring);
    a non-finite or huge ``jh`` gives the truncated value ``min_prev + wtau``.
    Requires ``K >= 2``.
    """
    K = D.shape[0]
    trunc = min_prev + wtau
    if not (abs(jh) < _JH_MAX):  # also catches NaN
        return trunc
    jc = jh
    extra = np.float32(0.0)
    top = np.float32(K - 1)
    if jc < 0:
        extra = -jc
        jc = np.float32(0.0)
    elif jc > top:
        extra = jc - top
        jc = top
    f = int(jc)
    if f > K - 2:
        f = K - 2
    t = jc - np.float32(f)
    v0 = D[f] + w * t
    v1 = D[f + 1] + w * (np.float32(1.0) - t)
    v = (v0 if v0 < v1 else v1) + w * extra
    return v if v < trunc else trunc


# ----------------------------------------------------------------------------------------------
# Sweeps.


@njit(cache=True, fastmath=_FASTMATH)
def _predict(dks_k, a, den, off):
    """Fractional label predicted for the neighbour (NaN when uninformative)."""
    if abs(den) > _DEN_EPS:
        return dks_k * a / den - off
    return np.float32(np.nan)


@njit(parallel=True, cache=True, fastmath=_FASTMATH)
def _sweep_vertical(
    cost, normals, rays, dks, off, alpha, w, wtau, S, down, diag, first, nchunks, bufs, steps
):
    """Top-to-bottom (``down``) or bottom-to-top paths: vertical (+ both diagonals).

    Rows are processed in order; the columns of a row in parallel. Path
    buffers ``bufs`` = (Dbuf (2, nd, W, K), mbuf (2, nd, W)) float32: the
    distance transforms and minima of the previous row's ``L_r`` (nd = 3
    with ``diag``, else 1). ``first``: assign ``S`` instead of accumulating.
    ``nchunks``: column blocks per row (<= W). ``steps`` = (s0, s1): the rows
    s0 .. s1 - 1 of the sweep's order, so that a sweep can run in bands
    (the buffers carry the last row from one band to the next).
    """
    H, W, K = cost.shape
    nd = 3 if diag else 1
    # direction r = (di, dj): predecessor q = (i - di, j - dj)
    djs = np.array([0, 1, -1], dtype=np.int64)
    Dbuf, mbuf = bufs
    for step in range(steps[0], steps[1]):
        i = step if down else H - 1 - step
        qi = i - 1 if down else i + 1
        cur = step & 1
        prv = 1 - cur
        for c in prange(nchunks):
            j0 = c * W // nchunks
            j1 = (c + 1) * W // nchunks
            qj = np.empty(nd, dtype=np.int64)
            rq = np.zeros((nd, 3), dtype=np.float32)
            mn = np.empty(nd, dtype=np.float32)
            mq = np.zeros(nd, dtype=np.float32)
            for j in range(j0, j1):
                nvalid = 0
                for d in range(nd):
                    qj[d] = j - djs[d]
                    if step > 0 and 0 <= qj[d] < W:
                        rq[d, 0] = rays[qi, qj[d], 0]
                        rq[d, 1] = rays[qi, qj[d], 1]
                        rq[d, 2] = rays[qi, qj[d], 2]
                        mq[d] = mbuf[prv, d, qj[d]]
                        nvalid += 1
                    else:
                        qj[d] = -1
                    mn[d] = np.float32(np.inf)
                rpx = rays[i, j, 0]
                rpy = rays[i, j, 1]
                rpz = rays[i, j, 2]
                for k in range(K):
                    base = alpha * cost[i, j, k]
                    nx = _to_f32(normals[i, j, k, 0])
                    ny = _to_f32(normals[i, j, k, 1])
                    nz = _to_f32(normals[i, j, k, 2])
                    a = nx * rpx + ny * rpy + nz * rpz
                    tot = np.float32(0.0)
                    for d in range(nd):
                        L = base
                        if qj[d] >= 0:
                            den = nx * rq[d, 0] + ny * rq[d, 1] + nz * rq[d, 2]
                            jh = _predict(dks[k], a, den, off)
                            L += _eval_prior(Dbuf[prv, d, qj[d]], mq[d], jh, w, wtau) - mq[d]
                        Dbuf[cur, d, j, k] = L
                        if L < mn[d]:
                            mn[d] = L
                        tot += L
                    if first:
                        S[i, j, k] = tot
                    else:
                        S[i, j, k] += tot
                for d in range(nd):
                    mbuf[cur, d, j] = mn[d]
                    _distance_transform_l1(Dbuf[cur, d, j], w)


@njit(parallel=True, cache=True, fastmath=_FASTMATH)
def _sweep_horizontal(cost, normals, rays, dks, off, alpha, w, wtau, S, labels, first):
    """Left-to-right and right-to-left paths, rows in parallel; then ``argmin S``.

    The two senses are interleaved (step ``t`` visits column ``t`` of the
    left-to-right and column ``W - 1 - t`` of the right-to-left path), so one
    pass over a row's cost and normals serves both. Path buffers: ``4 * K``
    floats per row in flight.
    """
    H, W, K = cost.shape
    for i in prange(H):
        buf = np.empty((2, 2, K), dtype=np.float32)  # [sense, parity, k]
        mprev = np.zeros(2, dtype=np.float32)
        mnew = np.empty(2, dtype=np.float32)
        for t in range(W):
            cur = t & 1
            prv = 1 - cur
            ja = t
            jb = W - 1 - t
            qa = ja - 1
            qb = jb + 1
            Da = buf[0, prv]
            Db = buf[1, prv]
            La = buf[0, cur]
            Lb = buf[1, cur]
            ma = mprev[0]
            mb = mprev[1]
            mnew[0] = np.float32(np.inf)
            mnew[1] = np.float32(np.inf)
            rax = rays[i, ja, 0]
            ray_ = rays[i, ja, 1]
            raz = rays[i, ja, 2]
            rbx = rays[i, jb, 0]
            rby = rays[i, jb, 1]
            rbz = rays[i, jb, 2]
            qax = np.float32(0.0)
            qay = np.float32(0.0)
            qaz = np.float32(0.0)
            qbx = np.float32(0.0)
            qby = np.float32(0.0)
            qbz = np.float32(0.0)
            if t > 0:
                qax = rays[i, qa, 0]
                qay = rays[i, qa, 1]
                qaz = rays[i, qa, 2]
                qbx = rays[i, qb, 0]
                qby = rays[i, qb, 1]
                qbz = rays[i, qb, 2]
            for k in range(K):
                # left-to-right: p = (i, ja) predicts q = (i, ja - 1)
                la = alpha * cost[i, ja, k]
                lb = alpha * cost[i, jb, k]
                if t > 0:
                    nx = _to_f32(normals[i, ja, k, 0])
                    ny = _to_f32(normals[i, ja, k, 1])
                    nz = _to_f32(normals[i, ja, k, 2])
                    a = nx * rax + ny * ray_ + nz * raz
                    den = nx * qax + ny * qay + nz * qaz
                    la += _eval_prior(Da, ma, _predict(dks[k], a, den, off), w, wtau) - ma
                    # right-to-left: p = (i, jb) predicts q = (i, jb + 1)
                    nx = _to_f32(normals[i, jb, k, 0])
                    ny = _to_f32(normals[i, jb, k, 1])
                    nz = _to_f32(normals[i, jb, k, 2])
                    a = nx * rbx + ny * rby + nz * rbz
                    den = nx * qbx + ny * qby + nz * qbz
                    lb += _eval_prior(Db, mb, _predict(dks[k], a, den, off), w, wtau) - mb
                La[k] = la
                Lb[k] = lb
                if la < mnew[0]:
                    mnew[0] = la
                if lb < mnew[1]:
                    mnew[1] = lb
                if first and 2 * t < W - 1:  # first visit of both columns
                    S[i, ja, k] = la
                    S[i, jb, k] = lb
                elif first and 2 * t == W - 1:  # odd W, the middle column
                    S[i, ja, k] = la + lb
                else:
                    S[i, ja, k] += la
                    S[i, jb, k] += lb
            mprev[0] = mnew[0]
            mprev[1] = mnew[1]
            _distance_transform_l1(La, w)
            _distance_transform_l1(Lb, w)
        for j in range(W):
            best = 0
            bv = S[i, j, 0]
            for k in range(1, K):
                if S[i, j, k] < bv:
                    bv = S[i, j, k]
                    best = k
            labels[i, j] = best


# ----------------------------------------------------------------------------------------------
# Energy.


@njit(cache=True)
def _energy(labels, cost, normals, rays, dks, off, alpha, tau, diag):
    H, W, K = cost.shape
    data = 0.0
    prior = 0.0
    # forward offsets r; q = p - r (left, up, up-left, up-right)
    ndir = 4 if diag else 2
    dis = (0, 1, 1, 1)
    djs = (1, 0, 1, -1)
    for i in range(H):
        for j in range(W):
            k = labels[i, j]
            data += np.float64(cost[i, j, k])
            nx = np.float64(_to_f32(normals[i, j, k, 0]))
            ny = np.float64(_to_f32(normals[i, j, k, 1]))
            nz = np.float64(_to_f32(normals[i, j, k, 2]))
            a = nx * rays[i, j, 0] + ny * rays[i, j, 1] + nz * rays[i, j, 2]
            for d in range(ndir):
                qi = i - dis[d]
                qj = j - djs[d]
                if qi < 0 or qj < 0 or qj >= W:
                    continue
                den = nx * rays[qi, qj, 0] + ny * rays[qi, qj, 1] + nz * rays[qi, qj, 2]
                v = tau
                if abs(den) > _DEN_EPS:
                    jh = dks[k] * a / den - off
                    if np.isfinite(jh):
                        v = min(abs(labels[qi, qj] - jh), tau)
                prior += v
    return alpha * data + (1.0 - alpha) * prior


# ----------------------------------------------------------------------------------------------
# Public API.


def _prepare(cost, normals, rays, depths, alpha, tau):
    cost = np.ascontiguousarray(cost, dtype=np.float32)
    if cost.ndim != 3:
        raise ValueError(f"cost must be (H, W, K), got shape {cost.shape}")
    H, W, K = cost.shape
    if K < 2:
        raise ValueError("need at least two depth labels")
    normals = np.asarray(normals)
    if normals.shape != (H, W, K, 3):
        raise ValueError(f"normals must be {(H, W, K, 3)}, got {normals.shape}")
    if normals.dtype == np.float16:
        normals = np.ascontiguousarray(normals).view(np.uint16)
    else:
        normals = np.ascontiguousarray(normals, dtype=np.float32)
    rays = np.ascontiguousarray(rays, dtype=np.float32)
    if rays.shape != (H, W, 3):
        raise ValueError(f"rays must be {(H, W, 3)}, got {rays.shape}")
    d = np.asarray(depths, dtype=np.float64)
    if d.shape != (K,):
        raise ValueError(f"depths must be ({K},), got {d.shape}")
    dz = (d[-1] - d[0]) / (K - 1)
    if not dz > 0 or np.max(np.abs(np.diff(d) - dz)) > 1e-3 * dz:
        raise ValueError("depths must be uniformly spaced and increasing")
    if not 0.0 < alpha < 1.0:
        raise ValueError("alpha must lie in (0, 1)")
    if not (np.isfinite(tau) and tau > 0):
        raise ValueError("tau must be finite and positive")
    return cost, normals, rays, d / dz, d[0] / dz


def sgm_depth_normal(
    cost: np.ndarray,
    normals: np.ndarray,
    rays: np.ndarray,
    depths: np.ndarray,
    alpha: float = 0.5,
    tau: float = 3.0,
    directions: int = 8,
    say=None,
) -> tuple[np.ndarray, np.ndarray]:
    """Bayesian HS depth labelling by SGM with the depth-normal consistency prior.

    Approximately minimises ``alpha * E_data + (1 - alpha) * E_prior`` (paper,
    section III-E; prior of Roubtsova and Guillemaut [8]) by semi-global
    aggregation along 8 (or 4) image directions (Hirschmueller 2008); see the
    module docstring for the exact recursion.

    Parameters
    ----------
    cost : ndarray, float32 (H, W, K)
        Data cost, >= 0, lower is better; invalid hypotheses should carry a
        large *finite* cost.
    normals : ndarray, float16 or float32 (H, W, K, 3)
        Unit normal hypothesised at every (pixel, label), world frame.
    rays : ndarray, float32 (H, W, 3)
        World ray direction of each pixel scaled to unit z-depth, so that the
        point at label ``k`` is ``c + depths[k] * rays[p]``.
    depths : ndarray (K,)
        Uniformly spaced, increasing z-depths of the labels.
    alpha : float
        Weight of the data term, in (0, 1); the prior has weight ``1 - alpha``.
    tau : float
        Truncation of the prior, in labels (finite, > 0).
    directions : {8, 4}
        8: rows, columns and both diagonals, both senses; 4: rows and columns.
    say : callable, optional
        Called with a line before each of the three sweeps and before each
        later band of ``SWEEP_BANDS`` of a vertical sweep's rows (progress: a
        vertical sweep takes seconds at high resolution).

    Returns
    -------
    labels : ndarray, int32 (H, W)
        ``argmin_k S`` (the lowest label on ties).
    S : ndarray, float32 (H, W, K)
        Aggregated cost ``sum_r L_r``, e.g. for sub-label refinement.

    Notes
    -----
    Memory: ``S`` plus ``O(W * K)`` path buffers; ``cost``, ``normals`` and
    ``rays`` are used in place when C-contiguous in the stated dtypes
    (otherwise converted once). Runs on ``numba.get_num_threads()`` threads.
    """
    if directions not in (4, 8):
        raise ValueError("directions must be 4 or 8")
    cost, nrm, rays, dks, off = _prepare(cost, normals, rays, depths, alpha, tau)
    H, W, K = cost.shape
    S = np.empty((H, W, K), dtype=np.float32)
    labels = np.empty((H, W), dtype=np.int32)
    f32 = np.float32
    a32, w32, wtau = f32(alpha), f32(1.0 - alpha), f32((1.0 - alpha) * tau)
    dks32, off32 = dks.astype(np.float32), f32(off)
    diag = directions == 8
    args = (cost, nrm, rays, dks32, off32, a32, w32, wtau, S)
    nchunks = min(W, 4 * numba.get_num_threads())
    columns = "columns and diagonals" if diag else "columns"
    nd = 3 if diag else 1
    bufs = (np.empty((2, nd, W, K), np.float32), np.empty((2, nd, W), np.float32))
    for down, text in ((True, "top to bottom"), (False, "bottom to top")):
        if say is not None:
            say(f"MRF: paths along the {columns}, {text}")
        for b in range(SWEEP_BANDS):  # a line per band: a sweep is long at high resolution
            s0, s1 = b * H // SWEEP_BANDS, (b + 1) * H // SWEEP_BANDS
            if b and say is not None:
                say(f"MRF: {text}, {s0} of {H} rows")
            _sweep_vertical(*args, down, diag, down, nchunks, bufs, (s0, s1))
    if say is not None:
        say("MRF: paths along the rows, both ways; the labels")
    _sweep_horizontal(*args, labels, False)
    return labels, S


def labelling_energy(
    labels: np.ndarray,
    cost: np.ndarray,
    normals: np.ndarray,
    rays: np.ndarray,
    depths: np.ndarray,
    alpha: float,
    tau: float,
    directions: int = 8,
) -> float:
    """Energy ``alpha * E_data + (1 - alpha) * E_prior`` of a labelling (section III-E).

    ``E_data = sum_p cost[p, l_p]``. ``E_prior`` counts every undirected pair
    of 8-neighbours (4-neighbours for ``directions=4``) once, as the pair
    ``(p, q = p - r)`` with ``r`` in ``{(0, 1), (1, 0), (1, 1), (1, -1)}``
    (``(row, column)`` offsets: ``q`` is the left, upper, upper-left or
    upper-right neighbour of ``p``), with ``p``'s hypothesis
    ``(l_p, normals[p, l_p])`` predicting ``q``'s label as in the forward SGM
    paths: ``V = min(|l_q - j_hat|, tau)``, ``V = tau`` when uninformative.
    All pairs have weight 1 (diagonal ones included). Evaluated in float64.

    Parameters
    ----------
    labels : ndarray, int (H, W)
    cost, normals, rays, depths, alpha, tau
        As for :func:`sgm_depth_normal`.
    directions : {8, 4}
        Neighbourhood: 8 or 4.

    Returns
    -------
    float
        The energy.
    """
    if directions not in (4, 8):
        raise ValueError("directions must be 4 or 8")
    cost, nrm, rays, dks, off = _prepare(cost, normals, rays, depths, alpha, tau)
    labels = np.ascontiguousarray(labels, dtype=np.int64)
    if labels.shape != cost.shape[:2]:
        raise ValueError(f"labels must be {cost.shape[:2]}, got {labels.shape}")
    if labels.min() < 0 or labels.max() >= cost.shape[2]:
        raise ValueError("labels out of range")
    return float(
        _energy(labels, cost, nrm, rays, dks, float(off), float(alpha), float(tau), directions == 8)
    )
