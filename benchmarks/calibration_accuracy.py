"""Accuracy of the calibration stages against a synthetic dataset's ground truth.

Run after the workflow (``.venv/bin/snakemake --cores 2``):
``.venv/bin/python benchmarks/calibration_accuracy.py [NAME]`` (default demo).
Reads ``data/synthetic/NAME`` and ``results/NAME/calib/`` and writes
``benchmarks/results/calibration_NAME.json``: marker-plane errors per pose,
mu map errors (calibrated and uncalibrated) per Helmholtz camera,
chromaticity errors per object and camera, and the cross-talk matrices'
errors.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import h5py
import numpy as np

from colourhs.calibration.chromaticity import chromaticity_error
from colourhs.calibration.crosstalk import load_crosstalk
from colourhs.calibration.markers import read_marker_poses
from colourhs.calibration.photometric import read_mu_maps
from colourhs.capture import load_rig
from colourhs.evaluation.photometric_errors import mu_map_errors

HERE = Path(__file__).parent


def main(name: str = "demo") -> dict:
    data = Path("data/synthetic") / name
    calib = Path("results") / name / "calib"
    rig = load_rig(data)
    out: dict = {"dataset": str(data)}

    truth = json.loads((data / "gt" / "board_poses.json").read_text())
    poses = []
    for _, row in read_marker_poses(calib / "marker_poses.csv").iterrows():
        gt = truth[row["pose"]]
        R, t = np.array(gt["R"]), np.array(gt["t"])
        n_true = R @ [0.0, 0.0, -1.0]
        p_true = R @ (np.array(rig.board.size + (0.0,)) / 2) + t
        n = row[["normal_x", "normal_y", "normal_z"]].to_numpy(float)
        p = row[["point_x", "point_y", "point_z"]].to_numpy(float)
        ang = np.degrees(np.arccos(np.clip(n @ n_true, -1, 1)))
        off = max(abs((p_true - p) @ n), abs((p - p_true) @ n_true)) * 1e3
        poses.append(
            {
                "pose": row["pose"],
                "normal_err_deg": ang,
                "offset_err_mm": off,
                "rms_px": float(row["rms_px"]),
            }
        )
    out["marker_poses"] = poses

    with h5py.File(calib / "photometric.h5") as f:
        est = {"maps": {}, "calibrated": {}}
        for key in read_mu_maps(calib / "photometric.h5"):
            est["maps"][key] = f[key][()]
            est["calibrated"][key] = f[f"calibrated/{key}"][()]
    err = mu_map_errors(est, read_mu_maps(data / "gt" / "photometric.h5"), rig)
    out["photometric"] = err.to_dict(orient="records")

    out["chromaticity"] = {}
    for h5 in sorted((calib / "chromaticity").glob("*.h5")):
        scene = h5.stem  # the synthetic objects share their scene's name
        gt_path = data / "scenes" / scene / "gt" / "chromaticity.h5"
        if not gt_path.exists():
            continue
        with h5py.File(h5) as f, h5py.File(gt_path) as g:
            out["chromaticity"][scene] = {}
            for cam in rig.camera_names:
                e = chromaticity_error(f[cam][()], g[cam][()])
                ok = np.isfinite(e)
                out["chromaticity"][scene][cam] = {
                    "median_rel_error": float(np.median(e[ok])),
                    "p90_rel_error": float(np.percentile(e[ok], 90)),
                    "coverage_of_true_pixels": float(ok.sum() / np.isfinite(g[cam][..., 0]).sum()),
                }

    model = json.loads((data / "gt" / "rig_model.json").read_text())
    mixing = load_crosstalk(calib / "crosstalk.json")
    out["crosstalk_max_abs_error"] = {}
    for cam in model["cameras"]:
        X, g = np.array(cam["crosstalk"]), np.array(cam["gains"])
        true = (g[:, None] * X) / (g[None, :] * np.diag(X)[None, :])
        out["crosstalk_max_abs_error"][cam["name"]] = float(
            np.abs(mixing[cam["name"]] - true).max()
        )

    (HERE / "results").mkdir(exist_ok=True)
    path = HERE / "results" / f"calibration_{name}.json"
    path.write_text(json.dumps(out, indent=2))
    return out


if __name__ == "__main__":
    result = main(*sys.argv[1:])
    print(json.dumps(result, indent=2))
