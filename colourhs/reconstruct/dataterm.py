"""The colour HS data term over depth hypotheses, compiled with numba.

For every pixel of the reference camera and every depth hypothesis z_k, the
hypothesised point X = c + z_k r (r: the pixel's ray scaled to unit z-depth)
is projected into every camera (OpenCV model); the six reciprocal
intensities are sampled bilinearly, multiplied by mu (eq. 2) and the
chromaticity p, and assembled into the 3 x 3 constraint matrix W whose rows
are equation (5). The singular values of W give the cost sigma_3 / sigma_2
(0 for a perfect rank-2 W) and its null vector the normal (oriented towards
the reference camera).

A hypothesis is *invalid* (cost ``INVALID_COST``, normal 0) when it leaves
an image, falls outside a silhouette, lands on a saturated pixel, or when
any of its six samples is too dark to measure (a black marker, a shadow from
a light, a pure colour in the wrong band) or has no chromaticity: with fewer
than three rows W would be trivially rank 2, so such hypotheses are never
scored as good. Beyond the paper, with a chromaticity map tracked away from
its chromatic frame (:mod:`colourhs.calibration.chromaticity_tracking`,
``borrow_p``), a camera's sample with no p of its own (none at any texel of
its footprint: one that mixes texels with and without p is invalid) takes
the reference pixel's p in that band: p is a property of the surface point
(eq. 4, once cross-talk is unmixed), and at the true depth both pixels see
the same point. A tracked map has holes where the object moved; without
this, the true depth of every ray that meets a hole in another camera would
be excluded while false roots elsewhere stay scored. A calibrated map's
holes (where the chromatic captures could not measure p) stay invalid, as in
the paper; so does a hypothesis whose reference pixel has no p. Beyond the
paper, it is also invalid when its normal faces away from, or within 5
degrees of grazing to, a camera's light: with three pairs, det W(z) = 0 has
further roots along a ray besides the surface, and many of them have such
normals (the test removes many false roots, not all: ML HS decides between
the rest, :mod:`colourhs.reconstruct.ml`).
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from colourhs.capture import MIN_SIGNAL
from colourhs.common.geometry import model_coefficients
from colourhs.common.sampling import footprint_jit, weights_jit
from colourhs.reconstruct.constraint import hs_row
from colourhs.reconstruct.simd import LANES, bilinear4, cache_tagged

INVALID_COST = 1.0
# sin(5 deg): a surface seen or lit within 5 degrees of grazing carries almost no
# signal (its intensities scale with that cosine); any rig, any scale.
MIN_FACING_COS = 0.087
MIN_FACING_COS2 = MIN_FACING_COS * MIN_FACING_COS


HALLEY_STEPS = 3  # exact to float32 for sigma_3 / sigma_2 < 0.6; 4 for < 0.8
TINY = 1e-300
LOW, HIGH = 1e-150, 1e150  # clamps that keep a product of two of them finite
SENTINEL = np.float32(-1.0e30)  # an unusable sample: any positive bilinear weight makes it < 0
# A p sample below this has all its bilinear weight (to float32 rounding) on
# texels without p: their J = mu i, undivided; one above it and <= 0 mixes both.
ALL_UNKNOWN = np.float32(0.99999 * SENTINEL)


class Prepared(NamedTuple):
    """A frame's images packed for the kernel (see :func:`prepare_images`).

    Attributes
    ----------
    S : (C, H, W, nv) float32
        Per camera and pixel, the s Helmholtz-camera values J = mu * i / p of
        the camera's slots, then (with chromaticity calibration only) their
        chromaticities p, padded with 1 to nv, a multiple of 4 (the kernel
        reads 4 slots per call of :data:`~colourhs.reconstruct.simd.bilinear4`).
        ``SENTINEL`` where J is unusable. Where only p is unknown and
        ``borrow``, J = mu * i and its p slot is ``SENTINEL``: the kernel then
        takes the reference camera's p (see :func:`data_term`).
    slots : (P, 2) int64
        Slot of each side of each reciprocal pair in its camera's S.
    use_p : bool
        Whether the eq. (5) weights p_ab p_ba are applied.
    P : (C, H, W, 4) float32
        Per camera and pixel, the chromaticity p of the three bands (padded
        with 1), ``SENTINEL`` where unknown; (1, 1, 1, 4) ones unless ``borrow``.
    borrow : bool
        Whether a sample with no p of its own takes the reference pixel's.
    """

    S: np.ndarray
    slots: np.ndarray
    use_p: bool
    P: np.ndarray = np.ones((1, 1, 1, LANES), np.float32)
    borrow: bool = False


@nb.njit(cache=True, fastmath=True, inline="always")
def _smallest_eig(a, b, c, d, e, f):
    """Smallest eigenvalue lam3 of the symmetric PSD matrix
    [[a, d, e], [d, b, f], [e, f, c]], with q = lam1 lam2 and
    den = lam1 + lam2 + |lam1 - lam2| (so the next one is lam2 = 2 q / den).

    ``HALLEY_STEPS`` Halley steps on the characteristic polynomial from 0 (one
    division each, cubic convergence): it is convex and decreasing up to the
    smallest root, and the iterates rise monotonically to it (never a step
    down, against rounding past the root), fast when sigma_3 << sigma_2 (the
    hypotheses that matter); slowly only as sigma_3 -> sigma_2, costs that
    the MRF truncates anyway. Branch-free, so the loop over hypotheses
    vectorises."""
    tr = a + b + c
    c2 = a * b + a * c + b * c - d * d - e * e - f * f
    det = max(a * (b * c - f * f) - d * (d * c - f * e) + e * (d * f - b * e), 0.0)
    lam = 0.0
    for _ in range(HALLEY_STEPS):
        p = det - lam * (c2 - lam * (tr - lam))
        dp = lam * (2.0 * tr - 3.0 * lam) - c2
        ddp = 2.0 * tr - 6.0 * lam
        lam += max(-2.0 * p * dp / max(2.0 * dp * dp - p * ddp, TINY), 0.0)
    s = tr - lam  # lam1 + lam2
    q = max(c2 - lam * s, 0.0)  # lam1 * lam2
    disc = max(s * s - 4.0 * q, 0.0)
    return lam, q, s + np.sqrt(disc)


@nb.njit(cache=True, inline="always")
def to_pixel(x, y, K, dist):
    """Pixel (u, v) of normalised camera coordinates (x, y): the package's
    camera model (:func:`colourhs.common.geometry.pixels_of`) compiled; ``dist``
    the 12 coefficients of :func:`colourhs.common.geometry.model_coefficients`."""
    return _to_pixel(x, y, K[0, 0], K[0, 1], K[0, 2], K[1, 1], K[1, 2], dist)


@nb.njit(cache=True, fastmath=True, inline="always")
def _to_pixel(x, y, fx, sk, cx, fy, cy, d):
    """Pixel (u, v) of normalised camera coordinates (x, y): OpenCV's
    distortion with the 12 coefficients ``d`` (k1, k2, p1, p2, k3, k4, k5,
    k6, s1, s2, s3, s4), then K with its skew ``sk`` (as
    :func:`colourhs.common.geometry.pixels_of`)."""
    rr = x * x + y * y
    radial = 1.0 + rr * (d[0] + rr * (d[1] + rr * d[4]))
    radial /= 1.0 + rr * (d[5] + rr * (d[6] + rr * d[7]))
    return _distorted(x, y, rr, radial, fx, sk, cx, fy, cy, d)


@nb.njit(cache=True, fastmath=True, inline="always")
def _to_pixel_poly(x, y, fx, sk, cx, fy, cy, d):
    """:func:`_to_pixel` for a lens whose rational coefficients k4, k5, k6 are 0
    (OpenCV's 5- and 8-coefficient models with the last three 0, most real
    calibrations): its denominator is exactly 1, so this gives the same pixel
    to the bit without the division (one of the data term's costliest
    operations per hypothesis)."""
    rr = x * x + y * y
    radial = 1.0 + rr * (d[0] + rr * (d[1] + rr * d[4]))
    return _distorted(x, y, rr, radial, fx, sk, cx, fy, cy, d)


@nb.njit(cache=True, fastmath=True, inline="always")
def _distorted(x, y, rr, radial, fx, sk, cx, fy, cy, d):
    """The rest of :func:`_to_pixel` once the radial factor is known."""
    xd = x * radial + 2.0 * d[2] * x * y + d[3] * (rr + 2.0 * x * x) + rr * (d[8] + rr * d[9])
    yd = y * radial + d[2] * (rr + 2.0 * y * y) + 2.0 * d[3] * x * y + rr * (d[10] + rr * d[11])
    return fx * xd + sk * yd + cx, fy * yd + cy


@nb.njit(cache=True, fastmath=True, inline="always")
def _falloff(d0, d1, d2):
    """Light fall-off 1 / |d|^3 of a point at offset d from the light (the
    1 / |d|^2 of eq. (4) times the normalisation of d), in float32: cheap."""
    r = np.float32(1.0) / np.sqrt(np.float32(d0 * d0 + d1 * d1 + d2 * d2))
    return r * r * r


@nb.njit(cache=True, fastmath=True, inline="always")
def _into_camera(depths, geo, lens, d, rational, Ww, Hh, cbase, row, nv, wts, base, fall, ok, c):
    """Every hypothesis k (z-depth ``depths[k]``) in camera c: the light
    fall-off ``fall[c, k]``, the bilinear weights ``wts[c, :, k]`` and the
    top-left texel's flat index ``base[c, k]`` (exact in float64); ``ok[k]``
    cleared where it is behind the camera or outside its image.

    ``geo``: the ray, A and B with ``A + z B`` the point in the camera's
    homogeneous image coordinates, and the light's offset from the rays'
    origin (3 each, flat); ``lens``: fx, skew, cx, fy, cy, and ``d`` its 12 distortion
    coefficients; ``rational``: whether they include k4-k6 (else
    :func:`_to_pixel_poly`); ``Ww``, ``Hh``: the image's size; ``cbase``,
    ``row``, ``nv``: the camera's flat offset in S, a row's and a pixel's."""
    # Indexed, not unpacked: numba's parfor analysis mistakes unpacked tuples for shapes.
    r0, r1, r2, A0, A1, A2 = geo[0], geo[1], geo[2], geo[3], geo[4], geo[5]
    B0, B1, B2, l0, l1, l2 = geo[6], geo[7], geo[8], geo[9], geo[10], geo[11]
    fx, sk, cx, fy, cy = lens[0], lens[1], lens[2], lens[3], lens[4]
    for k in range(depths.shape[0]):
        z = depths[k]
        h = A2 + z * B2
        fall[c, k] = _falloff(l0 - z * r0, l1 - z * r1, l2 - z * r2)
        ih = 1.0 / max(h, 1e-12)  # finite even behind the camera (then invalid)
        x, y = (A0 + z * B0) * ih, (A1 + z * B1) * ih
        if rational:
            u, v = _to_pixel(x, y, fx, sk, cx, fy, cy, d)
        else:
            u, v = _to_pixel_poly(x, y, fx, sk, cx, fy, cy, d)
        inside, u0, v0, a, b = footprint_jit(u, v, Ww, Hh)
        # float64 weights rounded into wts: a tiny positive weight stays positive,
        # so a SENTINEL under it still counts.
        w00, w01, w10, w11 = weights_jit(a, b)
        wts[c, 0, k] = w00
        wts[c, 1, k] = w01
        wts[c, 2, k] = w10
        wts[c, 3, k] = w11
        base[c, k] = int(cbase + v0 * row + u0 * nv)
        ok[k] &= inside & (h > 0.0)


