"""SGM with the depth-normal consistency prior (colourhs.reconstruct.bayes.mrf)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numba import njit

from colourhs.reconstruct.bayes import mrf
from colourhs.reconstruct.bayes.mrf import labelling_energy, sgm_depth_normal

ALPHA, TAU = 0.5, 3.0


# ----------------------------------------------------------------------------------------------
# Synthetic scenes and pure-Python references.


def plane_scene(normal, offset, H=40, W=50, K=32, f=50.0, zmin=1.0, zmax=2.0):
    """Pinhole camera at the origin looking along +z; plane ``n . X = offset``.

    Returns rays (z = 1), depths, true labels and the plane normal at every (p, k).
    """
    Km = np.array([[f, 0.0, (W - 1) / 2], [0.0, f, (H - 1) / 2], [0.0, 0.0, 1.0]])
    v, u = np.mgrid[0:H, 0:W]
    pix = np.stack([u, v, np.ones_like(u)], -1).astype(float)
    rays = pix @ np.linalg.inv(Km).T
    n = np.asarray(normal, float)
    n = n / np.linalg.norm(n)
    z = offset / (rays @ n)
    depths = np.linspace(zmin, zmax, K)
    ktrue = np.rint((z - zmin) / (depths[1] - depths[0])).astype(int)
    assert ktrue.min() >= 0 and ktrue.max() < K
    normals = np.broadcast_to(n.astype(np.float32), (H, W, K, 3)).copy()
    return rays.astype(np.float32), depths.astype(np.float32), ktrue, normals


def noisy_cost(ktrue, K, rng, outliers=0.3, noise=0.1):
    """``|k - k_true| / K`` + uniform noise; a fraction of pixels has its minimum (0) elsewhere."""
    H, W = ktrue.shape
    cost = np.abs(np.arange(K) - ktrue[..., None]) / K + rng.uniform(0.0, noise, (H, W, K))
    ii, jj = np.nonzero(rng.random((H, W)) < outliers)
    cost[ii, jj, rng.integers(0, K, ii.size)] = 0.0
    return cost.astype(np.float32)


def tilted_plane():
    th = np.deg2rad(20.0)
    return plane_scene((np.sin(th), 0.0, -np.cos(th)), -1.35)  # labels 7..23 across the image


def random_problem(rng, H, W, K):
    cost = rng.random((H, W, K)).astype(np.float32)
    n = rng.normal(size=(H, W, K, 3))
    n[..., 2] -= 2.0
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    xy = rng.uniform(-0.3, 0.3, (H, W, 2))
    rays = np.concatenate([xy, np.ones((H, W, 1))], -1).astype(np.float32)
    depths = np.linspace(1.0, 2.0, K).astype(np.float32)
    return cost, n.astype(np.float32), rays, depths


def _prediction(n, rp, rq, depths):
    """Fractional label of q predicted by p's hypothesis, or None (uninformative)."""
    K = len(depths)
    dz = (float(depths[-1]) - float(depths[0])) / (K - 1)
    den = sum(float(n[c]) * float(rq[c]) for c in range(3))
    if abs(den) <= 1e-12:
        return None
    num = sum(float(n[c]) * float(rp[c]) for c in range(3))
    return lambda k: (float(depths[k]) * num / den - float(depths[0])) / dz


def slow_energy(labels, cost, normals, rays, depths, alpha, tau, directions=8):
    H, W, _ = cost.shape
    offsets = [(0, 1), (1, 0), (1, 1), (1, -1)][: 4 if directions == 8 else 2]
    data = prior = 0.0
    for i in range(H):
        for j in range(W):
            k = int(labels[i, j])
            data += float(cost[i, j, k])
            for di, dj in offsets:
                qi, qj = i - di, j - dj
                if not (0 <= qi < H and 0 <= qj < W):
                    continue
                pred = _prediction(normals[i, j, k].astype(float), rays[i, j], rays[qi, qj], depths)
                v = tau
                if pred is not None and math.isfinite(pred(k)):
                    v = min(abs(int(labels[qi, qj]) - pred(k)), tau)
                prior += v
    return alpha * data + (1.0 - alpha) * prior


