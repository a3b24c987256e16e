"""Photometric calibration of the Helmholtz cameras, paper section III-C.

Each camera's channel that records another camera's light, together with the
camera's own collocated light, is a Helmholtz camera with a
radiance/sensitivity ratio map mu = rho / sigma (eq. 2); three cameras give
six. The board poses of ``photometric/`` calibrate them. What each step
implements:

1. **kappa, eq. (6).** For a reciprocal pair (a, b) and a point x of the
   white board on plane Pi_j, ``kappa = p_ba mu_a(v_a) / (p_ab mu_b(v_b))``
   is measured from the two reciprocal intensities (:func:`kappa`). Samples
   are taken on a regular pixel grid of each of the two cameras
   (:func:`kappa_samples`), on every pose.
2. **Transfer, eq. (7), and the system of eq. (8).** The paper transfers a
   point along the partner's ray v_b to another pose and divides two kappas,
   so that mu_b cancels and ``mu_a(v_a) / mu_a(v_a')`` remains; the log
   constraints on bilinear control points form the least squares of eq. (8),
   solved per map, and the partner's map is then obtained "by transfer via
   (6)". Here the same least squares is solved *jointly* for the two maps of
   a pair from the eq. (6) samples themselves: every sample is one row
   ``lambda_a(u_a) - lambda_b(u_b) + c_ab = log kappa`` (lambda = log mu on
   the control grid, c_ab = log(p_ab / p_ba), one unknown per pair). Two rows
   that share the partner's pixel u_b on two poses difference to exactly the
   eq. (7) row, so the eq. (8) constraints are all in this system; beyond
   the paper, the rows also tie mu_a to mu_b at every point instead of
   through one transfer, and each measurement enters once (eq. 7 rows of all
   pose pairs re-use each kappa n_poses - 1 times, with correlated errors).
3. **Two pairs per camera (paper: "a Helmholtz camera must be observed in at
   least two Helmholtz camera pairs").** eq. (6) cannot see a factor that
   is constant on each epipolar plane of a pair: it multiplies mu_a and
   mu_b alike and cancels in kappa (and in the HS constraint of eq. 5, where
   it scales a row of W). What fixes it is the other pair of each camera:
   the two maps of camera a are ``rho_a / sigma_{a,c1}`` and
   ``rho_a / sigma_{a,c2}``, so their log difference is the camera's colour
   shading ``log(sigma_{a,c2} / sigma_{a,c1})``. The paper takes it as
   constant. Real lenses and sensors shade each colour channel differently
   (per-channel vignetting with its own centre: a few per cent, smooth), so
   here the coupling lets a polynomial of total degree ``shading_order``
   (default 2) in the camera's undistorted normalised image coordinates be
   free: the penalty is on the gradient of
   ``lambda_{a,c1} - lambda_{a,c2} - P beta_a`` (P the monomials, beta_a the
   camera's shading coefficients), beyond the paper.
4. **What the data cannot tell, fixed by a prior.** Shading and the
   epipolar factors of step 3 overlap: a factor linear (or quadratic) in the
   epipolar angle looks, in each camera, like a linear (quadratic) shading.
   Three pairs bring three such factors per order against six linear and nine
   quadratic shading coefficients, so the data fix most of the shading but
   not all; a free polynomial alone would leave the maps tilted at random.
   A weak ridge (``shading_prior``) on beta takes, among the explanations the
   data allow, the one with the smallest colour shading; it is too weak to
   bias what the data do determine.
5. **Regulariser.** A weak curvature (second-difference) penalty on every
   map (the paper uses first differences; beyond the paper): where data end
   it extends a map linearly instead of flat, and it leaves linear terms,
   hence the gauge of step 4, to the shading prior alone.
6. **Gauge.** Each map is known up to one constant per pair (the pair's
   free scale); eq. (6) fixes the relative scale of its two maps (c_ab,
   applied to mu_b and reported as the pair's offset); the first map of each
   pair has mean log mu 0 over the control points.

Images are unmixed (see :mod:`colourhs.calibration.crosstalk`) before calibration when a
cross-talk calibration is given. :mod:`colourhs.evaluation.photometric_errors`
measures a result against ground truth: each map up to one scale per pair, and
the ratio ``mu_a / mu_b`` at points seen by both cameras (what the HS
constraint uses).

The pieces: :mod:`colourhs.calibration.photometric_samples` (step 1, the eq. (6) samples),
:mod:`colourhs.calibration.photometric_solve` (steps 2-6: the control grid and the least
squares of eqs. (7)-(8)); this module holds the parameters, reads the board poses,
calibrates, writes and reads ``photometric.h5``, and re-exports the public
names of the others.
"""

