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

import numba as nb
import numpy as np

INVALID_COST = 1.0


@nb.njit(cache=True, fastmath=True, inline="always")
def _bilinear(img, u, v):
    """Bilinear sample of a 2-D float32 image; NaN outside [0, W-1] x [0, H-1]."""
    H, W = img.shape
    if not (u >= 0.0 and v >= 0.0 and u <= W - 1 and v <= H - 1):
        return np.nan
    u0 = min(int(u), W - 2)
    v0 = min(int(v), H - 2)
    a = u - u0
    b = v - v0
    return (1 - a) * ((1 - b) * img[v0, u0] + b * img[v0 + 1, u0]) + a * (
        (1 - b) * img[v0, u0 + 1] + b * img[v0 + 1, u0 + 1]
    )


@nb.njit(cache=True, fastmath=True, inline="always")
def _distort(K, dist, x, y):
    """Pixel of normalised coordinates (x, y) under the OpenCV model (k1, k2, p1, p2, k3)."""
    r2 = x * x + y * y
    radial = 1.0 + r2 * (dist[0] + r2 * (dist[1] + r2 * dist[4]))
    xd = x * radial + 2.0 * dist[2] * x * y + dist[3] * (r2 + 2.0 * x * x)
    yd = y * radial + dist[2] * (r2 + 2.0 * y * y) + 2.0 * dist[3] * x * y
    return K[0, 0] * xd + K[0, 1] * yd + K[0, 2], K[1, 1] * yd + K[1, 2]


@nb.njit(cache=True, fastmath=True, inline="always")
def _smallest_eig(a, b, c, d, e, f):
    """Smallest eigenvalue and the next one of the symmetric PSD matrix
    [[a, d, e], [d, b, f], [e, f, c]], by monotone Newton on the characteristic
    polynomial from 0 (it is convex and decreasing up to the smallest root)."""
    tr = a + b + c
    c2 = a * b + a * c + b * c - d * d - e * e - f * f
    det = a * (b * c - f * f) - d * (d * c - f * e) + e * (d * f - b * e)
    if det < 0.0:
        det = 0.0
    lam = 0.0
    for _ in range(8):
        p = det - lam * (c2 - lam * (tr - lam))
        dp = -c2 + lam * (2.0 * tr - 3.0 * lam)
        if dp >= 0.0:
            break
        step = p / dp
        lam -= step
        if -step < 1e-12 * tr:
            break
    s = tr - lam  # lam1 + lam2
    q = c2 - lam * s  # lam1 * lam2
    disc = s * s - 4.0 * q
    if disc < 0.0:
        disc = 0.0
    lam2 = 2.0 * q / (s + np.sqrt(disc)) if s > 0.0 else 0.0
    return lam, lam2


