"""Accuracy on randomised rigs: every nuisance on, every calibration from the pipeline.

Run: ``.venv/bin/python benchmarks/generalisation.py [--seeds 0-7] [--preset random]
[--sheet-frames 2] [--scenes plane,statue] [--calibrate-rig | --reference-world]
[--keep DIR]``.

For every seed it renders ``colourhs synth --preset random --seed N`` (a
different rig and scene set each time, ranges in
:mod:`colourhs.synth.randomrig`; ``--preset corner`` draws from the ranges'
hard ends combined, ``random-tiny`` and ``corner-tiny`` at 160x120), runs
the calibration stages exactly as the workflow does (marker poses,
cross-talk with the board's LED factor, noise model, photometric maps,
chromaticity maps of the statue and the toy), then reconstructs every scene
with the paper's ablation (``vh``, ``ml_full``, ``bayes_nocalib``,
``bayes_ph``, ``bayes_full``, the workflow's calibration files per variant)
and compares each depth map with the ground truth rendered into the
reference camera. Nothing in the pipeline sees the seed, the preset or the
``gt/`` folder. ``--scenes`` renders and measures only those scenes (their files
are those of a full render; the calibration stages run on what is rendered).

``--calibrate-rig`` (a rig owner's calibrated rig.json against the
true one) calibrates the three cameras from the dataset's ``geometric/``
ChArUco captures first (:func:`colourhs.calibration.geometric.calibrate_rig`,
world on the reference camera, merged into the true rig.json, which is kept as
``gt/rig_true.json``) and puts the result in place of ``rig.json``, so every
stage (marker poses, cross-talk, noise, photometric, chromaticity,
reconstruction) runs on it, as a rig owner's run would. The ground truth is
in the true world, the depth maps in the calibrated rig's, and the two frames
differ by a rigid map that no capture can fix (the gauge: the calibration's
world is its reference camera's frame; its scale is measured, from the
target's square length, and its error counts). The truth is moved into the
calibrated world by the map under which the calibrated cameras project the
rig's working volume where the true cameras do (:func:`gauge_transforms`,
``projection``): a reconstruction from the calibrated rig is the true surface
under that map up to what the calibrated projections get wrong, which is the
calibration's error the comparison is after. Rendering the moved mesh through
the depth file's camera (the calibrated reference camera) then measures the
error along the calibrated camera's own rays. Fitting the gauge to the camera
poses instead (``cameras``: :func:`colourhs.calibration.geometric.world_transform`,
as :func:`~colourhs.calibration.geometric.merge_rig` carries world positions
over) or to the reference camera's pose (``reference``) instead charges the
reconstruction with the poses' errors along what the views cannot tell apart
(a principal point against a tilt of the camera): errors that leave every
projection in place and so move the whole reconstruction with the cameras.
Their depth figures are reported beside (``--gauge`` picks the main one).
``--reference-world`` is the control: the true rig moved rigidly into its
reference camera's frame (the calibrated rig's world, without its errors), the
same gauges; what it changes against the true rig is the pipeline's own
dependence on the world frame and on the smallest change of its input, not a
calibration's error.

Writes to ``benchmarks/results/`` (``--tag`` suffixes each name):

- ``generalisation_seeds.csv``: one row per seed x scene x variant (frames of
  the sheet pooled): the set (the preset's name), depth median of the
  absolute errors and of the signed ones (``depth_signed_median_mm``:
  reconstructed minus true z-depth, a bias), RMS, p95 (mm), normal median
  (deg), completeness (reconstructed / ground-truth-visible pixels), the
  depth files' error bars over the same pixels (``depth_sigma_median_mm``;
  ``sigma_within_1/2/3``: share of pixels with ``|error| <= k sigma``; empty
  without ``depth_sigma``, e.g. ``vh``), and per seed the calibration errors
  (mu RMS log error, worst and median map, and the worst of mu = 1
  uncalibrated; chromaticity median) and the rig's drawn settings. The
  ``rig`` column says which rig.json the stages ran on (``true``,
  ``calibrated`` or ``reference-world``; the set of the latter two is named
  ``<preset>, calibrated rig`` or ``<preset>, true rig in reference world``,
  so that the summaries keep them apart), ``gauge`` the gauge of the depth
  figures (empty for the true rig); with ``--calibrate-rig`` also the
  geometric calibration's figures per seed (:func:`calibrated_rig`:
  reprojection RMS, the worst camera's errors against the true rig from
  :func:`colourhs.evaluation.rig_errors.rig_errors`, the reference camera's,
  the gauge fit) and, with either option, the other gauges' depth median,
  signed median and RMS (``depth_median_mm_cameras`` etc.).
- ``generalisation_summary.json``: per set (the ``set`` column; ``all`` for
  tables without it), per scene x variant and metric the median over the
  set's rigs and the worst rig, the accuracy targets beside them with ``met``
  (:data:`TARGETS`); the depth sigma's calibration per Bayesian variant
  (:func:`sigma_calibration`); whether the ablation order ``vh > ml_full >
  bayes_nocalib > bayes_ph >= bayes_full`` held on every rig, on the depth
  median error and on the RMS (``_rms``: the paper's statistic), with the
  links that broke and the rigs where ``ml_full > bayes_nocalib`` was not
  applicable (:data:`ML_LINK_MU_LIMIT`); the calibration errors over the rigs.
- ``generalisation_summary.md``: the same per set as tables
  (:func:`summarise_markdown`).

``--summarise CSV [CSV ...]`` summarises existing per-seed tables again
(concatenated: e.g. a random and a corner run), rendering nothing.

Each seed renders a 640x480 dataset and runs every stage on it: minutes per seed
on 2 cores (``--sheet-frames 1`` the least).
"""

from __future__ import annotations

import argparse
import json
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from colourhs.cli.commands import frame_indices
from colourhs.common.metrics_csv import DROP_COLUMNS, GAUSSIAN_WITHIN, SIGMA_MULTIPLES
from colourhs.common.progress import show_progress
from colourhs.workflow.variants import PAPER_VARIANTS as VARIANTS  # bayes_dyn: no sequence

