"""A plain NumPy colour HS data term: the reference the compiled one is measured against.

The same quantity as :func:`colourhs.reconstruct.dataterm.data_term` (eq. 5:
sigma_3 / sigma_2 of the 3 x 3 matrix W of the three reciprocal pairs' rows
at every pixel and depth hypothesis, and W's null vector as the normal), on
the same inputs (:class:`~colourhs.reconstruct.dataterm.Prepared` images),
written the obvious way: vectorised over pixels and hypotheses, the
projection of :func:`colourhs.common.geometry.project`, bilinear sampling by
indexing, ``numpy.linalg.eigh`` of W^T W in float64. No numba, no float32
arithmetic, no fused loops, no attempt at speed: it exists so that
``benchmarks/bench_reconstruct.py`` reports the compiled kernel's speed as a
ratio to a plain implementation run on the same pixels, and so that a test
(``tests/reconstruct/test_exact.py``) checks the kernel against an independent one.
"""

from __future__ import annotations

import numpy as np

from colourhs.common.geometry import project
from colourhs.reconstruct.dataterm import INVALID_COST, MIN_FACING_COS, Prepared


def _bilinear(S: np.ndarray, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bilinear samples (..., nv) of one camera's packed images S (H, W, nv) at
    pixels ``uv`` (..., 2); and whether each lies inside the image."""
    H, W = S.shape[:2]
    u, v = uv[..., 0], uv[..., 1]
    inside = (u >= 0) & (v >= 0) & (u <= W - 1) & (v <= H - 1)
    u = np.clip(np.nan_to_num(u), 0, W - 1)
    v = np.clip(np.nan_to_num(v), 0, H - 1)
    u0 = np.minimum(np.floor(u), W - 2).astype(int)
    v0 = np.minimum(np.floor(v), H - 2).astype(int)
    a, b = (u - u0)[..., None], (v - v0)[..., None]
    S = S.astype(np.float64)
    out = (
        (1 - a) * (1 - b) * S[v0, u0]
        + a * (1 - b) * S[v0, u0 + 1]
        + (1 - a) * b * S[v0 + 1, u0]
        + a * b * S[v0 + 1, u0 + 1]
    )
    return out, inside


def reference_data_term(
    rays: np.ndarray,
    c_ref: np.ndarray,
    depths: np.ndarray,
    cameras,
    prepared: Prepared,
    pairs,
) -> tuple[np.ndarray, np.ndarray]:
    """Cost (N, K) and unit normals (N, K, 3) of every pixel and hypothesis, as
    :func:`colourhs.reconstruct.dataterm.data_term` (same arguments, same
    validity rules: every sample inside its image and usable, W of rank >= 2,
    the normal facing every light by more than ``MIN_FACING_COS``)."""
    pair_cams, _ = pairs
    rays = np.asarray(rays, float)
    c_ref = np.asarray(c_ref, float)
    z = np.asarray(depths, float)
    X = c_ref + rays[:, None, :] * z[None, :, None]  # (N, K, 3)
    ns = int(prepared.slots.max()) + 1
    samples, fall, ok = [], [], np.ones(X.shape[:2], bool)
    for cam, S in zip(cameras, prepared.S, strict=True):
        uv = project(X, cam.K, cam.dist, cam.R, cam.t)
        s, inside = _bilinear(S, uv)
        samples.append(s)
        d = np.asarray(cam.light_centre, float) - X
        fall.append(1.0 / np.linalg.norm(d, axis=-1) ** 3)
        ok &= inside & np.all(np.isfinite(uv), axis=-1)
    Wm = np.zeros(X.shape[:2] + (3, 3))
    for p, (a, b) in enumerate(pair_cams):
        ja, jb = prepared.slots[p]
        Ja, Jb = samples[a][..., ja], samples[b][..., jb]
        ok &= (Ja > 0) & (Jb > 0)
        pp = samples[a][..., ns + ja] * samples[b][..., ns + jb] if prepared.use_p else 1.0
        La = np.asarray(cameras[a].light_centre, float) - X
        Lb = np.asarray(cameras[b].light_centre, float) - X
        Wm[..., p, :] = (pp * Ja * fall[a])[..., None] * La - (pp * Jb * fall[b])[..., None] * Lb
    Wm = np.where(ok[..., None, None], Wm, 0.0)
    lam, vec = np.linalg.eigh(np.einsum("nkpi,nkpj->nkij", Wm, Wm))
    n = vec[..., 0]
    n = np.where((np.sum(n * rays[:, None, :], axis=-1) > 0)[..., None], -n, n)
    ok &= lam[..., 1] > 0
    for cam in cameras:
        d = np.asarray(cam.light_centre, float) - X
        ok &= np.sum(n * d, axis=-1) > MIN_FACING_COS * np.linalg.norm(d, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        cost = np.sqrt(np.clip(lam[..., 0] / lam[..., 1], 0.0, 4.0))
    cost = np.where(ok, cost, INVALID_COST).astype(np.float32)
    return cost, np.where(ok[..., None], n, 0.0).astype(np.float32)
