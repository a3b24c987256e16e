"""Render the README's figures: the pipeline stages and a synthetic capture.

Run: ``.venv/bin/python docs/make_figures.py [DATASET]`` (DATASET defaults to
data/synthetic/demo, made by the README's first command).
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import FancyBboxPatch  # noqa: E402

from colourhs.capture import open_dataset, read_image  # noqa: E402

HERE = Path(__file__).parent

STAGES = [
    ("raw captures", "capture format v1\nrig.json + PNG"),
    ("marker poses", "ArUco,\ntriangulation\nmarker_poses.csv"),
    ("photometric", "mu per Helmholtz cam.\neq. (6)-(8)\nphotometric.h5"),
    ("chromaticity", "p per camera\neq. (12)\nchromaticity/<obj>.h5"),
    ("depth + normals", "ML / Bayesian HS\neq. (5)\ndepth/<frame>.h5"),
    ("Poisson mesh", "oriented points\n+ visual hull\nmesh/<frame>.ply"),
    ("evaluation", "Hausdorff vs\nground truth\nmetrics.csv"),
    ("report", "figures, tables\nindex.html"),
]


def pipeline(out: Path) -> None:
    fig, ax = plt.subplots(figsize=(15, 2.6))
    ax.set_xlim(0, len(STAGES) * 1.6)
    ax.set_ylim(0, 1.6)
    ax.axis("off")
    for k, (title, sub) in enumerate(STAGES):
        x = k * 1.6 + 0.05
        ax.add_patch(
            FancyBboxPatch(
                (x, 0.3), 1.3, 1.0, boxstyle="round,pad=0.03", fc="#e8eef7", ec="#3b5b8c"
            )
        )
        ax.text(x + 0.65, 1.05, title, ha="center", va="center", fontsize=9, weight="bold")
        ax.text(x + 0.65, 0.62, sub, ha="center", va="center", fontsize=7)
        if k < len(STAGES) - 1:
            ax.annotate("", (x + 1.55, 0.8), (x + 1.36, 0.8), arrowprops={"arrowstyle": "->"})
    ax.set_title("colourhs: one Snakemake rule per stage, files between stages", fontsize=10)
    fig.savefig(out, dpi=110, bbox_inches="tight")
    plt.close(fig)


def capture(dataset: Path, out: Path) -> None:
    ds = open_dataset(dataset)
    rows = [("photometric", ds.poses[0]), ("statue", None), ("toy", None), ("sheet", None)]
    cams = ds.rig.camera_names
    fig, axes = plt.subplots(len(rows), len(cams), figsize=(3.2 * len(cams), 2.5 * len(rows)))
    for r, (what, pose) in enumerate(rows):
        for c, cam in enumerate(cams):
            if pose is not None:
                path = ds.photometric_image(pose, cam)
            else:
                frames = ds.scenes[what].frames
                path = ds.frame_image(what, frames[len(frames) // 2], cam)
            img, _ = read_image(path, ds.rig.image)
            ax = axes[r, c]
            ax.imshow(np.clip(img * 1.6, 0, 1))
            ax.set_title(f"{path.relative_to(dataset)}", fontsize=7)
            ax.axis("off")
    fig.tight_layout()
    fig.savefig(out, dpi=80)
    plt.close(fig)


if __name__ == "__main__":
    pipeline(HERE / "pipeline.png")
    dataset = Path(sys.argv[1] if len(sys.argv) > 1 else "data/synthetic/demo")
    if dataset.exists():
        capture(dataset, HERE / "synthetic_demo.png")