HERE = Path(__file__).parent
#: The accuracy targets, per set: (scene, variant, metric) -> upper bounds on (the median
#: over the set's rigs, the worst rig); for the signed median on its absolute value.
TARGETS = {
    ("plane", "bayes_ph", "depth_median_mm"): (0.1, 0.3),
    ("plane", "bayes_ph", "depth_rms_mm"): (0.5, 1.0),
    ("plane", "bayes_ph", "depth_signed_median_mm"): (0.05, 0.05),
    ("sheet", "bayes_ph", "depth_median_mm"): (0.2, 0.5),
    ("sheet", "bayes_ph", "depth_signed_median_mm"): (0.05, 0.05),
    ("statue", "bayes_full", "depth_median_mm"): (0.5, 1.0),
    ("statue", "bayes_full", "normal_median_deg"): (2.0, 3.0),
    ("toy", "bayes_full", "depth_median_mm"): (1.0, 2.0),
}
#: Per-seed metrics summarised per scene x variant (those the table has).
METRICS = (
    "depth_median_mm",
    "depth_signed_median_mm",
    "depth_rms_mm",
    "depth_p95_mm",
    "normal_median_deg",
    "coverage",
    "depth_sigma_median_mm",
    *(f"sigma_within_{k}" for k in SIGMA_MULTIPLES),
    *DROP_COLUMNS,  # where the ground truth's pixels without a depth went
)
#: Metrics whose worst rig is the largest absolute value (kept with its sign).
SIGNED_METRICS = ("depth_signed_median_mm",)
#: Variants whose depth files carry a sigma to calibrate.
BAYES_VARIANTS = ("bayes_nocalib", "bayes_ph", "bayes_full")
#: The sigma calibration's entry of each scene's own variant (the one its targets name).
OWN_VARIANT = "own variant per scene"
#: Each pooled sigma share within this of the Gaussian's (GAUSSIAN_WITHIN).
SIGMA_TOLERANCE = 0.1
#: ml_full > bayes_nocalib is checked only on rigs whose uncalibrated mu
#: (mu = 1) is within 2 % (``mu_uncalibrated_rms_log_worst <= 0.02``).
ML_LINK_MU_LIMIT = 0.02  # a relative (dimensionless) error of mu: the same bound on any rig
#: The ablation's links (a, b, tie): a's error above b's (at least b's, to 0.1 %, where tie).
LINKS = (
    ("vh", "ml_full", False),
    ("ml_full", "bayes_nocalib", False),
    ("bayes_nocalib", "bayes_ph", False),
    ("bayes_ph", "bayes_full", True),
)
ML_LINK = "ml_full > bayes_nocalib"
#: The markdown's rows: every (scene, variant) with a target, and ML on the plane
#: (ML on a narrow baseline: reported beside, no target).
MARKDOWN_ROWS = (*dict.fromkeys((s, v) for s, v, _ in TARGETS), ("plane", "ml_full"))


def seeds_in_temp(seeds, prefix: str, run, out_csv: Path) -> list[dict]:
    """``run(seed, root)`` (rows) for each seed in its own temporary folder, removed
    after it; the rows so far go to ``out_csv`` after each seed (a partial run counts)."""
    rows = []
    for seed in seeds:
        root = Path(tempfile.mkdtemp(prefix=f"{prefix}-{seed}-"))
        try:
            rows += run(seed, root)
            pd.DataFrame(rows).to_csv(out_csv, index=False)
        finally:
            shutil.rmtree(root, ignore_errors=True)
    return rows


def calibrate(data: Path, calib: Path) -> dict:
    """The workflow's calibration stages on one dataset; returns the files by name."""
    from colourhs.calibration.chromaticity import chromaticity_maps
    from colourhs.calibration.crosstalk import calibrate_crosstalk
    from colourhs.calibration.markers import marker_poses
    from colourhs.calibration.noise import calibrate_noise
    from colourhs.calibration.photometric import photometric_maps
    from colourhs.capture import open_dataset

    calib.mkdir(parents=True, exist_ok=True)
    files = {
        k: calib / f
        for k, f in (
            ("poses", "marker_poses.csv"),
            ("crosstalk", "crosstalk.json"),
            ("noise", "noise.json"),
            ("photometric", "photometric.h5"),
        )
    }
    marker_poses(data, files["poses"])
    calibrate_crosstalk(data, files["crosstalk"], poses_csv=files["poses"])
    calibrate_noise(data, files["noise"])
    photometric_maps(data, files["poses"], files["photometric"], files["crosstalk"])
    ds = open_dataset(data, check_images=False)
    for obj in ds.chromatic_objects:
        if obj != "white":
            files[f"chroma/{obj}"] = calib / f"chromaticity_{obj}.h5"
            chromaticity_maps(data, obj, files[f"chroma/{obj}"], noise_json=files["noise"])
    return files


def variant_files(variant: str, files: dict, chromatic: str | None) -> dict:
    """The calibration files of a variant, as :class:`CalibrationFiles` keywords (the
    workflow plan's choice)."""
    kw = {"noise_json": files["noise"]}
    if variant in ("ml_full", "bayes_ph", "bayes_full"):
        kw |= {"photometric_h5": files["photometric"], "crosstalk_json": files["crosstalk"]}
    if variant in ("ml_full", "bayes_full") and chromatic:
        kw["chromaticity_h5"] = files[f"chroma/{chromatic}"]
    return kw


def calibration_errors(data: Path, files: dict) -> dict:
    """mu maps, cross-talk and chromaticity against the dataset's ground truth."""
    import h5py

    from colourhs.calibration.chromaticity import chromaticity_error
    from colourhs.calibration.photometric import read_mu_maps
    from colourhs.capture import load_rig
    from colourhs.evaluation.photometric_errors import mu_map_errors

    rig = load_rig(data)
    with h5py.File(files["photometric"]) as f:
        est = {"maps": {}, "calibrated": {}}
        for key in read_mu_maps(files["photometric"]):
            est["maps"][key] = f[key][()]
            est["calibrated"][key] = f[f"calibrated/{key}"][()]
    err = mu_map_errors(est, read_mu_maps(data / "gt" / "photometric.h5"), rig)
    cal = err[err["method"] == "calibrated"]["rms_log_error"]
    out = {"mu_rms_log_worst": float(cal.max()), "mu_rms_log_median": float(cal.median())}
    # How far the rig is from mu = 1 (what bayes_nocalib assumes): the ablation's
    # bayes_nocalib error grows with it (see the summary's ablation_links).
    nocal = err[err["method"] == "no calibration"]["rms_log_error"]
    out["mu_uncalibrated_rms_log_worst"] = float(nocal.max())
    chroma = []
    for key, path in files.items():
        if not key.startswith("chroma/"):
            continue
        gt = data / "scenes" / key.split("/", 1)[1] / "gt" / "chromaticity.h5"
        if gt.exists():
            with h5py.File(path) as f, h5py.File(gt) as g:
                for cam in rig.camera_names:
                    e = chromaticity_error(f[cam][()], g[cam][()])
                    chroma.append(float(np.nanmedian(e)))
    out["chromaticity_median_rel"] = float(np.median(chroma)) if chroma else None
    return out