from __future__ import annotations

import json
import logging
import warnings
from pathlib import Path
from time import perf_counter

import h5py
import numpy as np

from colourhs.calibration.crosstalk import load_crosstalk, load_mixing_cov, load_mixing_sd, unmix
from colourhs.calibration.photometric_samples import (
    KappaSamples,
    PoseView,
    crosstalk_ratio_sigma,
    kappa,
    kappa_samples,
    pixel_footprint_m,
)
from colourhs.calibration.photometric_solve import (
    Grid,
    coverage,
    eq7_noise_rms,
    eq7_residual_rms,
    pair_ratio_sigma,
    shading_basis,
    shading_coordinates,
    solve_mu_grids,
)
from colourhs.capture import COLOURS, Rig, dataset_of, read_image
from colourhs.common.files import atomic_output, note_read, sha256_files
from colourhs.common.progress import bar, stage

log = logging.getLogger(__name__)

__all__ = [
    "DEFAULTS",
    "Grid",
    "KappaSamples",
    "POSE_COLUMNS",
    "PoseView",
    "calibrate",
    "coverage",
    "crosstalk_ratio_sigma",
    "eq7_noise_rms",
    "eq7_residual_rms",
    "kappa",
    "kappa_samples",
    "load_views",
    "model_warnings",
    "pair_ratio_sigma",
    "photometric_maps",
    "pixel_footprint_m",
    "read_mu_maps",
    "read_poses_table",
    "read_ratio_sigma",
    "resolve_params",
    "shading_basis",
    "shading_coordinates",
    "solve_mu_grids",
]


MODEL_RATIO_WARN = 1.3
"""Largest eq. (7) residual RMS over the part its noise explains before
:func:`calibrate` warns. A ratio of two spreads, so the same on any rig and
noise level; captures that follow eq. (6) give about 1 (from thousands of
sample pairs, within a few per cent), and 1.3 is a disagreement between poses
of 0.83 times the noise."""

MODEL_EXCESS_MIN = 5e-4
"""Smallest disagreement beyond noise, sqrt(residual^2 - noise^2) in natural log
of mu, that :func:`calibrate` warns about (exact, noise-free captures have both
spreads near zero, and their ratio then means nothing). A relative error of mu,
so the same on any rig: 0.05 % is far below the per-cent errors the check is
for and far above the rounding of exact captures."""