@nb.njit(cache=True, fastmath=True, inline="always")
def _gram(M, smp, depths, pair_idx, pref, lights, fall, ok, ray, ns, use_p, borrow):
    """Pass 3 of :func:`_kernel`: the Gram matrix ``M`` (6, K) of W, row by row
    (eq. 5), from the samples ``smp`` (their p from slot ``ns`` on, if
    ``use_p``); ``ok[k]`` cleared where a J sample is <= 0. ``pair_idx`` (P, 6):
    per pair its cameras, their slots in S and their channels. ``borrow`` (a
    constant at each call): a p unknown over the whole footprint (J = mu i
    undivided there) is the reference pixel's, ``pref``; a footprint that mixes
    texels with and without p, or a reference pixel without p, is invalid.
    Without it, an unknown p made J unusable (:func:`prepare_images`). ``ray``:
    the pixel's ray (3)."""
    r0, r1, r2 = ray[0], ray[1], ray[2]
    for k in range(depths.shape[0]):
        M[0, k] = 0.0
        M[1, k] = 0.0
        M[2, k] = 0.0
        M[3, k] = 0.0
        M[4, k] = 0.0
        M[5, k] = 0.0
    for p in range(pair_idx.shape[0]):
        a, b = pair_idx[p, 0], pair_idx[p, 1]
        ja, jb = pair_idx[p, 2], pair_idx[p, 3]
        # float32 like the samples: p_ab p_ba rounds as the samples' own product
        qa, qb = pref[pair_idx[p, 4]], pref[pair_idx[p, 5]]
        qa = qa if qa > 0.0 else np.float32(0.0)
        qb = qb if qb > 0.0 else np.float32(0.0)
        la0, la1, la2 = lights[a, 0], lights[a, 1], lights[a, 2]
        lb0, lb1, lb2 = lights[b, 0], lights[b, 1], lights[b, 2]
        for k in range(depths.shape[0]):
            z = depths[k]
            Ja = smp[a, ja, k]
            Jb = smp[b, jb, k]
            # Eq. (5) weights p_ab p_ba (mu_a i_a / p_ab v_a - ...): rounded to
            # float32, the rest in float64.
            pa = smp[a, ns + ja, k] if use_p else np.float32(1.0)
            pb = smp[b, ns + jb, k] if use_p else np.float32(1.0)
            if borrow:
                ea = pa if pa > 0.0 else (qa if pa < ALL_UNKNOWN else np.float32(0.0))
                eb = pb if pb > 0.0 else (qb if pb < ALL_UNKNOWN else np.float32(0.0))
                ok[k] &= (Ja > 0.0) & (Jb > 0.0) & (ea > 0.0) & (eb > 0.0)
                sa = np.float64((pa if pa > 0.0 else np.float32(1.0)) * eb) * Ja * fall[a, k]
                sb = np.float64((pb if pb > 0.0 else np.float32(1.0)) * ea) * Jb * fall[b, k]
            else:
                ok[k] &= (Ja > 0.0) & (Jb > 0.0)
                pp = np.float64(pa * pb)
                sa = pp * Ja * fall[a, k]
                sb = pp * Jb * fall[b, k]
            w0, w1, w2 = hs_row(
                sa,
                sb,
                la0 - z * r0,
                la1 - z * r1,
                la2 - z * r2,
                lb0 - z * r0,
                lb1 - z * r1,
                lb2 - z * r2,
            )
            M[0, k] += w0 * w0
            M[1, k] += w1 * w1
            M[2, k] += w2 * w2
            M[3, k] += w0 * w1
            M[4, k] += w0 * w2
            M[5, k] += w1 * w2