def moved_mesh(mesh, A: np.ndarray, b: np.ndarray) -> tuple:
    """A mesh (vertices, triangles, normals) under the rigid map ``X' = A X + b``."""
    vertices, triangles, normals = mesh
    return vertices @ A.T + b, triangles, normals @ A.T


def rig_cameras(rig_json: Path) -> list:
    """A rig.json's cameras (:class:`colourhs.capture.Camera`), in its order."""
    from colourhs.capture import load_rig

    return list(load_rig(rig_json).cameras)


def working_points(cameras, size: tuple[int, int]) -> np.ndarray:
    """World points (N, 3) where the rig works, every one seen by every camera.

    A grid of the reference camera's image (80 % of its width and height, 9 x 7
    pixels) at five z-depths from 0.85 to 1.15 times the rig's fixation point's:
    the volume the scenes and the ChArUco target's poses fill.
    """
    from colourhs.capture.rig import cameras_fixation_point
    from colourhs.common.geometry import normalised_coordinates, project

    ref = cameras[0]
    w, h = size
    z0 = float((ref.R @ cameras_fixation_point(cameras) + ref.t)[2])
    uv = np.stack(
        np.meshgrid(np.linspace(0.1, 0.9, 9) * (w - 1), np.linspace(0.1, 0.9, 7) * (h - 1)),
        axis=-1,
    ).reshape(-1, 2)
    xy = normalised_coordinates(uv, ref.K, ref.dist)
    pts = []
    for z in z0 * np.linspace(0.85, 1.15, 5):
        xc = np.column_stack([xy * z, np.full(len(xy), z)])
        pts.append((xc - ref.t) @ ref.R)  # camera -> world: R^T (x_c - t)
    X = np.concatenate(pts)
    seen = np.ones(len(X), bool)
    for c in cameras:
        p = project(X, c.K, c.dist, c.R, c.t)
        seen &= np.all(np.isfinite(p), axis=1) & (p[:, 0] >= 0) & (p[:, 0] <= w - 1)
        seen &= (p[:, 1] >= 0) & (p[:, 1] <= h - 1)
    return X[seen]


def gauge_transforms(true_json: Path, cal_json: Path) -> tuple[dict, dict]:
    """The rigid maps ``X_cal = A X_true + b`` from the true world into a calibrated rig's.

    A calibration fixes its own world (the reference camera's frame), which the
    true world's is not: its cameras must be compared with the truth in one frame.
    Three choices of that frame (the gauge), each a rigid map (the scale is the
    calibration's own, from the target's square length, and its error counts):

    - ``projection``: the map under which the calibrated cameras project the points of
      the rig's working volume (:func:`working_points`) where the true cameras do,
      least squares over every camera's pixels. A reconstruction from the calibrated
      rig lands on the true surface moved by this map, up to what the calibrated
      projections get wrong there; the calibration fitted exactly those projections
      (of the target's poses in that volume), so this is the frame its
      reconstructions are in and what is left is the calibration's error.
    - ``cameras``: :func:`colourhs.calibration.geometric.world_transform`, the fit of
      the three camera poses (rotations' chordal mean, centres by least squares), as
      :func:`~colourhs.calibration.geometric.merge_rig` carries world positions over.
    - ``reference``: the calibrated reference camera's frame on the true one's (the
      calibration's own gauge: its ``world="reference"``).

    Returns
    -------
    gauges : dict
        name -> (A, b), ``projection`` first.
    fit : dict
        ``gauge_projection_rms_px`` (the projection fit's RMS pixel disagreement over
        the cameras and points; 0 where the rigs agree), ``gauge_points``.
    """
    from scipy.optimize import least_squares
    from scipy.spatial.transform import Rotation

    from colourhs.calibration.geometric import world_transform
    from colourhs.common.geometry import project

    true, cal = rig_cameras(true_json), rig_cameras(cal_json)
    rig = json.loads(true_json.read_text())
    size = (rig["image"]["width"], rig["image"]["height"])
    entries = [{"name": c.name, "R": c.R, "t": c.t} for c in true]
    A, b, _, _ = world_transform(entries, {c.name: c.R for c in cal}, {c.name: c.t for c in cal})
    gauges = {"cameras": (A, b)}
    R0, t0, Rc, tc = true[0].R, true[0].t, cal[0].R, cal[0].t
    gauges["reference"] = (Rc.T @ R0, Rc.T @ (t0 - tc))  # R_c X' + t_c = R_0 X + t_0
    X = working_points(true, size)
    target = [project(X, c.K, c.dist, c.R, c.t) for c in true]

    def residuals(x):
        Xc = X @ Rotation.from_rotvec(x[:3]).as_matrix().T + x[3:]
        return np.concatenate(
            [
                (project(Xc, c.K, c.dist, c.R, c.t) - u).ravel()
                for c, u in zip(cal, target, strict=True)
            ]
        )

    x0 = np.concatenate([Rotation.from_matrix(A).as_rotvec(), b])
    sol = least_squares(residuals, x0, method="lm", xtol=1e-12, ftol=1e-12)
    A_p = Rotation.from_rotvec(sol.x[:3]).as_matrix()
    rms = float(np.sqrt(np.mean(np.sum(sol.fun.reshape(-1, 2) ** 2, axis=1))))
    gauges = {"projection": (A_p, sol.x[3:])} | gauges
    return gauges, {"gauge_projection_rms_px": rms, "gauge_points": len(X)}


#: The set name's suffix per rig other than the true one (``run_seed``'s ``rig_source``).
RIG_SETS = {"calibrated": "calibrated rig", "reference-world": "true rig in reference world"}
#: The calibrated rig's figures in the per-seed table (a seed's figure: its worst camera).
RIG_FIGURES = ("f_rel", "pp_px", "field_px", "rotation_deg", "centre_mm")