DEFAULTS = {
    "grid_spacing_px": None,
    "grid_angle_deg": 1.0,
    "min_grid_px": 8.0,
    "step_px": None,
    "samples_per_cell": 7,
    "box_px": None,
    "margin_m": None,
    "margin_px": 2.0,
    "min_cos": 0.3,
    "min_signal": 0.05,
    "smoothness": 1e-4,
    "coupling": 0.1,
    "shading_order": 2,
    "shading_prior": 0.01,
    "min_support": 0.05,
}
"""Default parameters of :func:`calibrate`; why each value holds on any rig:

- ``grid_spacing_px`` None: the pixels that ``grid_angle_deg`` of field
  angle spans (mean focal length x angle), at least ``min_grid_px``.
- ``grid_angle_deg`` 1.0: mu = rho / sigma is a function of the ray's
  direction (eq. 2): LED profiles and vignetting change over degrees, so
  nodes 1 deg apart keep the bilinear surface close to such maps, whatever
  the focal length and image size.
- ``min_grid_px`` 8: a cell holds at least 64 pixels of each pose, so a node
  averages the pixel noise of hundreds of samples even on small images.
- ``step_px`` None: ``grid_spacing_px / samples_per_cell`` rounded, at
  least 1; ``samples_per_cell`` 7: about 50 samples per cell and pose per
  direction, so the sample count per node does not depend on the resolution.
- ``box_px`` None: the sample step rounded up to odd (a box centred on the
  sample's pixel): each reading is the mean of the box around its pixel
  (:func:`colourhs.calibration.photometric_samples.box_means`, beyond the paper), so the
  samples use every pixel's reading whatever the step; 1 reads the pixel
  alone. The board is smooth on a box of a few pixels on any rig, since the
  box is a fraction of a grid cell (``samples_per_cell``).
- ``margin_m`` None: ``margin_px`` 2 pixel footprints (the larger of the two
  cameras', :func:`pixel_footprint_m`) around markers and board edges:
  edges blur over a pixel or two in any camera, so the margin is set in
  pixels, not metres (a metric margin is several pixels on a close rig and
  less than one on a far one). A number (metres) overrides it.
- ``min_cos`` 0.3: grazing limit (cosine between the plane's normal and the
  light direction, eq. 6): an error of the board's normal of e radians
  changes cos by e tan(theta), 3e at cos 0.3; beyond, a 0.1 deg normal error
  would cost more than half a per cent. A cosine is the same on any rig.
- ``min_signal`` 0.05 of full scale: darkest usable reading. At 5 % an 8-bit
  pixel has 12 DN, so quantisation and black-level errors (a fraction of a
  DN) stay below ~2 % per sample, which the least squares averages; full
  scale is the sensor's own unit, so it holds for any exposure and depth.
- ``smoothness`` 1e-4: curvature weight relative to one eq. (6) row, for an
  image one unit wide (see :func:`solve_mu_grids`): it only decides nodes at
  the edge of the data, where it continues a map linearly.
- ``coupling`` 0.1: weight of the shading-corrected difference of one
  camera's two maps; only what neither data nor the shading polynomial
  explain competes with it, so any value well above ``smoothness`` works.
- ``shading_order`` 2: colour shading is per-channel vignetting, radial
  about slightly different centres: to second order a constant, a linear
  term (the centre shift) and a quadratic one (the strength difference);
  higher terms are below 0.1 % on the calibrated field.
- ``shading_prior`` 0.01: a shading coefficient beta (at the image corner)
  costs like a misfit of 0.01 beta on every eq. (6) row: 100 times below a
  per-cent noise, so it cannot bias what the data determine, while it picks
  the smallest shading where they cannot.
- ``min_support`` 0.05: a node needs 5 % of the median node's sample weight
  to count as calibrated (a relative count, so the same on any number of
  samples); below, a node is decided by the regulariser alone.
"""


#: The columns of the marker poses table (:func:`colourhs.calibration.markers.marker_poses`)
#: that the board poses are read from.
POSE_COLUMNS = ("pose", *(f"R{i}{j}" for i in range(3) for j in range(3)), "t_x", "t_y", "t_z")


def read_poses_table(poses_csv):
    """The marker poses table (a DataFrame with :data:`POSE_COLUMNS`); ValueError naming
    the file when it is not a CSV table or lacks a column (not what ``colourhs markers``
    writes)."""
    import pandas as pd  # here: a reconstruction job need not import it

    try:
        table = pd.read_csv(poses_csv)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as e:
        reason = " ".join(str(e).split()) or type(e).__name__
        raise ValueError(f"{poses_csv}: not a CSV table ({reason})") from None
    missing = [c for c in POSE_COLUMNS if c not in table.columns]
    if missing:
        raise ValueError(
            f"{poses_csv}: not a board poses table (no column {', '.join(missing[:4])}"
            f"{', ...' if len(missing) > 4 else ''}; `colourhs markers` writes one)"
        )
    return table


