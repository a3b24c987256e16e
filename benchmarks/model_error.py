"""Bias and scatter under sensor noise on a scene that breaks eq. (4), and the error bar.

Run: ``.venv/bin/python benchmarks/model_error.py [--seeds 0-2] [--size 640x480]
[--noise 0,0.5,1,2] [--realisations 3] [--scene cloth]``.

For every seed, one frame (``--frame``, default 0) of a random-dynamic scene
(default the cloth: a white-specular dielectric over coloured patches, whose
white highlight breaks eq. (4)'s one p per surface point) is rendered without
noise or cross-talk (16 bit, exact masks) and reconstructed with Bayesian HS,
the TRUE mu (``gt/photometric.h5``) and the TRUE p of that frame, so what is
left is the scene against the model. Sensor noise is then added as the renderer
makes it (:func:`colourhs.synth.simulated_rig.sensor`: Poisson electrons and
Gaussian read noise, unquantised), its full well divided by k^2 and its read
noise by k for each level k of ``--noise``, ``--realisations`` times, with the
noise model given exactly. Noise may widen the scatter; it must not move the
expectation, and the error bar must cover both.

Writes ``benchmarks/results/model_error{--tag}.csv``: one row per seed x level x
realisation with the depth median, signed median and p95 (mm), the median
``depth_sigma`` (mm), the shares within 1, 2 and 3 sigma, the coverage and the
largest per-surface ``robust_pull_m`` (mm); and prints, per seed and level, the
bias (median over pixels of the realisations' mean error) beside the scatter
(median absolute deviation of a realisation from that mean).
"""

from __future__ import annotations

import argparse
import copy
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
from generalisation import seeds_in_temp

from colourhs.cli.commands import frame_indices

HERE = Path(__file__).parent


def render(root: Path, seed: int, scene: str, frame: int, size: tuple[int, int]) -> Path:
    """One frame of a random-dynamic scene without noise or cross-talk (exact draw)."""
    from colourhs.synth.synthesise import PRESETS, RenderSelection, synthesise_exact

    w, h = size
    preset = replace(PRESETS["random-dynamic"], name=f"random-dynamic-{w}", width=w, height=h)
    parts = ("photometric", "chromatic", "scenes")
    selection = RenderSelection(parts=parts, scenes=(scene,), frames=[frame])
    return synthesise_exact(root / "data", preset, seed, selection, workers=2)


def noisy(frame, nuisances, k: float, rng):
    """The frame with the renderer's sensor noise at level ``k`` and its exact variance."""
    from colourhs.synth.simulated_rig import sensor

    n = replace(
        nuisances,
        full_well_e=nuisances.full_well_e / k**2,
        read_noise_e=nuisances.read_noise_e / k,
        quantise=False,
        saturate=False,
    )
    white = 2.0**16 - 1
    out = copy.copy(frame)
    out.images = (sensor(frame.images, rng, n) / white).astype(frame.images.dtype)
    variance = np.clip(out.images, 0, None) / n.full_well_e + (n.read_noise_e / n.full_well_e) ** 2
    out.variance = variance.astype(np.float32)
    return out