@nb.njit(parallel=True, cache=True, fastmath=True)
@cache_tagged
def _kernel(
    rays,
    c_ref,
    depths,
    Ks,
    dists,
    rational,
    Ps,
    lights,
    S,
    Pc,
    ns,
    pair_idx,
    use_p,
    borrow,
    ref,
    others,
    nthreads,
    cost,
    normals,
):
    """Pixels over prange; per pixel, four passes over the hypotheses: project
    into every camera (OpenCV model), with the bilinear weights and the
    light fall-offs; sample all packed slots of each footprint (4 at a time,
    :mod:`colourhs.reconstruct.simd`: no gathers); accumulate the Gram matrix
    of W row by row (eq. 5); then sigma_3 / sigma_2 and the null vector; the
    facing test. Passes 1, 3,
    4 and 5 vectorise over the hypotheses. ``lights``: light centres minus ``c_ref``. ``ns``:
    offset of the p slots in S. ``ref``: the
    camera the rays leave from, or -1; every point of a ray through a camera's
    centre projects to the same pixel, so its footprint is computed and sampled
    once per pixel. ``others``: the other cameras."""
    N = rays.shape[0]
    Kn = depths.shape[0]
    ncam = Ks.shape[0]
    Hh, Ww, nv = S.shape[1], S.shape[2], S.shape[3]
    row = Ww * nv
    plane = Hh * row
    # Flat, and no array views inside the prange: any alias there makes numba
    # drop noalias on the arrays, which the vectorised passes rely on.
    Sf = S.reshape(S.size)
    Pf = Pc.reshape(Pc.size)
    nblocks = 4 * nthreads
    chunk = (N + nblocks - 1) // nblocks
    for t in nb.prange(nblocks):
        base = np.empty((ncam, Kn), np.int64)
        wts = np.empty((ncam, 4, Kn), np.float32)
        fall = np.empty((ncam, Kn), np.float32)  # light fall-off 1 / |L_c - X|^3
        smp = np.empty((ncam, nv, Kn), np.float32)
        M = np.empty((6, Kn))
        R = np.empty((3, Kn), np.float32)  # normal, copied out after the vectorised pass
        score = np.empty(Kn, np.float32)
        ok = np.empty(Kn, np.uint8)
        pref = np.empty(LANES, np.float32)  # the reference pixel's p, three bands
        ray = np.empty(3)  # the pixel's ray, for _gram
        for n in range(t * chunk, min(N, (t + 1) * chunk)):
            r0, r1, r2 = rays[n, 0], rays[n, 1], rays[n, 2]
            for k in range(Kn):
                ok[k] = 1
            for g in range(LANES):
                pref[g] = -1.0
            if ref >= 0:
                # The camera the rays leave from: one footprint, the same for
                # every hypothesis (a pixel centre: weight 1 on its own texel).
                X0, X1, X2 = c_ref[0] + r0, c_ref[1] + r1, c_ref[2] + r2  # unit depth
                x = Ps[ref, 0, 3] + Ps[ref, 0, 0] * X0 + Ps[ref, 0, 1] * X1 + Ps[ref, 0, 2] * X2
                y = Ps[ref, 1, 3] + Ps[ref, 1, 0] * X0 + Ps[ref, 1, 1] * X1 + Ps[ref, 1, 2] * X2
                h = Ps[ref, 2, 3] + Ps[ref, 2, 0] * X0 + Ps[ref, 2, 1] * X1 + Ps[ref, 2, 2] * X2
                u, v = _to_pixel(
                    x / h,
                    y / h,
                    Ks[ref, 0, 0],
                    Ks[ref, 0, 1],
                    Ks[ref, 0, 2],
                    Ks[ref, 1, 1],
                    Ks[ref, 1, 2],
                    dists[ref],
                )
                u = np.round(u) if abs(u - np.round(u)) < 1e-6 else u
                v = np.round(v) if abs(v - np.round(v)) < 1e-6 else v
                inside, u0, v0, a, b = footprint_jit(u, v, Ww, Hh)
                w00, w01, w10, w11 = weights_jit(a, b)
                at = int(ref * plane + v0 * row + u0 * nv)
                for g in range(0, nv, LANES):
                    bilinear4(Sf, at + g, nv, row, w00, w01, w10, w11, smp, (ref * nv + g) * Kn, Kn)
                if borrow:
                    at = int(((ref * Hh + v0) * Ww + u0) * LANES)
                    bilinear4(Pf, at, LANES, Ww * LANES, w00, w01, w10, w11, pref, 0, 1)
                for g in range(nv):
                    val = smp[ref, g, 0]
                    for k in range(1, Kn):
                        smp[ref, g, k] = val
                l0, l1, l2 = lights[ref, 0], lights[ref, 1], lights[ref, 2]
                for k in range(Kn):
                    z = depths[k]
                    fall[ref, k] = _falloff(l0 - z * r0, l1 - z * r1, l2 - z * r2)
                    ok[k] = inside & (z > 0.0)
            # 1. Project every hypothesis into every other camera; bilinear
            # footprints and the fall-off of the camera's light.
            for c in others:
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
                dc = dists[c]
                l0, l1, l2 = lights[c, 0], lights[c, 1], lights[c, 2]
                geo = (r0, r1, r2, A0, A1, A2, B0, B1, B2, l0, l1, l2)
                lens = (fx, sk, cx, fy, cy)
                cbase = c * plane
                # One loop per lens kind (the flag a constant, folded once inlined):
                # a branch inside the loop stops it vectorising.
                if rational[c]:
                    _into_camera(
                        depths, geo, lens, dc, True, Ww, Hh, cbase, row, nv, wts, base, fall, ok, c
                    )
                else:
                    _into_camera(
                        depths, geo, lens, dc, False, Ww, Hh, cbase, row, nv, wts, base, fall, ok, c
                    )
            # 2. Sample every slot of every camera in one bilinear footprint, 4
            # slots at a time: the Helmholtz cameras' J = mu i / p, then (with
            # chromaticity) their p. Scalar over k: bilinear sampling would
            # need gathers, which cost more than these 16-byte loads.
            for c in others:
                for k in range(Kn):
                    w00, w01, w10, w11 = wts[c, 0, k], wts[c, 1, k], wts[c, 2, k], wts[c, 3, k]
                    for g in range(0, nv, LANES):
                        bilinear4(
                            Sf,
                            base[c, k] + g,
                            nv,
                            row,
                            w00,
                            w01,
                            w10,
                            w11,
                            smp,
                            (c * nv + g) * Kn + k,
                            Kn,
                        )
            # 3. The Gram matrix of W, row by row (eq. 5); a hypothesis with a
            # J sample <= 0 (dark, saturated, outside, no p) is invalid. One
            # loop per mode (the flag a constant, folded once inlined).
            ray[0], ray[1], ray[2] = r0, r1, r2
            if borrow:
                _gram(M, smp, depths, pair_idx, pref, lights, fall, ok, ray, ns, use_p, True)
            else:
                _gram(M, smp, depths, pair_idx, pref, lights, fall, ok, ray, ns, use_p, False)
            # 4. sigma_3 / sigma_2 and the oriented null vector.
            for k in range(Kn):
                m00, m11, m22, m01, m02, m12 = M[0, k], M[1, k], M[2, k], M[3, k], M[4, k], M[5, k]
                lam3, q, den = _smallest_eig(m00, m11, m22, m01, m02, m12)
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
                # lam2 = 2 q / den > 0 and a null vector; one division for both
                # 1 / lam2 and 1 / |n| (q and nn clamped so the product is finite).
                valid = (ok[k] != 0) & (2.0 * q > TINY * den) & (nn > TINY)
                q2 = min(max(2.0 * q, LOW), HIGH)
                nnc = min(max(nn, LOW), HIGH)
                rq = 1.0 / (q2 * nnc)
                inv = np.sqrt(q2 * rq)
                # Orient towards the reference camera: n . (c - X) = -z n . r > 0.
                inv = -inv if nx * r0 + ny * r1 + nz * r2 > 0.0 else inv
                # (sigma_3 / sigma_2)^2 <= 1: its square root in float32, like the output.
                score[k] = np.sqrt(np.float32(min(max(lam3, 0.0) * den * nnc * rq, 4.0)))
                ok[k] = valid
                R[0, k] = nx * inv
                R[1, k] = ny * inv
                R[2, k] = nz * inv
            # 5. A point every camera sees and every light lights faces them all
            # (by more than MIN_FACING_COS): a normal that does not is a false
            # root of det W = 0. One pass per camera, so each vectorises over k
            # (a camera loop inside the k loop stops pass 4 vectorising).
            for c in range(ncam):
                l0, l1, l2 = lights[c, 0], lights[c, 1], lights[c, 2]
                for k in range(Kn):
                    z = depths[k]
                    dx, dy, dz = l0 - z * r0, l1 - z * r1, l2 - z * r2
                    facing = R[0, k] * dx + R[1, k] * dy + R[2, k] * dz
                    # facing > cos |d|, squared: no square root per camera and hypothesis.
                    lim2 = MIN_FACING_COS2 * (dx * dx + dy * dy + dz * dz)
                    ok[k] &= (facing > 0.0) & (facing * facing > lim2)
            # Selects, not products: an invalid hypothesis may carry inf or nan.
            for k in range(Kn):
                valid = ok[k] != 0
                cost[n, k] = score[k] if valid else np.float32(INVALID_COST)
                normals[n, k, 0] = R[0, k] if valid else np.float32(0.0)
                normals[n, k, 1] = R[1, k] if valid else np.float32(0.0)
                normals[n, k, 2] = R[2, k] if valid else np.float32(0.0)


