"""Speed and memory of the reconstruction stage (never a timed test).

Run after the calibration stages (``.venv/bin/snakemake --cores 2``):
``.venv/bin/python benchmarks/bench_reconstruct.py [--scene plane]``. Writes
``benchmarks/results/reconstruct_demo.json``: data-term throughput (pixel
hypotheses per second, over the foreground and over the whole frame; best
and median of ``--repeat`` runs), the
wall time of a whole Bayesian frame at 640x480 with 192 labels, and the
peak resident memory of the process. Targets: at least 60 million
pixel-hypotheses per second and a whole frame in at most 10 s and 2 GB on
2 cores. The same data term written plainly in NumPy (the tests' oracle,
``tests/hs_constraint.py``) runs on the same 2,000 foreground pixels and
hypotheses, and the ratio of the two rates is reported.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import time
from pathlib import Path

import numba
import numpy as np

from colourhs.reconstruct.dataterm import data_term, pair_arrays, prepare_images
from colourhs.reconstruct.frame import load_frame, reconstruct, reference_rays, working_depth

HERE = Path(__file__).parent
sys.path.insert(0, str(HERE.parent / "tests"))
from hs_constraint import numpy_data_term  # noqa: E402  (the tests' oracle)


def rates(run, hypotheses: int, repeat: int) -> dict:
    """Million pixel-hypotheses per second of ``repeat`` runs: best and median
    (a shared machine's other load only ever slows a run down)."""
    seconds = []
    for _ in range(repeat):
        t = time.perf_counter()
        run()
        seconds.append(time.perf_counter() - t)
    mhyp = hypotheses / np.array(seconds) / 1e6
    return {"best": round(float(mhyp.max()), 1), "median": round(float(np.median(mhyp)), 1)}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--dataset", default="data/synthetic/demo")
    ap.add_argument("--scene", default="plane")
    ap.add_argument("--labels", type=int, default=192)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    name = Path(args.dataset).name
    cal = Path("results") / name / "calib"
    frame = load_frame(
        args.dataset, args.scene, "000000", cal / "crosstalk.json", cal / "photometric.h5"
    )
    rig = frame.rig
    ref = rig.cameras[0]
    W, H = rig.image.width, rig.image.height
    rays = reference_rays(ref, W, H)
    zc = working_depth(rig, ref)
    depths = np.linspace(zc - 0.15, zc + 0.15, args.labels)
    pairs = pair_arrays(rig)
    prepared = prepare_images(frame.images, frame.saturated, pairs, frame.mu, None, None)
    data_term(rays[:64], ref.centre, depths, rig.cameras, prepared, pairs)  # JIT warm-up
    chunk = rays[: 16384 * 4]
    whole = rates(
        lambda: data_term(chunk, ref.centre, depths, rig.cameras, prepared, pairs),
        len(chunk) * len(depths),
        args.repeat,
    )
    fg = prepare_images(frame.images, frame.saturated, pairs, frame.mu, None, frame.silhouettes)
    sil = frame.silhouettes[0].ravel() if frame.silhouettes is not None else np.ones(H * W, bool)
    sel = rays[sil][: 16384 * 4]
    fg_rate = rates(
        lambda: data_term(sel, ref.centre, depths, rig.cameras, fg, pairs),
        len(sel) * len(depths),
        args.repeat,
    )
    few = sel[:2000]
    plain = rates(
        lambda: numpy_data_term(few, ref.centre, depths, rig.cameras, fg, pairs),
        len(few) * len(depths),
        1,
    )
    compiled = rates(
        lambda: data_term(few, ref.centre, depths, rig.cameras, fg, pairs),
        len(few) * len(depths),
        args.repeat,
    )
    reconstruct(frame, "bayes", n_labels=args.labels)  # warm-up of every kernel
    t = time.perf_counter()
    res = reconstruct(frame, "bayes", n_labels=args.labels)
    frame_s = time.perf_counter() - t
    result = {
        "dataset": args.dataset,
        "scene": args.scene,
        "image": [W, H],
        "labels": args.labels,
        "threads": numba.get_num_threads(),
        "cpu_count": os.cpu_count(),
        "repeats": args.repeat,
        "dataterm_mhyp_per_s_rows_of_frame": whole,
        "dataterm_mhyp_per_s_foreground": fg_rate,
        "numpy_reference_mhyp_per_s": plain["best"],
        "compiled_on_the_same_2000_pixels_mhyp_per_s": compiled,
        "speedup_over_numpy_reference": round(compiled["best"] / plain["best"], 1),
        "bayes_frame_s": round(frame_s, 2),
        "bayes_frame_pixels": res.info["pixels"],
        "peak_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
    }
    (HERE / "results").mkdir(exist_ok=True)
    (HERE / "results" / f"reconstruct_{Path(args.dataset).name}.json").write_text(
        json.dumps(result, indent=2)
    )
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