def load_views(dataset_dir, poses_csv, crosstalk_json=None) -> tuple[Rig, list[PoseView]]:
    """Read every usable board pose (from the marker poses table) and its images
    (a bar over the poses, :func:`colourhs.common.progress.bar`)."""
    ds = dataset_of(dataset_dir, scenes=())
    table = read_poses_table(poses_csv)
    mixing = load_crosstalk(crosstalk_json) if crosstalk_json else {}
    views = []
    label = "photometric: reading" + (" and unmixing" if mixing else "") + " the board poses"
    rows = bar(table.iterrows(), label, total=len(table), unit="pose")
    for _, row in rows:
        pose = str(row["pose"])
        R = np.array([[row[f"R{i}{j}"] for j in range(3)] for i in range(3)], float)
        t = np.array([row["t_x"], row["t_y"], row["t_z"]], float)
        images, saturated = {}, {}
        for cam in ds.rig.camera_names:
            img, sat = read_image(ds.photometric_image(pose, cam), ds.rig.image)
            images[cam] = unmix(img, mixing[cam]) if cam in mixing else img
            saturated[cam] = sat
        views.append(PoseView(pose, R, t, images, saturated))
    if len(views) < 3:
        raise ValueError(f"{poses_csv}: {len(views)} usable board poses, need at least 3")
    return ds.rig, views


def resolve_params(rig: Rig, **params) -> dict:
    """:data:`DEFAULTS` overridden by ``params`` (None = default), rig-dependent ones resolved."""
    unknown = set(params) - set(DEFAULTS)
    if unknown:
        raise TypeError(f"unknown photometric parameter(s) {sorted(unknown)}")
    opts = DEFAULTS | {k: v for k, v in params.items() if v is not None}
    if opts["grid_spacing_px"] is None:
        f = np.mean([0.5 * (c.K[0, 0] + c.K[1, 1]) for c in rig.cameras])
        spacing = f * np.tan(np.radians(opts["grid_angle_deg"]))
        opts["grid_spacing_px"] = float(max(spacing, opts["min_grid_px"]))
    opts["grid_spacing_px"] = float(opts["grid_spacing_px"])
    if opts["step_px"] is None:
        opts["step_px"] = max(1, round(opts["grid_spacing_px"] / opts["samples_per_cell"]))
    opts["step_px"] = int(opts["step_px"])
    if opts["box_px"] is None:
        opts["box_px"] = opts["step_px"] | 1
    opts["box_px"] = int(opts["box_px"])
    opts["shading_order"] = int(opts["shading_order"])
    return opts