def slow_sgm(cost, normals, rays, depths, alpha, tau, directions=8):
    """The SGM recursion of the module docstring, brute force over k' (float64)."""
    H, W, K = cost.shape
    dirs = [(0, 1), (0, -1), (1, 0), (-1, 0)]
    if directions == 8:
        dirs += [(1, 1), (1, -1), (-1, 1), (-1, -1)]
    kk = np.arange(K)
    S = np.zeros((H, W, K))
    for di, dj in dirs:
        L = np.zeros((H, W, K))
        for i in range(H) if di >= 0 else range(H - 1, -1, -1):
            for j in range(W) if dj >= 0 else range(W - 1, -1, -1):
                qi, qj = i - di, j - dj
                L[i, j] = alpha * cost[i, j].astype(float)
                if not (0 <= qi < H and 0 <= qj < W):
                    continue
                prev = L[qi, qj]
                for k in range(K):
                    pred = _prediction(
                        normals[i, j, k].astype(float), rays[i, j], rays[qi, qj], depths
                    )
                    V = np.full(K, tau)
                    if pred is not None and math.isfinite(pred(k)):
                        V = np.minimum(np.abs(kk - pred(k)), tau)
                    L[i, j, k] += np.min(prev + (1 - alpha) * V) - prev.min()
        S += L
    return S


def within1(labels, ktrue):
    return float(np.mean(np.abs(labels - ktrue) <= 1))


# ----------------------------------------------------------------------------------------------
# Building blocks.


def _min_prior(prev_L, j_hat, w, tau):
    """``min_k' prev_L[k'] + w * min(|k' - j_hat|, tau)`` in ``O(K)`` from the sweeps'
    building blocks (a distance transform, then the truncated prior at ``j_hat``)."""
    D = prev_L.astype(np.float32)
    w32 = np.float32(w)
    mrf._distance_transform_l1(D, w32)
    jh = np.float32(j_hat)
    return mrf._eval_prior(D, np.float32(prev_L.min()), jh, w32, np.float32(w * tau))


def test_min_prior_matches_brute_force():
    rng = np.random.default_rng(0)
    for trial in range(300):
        K = int(rng.integers(2, 40))
        prev = (rng.random(K) * rng.choice([0.1, 1.0, 5.0])).astype(np.float32)
        w = float(rng.uniform(0.05, 0.95))
        tau = float(rng.choice([0.5, 1.0, 3.0, 10.0, 100.0]))
        if trial % 5 == 0:
            jh = float(rng.integers(-2, K + 2))  # exactly on a label
        else:
            jh = float(rng.uniform(-6.0, K + 5.0))
        brute = np.min(prev + w * np.minimum(np.abs(np.arange(K) - jh), tau))
        # float32 sums: measured at most half of this bound (|d| 1.5e-6 at |brute| < 1)
        assert _min_prior(prev, jh, w, tau) == pytest.approx(brute, rel=3e-6, abs=3e-6)
    prev = rng.random(16).astype(np.float32)
    for jh in (np.nan, np.inf, -np.inf, 1e9, -1e9):  # uninformative: V = tau everywhere
        got = _min_prior(prev, jh, 0.4, 3.0)
        assert got == pytest.approx(prev.min() + 0.4 * 3.0, rel=1e-6)


def test_distance_transform_l1():
    rng = np.random.default_rng(1)
    a = rng.random(50).astype(np.float32) * 3
    D = a.copy()
    mrf._distance_transform_l1(D, np.float32(0.3))
    k = np.arange(50)
    brute = np.min(a[None, :] + 0.3 * np.abs(k[:, None] - k[None, :]), axis=1)
    # float32: measured 1.05e-7 relative; bound about two ulps
    np.testing.assert_allclose(D, brute, rtol=2.5e-7, atol=1e-12)


@njit
def _decode_all(bits, out):
    for i in range(bits.shape[0]):
        out[i] = mrf._half_to_f32(bits[i])


def test_half_decoding_is_exact():
    bits = np.arange(65536, dtype=np.uint32).astype(np.uint16)
    got = np.empty(bits.size, np.float32)
    _decode_all(bits, got)
    want = bits.view(np.float16).astype(np.float32)
    nan = np.isnan(want)
    assert np.array_equal(np.isnan(got), nan)
    assert np.array_equal(got[~nan], want[~nan])
    assert np.array_equal(np.signbit(got[~nan]), np.signbit(want[~nan]))


@pytest.mark.parametrize("directions", [4, 8])
@pytest.mark.parametrize("shape", [(6, 7, 9), (1, 6, 5), (5, 1, 4), (2, 2, 2)])
def test_sgm_matches_brute_force_recursion(directions, shape):
    cost, normals, rays, depths = random_problem(np.random.default_rng(2), *shape)
    labels, S = sgm_depth_normal(cost, normals, rays, depths, 0.4, 2.5, directions)
    ref = slow_sgm(cost, normals, rays, depths, 0.4, 2.5, directions)
    assert S.dtype == np.float32 and S.shape == shape
    assert labels.dtype == np.int32 and labels.shape == shape[:2]
    # float32 path sums up to 14: measured at most 5.5e-6 off; bound 1e-5.
    np.testing.assert_allclose(S, ref, rtol=0, atol=1e-5)
    np.testing.assert_array_equal(labels, S.argmin(axis=-1))