def prepare_images(
    images: np.ndarray,
    saturated: np.ndarray,
    pairs,
    mu: np.ndarray | None = None,
    chroma: np.ndarray | None = None,
    silhouettes: np.ndarray | None = None,
    min_signal: float = MIN_SIGNAL,
    borrow_p: bool = False,
) -> Prepared:
    """Per-frame preparation of the data term's inputs.

    Every (camera, channel) of a reciprocal pair is one Helmholtz camera, so its
    mu map and chromaticity are folded into its image once: J = mu * i / p. J is
    replaced by ``SENTINEL`` where i is too dark (``min_signal``, after black
    level, in [0, 1]), p is unknown (unless ``borrow_p``), the pixel is
    saturated or outside the silhouette, or mu is not positive; a bilinear
    sample that gives any weight to such a pixel is then negative and its
    hypothesis invalid. The eq. (5) weights p_ab p_ba are restored in the kernel
    from the packed p. Each camera's slots (one per channel it contributes to a
    pair) are packed per pixel, so one bilinear footprint reads them all, 4 at a
    time.

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
    borrow_p : bool
        Whether a sample with no p of its own takes the reference pixel's (see
        the module docstring; a tracked map's holes), else it is unusable.
    """
    pair_cams, pair_ch = (np.asarray(a) for a in pairs)
    C, _, H, W = images.shape
    used = [
        sorted(
            {
                int(ch)
                for (cam, ch) in zip(pair_cams.ravel(), pair_ch.ravel(), strict=True)
                if cam == c
            }
        )
        for c in range(C)
    ]
    ns = max(len(u) for u in used)
    slots = np.array(
        [
            [used[cam].index(ch) for cam, ch in zip(pc, pch, strict=True)]
            for pc, pch in zip(pair_cams, pair_ch, strict=True)
        ],
        np.int64,
    )
    nv = LANES * -(-(2 * ns if chroma is not None else ns) // LANES)
    S = np.ones((C, H, W, nv), np.float32)
    P = np.ones((1, 1, 1, LANES), np.float32)
    if chroma is not None:
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            known = (chroma > 0) & np.isfinite(1.0 / chroma.astype(np.float32))
        p_all = np.where(known, chroma, SENTINEL).astype(np.float32)
        if borrow_p:
            P = np.ones((C, H, W, LANES), np.float32)
            P[..., :3] = np.moveaxis(p_all, 1, -1)
    unusable = saturated.astype(bool).copy()
    if silhouettes is not None:
        unusable |= ~silhouettes.astype(bool)
    for c in range(C):
        for s, ch in enumerate(used[c]):
            J = images[c, ch].astype(np.float32)
            bad = unusable[c] | ~(J > min_signal)
            if chroma is not None:
                # Never a nan or inf in S: the kernel's fastmath assumes none.
                J = np.where(known[c, ch], J / np.where(known[c, ch], p_all[c, ch], 1.0), J)
                if borrow_p:  # mu i undivided, its p SENTINEL: the kernel borrows
                    S[c, :, :, ns + s] = p_all[c, ch]
                else:
                    bad |= ~known[c, ch]
                    S[c, :, :, ns + s] = np.where(bad, 1.0, p_all[c, ch])
            S[c, :, :, s] = np.where(bad, SENTINEL, J)
    if mu is not None:
        for p, ((a, b), (sa, sb)) in enumerate(zip(pair_cams, slots, strict=True)):
            for cam, slot, m in ((a, sa, mu[p, 0]), (b, sb, mu[p, 1])):
                J = S[cam, :, :, slot]
                S[cam, :, :, slot] = np.where((J > 0) & (m > 0) & np.isfinite(m), J * m, SENTINEL)
    return Prepared(S, slots, chroma is not None, P, bool(borrow_p and chroma is not None))


def data_term(
    rays: np.ndarray,
    c_ref: np.ndarray,
    depths: np.ndarray,
    cameras,
    prepared: Prepared,
    pairs,
) -> tuple[np.ndarray, np.ndarray]:
    """Cost and normal of every (pixel, depth hypothesis), equation (5).

    With ``prepared.borrow``, a sample with no p of its own takes the p of the
    reference camera's pixel (the camera whose centre is ``c_ref``; none if no
    camera's is), as the module docstring says.

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
    dists = np.stack([model_coefficients(c.dist) for c in cameras])
    Ps = np.stack(
        [np.hstack([np.asarray(c.R, float), np.asarray(c.t, float)[:, None]]) for c in cameras]
    )
    # Light centres relative to the reference centre (the rays' origin).
    lights = np.stack([np.asarray(c.light_centre, float) for c in cameras]) - np.asarray(
        c_ref, float
    )
    ns = int(prepared.slots.max()) + 1  # slots of the busiest camera: where its p start
    centres = np.stack([np.asarray(c.centre, float) for c in cameras])
    at_ref = np.flatnonzero(np.linalg.norm(centres - np.asarray(c_ref, float), axis=1) < 1e-9)
    ref = int(at_ref[0]) if len(at_ref) else -1
    others = np.array([c for c in range(len(cameras)) if c != ref], np.int64)
    cost = np.empty((len(rays), len(depths)), np.float32)
    normals = np.empty((len(rays), len(depths), 3), np.float32)
    _kernel(
        np.ascontiguousarray(rays, np.float64),
        np.asarray(c_ref, float),
        np.asarray(depths, np.float64),
        Ks,
        dists,
        np.any(dists[:, 5:8] != 0.0, axis=1),
        Ps,
        lights,
        np.ascontiguousarray(prepared.S),
        np.ascontiguousarray(prepared.P, np.float32),
        ns,
        # Per pair: its cameras, their slots in S, their channels (for p_ref).
        np.column_stack([pair_cams, prepared.slots, pairs[1]]).astype(np.int64),
        prepared.use_p,
        prepared.borrow,
        ref,
        others,
        nb.get_num_threads(),
        cost,
        normals,
    )
    return cost, normals


def pair_arrays(rig) -> tuple[np.ndarray, np.ndarray]:
    """Reciprocal pairs as index arrays: (P, 2) camera indices and (P, 2) channels."""
    names = list(rig.camera_names)
    pairs = rig.reciprocal_pairs()
    cams = np.array([[names.index(p.cam_a), names.index(p.cam_b)] for p in pairs], np.int64)
    chans = np.array([[p.channel_a, p.channel_b] for p in pairs], np.int64)
    return cams, chans