def calibrated_rig(data: Path, root: Path) -> tuple[dict, dict]:
    """Calibrate ``data``'s cameras from its ``geometric/`` captures and put the result
    in place of its rig.json, as a rig owner's run would; the true rig.json is kept as
    ``gt/rig_true.json`` (the pipeline never reads ``gt/``) and is the merge's base
    (lights, boards, image encoding).

    Returns
    -------
    gauges : dict
        :func:`gauge_transforms` (true world -> the calibrated rig's).
    figures : dict
        ``rig_rms_px`` (the calibration's reprojection RMS), ``rig_<figure>`` per
        :data:`RIG_FIGURES` (:func:`colourhs.evaluation.rig_errors.rig_errors` against
        the true rig, the worst camera), ``rig_ref_pp_px`` and ``rig_ref_f_rel`` (the
        reference camera's: the depth maps' rays), the projection gauge's fit, the
        merge's fit of the true cameras (``rig_world_rotation_rms_deg``,
        ``rig_world_centre_rms_mm``) and ``rig_calib_s``.
    """
    from colourhs.calibration.geometric import calibrate_rig
    from colourhs.evaluation.rig_errors import rig_errors

    t0 = time.time()
    true_json, cal_json = data / "gt" / "rig_true.json", root / "rig_calibrated.json"
    shutil.copyfile(data / "rig.json", true_json)
    report = calibrate_rig(data, cal_json, base_rig=true_json, report_json=root / "rig_report.json")
    seconds = time.time() - t0
    shutil.copyfile(cal_json, data / "rig.json")
    true, cal = rig_cameras(true_json), rig_cameras(cal_json)
    rig = json.loads(true_json.read_text())
    errors = rig_errors(true, cal, (rig["image"]["width"], rig["image"]["height"]))
    figures = {"rig_rms_px": report["rms_px"]}
    figures |= {f"rig_{k}": max(e[k] for e in errors.values()) for k in RIG_FIGURES}
    figures["rig_ref_pp_px"] = errors[true[0].name]["pp_px"]
    figures["rig_ref_f_rel"] = errors[true[0].name]["f_rel"]
    gauges, fit = gauge_transforms(true_json, cal_json)
    figures |= fit
    figures["rig_world_rotation_rms_deg"] = report["old_world"]["rotation_rms_deg"]
    figures["rig_world_centre_rms_mm"] = report["old_world"]["centre_rms_mm"]
    return gauges, figures | {"rig_calib_s": seconds}


def true_rig_in_reference_world(data: Path) -> tuple[dict, dict]:
    """Put ``data``'s true rig.json, moved rigidly into its reference camera's frame (the
    world a calibration takes), in place of its rig.json (the true one kept as
    ``gt/rig_true.json``): the control of :func:`calibrated_rig`, its world without its
    errors. Returns :func:`gauge_transforms` and its fit (a projection RMS of 0)."""
    true_json = data / "gt" / "rig_true.json"
    shutil.copyfile(data / "rig.json", true_json)
    rig = json.loads(true_json.read_text())
    R0, t0 = (np.asarray(rig["cameras"][0][k], float) for k in ("R", "t"))
    for entry in rig["cameras"]:  # X_new = R0 X + t0: x_c = R R0^T (X_new - t0) + t
        R = np.asarray(entry["R"], float) @ R0.T
        entry["t"] = (np.asarray(entry["t"], float) - R @ t0).tolist()
        entry["R"] = R.tolist()
    light = rig.get("chromatic_light", {})
    if "position" in light:
        light["position"] = (R0 @ np.asarray(light["position"], float) + t0).tolist()
    (data / "rig.json").write_text(json.dumps(rig, indent=1))
    return gauge_transforms(true_json, data / "rig.json")


def evaluate_variant(data, scene, frames, variant, files, chromatic, work, gauges=None) -> dict:
    """Depth maps of one scene x variant over its frames, pooled against the ground truth.

    ``gauges`` (name -> (A, b), the rigid map ``X = A X_true + b`` from the true world
    into the dataset rig's; :func:`gauge_transforms`) places the ground-truth mesh in the
    frame of a rig in a world of its own (``--calibrate-rig``, ``--reference-world``):
    the first entry gives the figures below, every other one its
    ``depth_median_mm_<name>``, ``depth_signed_median_mm_<name>`` and
    ``depth_rms_mm_<name>`` beside them. None (the default): the rig is the true one,
    the mesh is used as it is.

    Returns
    -------
    dict
        :func:`colourhs.evaluation.depth_errors.depth_summary` of the pooled pixels (less
        ``truth_pixels``); ``depth_sigma_median_mm`` and ``sigma_within_1/2/3``
        (:func:`colourhs.evaluation.depth_errors.sigma_summary`) over the pooled pixels with both a
        finite error and a finite ``depth_sigma`` (None where the files carry none:
        ``vh``, files written before it); ``dropped_<reason>`` and ``dropped_other``
        (:func:`colourhs.evaluation.depth_errors.drop_summary`), shares of the frames' pooled
        ground-truth pixels (None without ``dropped``); ``reciprocity_defect_deg``, the
        frames' median of the depth files' (None where they do not say); ``seconds``. A frame with
        nothing reconstructed (a depth file :func:`read_depth` refuses) counts
        every truth pixel as lost (``dropped_other``), not as an error.
    """
    from colourhs.capture import load_rig
    from colourhs.common.depthfile import read_depth
    from colourhs.common.ply import load_mesh
    from colourhs.common.raycast import render_depth_normals
    from colourhs.evaluation.depth_errors import depth_errors, depth_summary, sigma_summary
    from colourhs.reconstruct.frame import reconstruct_frame
    from colourhs.reconstruct.inputs import CalibrationFiles
    from colourhs.surfaces.hull import visual_hull

    rig = load_rig(data)
    size = (rig.image.width, rig.image.height)
    gauges = dict(gauges or {})
    primary = next(iter(gauges), None)
    extra = {name: [] for name in list(gauges)[1:]}  # name -> frames' finite signed errors
    errs, angs, truth = [], [], 0
    sigma_errs, sigmas, defects = [], [], []
    lost = dict.fromkeys(DROP_COLUMNS, 0.0)
    t0 = time.time()
    for frame in frames:
        h5 = work / scene / variant / f"{frame}.h5"
        if variant == "vh":
            visual_hull(data, scene, frame, work / scene / "hull" / f"{frame}.ply", out_depth_h5=h5)
        else:
            method = "ml" if variant.startswith("ml") else "bayes"
            calibration = CalibrationFiles(**variant_files(variant, files, chromatic))
            reconstruct_frame(data, scene, frame, h5, method, calibration)
        mesh = load_mesh(data / "scenes" / scene / "gt" / f"{frame}.ply")
        gt = mesh if primary is None else moved_mesh(mesh, *gauges[primary])
        try:
            depth = read_depth(h5)
        except ValueError as exc:  # nothing reconstructed: every truth pixel lost
            if "no reconstructed pixels" not in str(exc):
                raise
            n = int(np.isfinite(render_depth_normals(*gt, rig.cameras[0], *size)[0]).sum())
            truth += n
            if lost["dropped_other"] is not None:
                lost["dropped_other"] += n  # its reasons are in a file read_depth refuses
            continue
        err, ang, m = depth_errors(depth, *gt, *size)
        for name, pooled in extra.items():
            e = depth_errors(depth, *moved_mesh(mesh, *gauges[name]), *size)[0]
            pooled.append(e[np.isfinite(e)])
        defects.append((depth.params or {}).get("reciprocity_defect_deg"))
        ok = np.isfinite(err)
        errs.append(err[ok])
        angs.append(ang[ok])
        truth += m["truth_pixels"]
        for c in DROP_COLUMNS:  # shares of this frame's truth -> pixels, pooled below
            lost[c] = (
                None if lost[c] is None or m[c] is None else lost[c] + m[c] * m["truth_pixels"]
            )
        sigma = getattr(depth, "depth_sigma", None)
        if sigma is not None:
            sigma = np.asarray(sigma, float)
            both = ok & np.isfinite(sigma)
            sigma_errs.append(err[both])
            sigmas.append(sigma[both])
    empty = np.empty(0)
    s = depth_summary(np.concatenate([empty, *errs]), np.concatenate([empty, *angs]), truth)
    s.pop("truth_pixels")
    if sigmas:
        s |= sigma_summary(np.concatenate(sigma_errs), np.concatenate(sigmas))
    else:
        s |= sigma_summary(np.empty(0), None)
    s.pop("sigma_pixels")
    s |= {c: None if v is None or not truth else v / truth for c, v in lost.items()}
    known = [d for d in defects if d is not None]
    s["reciprocity_defect_deg"] = float(np.median(known)) if known else None
    for name, pooled in extra.items():
        g = depth_summary(np.concatenate([empty, *pooled]), empty, truth)
        for k in ("depth_median_mm", "depth_signed_median_mm", "depth_rms_mm"):
            s[f"{k}_{name}"] = g[k]
    return s | {"seconds": time.time() - t0}