def test_float16_normals_same_as_float32():
    cost, normals, rays, depths = random_problem(np.random.default_rng(3), 12, 15, 10)
    n16 = normals.astype(np.float16)
    l16, S16 = sgm_depth_normal(cost, n16, rays, depths)
    l32, S32 = sgm_depth_normal(cost, n16.astype(np.float32), rays, depths)
    # The two specialisations may order floating-point operations differently
    # (reassociation is allowed): equal to float32 rounding, not bit for bit.
    np.testing.assert_allclose(S16, S32, rtol=1e-5, atol=1e-5)
    assert np.mean(l16 == l32) > 0.99


def test_sgm_reports_its_three_sweeps_and_gives_the_same_labels():
    """``say`` gets a line before each sweep and each band of a vertical sweep's rows
    (progress at 1280 x 960, where each sweep takes seconds); the result is the one
    without it."""
    cost, normals, rays, depths = random_problem(np.random.default_rng(5), 9, 11, 8)
    lines = []
    labels, S = sgm_depth_normal(cost, normals, rays, depths, say=lines.append)
    ref_labels, ref_S = sgm_depth_normal(cost, normals, rays, depths)
    assert np.array_equal(labels, ref_labels) and np.array_equal(S, ref_S)
    assert lines == [
        "MRF: paths along the columns and diagonals, top to bottom",
        "MRF: top to bottom, 2 of 9 rows",  # the sweep's bands (SWEEP_BANDS = 4)
        "MRF: top to bottom, 4 of 9 rows",
        "MRF: top to bottom, 6 of 9 rows",
        "MRF: paths along the columns and diagonals, bottom to top",
        "MRF: bottom to top, 2 of 9 rows",
        "MRF: bottom to top, 4 of 9 rows",
        "MRF: bottom to top, 6 of 9 rows",
        "MRF: paths along the rows, both ways; the labels",
    ]


# ----------------------------------------------------------------------------------------------
# Planes, energy, discontinuities.


@pytest.mark.parametrize("scene", ["fronto", "tilted"])
def test_plane_recovered_from_noisy_cost(scene):
    if scene == "fronto":
        rays, depths, ktrue, normals = plane_scene((0.0, 0.0, -1.0), -1.4)
    else:
        rays, depths, ktrue, normals = tilted_plane()
    cost = noisy_cost(ktrue, len(depths), np.random.default_rng(4))
    assert within1(cost.argmin(axis=-1), ktrue) < 0.8  # winner-take-all fails
    labels, _ = sgm_depth_normal(cost, normals, rays, depths, ALPHA, TAU)
    assert within1(labels, ktrue) >= 0.98


def test_tilted_plane_needs_true_normals():
    rays, depths, ktrue, normals = tilted_plane()
    # along the optical axis: the prior predicts the same label (fronto-parallel smoothness)
    wrong = np.broadcast_to(np.float32([0.0, 0.0, -1.0]), normals.shape)
    for seed in (5, 6):
        cost = noisy_cost(ktrue, len(depths), np.random.default_rng(seed))
        good, _ = sgm_depth_normal(cost, normals, rays, depths, ALPHA, TAU)
        bad, _ = sgm_depth_normal(cost, wrong, rays, depths, ALPHA, TAU)
        n_good = int(np.sum(good != ktrue))
        n_bad = int(np.sum(bad != ktrue))
        assert n_bad > 2 * n_good + 40, (n_good, n_bad)


def test_energy_lower_than_wta_and_perturbed_truth():
    rays, depths, ktrue, normals = tilted_plane()
    rng = np.random.default_rng(7)
    cost = noisy_cost(ktrue, len(depths), rng)
    labels, _ = sgm_depth_normal(cost, normals, rays, depths, ALPHA, TAU)
    args = (cost, normals, rays, depths, ALPHA, TAU)
    e_sgm = labelling_energy(labels, *args)
    assert e_sgm < labelling_energy(cost.argmin(axis=-1), *args)
    pert = ktrue + rng.integers(-3, 4, ktrue.shape) * (rng.random(ktrue.shape) < 0.2)
    pert = np.clip(pert, 0, len(depths) - 1)
    assert np.mean(pert != ktrue) > 0.1
    assert e_sgm < labelling_energy(pert, *args)