@nb.njit(parallel=True, cache=True, fastmath=True)
def _kernel(
    rays, c_ref, depths, Ks, dists, Ps, lights, J, P, use_p, blocked,
    pair_cams, pair_ch, nthreads, cost, normals,
):  # fmt: skip
    """Rows over prange; J = mu * i / p per camera and channel (NaN where unusable),
    P = p per camera and band, blocked = saturated (dilated) or outside a silhouette."""
    N = rays.shape[0]
    Kn = depths.shape[0]
    ncam = Ks.shape[0]
    npair = pair_cams.shape[0]
    Hh, Ww = blocked.shape[1], blocked.shape[2]
    chunk = (N + 4 * nthreads - 1) // (4 * nthreads)
    for t in nb.prange(4 * nthreads):
        uv = np.empty((ncam, 2))
        A = np.empty((ncam, 3))
        B = np.empty((ncam, 3))
        Wm = np.empty((npair, 3))
        for n in range(t * chunk, min(N, (t + 1) * chunk)):
            for c in range(ncam):
                for i in range(3):
                    A[c, i] = Ps[c, i, 3] + (
                        Ps[c, i, 0] * c_ref[0] + Ps[c, i, 1] * c_ref[1] + Ps[c, i, 2] * c_ref[2]
                    )
                    B[c, i] = (
                        Ps[c, i, 0] * rays[n, 0]
                        + Ps[c, i, 1] * rays[n, 1]
                        + Ps[c, i, 2] * rays[n, 2]
                    )
            for k in range(Kn):
                z = depths[k]
                ok = True
                for c in range(ncam):
                    h = A[c, 2] + z * B[c, 2]
                    if h <= 0.0:
                        ok = False
                        break
                    u, v = _distort(
                        Ks[c], dists[c], (A[c, 0] + z * B[c, 0]) / h, (A[c, 1] + z * B[c, 1]) / h
                    )
                    if not (u >= 0.0 and v >= 0.0 and u <= Ww - 1 and v <= Hh - 1):
                        ok = False
                        break
                    if blocked[c, int(v), int(u)]:
                        ok = False
                        break
                    uv[c, 0] = u
                    uv[c, 1] = v
                if ok:
                    X0 = c_ref[0] + z * rays[n, 0]
                    X1 = c_ref[1] + z * rays[n, 1]
                    X2 = c_ref[2] + z * rays[n, 2]
                    for p in range(npair):
                        a = pair_cams[p, 0]
                        b = pair_cams[p, 1]
                        ia = _bilinear(J[a, pair_ch[p, 0]], uv[a, 0], uv[a, 1])
                        ib = _bilinear(J[b, pair_ch[p, 1]], uv[b, 0], uv[b, 1])
                        if not (ia > 0.0 and ib > 0.0):  # NaN: dark, or no chromaticity
                            ok = False
                            break
                        if use_p:
                            # Eq. (5) weights: p_ab p_ba (mu_a i_a / p_ab v_a - ...).
                            pp = _bilinear(P[a, pair_ch[p, 0]], uv[a, 0], uv[a, 1]) * _bilinear(
                                P[b, pair_ch[p, 1]], uv[b, 0], uv[b, 1]
                            )
                            ia *= pp
                            ib *= pp
                        da0 = lights[a, 0] - X0
                        da1 = lights[a, 1] - X1
                        da2 = lights[a, 2] - X2
                        db0 = lights[b, 0] - X0
                        db1 = lights[b, 1] - X1
                        db2 = lights[b, 2] - X2
                        ra2 = da0 * da0 + da1 * da1 + da2 * da2
                        rb2 = db0 * db0 + db1 * db1 + db2 * db2
                        sa = ia / (ra2 * np.sqrt(ra2))
                        sb = ib / (rb2 * np.sqrt(rb2))
                        Wm[p, 0] = sa * da0 - sb * db0
                        Wm[p, 1] = sa * da1 - sb * db1
                        Wm[p, 2] = sa * da2 - sb * db2
                if not ok:
                    cost[n, k] = INVALID_COST
                    normals[n, k, 0] = 0.0
                    normals[n, k, 1] = 0.0
                    normals[n, k, 2] = 0.0
                    continue
                _score(Wm, npair, rays[n], cost, normals, n, k)


@nb.njit(cache=True, fastmath=True, inline="always")
def _score(Wm, npair, ray, cost, normals, n, k):
    """Cost sigma_3 / sigma_2 and oriented null vector of W (rows Wm)."""
    m00 = m11 = m22 = m01 = m02 = m12 = 0.0
    for p in range(npair):
        w0, w1, w2 = Wm[p, 0], Wm[p, 1], Wm[p, 2]
        m00 += w0 * w0
        m11 += w1 * w1
        m22 += w2 * w2
        m01 += w0 * w1
        m02 += w0 * w2
        m12 += w1 * w2
    lam3, lam2 = _smallest_eig(m00, m11, m22, m01, m02, m12)
    cost[n, k] = np.sqrt(max(lam3, 0.0) / lam2) if lam2 > 0.0 else INVALID_COST
    # Null vector of M - lam3 I: the largest cross product of two of its rows.
    r00, r11, r22 = m00 - lam3, m11 - lam3, m22 - lam3
    c0x = m01 * m12 - m02 * r11
    c0y = m02 * m01 - r00 * m12
    c0z = r00 * r11 - m01 * m01
    c1x = m01 * r22 - m02 * m12
    c1y = m02 * m02 - r00 * r22
    c1z = r00 * m12 - m01 * m02
    c2x = r11 * r22 - m12 * m12
    c2y = m12 * m02 - m01 * r22
    c2z = m01 * m12 - r11 * m02
    n0 = c0x * c0x + c0y * c0y + c0z * c0z
    n1 = c1x * c1x + c1y * c1y + c1z * c1z
    n2 = c2x * c2x + c2y * c2y + c2z * c2z
    if n0 >= n1 and n0 >= n2:
        nx, ny, nz, nn = c0x, c0y, c0z, n0
    elif n1 >= n2:
        nx, ny, nz, nn = c1x, c1y, c1z, n1
    else:
        nx, ny, nz, nn = c2x, c2y, c2z, n2
    nn = np.sqrt(nn)
    if nn == 0.0:
        cost[n, k] = INVALID_COST
        nn = 1.0
    # Orient towards the reference camera: n . (c - X) = -z n . r > 0.
    if nx * ray[0] + ny * ray[1] + nz * ray[2] > 0.0:
        nn = -nn
    normals[n, k, 0] = nx / nn
    normals[n, k, 1] = ny / nn
    normals[n, k, 2] = nz / nn