def calibrate(
    rig: Rig,
    views: list[PoseView],
    *,
    mixing_sd: dict[str, np.ndarray] | None = None,
    mixing_cov: tuple[list, np.ndarray] | None = None,
    **params,
) -> dict:
    """Photometric calibration of every Helmholtz camera (eqs. 6-8, module docstring).

    Parameters (keyword, see :data:`DEFAULTS` for each value and why it
    holds on any rig): ``grid_spacing_px`` control point spacing,
    ``step_px`` sample spacing, ``margin_px`` / ``margin_m`` white-area
    margin around markers and board edges, ``min_cos`` grazing limit,
    ``min_signal`` darkest usable intensity, ``smoothness``, ``coupling``
    and ``shading_prior`` weights and ``shading_order`` (see
    :func:`solve_mu_grids`; ``shading_order=0`` is the paper's coupling,
    the two maps of a camera equal up to a constant), ``min_support``
    calibrated-region threshold. ``mixing_sd``: camera -> (3, 3) standard
    errors of the cross-talk mixing the views were unmixed with
    (:func:`colourhs.calibration.crosstalk.load_mixing_sd`), and ``mixing_cov`` their full
    covariance (:func:`colourhs.calibration.crosstalk.load_mixing_cov`), for the ratios'
    cross-talk term. Shows a bar over the reciprocal pairs' samples and logs a
    line at INFO per later step (:mod:`colourhs.common.progress`).

    Returns a dict with ``maps`` ("<camera>/<colour>" -> (H, W) float32 mu),
    ``grids`` (same keys -> (ny, nx) log mu control points), ``calibrated``
    (same keys -> (H, W) bool calibrated region), ``offsets`` (pair ->
    eq. 6 relative log scale applied), ``counts`` (eq. 6 samples per map),
    ``residual_rms`` (RMS of the eq. 7 residuals per map, log units),
    ``noise_rms`` (the part of it the readings' noise explains,
    :func:`eq7_noise_rms`), ``warnings`` (:func:`model_warnings`, also
    issued as Python warnings),
    ``ratio_sigma`` (pair -> 1-sigma of its log ratio mu_a / mu_b: the
    jackknife over poses, :func:`pair_ratio_sigma`, and the unmixing's error,
    :func:`crosstalk_ratio_sigma`, in quadrature; None with fewer than four
    poses), ``ratio_sigma_parts`` (pair -> {"poses", "crosstalk"}: the two
    terms),
    ``shading`` (camera -> {"maps": [the two keys], "order", "coefficients"}:
    the fitted log colour shading, first map over second, at the image
    corner), ``grid`` and ``params``.
    """
    opts = resolve_params(rig, **params)
    W, H = rig.image.width, rig.image.height
    grid = Grid(W, H, opts["grid_spacing_px"])
    pairs, own = [], {}
    rig_pairs = rig.reciprocal_pairs()
    for pr in bar(rig_pairs, "photometric: eq. (6) samples", unit="pair"):
        ka, kb = (pr.cam_a, pr.channel_a), (pr.cam_b, pr.channel_b)
        s_ab = kappa_samples(views, rig, pr.cam_a, pr.cam_b, opts)  # on b's pixels: map a
        s_ba = kappa_samples(views, rig, pr.cam_b, pr.cam_a, opts)  # on a's pixels: map b
        for key, s in ((ka, s_ab), (kb, s_ba)):
            if len(s.log_kappa) == 0:
                raise ValueError(
                    f"photometric calibration: no usable samples for {key[0]}/{COLOURS[key[1]]} "
                    "(every board sample masked: markers, saturation, grazing or dark)"
                )
        own[ka], own[kb] = s_ab, s_ba
        pairs.append((ka, kb, KappaSamples.concatenate([s_ab, s_ba.swapped()])))
    order = opts["shading_order"]
    bases = {
        c.name: shading_basis(shading_coordinates(c, grid.nodes, W, H), order) for c in rig.cameras
    }
    ny, nx = grid.shape
    stage(log, f"photometric: solving for {2 * len(pairs)} maps of {ny} x {nx} nodes")

    def solve(samples):
        return solve_mu_grids(
            samples, grid, bases, opts["smoothness"], opts["coupling"], opts["shading_prior"]
        )

    grids, shading, offs = solve(pairs)
    stage(log, "photometric: the pair ratios' uncertainty (jackknife over poses)")
    ratio_sigma = pair_ratio_sigma(pairs, grid, lambda samples: solve(samples)[0])
    stage(log, "photometric: dense maps, calibrated regions, eq. (7) residuals")
    out = {
        "maps": {},
        "grids": {},
        "calibrated": {},
        "offsets": {},
        "counts": {},
        "residual_rms": {},
        "noise_rms": {},
        "shading": {},
        "ratio_sigma": {},
        "ratio_sigma_parts": {},
    }
    for p, (ka, kb, s) in enumerate(pairs):
        name = f"{ka[0]}/{COLOURS[ka[1]]}~{kb[0]}/{COLOURS[kb[1]]}"
        out["offsets"][name] = offs[p]
        jack = float(ratio_sigma[p])
        xt = crosstalk_ratio_sigma(
            s, views, rig.camera(ka[0]), rig.camera(kb[0]), mixing_sd or {}, mixing_cov
        )
        sigma = float(np.hypot(jack, xt))
        out["ratio_sigma"][name] = sigma if np.isfinite(sigma) else None  # JSON null
        out["ratio_sigma_parts"][name] = {
            "poses": jack if np.isfinite(jack) else None,
            "crosstalk": xt,
        }
        for key in (ka, kb):
            k = f"{key[0]}/{COLOURS[key[1]]}"
            g = grids[key]
            out["maps"][k] = np.exp(grid.dense(g)).astype(np.float32)
            out["grids"][k] = g
            # calibrated where eq. (7) constrains the map: a pixel seen on two poses
            t = own[key].transferred()
            out["calibrated"][k] = coverage(grid, own[key].uv_a[t], opts["min_support"])
            out["counts"][k] = len(s.log_kappa)
            out["residual_rms"][k] = eq7_residual_rms(own[key], grid, g)
            out["noise_rms"][k] = eq7_noise_rms(own[key], grid, g, opts["step_px"], opts["box_px"])
    for cam, beta in shading.items():
        k1, k2 = sorted(k for k in grids if k[0] == cam)
        out["shading"][cam] = {
            "maps": [f"{cam}/{COLOURS[k1[1]]}", f"{cam}/{COLOURS[k2[1]]}"],
            "order": order,
            "coefficients": [float(b) for b in beta],
        }
    out["grid"] = grid
    out["params"] = opts
    out["warnings"] = model_warnings(out["residual_rms"], out["noise_rms"])
    for text in out["warnings"]:
        warnings.warn(text, stacklevel=2)
    return out