@pytest.mark.parametrize("directions", [4, 8])
@pytest.mark.parametrize("dtype", [np.float32, np.float16])
def test_energy_matches_slow_python(directions, dtype):
    cost, normals, rays, depths = random_problem(np.random.default_rng(8), 5, 6, 8)
    normals = normals.astype(dtype)
    normals[0, 0, 3] = 0.0  # an uninformative prediction (n . r_q = 0)
    labels = np.random.default_rng(9).integers(0, 8, (5, 6))
    labels[0, 0] = 3
    for alpha, tau in ((0.5, 3.0), (0.3, 1.5)):
        want = slow_energy(labels, cost, normals, rays, depths, alpha, tau, directions)
        got = labelling_energy(labels, cost, normals, rays, depths, alpha, tau, directions)
        assert got == pytest.approx(want, rel=1e-9)  # round-off: measured 3e-16


def test_depth_discontinuity_stays_sharp():
    rays, depths, _, normals = plane_scene((0.0, 0.0, -1.0), -1.2)
    H, W, K = normals.shape[:3]
    ktrue = np.where(np.arange(W) < W // 2, 6, 25)[None, :].repeat(H, axis=0)
    cost = noisy_cost(ktrue, K, np.random.default_rng(10))
    labels, _ = sgm_depth_normal(cost, normals, rays, depths, ALPHA, TAU)
    bad_cols = np.nonzero(np.any(np.abs(labels - ktrue) > 1, axis=0))[0]
    assert np.all(np.abs(bad_cols - (W // 2 - 0.5)) <= 2.0), bad_cols
    assert within1(labels, ktrue) >= 0.98


@pytest.mark.parametrize("directions", [4, 8])
def test_four_and_eight_directions(directions):
    rays, depths, ktrue, normals = tilted_plane()
    cost = noisy_cost(ktrue, len(depths), np.random.default_rng(11))
    labels, S = sgm_depth_normal(cost, normals, rays, depths, ALPHA, TAU, directions)
    assert within1(labels, ktrue) >= 0.98
    np.testing.assert_array_equal(labels, S.argmin(axis=-1))


def test_input_validation():
    cost, normals, rays, depths = random_problem(np.random.default_rng(12), 4, 5, 6)
    with pytest.raises(ValueError, match="directions"):
        sgm_depth_normal(cost, normals, rays, depths, directions=6)
    with pytest.raises(ValueError, match="uniformly"):
        sgm_depth_normal(cost, normals, rays, depths**2)
    with pytest.raises(ValueError, match="alpha"):
        sgm_depth_normal(cost, normals, rays, depths, alpha=1.0)
    with pytest.raises(ValueError, match="tau"):
        sgm_depth_normal(cost, normals, rays, depths, tau=np.inf)
    with pytest.raises(ValueError, match="normals"):
        sgm_depth_normal(cost, normals[:, :, :3], rays, depths)
    with pytest.raises(ValueError, match="two depth labels"):
        sgm_depth_normal(cost[..., :1], normals[:, :, :1], rays, depths[:1])
    with pytest.raises(ValueError, match="out of range"):
        labelling_energy(np.full((4, 5), 6), cost, normals, rays, depths, ALPHA, TAU)


_SGM_RUN = """
import sys
import numpy as np
from colourhs.reconstruct.bayes.mrf import sgm_depth_normal
rng = np.random.default_rng(0)
H, W, K = 24, 32, 48
cost = rng.random((H, W, K), dtype=np.float32)
n = rng.normal(size=(H, W, K, 3)).astype(np.float32)
n /= np.linalg.norm(n, axis=-1, keepdims=True)
u, v = np.meshgrid(np.linspace(-0.3, 0.3, W), np.linspace(-0.2, 0.2, H))
rays = np.stack([u, v, np.ones_like(u)], -1).astype(np.float32)
lab, S = sgm_depth_normal(cost, n, rays, np.linspace(0.6, 1.0, K), 0.35, 30.0)
sys.stdout.write(S.tobytes().hex())
"""


def test_same_result_compiled_afresh_or_from_the_cache(tmp_path):
    """The SGM kernels give the same S whether numba compiles them or loads them
    from its cache (with fastmath's "reassoc"/"contract" they did not: a fresh
    checkout's first run differed from later ones). Two processes, one cache
    folder; about 25 s (most of it compiling)."""
    import os
    import subprocess
    import sys

    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"))
    runs = [
        subprocess.run(
            [sys.executable, "-c", _SGM_RUN], env=env, capture_output=True, text=True, check=True
        ).stdout
        for _ in range(2)
    ]
    assert list((tmp_path / "numba").rglob("*.nbc"))  # the second run loaded the cache
    assert runs[0] == runs[1]
