"""How far a known mu error moves ML and Bayesian HS (the ablation's
``ml_full > bayes_nocalib`` link).

Run: ``.venv/bin/python benchmarks/mu_sensitivity.py [--seeds 1-3]
[--errors 0,0.005,0.01,0.02,0.04,0.08]``.

For every seed it renders an exact random rig (the ``random-tiny`` ranges at
320 x 240, noise and cross-talk off, 16 bit, exact masks: ``tests/reconstruct/test_exact.py``'s
setting) with its plane and one sheet frame, and reconstructs both from the
TRUE mu maps (``gt/photometric.h5``, eqs. 6-8) with every map of the first
camera multiplied by ``1 + e``: the two reciprocal pairs with that camera
see a mu ratio error of ``e``, the third none. So the only error in the
data is a known photometric one. ``bayes_nocalib`` makes such an error on
purpose (it takes mu = 1, what the rig's mu would be if cameras and lights
were colour-balanced); ``benchmarks/generalisation.py`` records how far
each random rig is from that (``mu_uncalibrated_rms_log_worst``).

Writes ``benchmarks/results/mu_sensitivity.csv`` (seed, scene, method, e,
depth median / signed median / RMS in mm, normal median in deg) and prints a
median-over-seeds table.
"""

from __future__ import annotations

import argparse
import shutil
from dataclasses import replace
from pathlib import Path

import h5py
import pandas as pd
from generalisation import evaluate_variant, seeds_in_temp

from colourhs.cli.commands import frame_indices as _seeds

HERE = Path(__file__).parent
SCENES = ("plane", "sheet")
METHODS = {"bayes": "bayes_ph", "ml": "ml_full"}  # both with the given mu, no cross-talk


def scaled_mu(gt: Path, out: Path, camera: str, factor: float) -> Path:
    """A copy of the mu maps ``gt`` with every map of ``camera`` times ``factor``."""
    shutil.copy(gt, out)
    with h5py.File(out, "r+") as f:
        for key in f[camera]:
            f[camera][key][...] = f[camera][key][()] * factor
    return out


def run_seed(seed: int, errors, ml_errors, root: Path) -> list[dict]:
    from colourhs.capture import load_rig
    from colourhs.synth.synthesise import PRESETS, RenderSelection, synthesise_exact

    preset = replace(PRESETS["random-tiny"], name="musens", width=320, height=240, sheet_frames=1)
    selection = RenderSelection(parts=("photometric", "scenes"), scenes=SCENES)
    data = synthesise_exact(root / "data", preset, seed, selection)
    camera = load_rig(data).camera_names[0]
    rows = []
    for e in errors:
        mu = scaled_mu(data / "gt" / "photometric.h5", root / f"mu_{e}.h5", camera, 1.0 + e)
        files = {"photometric": mu, "crosstalk": None, "noise": None}
        for scene in SCENES:
            for method, variant in METHODS.items():
                if method == "ml" and e not in ml_errors:
                    continue
                work = root / f"work_{e}"
                m = evaluate_variant(data, scene, ["000000"], variant, files, None, work)
                rows.append(
                    {
                        "seed": seed,
                        "scene": scene,
                        "method": method,
                        "mu_error": e,
                        "depth_median_mm": m["depth_median_mm"],
                        "depth_signed_median_mm": m["depth_signed_median_mm"],
                        "depth_rms_mm": m["depth_rms_mm"],
                        "normal_median_deg": m["normal_median_deg"],
                    }
                )
                print(
                    f"seed {seed} {scene:5s} {method:5s} mu error {e:5.3f}: depth median"
                    f" {m['depth_median_mm']:.3f} mm (signed {m['depth_signed_median_mm']:+.3f},"
                    f" RMS {m['depth_rms_mm']:.3f}), normals {m['normal_median_deg']:.2f} deg",
                    flush=True,
                )
    return rows


def main(argv=None) -> pd.DataFrame:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--seeds", default="1-3", help="seeds, e.g. 1-5 (default 1-3)")
    p.add_argument(
        "--errors", default="0,0.005,0.01,0.02,0.04,0.08", help="mu errors e of one camera"
    )
    p.add_argument(
        "--ml-errors", default="0,0.04", help="the errors ML HS also runs at (it costs more)"
    )
    args = p.parse_args(argv)
    errors = [float(v) for v in args.errors.split(",")]
    ml_errors = {float(v) for v in args.ml_errors.split(",")}
    out = HERE / "results" / "mu_sensitivity.csv"
    out.parent.mkdir(exist_ok=True)
    rows = seeds_in_temp(
        _seeds(args.seeds),
        "colourhs-musens",
        lambda seed, root: run_seed(seed, errors, ml_errors, root),
        out,
    )
    table = pd.DataFrame(rows)
    summary = (
        table.groupby(["method", "scene", "mu_error"])[["depth_median_mm", "normal_median_deg"]]
        .agg(["median", "max"])
        .round(3)
    )
    print(summary.to_string())
    return table


if __name__ == "__main__":
    main()