def figure(m: dict, key: str, fmt: str) -> str:
    """``m[key]`` formatted with ``fmt`` for a progress line; ``-`` where it is missing."""
    return "-" if m.get(key) is None else format(m[key], fmt)


def _line(m: dict) -> str:
    """One scene x variant's figures as a progress line (``-`` where there are none)."""

    def f(key, fmt):
        return figure(m, key, fmt)

    return (
        f"depth {f('depth_median_mm', '.3f')} mm (signed {f('depth_signed_median_mm', '+.3f')}) "
        f"rms {f('depth_rms_mm', '.3f')} normal {f('normal_median_deg', '.2f')} deg "
        f"coverage {f('coverage', '.3f')} ({m['seconds']:.0f} s)"
    )


def run_seed(
    seed: int,
    preset: str,
    sheet_frames: int,
    keep: Path | None,
    variants=tuple(VARIANTS),
    light_offset_m: tuple[float, float] | None = None,
    scenes=None,
    rig_source: str = "true",
    gauge: str = "projection",
) -> pd.DataFrame:
    """One rig of ``preset`` (seed ``seed``): render, calibrate, reconstruct and measure
    every scene (or those of ``scenes``) with each variant; ``light_offset_m`` replaces
    the preset's range of the lights' offset from the lenses (the set is then named
    after it). ``rig_source``: ``"true"``, the true rig.json; ``"calibrated"``, every
    stage runs on the rig calibrated from the dataset's ``geometric/`` captures
    (:func:`calibrated_rig`); ``"reference-world"``, on the true rig moved into its
    reference camera's frame (:func:`true_rig_in_reference_world`, the control); the
    set's name says which. Other than the true rig, each is compared with the truth in
    the gauge ``gauge`` (:func:`gauge_transforms`; the others' depth figures beside
    it)."""
    from dataclasses import replace

    from colourhs.capture import open_dataset
    from colourhs.synth.randomranges import RANGES_BY_NAME
    from colourhs.synth.synthesise import PRESETS, DrawOverrides, RenderSelection, synthesise

    ranges, name = None, preset
    if light_offset_m is not None:
        ranges = replace(
            RANGES_BY_NAME[PRESETS[preset].random_ranges], light_offset_m=light_offset_m
        )
        name = f"{preset}, lights {light_offset_m[0] * 1e3:g}-{light_offset_m[1] * 1e3:g} mm"
    root = Path(tempfile.mkdtemp(prefix=f"colourhs-gen-{seed}-"))
    try:
        t0 = time.time()
        # Only the scenes measured (their files are those of a full render).
        selection = RenderSelection(scenes=None if scenes is None else tuple(scenes))
        overrides = DrawOverrides(ranges=ranges)
        data = synthesise(root / "data", preset, seed=seed, draw=overrides, selection=selection)
        t_render = time.time() - t0
        gauges, rig_figures = None, {}
        if rig_source != "true":
            if rig_source == "calibrated":
                gauges, rig_figures = calibrated_rig(data, root)
            elif rig_source == "reference-world":
                gauges, rig_figures = true_rig_in_reference_world(data)
            else:
                raise ValueError(f"rig_source {rig_source!r}: true, calibrated or reference-world")
            gauges = {gauge: gauges[gauge]} | gauges  # the figures' own first
            name = f"{name}, {RIG_SETS[rig_source]}"
        t0 = time.time()
        files = calibrate(data, root / "calib")
        t_calib = time.time() - t0
        cal = calibration_errors(data, files)
        ds = open_dataset(data, check_images=False)
        rig = ds.rig
        rows = []
        for scene, sc in ds.scenes.items():
            frames = list(sc.frames)
            if len(frames) > sheet_frames:
                idx = np.linspace(0, len(frames) - 1, sheet_frames).round().astype(int)
                frames = [frames[i] for i in idx]
            for variant in variants:
                m = evaluate_variant(
                    data, scene, frames, variant, files, sc.chromatic, root / "work", gauges
                )
                rows.append(
                    {
                        "set": name,
                        "rig": rig_source,
                        "gauge": None if gauges is None else gauge,
                        "seed": seed,
                        "scene": scene,
                        "variant": variant,
                        "frames": len(frames),
                        **m,
                    }
                )
                print(f"seed {seed} {scene:7s} {variant:14s} {_line(m)}", flush=True)
        table = pd.DataFrame(rows)
        draw = json.loads((data / "gt" / "rig_model.json").read_text()).get("draw", {})
        for k, v in (cal | rig_figures).items():
            table[k] = v
        table["bit_depth"] = rig.image.bit_depth
        table["white_level"] = rig.image.white_level  # 4095: 12-bit data in 16-bit PNGs
        table["working_distance_m"] = draw.get("working_distance_m")
        table["masks"] = draw.get("mask_mode")
        table["render_s"], table["calib_s"] = t_render, t_calib
        if keep is not None:
            shutil.copytree(root, keep / f"seed{seed}", dirs_exist_ok=True)
        return table
    finally:
        shutil.rmtree(root, ignore_errors=True)