def prepare_images(
    images: np.ndarray,
    saturated: np.ndarray,
    pairs,
    mu: np.ndarray | None = None,
    chroma: np.ndarray | None = None,
    silhouettes: np.ndarray | None = None,
    min_signal: float = 0.01,
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """Per-frame preparation of the data term's inputs.

    Every (camera, channel) of a reciprocal pair is one Helmholtz camera, so
    its mu map and chromaticity can be folded into its image once:
    J = mu * i / p, NaN where i is too dark (``min_signal``) or p unknown.
    The eq. (5) weights p_ab p_ba are restored in the kernel from P = p.
    ``blocked`` marks pixels whose bilinear footprint touches a saturated
    pixel, and pixels outside the silhouette.

    Returns
    -------
    J : (C, 3, H, W) float32. P : (C, 3, H, W) float32 or None.
    blocked : (C, H, W) uint8.
    """
    J = np.array(images, np.float32, copy=True)
    J[J <= min_signal] = np.nan
    pair_cams, pair_ch = pairs
    if mu is not None:
        for p, ((a, b), (ca, cb)) in enumerate(zip(pair_cams, pair_ch, strict=True)):
            J[a, ca] *= mu[p, 0]
            J[b, cb] *= mu[p, 1]
    P = None
    if chroma is not None:
        P = np.ascontiguousarray(chroma, np.float32)
        with np.errstate(invalid="ignore", divide="ignore"):
            J /= np.where(P > 0, P, np.nan)
    sat = saturated.astype(bool)
    blocked = sat.copy()
    blocked[:, :-1] |= sat[:, 1:]
    blocked[:, :, :-1] |= sat[:, :, 1:]
    blocked[:, :-1, :-1] |= sat[:, 1:, 1:]
    if silhouettes is not None:
        blocked |= ~silhouettes.astype(bool)
    return J, P, blocked.astype(np.uint8)


def data_term(
    rays: np.ndarray,
    c_ref: np.ndarray,
    depths: np.ndarray,
    cameras,
    prepared: tuple,
    pairs,
) -> tuple[np.ndarray, np.ndarray]:
    """Cost and normal of every (pixel, depth hypothesis), equation (5).

    Parameters
    ----------
    rays : (N, 3) world ray of each reference pixel, scaled to unit z-depth.
    c_ref : (3,) reference camera centre, metres.
    depths : (K,) z-depths of the hypotheses, metres.
    cameras : sequence of :class:`colourhs.capture.Camera` (the images' order).
    prepared : ``(J, P, blocked)`` from :func:`prepare_images`.
    pairs : ``(pair_cams, pair_ch)`` from :func:`pair_arrays`.

    Returns
    -------
    cost : (N, K) float32, sigma_3 / sigma_2 of W (``INVALID_COST`` if invalid).
    normals : (N, K, 3) float32 unit world normals towards the reference camera.
    """
    J, P, blocked = prepared
    pair_cams, pair_ch = pairs
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
        np.asarray(depths, np.float64), Ks, dists, Ps, lights, J,
        np.ones((1, 1, 2, 2), np.float32) if P is None else P, P is not None, blocked,
        np.asarray(pair_cams, np.int64), np.asarray(pair_ch, np.int64), nb.get_num_threads(),
        cost, normals,
    )  # fmt: skip
    return cost, normals


def pair_arrays(rig) -> tuple[np.ndarray, np.ndarray]:
    """Reciprocal pairs as index arrays: (P, 2) camera indices and (P, 2) channels."""
    names = list(rig.camera_names)
    pairs = rig.reciprocal_pairs()
    cams = np.array([[names.index(p.cam_a), names.index(p.cam_b)] for p in pairs], np.int64)
    chans = np.array([[p.channel_a, p.channel_b] for p in pairs], np.int64)
    return cams, chans