def model_warnings(residual_rms: dict, noise_rms: dict) -> list[str]:
    """Warnings for maps whose eq. (7) residuals exceed what their noise explains.

    A ratio above :data:`MODEL_RATIO_WARN`, with a disagreement beyond noise
    above :data:`MODEL_EXCESS_MIN`, names the maps and the ratio (the board
    poses disagree with eq. (6) beyond noise; :func:`eq7_noise_rms`). Empty
    when every map is within them.
    """
    ratios = {
        k: residual_rms[k] / noise_rms[k]
        for k in residual_rms
        if np.isfinite(noise_rms.get(k, np.nan)) and noise_rms[k] > 0
    }
    excess = {k: np.sqrt(max(residual_rms[k] ** 2 - noise_rms[k] ** 2, 0.0)) for k in ratios}
    high = {
        k: r for k, r in ratios.items() if r > MODEL_RATIO_WARN and excess[k] > MODEL_EXCESS_MIN
    }
    if not high:
        return []
    listed = ", ".join(f"{k} {r:.2f}x" for k, r in sorted(high.items()))
    return [
        "photometric: the board poses disagree with eq. (6) beyond their noise "
        f"(eq. 7 residual over its noise: {listed}; above {MODEL_RATIO_WARN}): light that "
        "eq. (6) does not model reaches the board (interreflections from nearby surfaces, "
        "room light, channel cross-talk left unmixed) or the board is glossy with lights "
        "beside the lenses; the mu maps may be off by per cents"
    ]


