"""Where a smooth surface's Bayesian depth offset comes from.

Run: ``.venv/bin/python benchmarks/depth_offsets.py [--seeds 1-4] [--modes exact,noise]
[--blur 1,0,1c,0c]``.

For every seed (a random rig of the ``random-tiny`` ranges at ``--size``, 7 board
poses: a different draw than ``tests/reconstruct/test_exact.py``'s 3-pose rigs) it renders the
plane and one sheet frame per mode, with the TRUE calibration
(``gt/photometric.h5``):

- ``exact``: noise and cross-talk off (16 bit, exact masks);
- ``noise``: cross-talk off, every other nuisance on (shot and read noise among
  them), so the only error beyond ``exact`` is the sensor's noise.

and reconstructs each with Bayesian HS for each Gaussian blur of the Helmholtz
sides (``reconstruct(..., blur_px=)``, :func:`colourhs.reconstruct.sides.side_maps`),
sampled bilinearly or, with a trailing ``c`` (``1c``), by cubic convolution
(:data:`colourhs.reconstruct.sides.ORDER` set to 3 for that variant).
Besides the depth errors it evaluates the consistency energy E
(:func:`colourhs.reconstruct.bayes.surface.hs_residuals`, one robust scale: the
truth's) on the same pixels at the truth, at the result, and at the result
moved along the rays to the truth's median depth. ``E(result) < E(truth)``
means the energy itself prefers the offset surface (the spline's shape freedom
fits noise or image-model errors: a bias of the estimator, not of the search);
``E(result) > E(truth)`` means the search stopped short of E's minimum.

Writes ``benchmarks/results/depth_offsets.csv`` and prints it.
"""

from __future__ import annotations

import argparse
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

from colourhs.cli.commands import frame_indices as _seeds

HERE = Path(__file__).parent
SCENES = ("plane", "sheet")


def nuisances(mode: str):
    """The synthetic rig's effects of a mode (see the module docstring)."""
    from colourhs.synth.simulated_rig import Nuisances

    return {
        "exact": Nuisances().without("noise", "crosstalk"),
        "noise": Nuisances().without("crosstalk"),
    }[mode]


def energies(frame, result, truth_depth, blur_px) -> dict:
    """E at the truth, at the result and at the result moved to the truth's median depth."""
    from scipy.ndimage import binary_erosion

    from colourhs.reconstruct.bayes.surface import SurfaceGraph, hs_residuals
    from colourhs.reconstruct.dataterm import pair_arrays
    from colourhs.reconstruct.frame import reference_rays
    from colourhs.reconstruct.sides import helmholtz_sides

    ref = frame.rig.camera(result.info["reference"])
    W, H = frame.rig.image.width, frame.rig.image.height
    mask = binary_erosion(result.mask & np.isfinite(truth_depth), iterations=2).ravel()
    zt = np.where(mask, truth_depth.ravel(), 0.0)
    graph = SurfaceGraph(mask, (H, W), zt, zt / ref.K[0, 0])
    rays = reference_rays(ref, W, H)[graph.pix]
    sides = helmholtz_sides(frame, frame.variance, pair_arrays(frame.rig), blur_px=blur_px)
    z_true = zt[graph.pix]
    z_res = result.depth.ravel()[graph.pix].astype(float)
    _, _, info = hs_residuals(z_true, graph, rays, sides, ref.centre, jacobian=False)
    out = {}
    moved = z_res - np.median(z_res - z_true)
    for name, z in (("E_truth", z_true), ("E_result", z_res), ("E_result_moved", moved)):
        _, rho, _ = hs_residuals(
            z, graph, rays, sides, ref.centre, jacobian=False, scale=info["scale"]
        )
        out[name] = float(np.nansum(rho))
    return out


def run_seed(seed: int, mode: str, preset, blurs, root: Path) -> list[dict]:
    """One seed x mode: render, then every scene x blur (a trailing ``c``: cubic sampling)."""
    import colourhs.reconstruct.sides as sides
    from colourhs.common.ply import load_mesh
    from colourhs.common.raycast import render_depth_normals
    from colourhs.reconstruct.frame import load_frame, reconstruct
    from colourhs.synth.synthesise import DrawOverrides, RenderSelection, synthesise

    data = synthesise(
        root / f"{mode}{seed}",
        preset,
        seed=seed,
        nuisances=nuisances(mode),
        draw=DrawOverrides(exact=True),
        selection=RenderSelection(parts=("photometric", "scenes"), scenes=SCENES),
    )
    rows = []
    for scene in SCENES:
        frame = load_frame(data, scene, "000000", photometric_h5=data / "gt" / "photometric.h5")
        mesh = load_mesh(data / "scenes" / scene / "gt" / "000000.ply")
        for label in blurs:
            # The sampler: the module's default, set for this variant only.
            sides.ORDER = 3 if label.endswith("c") else 1
            blur = float(label.rstrip("c"))
            res = reconstruct(frame, "bayes", blur_px=blur)
            ref = frame.rig.camera(res.info["reference"])
            gd, gn = render_depth_normals(*mesh, ref, frame.rig.image.width, frame.rig.image.height)
            m = res.mask & np.isfinite(gd)
            e = (res.depth[m] - gd[m]) * 1e3
            ang = np.degrees(np.arccos(np.clip(np.sum(res.normal[m] * gn[m], axis=1), -1, 1)))
            row = {"seed": seed, "mode": mode, "scene": scene, "blur_px": label}
            row |= {
                "depth_median_mm": float(np.median(np.abs(e))),
                "depth_signed_median_mm": float(np.median(e)),
                "depth_p90_mm": float(np.percentile(np.abs(e), 90)),
                "normal_median_deg": float(np.median(ang)),
                "coverage": float(m.sum() / np.isfinite(gd).sum()),
            }
            rows.append(row | energies(frame, res, gd, blur))
            print(
                pd.DataFrame([rows[-1]]).to_string(index=False, header=len(rows) == 1), flush=True
            )
    return rows


def main(argv=None) -> pd.DataFrame:
    from colourhs.synth.synthesise import PRESETS

    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--seeds", default="1-4", help="seeds, e.g. 1-4 (default 1-4)")
    p.add_argument("--modes", default="exact,noise", help="exact and/or noise (default both)")
    p.add_argument(
        "--blur", default="1,0", help="blurs of the sides, pixels, c: cubic (default 1,0)"
    )
    p.add_argument("--size", default="320x240", help="image size WxH (default 320x240)")
    args = p.parse_args(argv)
    width, height = (int(v) for v in args.size.split("x"))
    preset = replace(
        PRESETS["random-tiny"], name="offsets", width=width, height=height, sheet_frames=1
    )
    blurs = args.blur.split(",")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in _seeds(args.seeds):
            for mode in args.modes.split(","):
                rows += run_seed(seed, mode, preset, blurs, Path(tmp))
    table = pd.DataFrame(rows)
    out = HERE / "results" / "depth_offsets.csv"
    out.parent.mkdir(parents=True, exist_ok=True)
    table.to_csv(out, index=False)
    print(
        table.groupby(["mode", "scene", "blur_px"])[
            ["depth_median_mm", "depth_signed_median_mm"]
        ].median()
    )
    return table


if __name__ == "__main__":
    main()
