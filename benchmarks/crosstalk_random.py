"""Cross-talk calibration against the true LED mixing on randomised rigs.

For each seed: render ``random`` (640x480, plane scene only) unless the
dataset is already there, run the markers stage, then calibrate cross-talk
two ways: today's constant matrix from the chromatic white captures
(``calibrate_crosstalk(ds)``) and the spatial field times the LED factor from
the board (``calibrate_crosstalk(ds, poses_csv=...)``). Each is compared with
the true LED mixing of every pixel,

    M_true[c, b](u) = X[c, b] sigma_c(u) / (X[b, b] sigma_b(u)),

X the camera's LED matrix ("crosstalk" in gt/rig_model.json) and sigma the
channel sensitivities of ``CameraModel.sensitivity`` at the pixel centre's
undistorted normalised coordinates (what ``channel_signal`` multiplies).
Reported per camera: max and RMS over the image and the 6 off-diagonals of
|M_est(u) - M_true(u)|; then median and worst over cameras and seeds.

    .venv/bin/python benchmarks/crosstalk_random.py --root /tmp/xt --seeds 0 1 2 3 4 5 6 7
    .venv/bin/python benchmarks/crosstalk_random.py --root /tmp/xt --preset demo --seeds 0
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from colourhs.calibration.crosstalk import MixingField, calibrate_crosstalk, load_crosstalk
from colourhs.common.geometry import normalised_coordinates, pixel_grid
from colourhs.common.progress import show_progress

OFF = ~np.eye(3, dtype=bool)


def true_mixing(dataset: Path) -> dict[str, np.ndarray]:
    """Camera name -> (H, W, 3, 3) true LED mixing on the pixel centres (see module doc)."""
    model = json.loads((dataset / "gt" / "rig_model.json").read_text())
    rig = json.loads((dataset / "rig.json").read_text())
    W, H = rig["image"]["width"], rig["image"]["height"]
    out = {}
    for cam in model["cameras"]:
        X = np.array(cam["crosstalk"], float)
        K, dist = np.array(cam["K"], float), np.array(cam["dist"], float)
        xy = normalised_coordinates(pixel_grid(W, H).reshape(-1, 2), K, dist)
        centre = np.array(cam["vignetting_centre"], float)
        r2 = np.sum((xy[:, None, :] - centre) ** 2, axis=-1) / cam["corner_radius"] ** 2
        sens = np.array(cam["gains"]) * np.clip(1.0 - np.array(cam["vignetting"]) * r2, 0.05, None)
        M = X[None] * sens[:, :, None] / (sens[:, None, :] * np.diag(X)[None, None, :])
        out[cam["name"]] = M.reshape(H, W, 3, 3)
    return out


def dense(mixing, shape) -> np.ndarray:
    if isinstance(mixing, MixingField):
        return mixing.dense()
    return np.broadcast_to(np.asarray(mixing, float), (*shape, 3, 3))


def errors(est: dict, truth: dict) -> dict[str, tuple[float, float]]:
    """Camera -> (max, RMS) over pixels and off-diagonals of |M_est - M_true|."""
    out = {}
    for cam, Mt in truth.items():
        e = np.abs(dense(est[cam], Mt.shape[:2]) - Mt)[..., OFF]
        out[cam] = (float(e.max()), float(np.sqrt(np.mean(e**2))))
    return out


def run_seed(root: Path, preset: str, seed: int, workers: int) -> dict:
    from colourhs.calibration.markers import marker_poses
    from colourhs.synth.synthesise import RenderSelection, synthesise

    data = root / f"{preset}-seed{seed}"
    if not data.exists():
        plane = RenderSelection(scenes=("plane",))
        synthesise(data, preset, seed=seed, selection=plane, workers=workers)
    poses = root / f"{preset}-seed{seed}_poses.csv"
    if not poses.exists():
        marker_poses(data, poses)
    truth = true_mixing(data)
    t0 = time.time()
    calibrate_crosstalk(data, root / f"{preset}-seed{seed}_today.json")
    t1 = time.time()
    new = calibrate_crosstalk(data, root / f"{preset}-seed{seed}_new.json", poses_csv=poses)
    t2 = time.time()
    today = errors(load_crosstalk(root / f"{preset}-seed{seed}_today.json"), truth)
    ours = errors(load_crosstalk(root / f"{preset}-seed{seed}_new.json"), truth)
    return {
        "seed": seed,
        "today": today,
        "new": ours,
        "time_today_s": t1 - t0,
        "time_new_s": t2 - t1,
        "led_fit": new["led_fit"],
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--root", type=Path, required=True, help="folder for datasets and results")
    ap.add_argument("--preset", default="random")
    ap.add_argument("--seeds", type=int, nargs="+", default=list(range(8)))
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    show_progress()  # the calibration stages' progress on stderr, as the CLI shows it
    args.root.mkdir(parents=True, exist_ok=True)
    results = []
    for s in args.seeds:
        r = run_seed(args.root, args.preset, s, args.workers)
        results.append(r)
        for method in ("today", "new"):
            cells = "  ".join(f"{c} {m * 100:.3f}/{q * 100:.3f}" for c, (m, q) in r[method].items())
            print(f"seed {s} {method:5s} max/RMS %: {cells}", flush=True)
        print(
            f"seed {s} times: today {r['time_today_s']:.1f} s, new {r['time_new_s']:.1f} s",
            flush=True,
        )
    print(f"\n{args.preset}, {len(results)} seeds: |M_est(u) - M_true(u)|, % of full scale")
    print("method  stat  median-seed  worst-seed   (per seed: worst camera)")
    for method in ("today", "new"):
        mx = np.array([max(v[0] for v in r[method].values()) for r in results])
        rms = np.array([max(v[1] for v in r[method].values()) for r in results])
        print(f"{method:6s}  max   {np.median(mx) * 100:10.3f}  {mx.max() * 100:10.3f}")
        print(f"{method:6s}  RMS   {np.median(rms) * 100:10.3f}  {rms.max() * 100:10.3f}")
    (args.root / f"{args.preset}_crosstalk_results.json").write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