def run_seed(seed: int, root: Path, args) -> list[dict]:
    from colourhs.common.ply import load_mesh
    from colourhs.common.raycast import render_depth_normals
    from colourhs.reconstruct.frame import load_frame, reconstruct
    from colourhs.synth.simulated_rig import Nuisances

    name = f"{args.frame:06d}"
    data = render(root, seed, args.scene, args.frame, args.size)
    truth_p = data / "scenes" / args.scene / "gt" / "chromaticity" / f"{name}.h5"
    exact = load_frame(
        data,
        args.scene,
        name,
        photometric_h5=data / "gt" / "photometric.h5",
        chromaticity_h5=truth_p,
    )
    model = json.loads((data / "gt" / "rig_model.json").read_text())["nuisances"]
    nuisances = replace(
        Nuisances(), full_well_e=model["full_well_e"], read_noise_e=model["read_noise_e"]
    )
    ref = exact.rig.cameras[0]
    mesh = load_mesh(data / "scenes" / args.scene / "gt" / f"{name}.ply")
    truth, _ = render_depth_normals(*mesh, ref, *args.size)
    rows = []
    for k in args.noise:
        errors = []
        for r in range(args.realisations if k else 1):
            frame = noisy(exact, nuisances, k, np.random.default_rng([seed, r])) if k else exact
            res = reconstruct(frame, "bayes")
            m = res.mask & np.isfinite(truth)
            err = (res.depth - truth) * 1e3
            errors.append(np.where(m, err, np.nan))
            ratio = np.abs(err[m]) / (res.depth_sigma[m] * 1e3)
            pulls = [p for p in res.info["surface"].get("robust_pull_m", []) if p is not None]
            rows.append(
                {
                    "seed": seed,
                    "scene": args.scene,
                    "frame": args.frame,
                    "noise_k": k,
                    "realisation": r,
                    "depth_median_mm": float(np.median(np.abs(err[m]))),
                    "depth_signed_median_mm": float(np.median(err[m])),
                    "depth_p95_mm": float(np.percentile(np.abs(err[m]), 95)),
                    "depth_sigma_median_mm": float(np.median(res.depth_sigma[m]) * 1e3),
                    **{f"sigma_within_{c}": float(np.mean(ratio <= c)) for c in (1, 2, 3)},
                    "coverage": float(m.sum() / np.isfinite(truth).sum()),
                    "robust_pull_max_mm": max(pulls) * 1e3 if pulls else None,
                }
            )
            print(
                f"seed {seed} k {k} r {r}: depth {rows[-1]['depth_median_mm']:.3f} mm "
                f"(signed {rows[-1]['depth_signed_median_mm']:+.3f}), sigma "
                f"{rows[-1]['depth_sigma_median_mm']:.3f} mm, within 1/2/3 sigma "
                + " ".join(f"{rows[-1][f'sigma_within_{c}']:.2f}" for c in (1, 2, 3)),
                flush=True,
            )
        if len(errors) > 1:
            e = np.stack(errors)
            both = np.all(np.isfinite(e), axis=0)
            mean = e[:, both].mean(axis=0)
            print(
                f"seed {seed} k {k}: bias {np.median(np.abs(mean)):.3f} mm, scatter "
                f"{np.median(np.abs(e[:, both] - mean)):.3f} mm",
                flush=True,
            )
    return rows


def main(argv=None) -> pd.DataFrame:
    from colourhs.common.progress import show_progress

    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--seeds", default="0", help="seeds, e.g. 0-2 or 1,3 (default 0)")
    p.add_argument("--scene", default="cloth", help="a random-dynamic scene (default cloth)")
    p.add_argument("--frame", type=int, default=0, help="the frame (default 0)")
    p.add_argument("--size", default="640x480", help="image size WxH (default 640x480)")
    p.add_argument("--noise", default="0,1", help="noise levels k (default 0,1)")
    p.add_argument("--realisations", type=int, default=3, help="per noisy level (default 3)")
    p.add_argument("--tag", default="", help="suffix of the output file")
    args = p.parse_args(argv)
    args.size = tuple(int(v) for v in args.size.lower().split("x"))
    args.noise = [float(v) for v in args.noise.split(",")]
    show_progress()
    out = HERE / "results"
    out.mkdir(exist_ok=True)
    csv = out / f"model_error{args.tag}.csv"
    rows = seeds_in_temp(
        frame_indices(args.seeds), "model-error", lambda s, root: run_seed(s, root, args), csv
    )
    table = pd.DataFrame(rows)
    print(table.groupby("noise_k")[["depth_median_mm", "sigma_within_3"]].median().to_string())
    return table


if __name__ == "__main__":
    main()
