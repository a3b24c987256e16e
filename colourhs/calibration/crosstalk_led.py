"""The LED factor F of each camera from the board captures: ``M_LED(u) = M_filter(u) * F``.

Estimate 2 of :mod:`colourhs.calibration.crosstalk`, whose docstring derives the
constraints from eq. (1) on the flat white Lambertian board ((a) own channel,
(b) same light, both pose invariant) and why (a) is needed. This module holds

- :class:`BoardShot` and :func:`read_board_shots`: the board poses of the
  markers stage with their raw all-lights-on images;
- the rows of the fit: :func:`_build_led_problem` samples every board pose on
  a pixel grid of each camera -- box means, with the ring around each box as
  an instrumental variable (:func:`_box_images`), and the derivatives of the
  pose corrections (:func:`_pose_derivatives`) -- into a :class:`_LedProblem`,
  which evaluates the log residuals and their Jacobian in F
  (:func:`_unmix_rows`) and eliminates the free per-pixel constants h(u);
  :data:`OFF_DIAGONAL` orders the six unknowns of F per camera;
- :func:`led_factor` (parameters :data:`LED_DEFAULTS`): the 18 off-diagonals
  of F by instrumental-variables Gauss-Newton on those rows
  (:func:`_solve_led_problem`, with a sandwich covariance), shrunk towards 1
  by empirical Bayes (:func:`shrink_towards_filter`);
- :func:`led_factor_from_dataset`: both on a dataset.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from colourhs.calibration.crosstalk_filter import legendre_basis
from colourhs.capture import read_image
from colourhs.common.progress import bar, stage

log = logging.getLogger(__name__)

OFF_DIAGONAL = tuple((c, b) for c in range(3) for b in range(3) if c != b)

RING_GAP = 1
"""Pixels between a reading's box and its ring (:func:`_box_images`): the ring is the
instrumental variable of the fit, so it must share no pixel, and hence no noise, with
the reading. A reading taken between pixels (the partner camera's pixel of a board
point, an offset light's direction: bilinear, :func:`_build_led_problem`) is made of
the boxes of the four pixels around it, which reach one pixel beyond each one's own
box; a ring one pixel clear of its box is clear of them all. Without the gap the ring
of one of the four held its neighbours' readings, and with single-pixel boxes (images
under 240 pixels wide) on a noisy sensor F came out many standard errors off. A
property of bilinear sampling on the pixel lattice, so it holds on any rig."""


def _inv3(M: np.ndarray) -> np.ndarray:
    """Inverses of (N, 3, 3) matrices by cofactors (much faster than a batched LU)."""
    a, b, c = M[:, 0, 0], M[:, 0, 1], M[:, 0, 2]
    d, e, f = M[:, 1, 0], M[:, 1, 1], M[:, 1, 2]
    g, h, i = M[:, 2, 0], M[:, 2, 1], M[:, 2, 2]
    co = np.stack(
        [
            e * i - f * h,
            c * h - b * i,
            b * f - c * e,
            f * g - d * i,
            a * i - c * g,
            c * d - a * f,
            d * h - e * g,
            b * g - a * h,
            a * e - b * d,
        ],
        axis=1,
    ).reshape(-1, 3, 3)
    det = a * co[:, 0, 0] + b * co[:, 1, 0] + c * co[:, 2, 0]
    return co / det[:, None, None]


def _unmix_rows(readings, Mf, Minv, ch):
    """Channel ``ch`` of T = M^-1 readings per row, and d log T_ch / d F[c, b] (N, 6).

    M = Mf * F; for an off-diagonal (c, b), dT/dF[c, b] = -M^-1 (dM/dF[c, b]) T
    = -Mf[c, b] T_b M^-1[:, c].
    """
    r = np.arange(len(readings))
    T = np.einsum("ncb,nb->nc", Minv, readings)
    t = T[r, ch]
    D = np.empty((len(readings), len(OFF_DIAGONAL)))
    with np.errstate(divide="ignore", invalid="ignore"):
        for q, (c, b) in enumerate(OFF_DIAGONAL):
            D[:, q] = -Mf[:, c, b] * T[:, b] * Minv[r, ch, c] / t
    return t, D


class _LedProblem:
    """The rows of the LED-factor fit (see :func:`led_factor`).

    Per row: the box-filtered readings ``Y`` of one or two cameras (the
    measurement), the readings ``Q`` of a ring around the same footprint
    (independent noise: they give the Jacobian and the weights, so the
    Gauss-Newton normal equations are an instrumental-variables estimator,
    unbiased by the noise of ``Y``), the filter mixing there, the geometry
    term, the nuisance design ``Z`` and the pixel group of the free h(u).
    """

    def __init__(self, rows: dict, nc: int, ncols: int):
        for k, v in rows.items():
            setattr(self, k, v)
        self.nc = nc
        self.N = len(self.group)
        self.ng = int(self.group.max()) + 1 if self.N else 0
        self.nth = nc * len(OFF_DIAGONAL)
        self.two = self.cam2 >= 0
        self.ncols = ncols

    def factors(self, theta) -> np.ndarray:
        F = np.ones((self.nc, 3, 3))
        for kk in range(self.nc):
            for q, (c, b) in enumerate(OFF_DIAGONAL):
                F[kk, c, b] = theta[kk * len(OFF_DIAGONAL) + q]
        return F

    def evaluate(self, theta):
        """y (N,) at factors theta, its Jacobian (N, nth) and noise weights, from the ring."""
        nq, N = len(OFF_DIAGONAL), self.N
        F = self.factors(theta)
        Minv = _inv3(self.M1 * F[self.cam])
        t1, _ = _unmix_rows(self.Y1, self.M1, Minv, self.ch)
        q1, d1 = _unmix_rows(self.Q1, self.M1, Minv, self.ch)
        with np.errstate(divide="ignore", invalid="ignore"):
            y = np.log(t1) - self.logG
        J = np.zeros((N, self.nth))
        np.put_along_axis(J, self.cam[:, None] * nq + np.arange(nq), d1, axis=1)
        var = 1.0 / q1
        i2 = np.flatnonzero(self.two)
        if len(i2):
            M2, c2, ch2 = self.M2[i2], self.cam2[i2], self.ch[i2]
            Minv2 = _inv3(M2 * F[c2])
            t2, _ = _unmix_rows(self.Y2[i2], M2, Minv2, ch2)
            q2, d2 = _unmix_rows(self.Q2[i2], M2, Minv2, ch2)
            with np.errstate(divide="ignore", invalid="ignore"):
                y[i2] -= np.log(t2)
            J2 = np.zeros((len(i2), self.nth))
            np.put_along_axis(J2, c2[:, None] * nq + np.arange(nq), -d2, axis=1)
            J[i2] += J2
            var[i2] += 1.0 / q2
        with np.errstate(divide="ignore", invalid="ignore"):
            w = np.where(np.isfinite(y) & (var > 0), 1.0 / var, 0.0)
        return np.nan_to_num(y), np.nan_to_num(J), F, np.nan_to_num(w)

    def design(self, J):
        """The sparse design [J, -Z] (each row touches one or two cameras' blocks)."""
        import scipy.sparse as sp

        if getattr(self, "_Zs", None) is None:
            self._Zs = -sp.csr_matrix(self.Z)
        return sp.hstack([sp.csr_matrix(J), self._Zs], format="csr")

    def normal_equations(self, X, y, w):
        """X^T W X and X^T W y of the rows with each pixel group's weighted mean removed."""
        import scipy.sparse as sp

        S = sp.csr_matrix((w, (self.group, np.arange(self.N))), shape=(self.ng, self.N))
        sw = np.asarray(S.sum(axis=1)).ravel()
        sw = np.where(sw > 0, sw, 1.0)
        Sx, Sy = S @ X, S @ y
        XtX = (X.T @ sp.diags(w) @ X).toarray() - (Sx.T @ sp.diags(1.0 / sw) @ Sx).toarray()
        Xty = X.T @ (w * y) - Sx.T @ (Sy / sw)
        return XtX, np.asarray(Xty).ravel()

    def demean(self, a, w):
        """``a`` minus its weighted mean over each pixel group (eliminates h(u))."""
        g, ng = self.group, self.ng
        sw = np.bincount(g, weights=w, minlength=ng)
        sw = np.where(sw > 0, sw, 1.0)
        if a.ndim == 1:
            return a - (np.bincount(g, weights=w * a, minlength=ng) / sw)[g]
        out = np.empty_like(a)
        for col in range(a.shape[1]):
            m = np.bincount(g, weights=w * a[:, col], minlength=ng) / sw
            out[:, col] = a[:, col] - m[g]
        return out


def _box_images(rig, shots, k: int, K: int, margin_m: float) -> list[dict]:
    """Per shot and camera: k x k box means, ring means, and where both are usable.

    A pixel is valid when its centre sees the board's white surface at least
    ``margin_m`` (and 1.5 pixels) from markers and edges and is not saturated. The box mean
    needs every pixel of its box valid; the ring (the K x K box less the
    (k + 2 :data:`RING_GAP`) one: :data:`RING_GAP` pixels clear of the box) averages
    its valid pixels and needs a third of them. A bar over
    the shots (:func:`colourhs.common.progress.bar`).
    """
    import cv2

    from colourhs.common.geometry import backproject, pixel_grid, ray_plane_intersection

    W, H = rig.image.width, rig.image.height
    grid = pixel_grid(W, H).reshape(-1, 2)
    rays = {c.name: backproject(grid, c.K, c.dist, c.R, c.t) for c in rig.cameras}

    def bsum(a, size):
        return cv2.boxFilter(a, -1, (size, size), normalize=False, borderType=cv2.BORDER_CONSTANT)

    out = []
    for shot in bar(shots, "cross-talk: board poses", unit="pose"):
        per = {}
        for cam in rig.cameras:
            name = cam.name
            origin, d = rays[name]
            x, t = ray_plane_intersection(origin, d, shot.t, shot.normal)
            xy = ((x - shot.t) @ shot.R)[:, :2]
            with np.errstate(invalid="ignore", divide="ignore"):
                # at least 1.5 pixels clear of a marker or edge, wherever the pixel lies
                pixel_m = t / (cam.K[0, 0] * np.abs(d @ shot.normal))
                margin = np.maximum(margin_m, 1.5 * np.nan_to_num(pixel_m, nan=np.inf))
                valid = (t > 0) & rig.board.white(xy, margin)
            valid = valid.reshape(H, W) & ~shot.saturated[name]
            v = valid.astype(np.float32)
            img = np.ascontiguousarray(shot.images[name], np.float32) * v[..., None]
            g = k + 2 * RING_GAP
            n_small, n_gap, n_big = bsum(v, k), bsum(v, g), bsum(v, K)
            s_small, s_gap, s_big = bsum(img, k), bsum(img, g), bsum(img, K)
            ring_n = n_big - n_gap
            ok = (n_small > k * k - 0.5) & (ring_n >= (K * K - g * g) / 3)
            with np.errstate(invalid="ignore", divide="ignore"):
                ring = (s_big - s_gap) / ring_n[..., None]
            per[name] = (s_small / (k * k), np.where(ok[..., None], ring, 0.0), ok)
        out.append(per)
    return out


POSE_STEP = (1e-3, 1e-3, 1e-3)  # m of depth, rad of tilt: the units of the pose corrections


def _pose_derivatives(shot, board, origin, d, cam) -> np.ndarray:
    """d log((n . v) / |c - x|^2) / d(plane depth, two tilts) for rays ``d`` of ``cam`` (N, 3).

    The board plane moved along its normal, or turned about its two in-plane
    axes through the board's centre; finite differences of the exact geometry.
    """
    from colourhs.common.geometry import axis_angle, ray_plane_intersection

    def log_g(R, t):
        n = R @ np.array([0.0, 0.0, -1.0])
        x, _ = ray_plane_intersection(origin, d, t, n)
        v = cam.light_centre - x
        d2 = np.sum(v**2, axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.log((v @ n) / np.sqrt(d2) / d2)

    base = log_g(shot.R, shot.t)
    centre = shot.R @ np.array([board.size[0] / 2, board.size[1] / 2, 0.0]) + shot.t
    out = np.empty((len(d), 3))
    eps = 1e-5
    out[:, 0] = (log_g(shot.R, shot.t + eps * shot.normal) - base) / eps * POSE_STEP[0]
    for k, axis in enumerate((shot.R[:, 0], shot.R[:, 1])):
        Q = axis_angle(axis, eps)
        R = Q @ shot.R
        out[:, k + 1] = (log_g(R, centre - Q @ (centre - shot.t)) - base) / eps * POSE_STEP[k + 1]
    return np.nan_to_num(out)


def _build_led_problem(rig, shots, fields, opts) -> _LedProblem:
    from colourhs.common.geometry import backproject, project, ray_plane_intersection
    from colourhs.common.sampling import sample_bilinear

    W, H = rig.image.width, rig.image.height
    step = int(opts["step_px"])
    k = 2 * (step // 2) + 1  # odd box, centred on the sample
    K = k + 2 * RING_GAP + 4  # a ring 2 pixels wide, RING_GAP pixels clear of the box
    cams = rig.cameras
    nc, npose = len(cams), len(shots)
    sdeg = int(opts["sigma_degree"])
    nbs = (sdeg + 1) * (sdeg + 2) // 2 - 1
    n_pose_cols = 3 * npose if opts["pose_refinement"] else 0
    ncols = n_pose_cols + nc * nbs
    half = K // 2 + 1
    us = np.arange(half, W - half, step, dtype=float)
    vs = np.arange(half, H - half, step, dtype=float)
    gu, gv = np.meshgrid(us, vs)
    uv = np.stack([gu.ravel(), gv.ravel()], axis=1)
    npx = len(uv)
    iu, iv = uv[:, 0].astype(int), uv[:, 1].astype(int)
    boxes = _box_images(rig, shots, k, K, opts["margin_m"])
    parts = []
    for a, A in enumerate(cams):
        origin, d = backproject(uv, A.K, A.dist, A.R, A.t)
        MA = fields[A.name].at(uv)
        # the light's rays: the camera's model moved to the light centre
        collocated = bool(np.allclose(A.light_offset, 0.0))
        l_origin, l_dir = origin, d
        if not collocated:
            l_origin, l_dir = backproject(uv, A.K, A.dist, A.R, -A.R @ A.light_centre)
        for j, shot in enumerate(shots):
            n = shot.normal
            x, s = ray_plane_intersection(origin, d, shot.t, n)
            yA, qA, okA = (v[iv, iu] for v in boxes[j][A.name])
            with np.errstate(invalid="ignore", divide="ignore"):
                vc = A.centre - x
                cos_c = (vc @ n) / np.linalg.norm(vc, axis=1)
                ok = (s > 0) & (cos_c > opts["min_cos"]) & okA
            # (a) the camera's own channel against the geometry of its own light, on a
            # grid of the light's directions (the camera's own grid when collocated)
            o = A.light_channel
            if collocated:
                xo, so, uo, yo, qo, oko = x, s, uv, yA, qA, okA
            else:
                xo, so = ray_plane_intersection(l_origin, l_dir, shot.t, n)
                uo = project(xo, A.K, A.dist, A.R, A.t)
                box, ring, okimg = boxes[j][A.name]
                yo, qo = sample_bilinear(box, uo), sample_bilinear(ring, uo)
                with np.errstate(invalid="ignore"):
                    oko = sample_bilinear(okimg.astype(np.float32), uo) > 1 - 1e-6
                    oko &= (uo[:, 0] >= half) & (uo[:, 0] <= W - 1 - half)
                    oko &= (uo[:, 1] >= half) & (uo[:, 1] <= H - 1 - half)
            vl = A.light_centre - xo
            dl2 = np.sum(vl**2, axis=1)
            vco = A.centre - xo
            with np.errstate(invalid="ignore", divide="ignore"):
                cos_l = (vl @ n) / np.sqrt(dl2)
                own = (so > 0) & oko & (cos_l > opts["min_cos"]) & (yo[:, o] > opts["min_signal"])
                own &= (vco @ n) / np.linalg.norm(vco, axis=1) > opts["min_cos"]
            idx = np.flatnonzero(own) if "own" in opts["constraints"] else np.zeros(0, int)
            z = np.zeros((len(idx), ncols))
            if n_pose_cols:
                # the markers stage's plane error (depth, two tilts), shared by the cameras
                dz = _pose_derivatives(shot, rig.board, l_origin, l_dir[idx], A)
                z[:, 3 * j : 3 * j + 3] = dz
            if not collocated:
                # the camera's own-channel vignetting at its pixel, S_a, as in (b)
                base = n_pose_cols + a * nbs
                z[:, base : base + nbs] = legendre_basis(uo[idx], W, H, sdeg)[:, 1:]
            parts.append(
                {
                    "kind": np.zeros(len(idx), int),
                    "cam": np.full(len(idx), a),
                    "cam2": np.full(len(idx), -1),
                    "ch": np.full(len(idx), o),
                    "Y1": yo[idx],
                    "Q1": qo[idx],
                    "M1": MA[idx] if collocated else fields[A.name].at(uo[idx]),
                    "Y2": np.ones((len(idx), 3)),
                    "Q2": np.ones((len(idx), 3)),
                    "M2": np.broadcast_to(np.eye(3), (len(idx), 3, 3)),
                    "logG": np.log(cos_l[idx] / dl2[idx]),
                    "Z": z,
                    "group": a * npx + idx,
                    "u1": uv[idx],
                    "u2": np.full((len(idx), 2), np.nan) if collocated else uo[idx],
                    "pose": np.full(len(idx), j),
                }
            )
            # (b) the light of camera m seen by camera a and by camera m itself
            for m, B in enumerate(cams):
                if m == a or "same_light" not in opts["constraints"]:
                    continue
                oB = B.light_channel
                uB = project(x, B.K, B.dist, B.R, B.t)
                vb = B.light_centre - x
                vcb = B.centre - x
                with np.errstate(invalid="ignore", divide="ignore"):
                    okb = ok & ((vcb @ n) / np.linalg.norm(vcb, axis=1) > opts["min_cos"])
                    okb &= (vb @ n) / np.linalg.norm(vb, axis=1) > opts["min_cos"]
                    okb &= (uB[:, 0] >= half) & (uB[:, 0] <= W - 1 - half)
                    okb &= (uB[:, 1] >= half) & (uB[:, 1] <= H - 1 - half)
                idx = np.flatnonzero(okb)
                ub = uB[idx]
                box_B, ring_B, ok_B = boxes[j][B.name]
                usable = sample_bilinear(ok_B.astype(np.float32), ub) > 1 - 1e-6
                yB = sample_bilinear(box_B, ub)
                qB = sample_bilinear(ring_B, ub)
                with np.errstate(invalid="ignore"):
                    keep = usable & (yA[idx, oB] > opts["min_signal"])
                    keep &= yB[:, oB] > opts["min_signal"]
                idx, ub, yB, qB = idx[keep], ub[keep], yB[keep], qB[keep]
                z = np.zeros((len(idx), ncols))
                base = n_pose_cols + m * nbs
                z[:, base : base + nbs] = -legendre_basis(ub, W, H, sdeg)[:, 1:]
                parts.append(
                    {
                        "kind": np.ones(len(idx), int),
                        "cam": np.full(len(idx), a),
                        "cam2": np.full(len(idx), m),
                        "ch": np.full(len(idx), oB),
                        "Y1": yA[idx],
                        "Q1": qA[idx],
                        "M1": MA[idx],
                        "Y2": yB,
                        "Q2": qB,
                        "M2": fields[B.name].at(ub),
                        "logG": np.zeros(len(idx)),
                        "Z": z,
                        "group": nc * npx + (a * nc + m) * npx + idx,
                        "u1": uv[idx],
                        "u2": ub,
                        "pose": np.full(len(idx), j),
                    }
                )
    rows = {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}
    block = np.floor(rows["u1"] / (8 * step)).astype(int)
    rows["cluster"] = np.stack(
        [rows["kind"], rows["cam"], rows["cam2"], rows["pose"], block[:, 0], block[:, 1]], axis=1
    )
    # a pixel seen in a single pose carries nothing once its h(u) is eliminated
    _, inv, counts = np.unique(rows["group"], return_inverse=True, return_counts=True)
    keep = counts[inv] >= 2
    rows = {key: v[keep] for key, v in rows.items()}
    rows["group"] = np.unique(rows["group"], return_inverse=True)[1]
    rows["cluster"] = np.unique(rows["cluster"], axis=0, return_inverse=True)[1].ravel()
    if len(rows["group"]) < 100:
        raise ValueError(f"LED factor: too few usable board samples ({len(rows['group'])})")
    prob = _LedProblem(rows, nc, ncols)
    prob.step, prob.box = step, k
    return prob


@dataclass(frozen=True)
class BoardShot:
    """One board pose with its all-lights-on images (raw, not unmixed)."""

    name: str
    R: np.ndarray  # board to world rotation
    t: np.ndarray  # board to world translation, metres
    images: dict  # camera name -> (H, W, 3) linear image
    saturated: dict  # camera name -> (H, W) bool

    @property
    def normal(self) -> np.ndarray:
        """Unit normal of the white face (towards the cameras), world frame."""
        return self.R @ np.array([0.0, 0.0, -1.0])


LED_DEFAULTS = {
    "step_px": None,
    "margin_m": 0.002,
    "min_cos": 0.3,
    "min_signal": 0.03,
    "sigma_degree": 4,
    "pose_refinement": False,
    "iterations": 10,
    "huber": 3.0,
    "constraints": ("own", "same_light"),
    "shrink": True,
}


def _solve_led_problem(prob: _LedProblem, theta, iterations: int, huber: float):
    """IV Gauss-Newton with Huber reweighting; returns theta, its covariance, diagnostics."""
    nth = prob.nth
    robust = np.ones(prob.N)
    steps = []
    for it in range(max(int(iterations), 1) + 1):
        y, J, F, wn = prob.evaluate(theta)
        w = wn * robust
        X = prob.design(J)
        XtX, Xty = prob.normal_equations(X, y, w)
        sol = np.linalg.lstsq(XtX, -Xty, rcond=1e-13)[0]
        r = prob.demean(y + X @ sol, w)
        if it == max(int(iterations), 1) or (steps and steps[-1] < 1e-5):
            break  # the last pass only evaluates (for the covariance)
        theta = theta + sol[:nth]
        z = r * np.sqrt(wn)
        scale = 1.4826 * np.median(np.abs(z[w > 0])) + 1e-15
        robust = np.minimum(1.0, huber * scale / np.maximum(np.abs(z), 1e-30))
        steps.append(float(np.max(np.abs(sol[:nth]))))
    # sandwich covariance of theta, nuisances eliminated, with the score summed over
    # clusters of nearby rows (residuals of neighbouring samples are correlated:
    # shared pixels of the partner camera, small model errors)
    import scipy.sparse as sp

    Xt = prob.demean(X.toarray(), w)
    Hi = np.linalg.pinv(XtX, rcond=1e-13)
    _, cl = np.unique(prob.cluster, return_inverse=True)
    C = sp.csr_matrix((w * r, (cl, np.arange(prob.N))), shape=(int(cl.max()) + 1, prob.N))
    score = C @ Xt
    cov = (Hi @ (score.T @ score) @ Hi)[:nth, :nth]
    # identifiability of theta: the Schur complement with the nuisances eliminated
    red = np.linalg.pinv(Hi[:nth, :nth], rcond=1e-15)
    # all zero where no camera's filters leak (nothing for F to scale): sv = 0
    sv = np.linalg.svd(red / max(np.abs(red).max(), 1e-300), compute_uv=False)
    diag = {
        "iterations": len(steps),
        "last_step": steps[-1],
        "rms_log_residual": float(np.sqrt(np.sum(w * r**2) / np.sum(w) / np.mean(wn[w > 0]))),
        "singular_values": [float(v) for v in sv],
    }
    return theta, cov, diag


def shrink_towards_filter(theta, cov) -> tuple[np.ndarray, np.ndarray, float]:
    """Empirical-Bayes estimate of the LED factors given their fit and its covariance.

    Prior: F = 1 + N(0, tau^2) for every off-diagonal (the filters chosen to
    match the LEDs' colours); tau maximises the marginal likelihood of the fit,
    ``theta - 1 ~ N(0, cov + tau^2 I)``. Returns the posterior mean, its
    covariance and tau. Where the fit is no better than its noise (LEDs
    and filters alike, or too few board pixels) tau -> 0 and F -> 1: the
    filter mixing, never worse than ignoring the board.
    """
    from scipy.optimize import minimize_scalar

    d = np.asarray(theta, float) - 1.0
    C = 0.5 * (cov + cov.T)
    eye = np.eye(len(d))

    def nll(log_tau):
        A = C + np.exp(2 * log_tau) * eye
        sign, logdet = np.linalg.slogdet(A)
        return 0.5 * (logdet + d @ np.linalg.solve(A, d)) if sign > 0 else np.inf

    res = minimize_scalar(nll, bounds=(np.log(1e-4), np.log(2.0)), method="bounded")
    tau2 = float(np.exp(2 * res.x))
    if nll(np.log(1e-4)) <= res.fun:
        tau2 = 0.0
    if tau2 == 0.0:  # no evidence against the filters (or nothing fitted: C = 0)
        return np.ones_like(d), np.zeros_like(C), 0.0
    A = C + tau2 * eye
    gain = tau2 * np.linalg.inv(A)
    return 1.0 + gain @ d, tau2 * eye - tau2 * gain, float(np.sqrt(tau2))


def led_factor(rig, shots: list[BoardShot], fields: dict, **params) -> dict:
    """The constant LED factor F per camera, ``M_LED(u) = M_filter(u) * F``, from the board.

    Constraints (:mod:`colourhs.calibration.crosstalk` docstring; eq. 1 with a Lambertian board),
    at samples on a grid of step ``step_px`` (default width / 160) of each camera a,
    for every board pose where the sample sees the white surface (``margin_m``
    clear of markers and edges, incidence cosines above ``min_cos``,
    unsaturated, readings above ``min_signal``):

    - (a) own channel o of camera a:
      ``log T_{a<-a} - log((n . v_a) / |c_a - x|^2) = h(u)``, h free per pixel
      (it is log(sigma rho) of the camera's own Helmholtz camera);
    - (b) each other light m: ``log T_{a<-m}(u) - log T_{m<-m}(u_m) = h'(u) -
      S_m(u_m)``, u_m the board point's pixel in camera m, h' free per pixel,
      S_m (log sigma of camera m's own channel) a Legendre polynomial of
      degree ``sigma_degree``.

    Readings are means over an odd box of about ``step_px`` pixels (as much
    information as every pixel, far fewer rows); the Jacobian and the noise
    weights come from the ring around each box (an instrumental variable:
    Jacobians from the sample's own noisy readings bias F by many standard
    errors). The 18 off-diagonals of F are solved by Gauss-Newton with the
    per-pixel constants eliminated (variable projection) and the
    polynomials solved jointly, with Huber weights at ``huber`` robust
    deviations.

    Only (a) depends on the board poses, through the geometry: a depth error
    dz of the markers stage shifts log G by about 2 dz / d, which F absorbs as
    a leak (more on small images, whose marker poses are less precise).
    ``pose_refinement`` adds a depth and two tilt corrections per pose, shared
    by the cameras; it removes that bias on noise-free images but is nearly
    degenerate with F and multiplies its noise errors many times over, so it
    is off by default. ``constraints``
    chooses the kinds of rows, ``("own", "same_light")``; without "own" the
    fit has six null directions (the mixing common to all cameras,
    :mod:`colourhs.calibration.crosstalk` docstring), visible as six vanishing ``singular_values``.

    With ``shrink`` (default) the fitted factors are shrunk towards 1 by
    :func:`shrink_towards_filter` (empirical Bayes, one prior spread for the
    18 numbers, from their fit and its sandwich covariance): LEDs that match
    the filters, or a fit too noisy to tell, give F = 1, i.e. the filter field.

    Shows a bar over the board poses and logs a line at INFO before the fit
    (:mod:`colourhs.common.progress`).

    Parameters
    ----------
    rig : the dataset's :class:`~colourhs.capture.Rig`.
    shots : board poses with their raw images.
    fields : camera name -> filter :class:`MixingField` (chromatic captures).

    Returns
    -------
    dict with ``factor`` (camera -> (3, 3) F, unit diagonal), ``sd`` (camera ->
    (3, 3) standard errors: sandwich estimate over 8 x 8 blocks of samples,
    posterior with ``shrink``), ``cov`` (their full covariance, in ``order``:
    (camera, channel, light) per off-diagonal), ``diagnostics``
    (JSON-able: rows per kind, iterations, RMS residual, singular values of
    the normal matrix of F with the nuisances eliminated, parameters).
    """
    opts = LED_DEFAULTS | {k: v for k, v in params.items() if v is not None}
    opts["step_px"] = int(opts["step_px"] or max(1, round(rig.image.width / 160)))
    prob = _build_led_problem(rig, shots, fields, opts)
    theta0 = np.ones(prob.nth) if opts.get("initial") is None else np.asarray(opts["initial"])
    if opts.get("return_problem"):
        return prob
    stage(log, f"cross-talk: fitting F to {prob.N} board samples")
    theta, cov, diag = _solve_led_problem(prob, theta0, opts["iterations"], opts["huber"])
    fit_sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    if opts["shrink"]:
        fit = theta
        theta, cov, tau = shrink_towards_filter(theta, cov)
        diag |= {"prior_sd": tau, "unshrunk": [float(v) for v in fit]}
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    diag["fit_sd"] = [float(v) for v in fit_sd]
    F = prob.factors(theta)
    factor, sds = {}, {}
    for kk, name in enumerate(rig.camera_names):
        factor[name] = F[kk]
        S = np.zeros((3, 3))
        for q, (c, b) in enumerate(OFF_DIAGONAL):
            S[c, b] = sd[kk * len(OFF_DIAGONAL) + q]
        sds[name] = S
    diag = (
        {
            "rows_own": int(np.sum(prob.kind == 0)),
            "rows_same_light": int(np.sum(prob.kind == 1)),
            "box_px": prob.box,
        }
        | diag
        | {"params": {k: v for k, v in opts.items() if k in LED_DEFAULTS}}
    )
    order = [(name, c, b) for name in rig.camera_names for c, b in OFF_DIAGONAL]
    return {"factor": factor, "sd": sds, "cov": cov, "order": order, "diagnostics": diag}


def read_board_shots(ds, poses_csv) -> list[BoardShot]:
    """The board poses of a marker poses table with their raw images (a bar over
    the poses read, :func:`colourhs.common.progress.bar`)."""
    import pandas as pd

    table = pd.read_csv(poses_csv, dtype={"pose": str}, keep_default_na=False)
    shots = []
    label = "cross-talk: reading the board captures"
    rows = bar(table.iterrows(), label, len(table), unit="pose")
    for _, row in rows:
        pose = str(row["pose"])
        R = np.array([[float(row[f"R{i}{j}"]) for j in range(3)] for i in range(3)])
        t = np.array([float(row["t_x"]), float(row["t_y"]), float(row["t_z"])])
        images, saturated = {}, {}
        for cam in ds.rig.camera_names:
            images[cam], saturated[cam] = read_image(ds.photometric_image(pose, cam), ds.rig.image)
        shots.append(BoardShot(pose, R, t, images, saturated))
    if len(shots) < 2:
        raise ValueError(f"{poses_csv}: {len(shots)} board poses, the LED factor needs >= 2")
    return shots


def led_factor_from_dataset(ds, poses_csv, fields: dict, **params) -> dict:
    """:func:`led_factor` on a dataset's board captures and a marker poses table."""
    shots = read_board_shots(ds, poses_csv)
    return led_factor(ds.rig, shots, fields, **params)