def worst_value(metric: str, values: np.ndarray) -> float:
    """The worst of a metric's finite per-rig values.

    The largest for errors, the smallest ``coverage``, the largest absolute value with
    its sign for :data:`SIGNED_METRICS`, the furthest from the Gaussian's share
    (:data:`GAUSSIAN_WITHIN`) for ``sigma_within_<k>``.
    """
    if metric == "coverage":
        return float(values.min())
    if metric in SIGNED_METRICS:
        return float(values[np.argmax(np.abs(values))])
    if metric.startswith("sigma_within_"):
        expected = GAUSSIAN_WITHIN[int(metric.rsplit("_", 1)[1])]
        return float(values[np.argmax(np.abs(values - expected))])
    return float(values.max())


def target_met(metric: str, median: float | None, worst: float | None, target) -> bool:
    """Whether a median over rigs and the worst rig are within a target's upper bounds
    (absolute values for :data:`SIGNED_METRICS`); False without values."""
    if median is None or worst is None:
        return False
    if metric in SIGNED_METRICS:
        median, worst = abs(median), abs(worst)
    return bool(median <= target[0] and worst <= target[1])


def metric_entry(scene: str, variant: str, metric: str, values) -> dict:
    """Median over rigs, worst rig (:func:`worst_value`) and rigs with a value; the
    target (None where none) and, where one exists, ``met``: never where a rig has no
    value (nothing reconstructed), which the median and the worst leave out."""
    v = np.asarray(values, float)
    finite = v[np.isfinite(v)]
    entry = {
        "median": float(np.median(finite)) if finite.size else None,
        "worst": worst_value(metric, finite) if finite.size else None,
        "rigs": int(finite.size),
        "target": None,
    }
    target = TARGETS.get((scene, variant, metric))
    if target is not None:
        entry["target"] = {"median": target[0], "worst": target[1]}
        met = target_met(metric, entry["median"], entry["worst"], target)
        entry["met"] = met and finite.size == v.size
    return entry


def scene_summary(table: pd.DataFrame) -> dict:
    """scene -> variant -> metric -> :func:`metric_entry` over one set's rows."""
    out = {}
    for (scene, variant), g in table.groupby(["scene", "variant"]):
        out.setdefault(scene, {})[variant] = {
            m: metric_entry(scene, variant, m, g[m].astype(float)) for m in METRICS if m in g
        }
    return out


def sigma_calibration(table: pd.DataFrame) -> dict:
    """The sigma calibration target per Bayesian variant over one set's rigs and scenes.

    Each ``sigma_within_<k>`` is the mean of the per-row shares (one row per rig x
    scene, each weighted equally whatever its pixel count, rows without a sigma left
    out), ``met`` when within :data:`SIGMA_TOLERANCE` of the Gaussian's share
    (:data:`GAUSSIAN_WITHIN`: 0.683, 0.954, 0.997); the variant's ``met`` when every
    share's is (False without rows with a sigma). Besides each variant, the entry
    :data:`OWN_VARIANT` holds each scene's own variant only (the one its targets
    name: the calibration a rig owner runs it with), since an ablation's missing
    calibration (mu = 1, p = 1) is an error no error bar of the data can see.

    Returns
    -------
    dict
        variant -> ``sigma_within_<k>`` -> {``mean``, ``target``, ``tolerance``,
        ``met``}, ``rows`` (rows with a sigma) and ``met``; variants the table lacks
        are left out.
    """
    out = {}
    own = {(s, v) for s, v, _ in TARGETS}
    groups = [(v, table[table["variant"] == v]) for v in BAYES_VARIANTS]
    pairs = list(zip(table["scene"], table["variant"], strict=True))
    groups.append((OWN_VARIANT, table[[p in own for p in pairs]]))
    for name, g in groups:
        if g.empty:
            continue
        entry, rows = {}, 0
        for k, expected in GAUSSIAN_WITHIN.items():
            col = f"sigma_within_{k}"
            v = g[col].astype(float).to_numpy() if col in g else np.empty(0)
            v = v[np.isfinite(v)]
            rows = max(rows, int(v.size))
            mean = float(v.mean()) if v.size else None
            met = mean is not None and abs(mean - expected) <= SIGMA_TOLERANCE
            entry[col] = {
                "mean": mean,
                "target": expected,
                "tolerance": SIGMA_TOLERANCE,
                "met": bool(met),
            }
        entry["rows"] = rows
        entry["met"] = all(entry[f"sigma_within_{k}"]["met"] for k in GAUSSIAN_WITHIN)
        out[name] = entry
    return out


def ml_link_applicable(table: pd.DataFrame) -> dict:
    """seed -> whether ``ml_full > bayes_nocalib`` is checked on that rig: its
    uncalibrated mu within :data:`ML_LINK_MU_LIMIT` (not where it is unknown)."""
    col = "mu_uncalibrated_rms_log_worst"
    if col not in table:
        return {seed: False for seed in table["seed"].unique()}
    mu = table.groupby("seed")[col].first().astype(float)
    return {seed: bool(np.isfinite(v) and v <= ML_LINK_MU_LIMIT) for seed, v in mu.items()}


def broken_links(d: dict, ml_link: bool) -> list[str]:
    """The ablation links that break on one rig x scene (``d``: variant -> metric);
    ``ml_full > bayes_nocalib`` only where ``ml_link``."""
    broken = []
    for a, b, tie in LINKS:
        name = f"{a} {'>=' if tie else '>'} {b}"
        if name == ML_LINK and not ml_link:
            continue
        holds = d[a] >= d[b] * 0.999 if tie else d[a] > d[b]
        if not holds:
            broken.append(name)
    return broken


