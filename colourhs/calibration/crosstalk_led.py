"""The LED factor F of each camera from the board captures: ``M_LED(u) = M_filter(u) * F``.

Estimate 2 of :mod:`colourhs.calibration.crosstalk`, whose docstring derives the
constraints from eq. (1) on the flat white Lambertian board ((a) own channel,
(b) same light, both pose invariant) and why (a) is needed. This module holds

- :class:`BoardShot` and :func:`read_board_shots`: the board poses of the
  markers stage with their raw all-lights-on images;
- :func:`led_factor` (parameters :data:`LED_DEFAULTS`): the 18 off-diagonals
  of F by instrumental-variables Gauss-Newton on the rows of
  :mod:`colourhs.calibration.crosstalk_led_rows` (:func:`_solve_led_problem`, with a
  sandwich covariance), shrunk towards 1 by empirical Bayes
  (:func:`shrink_towards_filter`);
- :func:`led_factor_from_dataset`: both on a dataset.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from colourhs.calibration.crosstalk_led_rows import OFF_DIAGONAL, _build_led_problem, _LedProblem
from colourhs.capture import read_image
from colourhs.common.progress import bar, stage


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


def led_factor(
    rig, shots: list[BoardShot], fields: dict, *, progress: bool = False, **params
) -> dict:
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
    a leak (0.02 mm, as on the synthetic 640x480 rigs: F off by ~0.005; 0.05-0.09
    mm at 160x120: ~0.05). ``pose_refinement`` adds a depth and two tilt
    corrections per pose, shared by the cameras; it removes that bias on
    noise-free images but is nearly degenerate with F and multiplies its
    noise errors about tenfold, so it is off by default. ``constraints``
    chooses the kinds of rows, ``("own", "same_light")``; without "own" the
    fit has six null directions (the mixing common to all cameras,
    :mod:`colourhs.calibration.crosstalk` docstring), visible as six vanishing ``singular_values``.

    With ``shrink`` (default) the fitted factors are shrunk towards 1 by
    :func:`shrink_towards_filter` (empirical Bayes, one prior spread for the
    18 numbers, from their fit and its sandwich covariance): LEDs that match
    the filters, or a fit too noisy to tell, give F = 1, i.e. the filter field.

    Parameters
    ----------
    rig : the dataset's :class:`~colourhs.capture.Rig`.
    shots : board poses with their raw images.
    fields : camera name -> filter :class:`MixingField` (chromatic captures).
    progress : a bar over the board poses and a line before the fit (stderr).

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
    prob = _build_led_problem(rig, shots, fields, opts, progress)
    theta0 = np.ones(prob.nth) if opts.get("initial") is None else np.asarray(opts["initial"])
    if opts.get("return_problem"):
        return prob
    stage(f"cross-talk: fitting F to {prob.N} board samples", enabled=progress)
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


def read_board_shots(ds, poses_csv, progress: bool = False) -> list[BoardShot]:
    """The board poses of a marker poses table with their raw images
    (``progress``: a bar over the poses read, on stderr)."""
    import pandas as pd

    table = pd.read_csv(poses_csv, dtype={"pose": str}, keep_default_na=False)
    shots = []
    label = "cross-talk: reading the board captures"
    rows = bar(table.iterrows(), label, len(table), progress, unit="pose")
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


def led_factor_from_dataset(ds, poses_csv, fields: dict, progress: bool = False, **params) -> dict:
    """:func:`led_factor` on a dataset's board captures and a marker poses table."""
    shots = read_board_shots(ds, poses_csv, progress)
    return led_factor(ds.rig, shots, fields, progress=progress, **params)