def photometric_maps(
    dataset_dir,
    poses_csv,
    out_h5,
    crosstalk_json=None,
    **params,
) -> dict:
    """Calibrate and write ``photometric.h5`` (results contract).

    The HDF5 file holds one float32 (H, W) mu map per Helmholtz camera at
    ``<camera>/<colour>``, its control grid at ``grid/<camera>/<colour>``
    (log mu), the calibrated region at ``calibrated/<camera>/<colour>``, and
    as attributes the parameters, the pair offsets, the pairs' log-ratio
    uncertainty (``pair_log_ratio_sigma``, JSON: pair -> 1 sigma, null where
    unknown; ``pair_log_ratio_sigma_parts``: its jackknife and cross-talk
    terms; the cross-talk calibration's ``led_mixing_sd`` feeds the second),
    the fitted colour shading per camera and a hash of the inputs. Written
    atomically: no partial file on error. Shows bars over the board poses and
    the pairs and logs a line per step at INFO (:mod:`colourhs.common.progress`).
    Returns :func:`calibrate`'s result, whose
    ``maps`` and ``calibrated`` the command draws as the paper's Figure 3
    (:func:`colourhs.report.figures.mu_maps_figure`): calibration modules do not
    import the figures.
    """
    t0 = perf_counter()
    ds = dataset_of(dataset_dir, scenes=())
    rig, views = load_views(ds, poses_csv, crosstalk_json)
    mixing_sd = load_mixing_sd(crosstalk_json) if crosstalk_json else None
    mixing_cov = load_mixing_cov(crosstalk_json) if crosstalk_json else None
    result = calibrate(rig, views, mixing_sd=mixing_sd, mixing_cov=mixing_cov, **params)
    inputs = [ds.photometric_image(v.name, c) for v in views for c in rig.camera_names]
    inputs += [Path(poses_csv)] + ([Path(crosstalk_json)] if crosstalk_json else [])
    stage(log, f"photometric: writing {Path(out_h5).name}", t0)
    with atomic_output(out_h5) as tmp, h5py.File(tmp, "w") as f:
        for key, mu in result["maps"].items():
            f.create_dataset(key, data=mu, compression="gzip")
            f.create_dataset(f"grid/{key}", data=result["grids"][key].astype(np.float32))
            f.create_dataset(
                f"calibrated/{key}", data=result["calibrated"][key], compression="gzip"
            )
        f.attrs["equations"] = (
            "kappa eq. (6); eqs. (7)-(8) as one least squares over the eq. (6) samples of "
            "each pair; two-pair coupling with a free colour-shading polynomial"
        )
        f.attrs["params"] = json.dumps(result["params"])
        f.attrs["pair_offsets"] = json.dumps(result["offsets"])
        f.attrs["constraints"] = json.dumps(result["counts"])
        f.attrs["residual_rms_log"] = json.dumps(result["residual_rms"])
        f.attrs["noise_rms_log"] = json.dumps(result["noise_rms"])
        f.attrs["warnings"] = json.dumps(result["warnings"])
        f.attrs["pair_log_ratio_sigma"] = json.dumps(result["ratio_sigma"])
        f.attrs["pair_log_ratio_sigma_parts"] = json.dumps(result["ratio_sigma_parts"])
        f.attrs["colour_shading"] = json.dumps(result["shading"])
        f.attrs["poses"] = json.dumps([v.name for v in views])
        f.attrs["inputs_sha256"] = sha256_files(inputs)
        f.attrs["crosstalk_unmixed"] = bool(crosstalk_json)
    return result


def read_ratio_sigma(path: str | Path, part: str | None = None) -> dict[str, float]:
    """Pair name (``"<cam>/<colour>~<cam>/<colour>"``) -> 1-sigma of its log ratio
    mu_a / mu_b from a photometric.h5; empty where the file has none (ground truth,
    files written before it), NaN where it is unknown.

    ``part``: None, the whole sigma; ``"poses"`` or ``"crosstalk"``, one term of
    ``pair_log_ratio_sigma_parts`` (a file without parts has the jackknife alone,
    so ``"poses"`` is then the whole sigma and ``"crosstalk"`` empty).
    """
    with h5py.File(path) as f:
        text = f.attrs.get("pair_log_ratio_sigma")
        parts = f.attrs.get("pair_log_ratio_sigma_parts")
    if text is None:
        return {}
    values = json.loads(text)
    if part is not None:
        if part not in ("poses", "crosstalk"):
            raise ValueError(f"read_ratio_sigma: part must be 'poses' or 'crosstalk', not {part!r}")
        if parts is None:
            values = values if part == "poses" else {}
        else:
            values = {k: v[part] for k, v in json.loads(parts).items()}
    return {k: float("nan") if v is None else float(v) for k, v in values.items()}


def read_mu_maps(path: str | Path) -> dict[str, np.ndarray]:
    """``"<camera>/<colour>"`` -> (H, W) mu from a photometric.h5 (ours or ground truth)."""
    note_read(path)
    with h5py.File(path) as f:
        return {
            f"{cam}/{colour}": f[cam][colour][()]
            for cam in f
            if cam not in ("grid", "calibrated")
            for colour in f[cam]
        }