def ablation(table: pd.DataFrame) -> dict:
    """The ablation order on one set's rigs, on the depth median and on the RMS.

    The order needs every variant (an empty dict otherwise). ``ml_full >
    bayes_nocalib`` is checked only on rigs where :func:`ml_link_applicable` (a
    rig far from mu = 1 fails that link whatever ML does), elsewhere it is not
    applicable (not broken); the other links on every rig.

    Returns
    -------
    dict
        Per statistic (suffix ``""``: depth median, ``_rms``: RMS, the paper's
        Section IV-A statistic): ``ablation_order_holds`` (``seed/scene`` -> bool),
        ``ablation_links_broken`` (``seed/scene`` -> links), ``ablation_order_all_seeds``
        and ``ablation_broken_counts`` (link -> cases, ``cases``); and
        ``ablation_ml_link_not_applicable`` (rigs where the ML link was not checked)
        with their seeds (``ablation_ml_link_not_applicable_seeds``).
    """
    out = {}
    if not set(VARIANTS) <= set(table["variant"]):
        return out
    applicable = ml_link_applicable(table)
    for metric, suffix in (("depth_median_mm", ""), ("depth_rms_mm", "_rms")):
        links = {}
        for (seed, scene), g in table.groupby(["seed", "scene"]):
            d = dict(zip(g["variant"], g[metric].astype(float), strict=True))
            links[f"{seed}/{scene}"] = broken_links(d, applicable[seed])
        counts = {}
        for broken in links.values():
            for link in broken:
                counts[link] = counts.get(link, 0) + 1
        out[f"ablation_order_holds{suffix}"] = {k: not v for k, v in links.items()}
        out[f"ablation_links_broken{suffix}"] = links
        out[f"ablation_order_all_seeds{suffix}"] = not any(links.values())
        out[f"ablation_broken_counts{suffix}"] = counts | {"cases": len(links)}
    skipped = sorted(int(seed) for seed, ok in applicable.items() if not ok)
    out["ablation_ml_link_not_applicable"] = len(skipped)
    out["ablation_ml_link_not_applicable_seeds"] = skipped
    return out


def calibration_summary(table: pd.DataFrame) -> dict:
    """Median and worst (largest) calibration error over one set's rigs."""
    cols = ["mu_rms_log_worst", "mu_uncalibrated_rms_log_worst", "chromaticity_median_rel"]
    cal = table.groupby("seed")[[c for c in cols if c in table]].first()
    return {
        c: {"median": float(cal[c].median()), "worst": float(cal[c].max())}
        for c in cal
        if cal[c].notna().any()
    }


def set_names(table: pd.DataFrame) -> pd.Series:
    """Each row's set: the ``set`` column, ``all`` where the table has none."""
    if "set" not in table:  # tables written before the column have none
        return pd.Series("all", index=table.index)
    return table["set"].fillna("all").astype(str)


def summarise(table: pd.DataFrame) -> dict:
    """Per set: the scenes' metrics, the sigma calibration, the ablation, the calibration.

    Parameters
    ----------
    table : DataFrame
        Per-seed rows (``generalisation_seeds.csv``; several concatenated).

    Returns
    -------
    dict
        ``seeds`` (every set's), ``sets``: set -> {``seeds``, ``scenes``
        (:func:`scene_summary`), ``sigma_calibration`` (:func:`sigma_calibration`),
        the ablation's keys (:func:`ablation`), ``calibration``}; and the decisions'
        thresholds (``ml_link_mu_limit``, ``sigma_tolerance``).
    """
    table = table.reset_index(drop=True)
    sets = set_names(table)
    out = {
        "seeds": sorted({int(s) for s in table["seed"].unique()}),
        "ml_link_mu_limit": ML_LINK_MU_LIMIT,
        "sigma_tolerance": SIGMA_TOLERANCE,
        "sets": {},
    }
    for name in sorted(sets.unique()):
        g = table[sets == name]
        out["sets"][name] = {
            "seeds": sorted(int(s) for s in g["seed"].unique()),
            "scenes": scene_summary(g),
            "sigma_calibration": sigma_calibration(g),
            **ablation(g),
            "calibration": calibration_summary(g),
        }
    return out


def _pair(entry: dict | None, fmt: str) -> str:
    """``median / worst`` of a metric entry, ``-`` where there is none."""
    if not entry or entry["median"] is None:
        return "-"
    return f"{entry['median']:{fmt}} / {entry['worst']:{fmt}}"


#: The markdown's metric columns: (metric, heading, format).
MARKDOWN_COLUMNS = (
    ("depth_median_mm", "depth median (mm)", ".3f"),
    ("depth_rms_mm", "RMS (mm)", ".3f"),
    ("depth_signed_median_mm", "signed median (mm)", "+.3f"),
    ("normal_median_deg", "normal median (deg)", ".2f"),
    ("coverage", "coverage", ".3f"),
)
SHORT_NAMES = {
    "depth_median_mm": "depth",
    "depth_rms_mm": "RMS",
    "depth_signed_median_mm": "abs signed",
    "normal_median_deg": "normal",
}


def _targets_text(scene: str, variant: str) -> str:
    """A row's targets, e.g. ``depth <= 0.1 / 0.3``; ``-`` without any."""
    parts = [
        f"{SHORT_NAMES.get(m, m)} <= {t[0]:g} / {t[1]:g}"
        for (s, v, m), t in TARGETS.items()
        if (s, v) == (scene, variant)
    ]
    return "; ".join(parts) or "-"


def _met_text(scene: str, variant: str, entries: dict) -> str:
    """``yes``, ``no (the targets missed, in :data:`TARGETS`' order)`` or ``-`` without
    targets."""
    judged = [m for s, v, m in TARGETS if (s, v) == (scene, variant) and m in entries]
    if not judged:
        return "-"
    missed = [SHORT_NAMES.get(m, m) for m in judged if not entries[m]["met"]]
    return f"no ({', '.join(missed)})" if missed else "yes"


