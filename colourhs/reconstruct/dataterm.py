"""The colour HS data term over depth hypotheses, compiled with numba.

For every pixel of the reference camera and every depth hypothesis z_k, the
hypothesised point X = c + z_k r (r: the pixel's ray scaled to unit z-depth)
is projected into every camera (OpenCV model); the six reciprocal
intensities are sampled bilinearly, multiplied by mu (eq. 2) and the
chromaticity p, and assembled into the 3 x 3 constraint matrix W whose rows
are equation (5). The singular values of W give the cost sigma_3 / sigma_2
(0 for a perfect rank-2 W) and its null vector the normal (oriented towards
the reference camera).

A hypothesis is *invalid* (cost ``INVALID_COST``, normal 0) when it leaves an
image, falls outside a silhouette, lands on a saturated pixel, or when any
of its six samples is too dark to measure (a black marker, a shadow from a
light, a pure colour in the wrong band) or has no chromaticity: with fewer
than three rows W would be trivially rank 2, so such hypotheses are never
scored as good.
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

INVALID_COST = 1.0


NEWTON_STEPS = 6
TINY = 1e-300
SENTINEL = np.float32(-1.0e30)  # an unusable sample: any positive bilinear weight makes it < 0


class Prepared(NamedTuple):
    """A frame's images packed for the kernel (see :func:`prepare_images`).

    Attributes
    ----------
    S : (C, H, W, 2 * s) float32
        Per camera and pixel, the s Helmholtz-camera values J = mu * i / p of
        the camera's slots, then their chromaticities p (1 without
        chromaticity calibration); ``SENTINEL`` where J is unusable.
    slots : (P, 2) int64
        Slot of each side of each reciprocal pair in its camera's S.
    use_p : bool
        Whether the eq. (5) weights p_ab p_ba are applied.
    """

    S: np.ndarray
    slots: np.ndarray
    use_p: bool


@nb.njit(cache=True, fastmath=True, inline="always")
def _smallest_eig(a, b, c, d, e, f):
    """Smallest eigenvalue and the next one of the symmetric PSD matrix
    [[a, d, e], [d, b, f], [e, f, c]].

    ``NEWTON_STEPS`` Newton steps on the characteristic polynomial from 0: it
    is convex and decreasing up to the smallest root, so the iterates rise
    monotonically to it, quadratically fast when sigma_3 << sigma_2 (the
    hypotheses that matter). Branch-free, so the loop over hypotheses
    vectorises."""
    tr = a + b + c
    c2 = a * b + a * c + b * c - d * d - e * e - f * f
    det = max(a * (b * c - f * f) - d * (d * c - f * e) + e * (d * f - b * e), 0.0)
    lam = 0.0
    for _ in range(NEWTON_STEPS):
        p = det - lam * (c2 - lam * (tr - lam))
        dp = lam * (2.0 * tr - 3.0 * lam) - c2
        lam += max(-p / min(dp, -TINY), 0.0)  # never a step down (rounding past the root)
    s = tr - lam  # lam1 + lam2
    q = max(c2 - lam * s, 0.0)  # lam1 * lam2
    disc = max(s * s - 4.0 * q, 0.0)
    lam2 = 2.0 * q / max(s + np.sqrt(disc), TINY)
    return lam, lam2


@nb.njit(parallel=True, cache=True, fastmath=True)
def _kernel(
    rays, c_ref, depths, Ks, dists, Ps, lights, S, slots, use_p, pair_cams,
    nthreads, cost, normals,
):  # fmt: skip
    """Pixels over prange; per pixel, passes over the hypotheses that each
    vectorise: project into every camera (OpenCV model), sample the six
    reciprocal intensities bilinearly (gathers), accumulate the Gram matrix of
    W row by row (eq. 5), then sigma_3 / sigma_2 and the null vector."""
    N = rays.shape[0]
    Kn = depths.shape[0]
    ncam = Ks.shape[0]
    npair = pair_cams.shape[0]
    Hh, Ww, nv = S.shape[1], S.shape[2], S.shape[3]
    ns = nv // 2
    row = Ww * nv
    nblocks = 4 * nthreads
    chunk = (N + nblocks - 1) // nblocks
    for t in nb.prange(nblocks):
        base = np.empty((ncam, Kn), np.int64)
        fa = np.empty((ncam, Kn))
        fb = np.empty((ncam, Kn))
        nread = nv if use_p else ns
        smp = np.empty((ncam, nv, Kn))
        M = np.empty((6, Kn))
        R = np.empty((4, Kn))  # cost and normal, copied out after the vectorised pass
        ok = np.empty(Kn, np.uint8)
        for n in range(t * chunk, min(N, (t + 1) * chunk)):
            r0, r1, r2 = rays[n, 0], rays[n, 1], rays[n, 2]
            ok[:] = 1
            # 1. Project every hypothesis into every camera; bilinear footprints.
            for c in range(ncam):
                A0 = (
                    Ps[c, 0, 3]
                    + Ps[c, 0, 0] * c_ref[0]
                    + Ps[c, 0, 1] * c_ref[1]
                    + Ps[c, 0, 2] * c_ref[2]
                )
                A1 = (
                    Ps[c, 1, 3]
                    + Ps[c, 1, 0] * c_ref[0]
                    + Ps[c, 1, 1] * c_ref[1]
                    + Ps[c, 1, 2] * c_ref[2]
                )
                A2 = (
                    Ps[c, 2, 3]
                    + Ps[c, 2, 0] * c_ref[0]
                    + Ps[c, 2, 1] * c_ref[1]
                    + Ps[c, 2, 2] * c_ref[2]
                )
                B0 = Ps[c, 0, 0] * r0 + Ps[c, 0, 1] * r1 + Ps[c, 0, 2] * r2
                B1 = Ps[c, 1, 0] * r0 + Ps[c, 1, 1] * r1 + Ps[c, 1, 2] * r2
                B2 = Ps[c, 2, 0] * r0 + Ps[c, 2, 1] * r1 + Ps[c, 2, 2] * r2
                fx, sk, cx, fy, cy = Ks[c, 0, 0], Ks[c, 0, 1], Ks[c, 0, 2], Ks[c, 1, 1], Ks[c, 1, 2]
                k1, k2, p1, p2, k3 = dists[c, 0], dists[c, 1], dists[c, 2], dists[c, 3], dists[c, 4]
                for k in range(Kn):
                    z = depths[k]
                    h = A2 + z * B2
                    ih = 1.0 / max(h, 1e-12)  # finite even behind the camera (then invalid)
                    x = (A0 + z * B0) * ih
                    y = (A1 + z * B1) * ih
                    rr = x * x + y * y
                    radial = 1.0 + rr * (k1 + rr * (k2 + rr * k3))
                    xd = x * radial + 2.0 * p1 * x * y + p2 * (rr + 2.0 * x * x)
                    yd = y * radial + p1 * (rr + 2.0 * y * y) + 2.0 * p2 * x * y
                    u = fx * xd + sk * yd + cx
                    v = fy * yd + cy
                    inside = (h > 0.0) & (u >= 0.0) & (v >= 0.0) & (u <= Ww - 1) & (v <= Hh - 1)
                    ok[k] &= inside
                    u = min(max(u, 0.0), Ww - 1.0)
                    v = min(max(v, 0.0), Hh - 1.0)
                    u0 = min(int(u), Ww - 2)
                    v0 = min(int(v), Hh - 2)
                    fa[c, k] = u - u0
                    fb[c, k] = v - v0
                    base[c, k] = v0 * row + u0 * nv
            # 2. Sample every slot of every camera in one bilinear footprint: the
            # Helmholtz cameras' J = mu i / p, then (with chromaticity) their p.
            for c in range(ncam):
                img = S[c].ravel()
                for k in range(Kn):
                    a = fa[c, k]
                    b = fb[c, k]
                    w00 = (1.0 - a) * (1.0 - b)
                    w01 = a * (1.0 - b)
                    w10 = (1.0 - a) * b
                    w11 = a * b
                    i0 = base[c, k]
                    good = True
                    for s in range(nread):
                        j = (w00 * img[i0 + s] + w01 * img[i0 + nv + s]
                             + w10 * img[i0 + row + s] + w11 * img[i0 + row + nv + s])  # fmt: skip
                        smp[c, s, k] = j
                        good &= (s >= ns) | (j > 0.0)  # else dark, saturated, outside, no p
                    ok[k] &= good
            # 3. The Gram matrix of W, row by row (eq. 5).
            M[:] = 0.0
            for p in range(npair):
                a = pair_cams[p, 0]
                b = pair_cams[p, 1]
                ja, jb = slots[p, 0], slots[p, 1]
                la0, la1, la2 = (
                    lights[a, 0] - c_ref[0],
                    lights[a, 1] - c_ref[1],
                    lights[a, 2] - c_ref[2],
                )
                lb0, lb1, lb2 = (
                    lights[b, 0] - c_ref[0],
                    lights[b, 1] - c_ref[1],
                    lights[b, 2] - c_ref[2],
                )
                for k in range(Kn):
                    z = depths[k]
                    da0 = la0 - z * r0
                    da1 = la1 - z * r1
                    da2 = la2 - z * r2
                    db0 = lb0 - z * r0
                    db1 = lb1 - z * r1
                    db2 = lb2 - z * r2
                    ra2 = da0 * da0 + da1 * da1 + da2 * da2
                    rb2 = db0 * db0 + db1 * db1 + db2 * db2
                    # Eq. (5) weights p_ab p_ba (mu_a i_a / p_ab v_a - ...).
                    pp = smp[a, ns + ja, k] * smp[b, ns + jb, k] if use_p else 1.0
                    sa = pp * smp[a, ja, k] / (ra2 * np.sqrt(ra2))
                    sb = pp * smp[b, jb, k] / (rb2 * np.sqrt(rb2))
                    w0 = sa * da0 - sb * db0
                    w1 = sa * da1 - sb * db1
                    w2 = sa * da2 - sb * db2
                    M[0, k] += w0 * w0
                    M[1, k] += w1 * w1
                    M[2, k] += w2 * w2
                    M[3, k] += w0 * w1
                    M[4, k] += w0 * w2
                    M[5, k] += w1 * w2
            # 4. sigma_3 / sigma_2 and the oriented null vector.
            for k in range(Kn):
                m00, m11, m22, m01, m02, m12 = M[0, k], M[1, k], M[2, k], M[3, k], M[4, k], M[5, k]
                lam3, lam2 = _smallest_eig(m00, m11, m22, m01, m02, m12)
                # Null vector of M - lam3 I: the largest cross product of two of its rows.
                q00, q11, q22 = m00 - lam3, m11 - lam3, m22 - lam3
                c0x = m01 * m12 - m02 * q11
                c0y = m02 * m01 - q00 * m12
                c0z = q00 * q11 - m01 * m01
                c1x = m01 * q22 - m02 * m12
                c1y = m02 * m02 - q00 * q22
                c1z = q00 * m12 - m01 * m02
                c2x = q11 * q22 - m12 * m12
                c2y = m12 * m02 - m01 * q22
                c2z = m01 * m12 - q11 * m02
                n0 = c0x * c0x + c0y * c0y + c0z * c0z
                n1 = c1x * c1x + c1y * c1y + c1z * c1z
                n2 = c2x * c2x + c2y * c2y + c2z * c2z
                big0 = (n0 >= n1) & (n0 >= n2)
                big1 = n1 >= n2
                nx = c0x if big0 else (c1x if big1 else c2x)
                ny = c0y if big0 else (c1y if big1 else c2y)
                nz = c0z if big0 else (c1z if big1 else c2z)
                nn = max(n0, max(n1, n2))
                valid = (ok[k] != 0) & (lam2 > TINY) & (nn > TINY)
                inv = 1.0 / np.sqrt(max(nn, TINY))
                inv = inv if valid else 0.0
                # Orient towards the reference camera: n . (c - X) = -z n . r > 0.
                inv = -inv if nx * r0 + ny * r1 + nz * r2 > 0.0 else inv
                score = np.sqrt(max(lam3, 0.0) / max(lam2, TINY))
                R[0, k] = score if valid else INVALID_COST
                R[1, k] = nx * inv
                R[2, k] = ny * inv
                R[3, k] = nz * inv
            for k in range(Kn):
                cost[n, k] = R[0, k]
                normals[n, k, 0] = R[1, k]
                normals[n, k, 1] = R[2, k]
                normals[n, k, 2] = R[3, k]


def prepare_images(
    images: np.ndarray,
    saturated: np.ndarray,
    pairs,
    mu: np.ndarray | None = None,
    chroma: np.ndarray | None = None,
    silhouettes: np.ndarray | None = None,
    min_signal: float = 0.01,
) -> Prepared:
    """Per-frame preparation of the data term's inputs.

    Every (camera, channel) of a reciprocal pair is one Helmholtz camera, so
    its mu map and chromaticity are folded into its image once:
    J = mu * i / p. J is replaced by ``SENTINEL`` where i is too dark
    (``min_signal``, after black level, in [0, 1]), p is unknown, the pixel is
    saturated or outside the silhouette; a bilinear sample that gives any
    weight to such a pixel is then negative and its hypothesis invalid. The
    eq. (5) weights p_ab p_ba are restored in the kernel from the packed p.
    Each camera's slots (one per channel it contributes to a pair) are packed
    per pixel, so one bilinear footprint reads them all.

    Parameters
    ----------
    images : (C, 3, H, W) float
        Cross-talk-unmixed images, [0, 1].
    saturated : (C, H, W) bool
        Saturated pixels.
    pairs : ``(pair_cams, pair_ch)`` from :func:`pair_arrays`.
    mu : (P, 2, H, W) float or None
        mu map of each side of each pair (eq. 2), or None for 1.
    chroma : (C, 3, H, W) float or None
        Chromaticity p per camera and band (sum 3), or None for white.
    silhouettes : (C, H, W) bool or None
        Object masks; None for no restriction.
    min_signal : float
        Samples at or below this are unusable.
    """
    pair_cams, pair_ch = (np.asarray(a) for a in pairs)
    C, _, H, W = images.shape
    used = [sorted({int(ch) for (cam, ch) in zip(pair_cams.ravel(), pair_ch.ravel(), strict=True)
                    if cam == c}) for c in range(C)]  # fmt: skip
    ns = max(len(u) for u in used)
    slots = np.array([[used[cam].index(ch) for cam, ch in zip(pc, pch, strict=True)]
                      for pc, pch in zip(pair_cams, pair_ch, strict=True)], np.int64)  # fmt: skip
    S = np.ones((C, H, W, 2 * ns), np.float32)
    unusable = saturated.astype(bool).copy()
    if silhouettes is not None:
        unusable |= ~silhouettes.astype(bool)
    for c in range(C):
        for s, ch in enumerate(used[c]):
            J = images[c, ch].astype(np.float32)
            bad = unusable[c] | ~(J > min_signal)
            if chroma is not None:
                p = chroma[c, ch].astype(np.float32)
                bad |= ~(p > 0)
                with np.errstate(invalid="ignore", divide="ignore"):
                    J = J / p
                S[c, :, :, ns + s] = np.where(bad, 1.0, p)
            S[c, :, :, s] = np.where(bad, SENTINEL, J)
    if mu is not None:
        for p, ((a, b), (sa, sb)) in enumerate(zip(pair_cams, slots, strict=True)):
            S[a, :, :, sa] = np.where(S[a, :, :, sa] > 0, S[a, :, :, sa] * mu[p, 0], SENTINEL)
            S[b, :, :, sb] = np.where(S[b, :, :, sb] > 0, S[b, :, :, sb] * mu[p, 1], SENTINEL)
    return Prepared(S, slots, chroma is not None)


def data_term(
    rays: np.ndarray,
    c_ref: np.ndarray,
    depths: np.ndarray,
    cameras,
    prepared: Prepared,
    pairs,
) -> tuple[np.ndarray, np.ndarray]:
    """Cost and normal of every (pixel, depth hypothesis), equation (5).

    Parameters
    ----------
    rays : (N, 3) world ray of each reference pixel, scaled to unit z-depth.
    c_ref : (3,) reference camera centre, metres.
    depths : (K,) z-depths of the hypotheses, metres.
    cameras : sequence of :class:`colourhs.capture.Camera` (the images' order).
    prepared : :class:`Prepared` from :func:`prepare_images`.
    pairs : ``(pair_cams, pair_ch)`` from :func:`pair_arrays`.

    Returns
    -------
    cost : (N, K) float32, sigma_3 / sigma_2 of W (``INVALID_COST`` if invalid).
    normals : (N, K, 3) float32 unit world normals towards the reference camera
        (0 where invalid).
    """
    pair_cams, _ = pairs
    Ks = np.stack([np.asarray(c.K, float) for c in cameras])
    dists = np.stack([np.pad(np.asarray(c.dist, float), (0, 5))[:5] for c in cameras])
    Ps = np.stack(
        [np.hstack([np.asarray(c.R, float), np.asarray(c.t, float)[:, None]]) for c in cameras]
    )
    lights = np.stack([np.asarray(c.light_centre, float) for c in cameras])
    cost = np.empty((len(rays), len(depths)), np.float32)
    normals = np.empty((len(rays), len(depths), 3), np.float32)
    _kernel(
        np.ascontiguousarray(rays, np.float64), np.asarray(c_ref, float),
        np.asarray(depths, np.float64), Ks, dists, Ps, lights, prepared.S, prepared.slots,
        prepared.use_p, np.asarray(pair_cams, np.int64), nb.get_num_threads(), cost, normals,
    )  # fmt: skip
    return cost, normals


def pair_arrays(rig) -> tuple[np.ndarray, np.ndarray]:
    """Reciprocal pairs as index arrays: (P, 2) camera indices and (P, 2) channels."""
    names = list(rig.camera_names)
    pairs = rig.reciprocal_pairs()
    cams = np.array([[names.index(p.cam_a), names.index(p.cam_b)] for p in pairs], np.int64)
    chans = np.array([[p.channel_a, p.channel_b] for p in pairs], np.int64)
    return cams, chans
