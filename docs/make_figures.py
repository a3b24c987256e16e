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

#: (title, details, column, row): row 1 runs once per rig, row 0 per scene, frame and variant.
STAGES = [
    ("captures", "capture format v1\nrig.json + PNG", 0, 1),
    ("validate", "every image decoded\ncapture/summary.json", 1, 1),
    ("marker poses", "ArUco, board poses\nmarker_poses.csv", 2, 1),
    ("cross-talk", "channel mixing M\n(white reference, board)\ncrosstalk.json", 3, 1),
    ("photometric", "mu per Helmholtz camera\neqs. (6)-(8)\nphotometric.h5", 4, 1),
    ("noise model", "gain per channel\nnoise.json", 5, 1),
    ("chromaticity", "p per camera, eq. (12)\nchromaticity/<obj>.h5", 6, 1),
    ("visual hull", "silhouettes, carving\nhull/<frame>.ply, vh", 1, 0),
    ("depth + normals", "ML / Bayesian HS\neq. (5)\ndepth/<frame>.h5", 2, 0),
    ("Poisson mesh", "oriented points\nmesh/<frame>.ply", 3, 0),
    ("evaluation", "Hausdorff vs\nground truth\neval/<frame>.json", 4, 0),
    ("metrics, figures", "metrics.csv\nfigures/<scene>/", 5, 0),
    ("report", "tables, figures\nindex.html", 6, 0),
]
#: Arrows between stages (by title): what each reads of the others.
ARROWS = [
    ("captures", "validate"),
    ("validate", "marker poses"),
    ("marker poses", "cross-talk"),
    ("cross-talk", "photometric"),
    ("validate", "visual hull"),
    ("visual hull", "depth + normals"),
    ("photometric", "depth + normals"),
    ("depth + normals", "Poisson mesh"),
    ("Poisson mesh", "evaluation"),
    ("evaluation", "metrics, figures"),
    ("metrics, figures", "report"),
]
W, H, STEP = 1.8, 0.95, 2.05  # box width, height, column spacing (data units)


def _box(col: int, row: int) -> tuple[float, float]:
    """Lower-left corner of a stage's box."""
    return col * STEP + 0.1, 0.35 + row * 1.55


def pipeline(out: Path) -> None:
    """The stages as boxes in two rows with the files between them; fails when a
    label does not fit inside its box."""
    fig, ax = plt.subplots(figsize=(15, 4.0))
    ax.set_xlim(0, 7 * STEP)
    ax.set_ylim(0, 3.35)
    ax.axis("off")
    ax.text(
        2 * STEP,
        3.05,
        "calibration, once per rig (also the noise model and chromaticity "
        "maps: into depth + normals)",
        fontsize=8,
        color="#3b5b8c",
    )
    ax.text(1 * STEP + 0.1, 0.1, "per scene, frame and variant", fontsize=8, color="#3b5b8c")
    texts, boxes = [], {}
    for title, sub, col, row in STAGES:
        x, y = _box(col, row)
        patch = FancyBboxPatch((x, y), W, H, boxstyle="round,pad=0.02", fc="#e8eef7", ec="#3b5b8c")
        ax.add_patch(patch)
        boxes[title] = (x, y)
        texts.append(
            (
                patch,
                ax.text(
                    x + W / 2,
                    y + H - 0.17,
                    title,
                    ha="center",
                    va="center",
                    fontsize=9,
                    weight="bold",
                ),
            )
        )
        texts.append(
            (patch, ax.text(x + W / 2, y + 0.36, sub, ha="center", va="center", fontsize=7))
        )
    for a, b in ARROWS:
        (xa, ya), (xb, yb) = boxes[a], boxes[b]
        if ya == yb:  # same row: side to side
            start, end = (xa + W + 0.02, ya + H / 2), (xb - 0.02, yb + H / 2)
        else:  # down a row: bottom to top
            start, end = (xa + W / 2, ya - 0.02), (xb + W / 2, yb + H + 0.02)
        ax.annotate("", end, start, arrowprops={"arrowstyle": "->"})
    ax.set_title("colourhs: one Snakemake rule per stage, files between stages", fontsize=10)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    for patch, text in texts:
        inner = patch.get_window_extent(renderer).padded(-2)
        got = text.get_window_extent(renderer)
        if not (
            inner.x0 <= got.x0 and got.x1 <= inner.x1 and inner.y0 <= got.y0 and got.y1 <= inner.y1
        ):
            raise ValueError(f"label {text.get_text()!r} spills out of its box")
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
