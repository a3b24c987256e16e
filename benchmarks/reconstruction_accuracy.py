"""Depth and normal accuracy of every reconstructed variant against ground truth.

Run after the workflow: ``.venv/bin/python benchmarks/reconstruction_accuracy.py [NAME]``.
For every ``results/NAME/<scene>/<variant>/depth/<frame>.h5`` with a
ground-truth mesh, renders the truth into the reference camera and writes
``benchmarks/results/reconstruction_NAME.csv`` with, per scene and variant
(frames pooled), the median, RMS and 95th percentile absolute depth error
(mm) and the median normal error (degrees), over the pixels the method
reconstructed, plus the fraction of true surface pixels it covers.
"""

from __future__ import annotations

import sys
from pathlib import Path

import h5py
import numpy as np
import pandas as pd

from colourhs.capture import load_rig
from colourhs.groundtruth import load_mesh, render_depth_normals

HERE = Path(__file__).parent


def main(name: str = "demo") -> pd.DataFrame:
    data = Path("data/synthetic") / name
    rig = load_rig(data)
    rows = []
    for depth_dir in sorted(Path("results", name).glob("*/*/depth")):
        scene, variant = depth_dir.parts[-3], depth_dir.parts[-2]
        errs, angs, covered, truth_px = [], [], 0, 0
        for h5 in sorted(depth_dir.glob("*.h5")):
            gt = data / "scenes" / scene / "gt" / f"{h5.stem}.ply"
            if not gt.exists():
                continue
            with h5py.File(h5) as f:
                depth, normal = f["depth"][()], f["normal"][()]
                cam = rig.camera(f.attrs["camera"])
            v, t, n = load_mesh(gt)
            gd, gn = render_depth_normals(v, t, n, cam, rig.image.width, rig.image.height)
            m = np.isfinite(depth) & np.isfinite(gd)
            errs.append(np.abs(depth[m] - gd[m]) * 1e3)
            angs.append(np.degrees(np.arccos(np.clip(np.sum(normal[m] * gn[m], 1), -1, 1))))
            covered += m.sum()
            truth_px += np.isfinite(gd).sum()
        if not errs:
            continue
        e, a = np.concatenate(errs), np.concatenate(angs)
        rows.append({"scene": scene, "variant": variant, "frames": len(errs),
                     "depth_median_mm": np.median(e), "depth_rms_mm": np.sqrt(np.mean(e**2)),
                     "depth_p95_mm": np.percentile(e, 95), "normal_median_deg": np.median(a),
                     "coverage": covered / max(truth_px, 1)})  # fmt: skip
    table = pd.DataFrame(rows)
    (HERE / "results").mkdir(exist_ok=True)
    table.to_csv(HERE / "results" / f"reconstruction_{name}.csv", index=False)
    return table


if __name__ == "__main__":
    print(main(*sys.argv[1:]).round(2).to_string(index=False))