def _scene_table(s: dict) -> list[str]:
    """One set's table: a row per :data:`MARKDOWN_ROWS` entry the set has."""
    head = ["scene", "variant", *(h for _, h, _ in MARKDOWN_COLUMNS), "target", "met"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for scene, variant in MARKDOWN_ROWS:
        entries = s["scenes"].get(scene, {}).get(variant)
        if entries is None:
            continue
        cells = [_pair(entries.get(m), fmt) for m, _, fmt in MARKDOWN_COLUMNS]
        cells += [_targets_text(scene, variant), _met_text(scene, variant, entries)]
        lines.append("| " + " | ".join([scene, variant, *cells]) + " |")
    return lines


def _sigma_table(s: dict) -> list[str]:
    """One set's sigma calibration table (a row per Bayesian variant it has)."""
    ks = list(GAUSSIAN_WITHIN)
    head = ["variant", *(f"within {k} sigma" for k in ks), "rows", "target", "met"]
    target = " / ".join(f"{GAUSSIAN_WITHIN[k]:.3f}" for k in ks) + f" +- {SIGMA_TOLERANCE:g}"
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for variant, e in s["sigma_calibration"].items():
        means = [e[f"sigma_within_{k}"]["mean"] for k in ks]
        cells = ["-" if v is None else f"{v:.3f}" for v in means]
        met = "yes" if e["met"] else "no"
        lines.append("| " + " | ".join([variant, *cells, str(e["rows"]), target, met]) + " |")
    return lines


def _ablation_lines(s: dict) -> list[str]:
    """One set's ablation: broken links per statistic, rigs where the ML link was not
    applicable."""
    if "ablation_broken_counts" not in s:
        return ["Not every variant ran: no ablation order."]
    names = [f"{a} {'>=' if tie else '>'} {b}" for a, b, tie in LINKS]
    head = ["statistic", "held on every rig x scene", *(f"`{n}` broken" for n in names), "cases"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for suffix, label in (("", "depth median"), ("_rms", "RMS")):
        counts = s[f"ablation_broken_counts{suffix}"]
        held = "yes" if s[f"ablation_order_all_seeds{suffix}"] else "no"
        cells = [str(counts.get(n, 0)) for n in names]
        lines.append("| " + " | ".join([label, held, *cells, str(counts["cases"])]) + " |")
    skipped = s["ablation_ml_link_not_applicable_seeds"]
    lines += [
        "",
        f"`{ML_LINK}` not applicable (uncalibrated mu error above {ML_LINK_MU_LIMIT:.0%}) on "
        f"{len(skipped)} of {len(s['seeds'])} rigs"
        + (f" (seeds {', '.join(map(str, skipped))})" if skipped else "")
        + "; not counted as broken.",
    ]
    return lines


def summarise_markdown(summary: dict) -> str:
    """:func:`summarise`'s summary as markdown: per set a table of the scenes with
    targets (and ML on the plane), each cell the median over rigs / the worst rig; the
    sigma calibration; the ablation's broken links."""
    lines = ["# Generalisation on randomised rigs", ""]
    for name, s in summary["sets"].items():
        seeds = ", ".join(map(str, s["seeds"]))
        lines += [f"## Set `{name}` (seeds {seeds})", "", "Median over rigs / worst rig.", ""]
        lines += _scene_table(s)
        lines += ["", "### Sigma calibration", ""]
        lines += ["Mean of the per-row shares (each rig x scene weighted equally).", ""]
        lines += _sigma_table(s)
        lines += ["", "### Ablation", ""]
        lines += _ablation_lines(s)
        lines.append("")
    return "\n".join(lines)


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--seeds", default="0-7", help="seeds, e.g. 0-7 or 1,3,5 (default 0-7)")
    p.add_argument(
        "--preset",
        default="random",
        help="a randomised preset: random or corner (640x480; corner: the ranges' hard ends "
        "combined), random-tiny or corner-tiny (160x120); default random",
    )
    p.add_argument("--sheet-frames", type=int, default=2, help="sheet frames per seed (default 2)")
    p.add_argument("--keep", type=Path, default=None, help="keep datasets and results here")
    p.add_argument("--tag", default="", help="suffix of the output files")
    p.add_argument(
        "--light-offset-mm",
        default=None,
        help="the lights' offset from the lenses, mm: 'A,B' draws it from U(A, B), '0' puts "
        "every light at its lens (default: the preset's range)",
    )
    p.add_argument(
        "--variants",
        default=",".join(VARIANTS),
        help="variants to run (default all; the summary's ablation order needs all)",
    )
    p.add_argument(
        "--scenes",
        default=None,
        help="scenes to render and measure, e.g. plane,statue (default all)",
    )
    p.add_argument(
        "--calibrate-rig",
        action="store_true",
        help="run every stage on the rig calibrated from the geometric/ captures "
        "(calibrate-rig, the true rig.json its base) instead of the true one",
    )
    p.add_argument(
        "--reference-world",
        action="store_true",
        help="the control of --calibrate-rig: run every stage on the true rig moved into its "
        "reference camera's frame (the calibrated rig's world, without its errors)",
    )
    p.add_argument(
        "--gauge",
        default="projection",
        choices=("projection", "cameras", "reference"),
        help="with --calibrate-rig or --reference-world: the map of the true world into the rig's "
        "that the depth figures are taken in (gauge_transforms; default projection), the "
        "others beside them",
    )
    p.add_argument(
        "--summarise",
        type=Path,
        nargs="+",
        default=None,
        help="only summarise these per-seed tables (generalisation_seeds CSVs, concatenated, "
        "e.g. a random and a corner run), rendering nothing",
    )
    args = p.parse_args(argv)
    show_progress()  # the calibration stages' progress on stderr, as the CLI shows it
    if args.summarise is None:
        from colourhs.synth.synthesise import PRESETS

        if args.preset not in PRESETS or not PRESETS[args.preset].randomised:
            randomised = ", ".join(k for k, v in PRESETS.items() if v.randomised)
            p.error(f"--preset {args.preset}: not a randomised preset ({randomised})")
    if args.calibrate_rig and args.reference_world:
        p.error("--calibrate-rig and --reference-world: one rig at a time")
    source = "true"
    if args.calibrate_rig or args.reference_world:
        source = "calibrated" if args.calibrate_rig else "reference-world"
    offset = None
    if args.light_offset_mm is not None:
        ends = [float(v) * 1e-3 for v in args.light_offset_mm.split(",")]
        offset = (ends[0], ends[-1])
    out_dir = HERE / "results"
    out_dir.mkdir(exist_ok=True)
    csv = out_dir / f"generalisation_seeds{args.tag}.csv"
    if args.summarise is not None:
        table = pd.concat([pd.read_csv(path) for path in args.summarise], ignore_index=True)
    else:
        tables = []
        for seed in frame_indices(args.seeds):
            tables.append(
                run_seed(
                    seed,
                    args.preset,
                    args.sheet_frames,
                    args.keep,
                    args.variants.split(","),
                    offset,
                    None if args.scenes is None else args.scenes.split(","),
                    source,
                    args.gauge,
                )
            )
            pd.concat(tables).to_csv(csv, index=False)  # after every seed: a partial run counts
        table = pd.concat(tables, ignore_index=True)
    summary = summarise(table)
    (out_dir / f"generalisation_summary{args.tag}.json").write_text(json.dumps(summary, indent=2))
    (out_dir / f"generalisation_summary{args.tag}.md").write_text(summarise_markdown(summary))
    print(json.dumps(summary, indent=2))
    return summary


if __name__ == "__main__":
    main()
