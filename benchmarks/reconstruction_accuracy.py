"""Depth and normal accuracy of every reconstructed variant against ground truth.

Run after the workflow: ``.venv/bin/python benchmarks/reconstruction_accuracy.py [NAME]``.
For every ``results/NAME/<scene>/<variant>/depth/<frame>.h5`` with a
ground-truth mesh, renders the truth into the reference camera and writes
``benchmarks/results/reconstruction_NAME.csv`` with, per scene and variant
(frames pooled), the median, RMS and 95th percentile absolute depth error
(mm) and the median normal error (degrees), over the pixels the method
reconstructed, plus the fraction of true surface pixels it covers. The
errors are :func:`colourhs.evaluation.accuracy.depth_errors`, pooled by
:func:`colourhs.evaluation.accuracy.depth_summary`.
"""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

from colourhs.capture import load_rig
from colourhs.common.depthfile import read_depth
from colourhs.common.ply import load_mesh
from colourhs.evaluation.depth_errors import depth_errors, depth_summary

HERE = Path(__file__).parent


def main(name: str = "demo") -> pd.DataFrame:
    data = Path("data/synthetic") / name
    rig = load_rig(data)
    rows = []
    for depth_dir in sorted(Path("results", name).glob("*/*/depth")):
        scene, variant = depth_dir.parts[-3], depth_dir.parts[-2]
        errs, angs, truth_px = [], [], 0
        for h5 in sorted(depth_dir.glob("*.h5")):
            gt = data / "scenes" / scene / "gt" / f"{h5.stem}.ply"
            if not gt.exists():
                continue
            dm = read_depth(h5)
            # The rig's distortion, also for depth files written before they stored 'dist'.
            dm = replace(dm, dist=rig.camera(dm.camera).dist)
            err, ang, metrics = depth_errors(dm, *load_mesh(gt), rig.image.width, rig.image.height)
            m = np.isfinite(err)
            errs.append(err[m])
            angs.append(ang[m])
            truth_px += metrics["truth_pixels"]
        if not errs:
            continue
        summary = depth_summary(np.concatenate(errs), np.concatenate(angs), truth_px)
        summary.pop("truth_pixels")
        rows.append({"scene": scene, "variant": variant, "frames": len(errs), **summary})
    table = pd.DataFrame(rows)
    (HERE / "results").mkdir(exist_ok=True)
    table.to_csv(HERE / "results" / f"reconstruction_{name}.csv", index=False)
    return table


if __name__ == "__main__":
    print(main(*sys.argv[1:]).round(2).to_string(index=False))
