"""Exact data, then each nuisance alone, then all of them.

Run: ``.venv/bin/python benchmarks/nuisance_ladder.py [--seeds 1-3] [--size 320x240]``.

For every seed (a random rig of the ``random-tiny`` ranges at ``--size``) it
renders the plane and one frame of the sheet once per rung of a ladder and
reconstructs them with ML HS (``ml_full``) and Bayesian HS (``bayes_ph``;
``--variants`` adds e.g. ``bayes_nocalib``, the paper's Bayesian HS without
photometric calibration, to see which effect moves it):

- ``exact``: noise and cross-talk off, 16 bit, exact masks, the TRUE
  calibration (``gt/photometric.h5``; no cross-talk to undo): the same as
  ``tests/reconstruct/test_exact.py``.
- ``none``: every effect off but quantisation (:meth:`Nuisances.none`), the
  seed's own encoding (8 or 16 bit, its masks); from here on every
  calibration comes from the pipeline (marker poses, cross-talk with the
  LED factor, noise model, photometric maps), exactly as in
  :mod:`benchmarks.generalisation`.
- one rung per effect, alone on top of ``none``: ``light_falloff`` (the LED
  beams' shape), ``vignetting`` (with per-channel colour shading),
  ``gain_spread`` (per-camera, per-channel sensitivity), ``crosstalk`` (the
  filters' and LEDs' mixing, with the chromatic light's filter tilt),
  ``noise`` (shot and read noise), ``saturate``.
- ``all``: every effect on (the generalisation benchmark's setting).

A rung that adds error beyond its neighbours names the stage to look at.
Writes ``benchmarks/results/nuisance_ladder.csv`` (one row per seed x rung x
scene x variant: depth median, RMS, signed median (mm), normal median (deg),
coverage; mu RMS log error of the pipeline's maps against the truth, and of
mu = 1, what ``bayes_nocalib`` assumes, against the truth) and
prints a median-over-seeds table. Nothing in the pipeline sees the seed, the
rung or ``gt/`` (except the ``exact`` rung's calibration, on purpose).
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace
from pathlib import Path

import pandas as pd
from generalisation import calibrate, calibration_errors, evaluate_variant, seeds_in_temp

from colourhs.cli.commands import frame_indices as _seeds
from colourhs.workflow.variants import parse_variants

HERE = Path(__file__).parent
SCENES = ("plane", "sheet")
VARIANTS = ("ml_full", "bayes_ph")
EFFECTS = ("light_falloff", "vignetting", "gain_spread", "crosstalk", "noise", "saturate")


def rungs() -> list[tuple[str, object]]:
    """The ladder: (name, Nuisances), in order."""
    from colourhs.synth.simulated_rig import Nuisances

    none = Nuisances.none()
    full = Nuisances()
    out = [("exact", Nuisances().without("noise", "crosstalk")), ("none", none)]
    for effect in EFFECTS:
        on = {effect: getattr(full, effect)}
        if effect == "crosstalk":
            on["chromatic_filter_tilt"] = full.chromatic_filter_tilt
        out.append((effect, replace(none, **on)))
    return out + [("all", full)]


def run_rung(seed: int, preset, name: str, nuisances, root: Path, variants=VARIANTS) -> list[dict]:
    """One seed x rung: render, calibrate (or take the truth), reconstruct, evaluate."""
    from colourhs.synth.synthesise import DrawOverrides, RenderSelection, synthesise

    exact = name == "exact"
    t0 = time.time()
    data = synthesise(
        root / name / "data",
        preset,
        seed=seed,
        nuisances=nuisances,
        draw=DrawOverrides(exact=exact),
        selection=RenderSelection(scenes=SCENES),
    )
    files = calibrate(data, root / name / "calib")
    cal = calibration_errors(data, files)
    mu, mu_none = cal["mu_rms_log_worst"], cal["mu_uncalibrated_rms_log_worst"]
    if exact:
        files = {"photometric": data / "gt" / "photometric.h5", "crosstalk": None, "noise": None}
    rows = []
    for scene in SCENES:
        for variant in variants:
            m = evaluate_variant(
                data, scene, ["000000"], variant, files, None, root / name / "work"
            )
            rows.append(
                {
                    "seed": seed,
                    "rung": name,
                    "scene": scene,
                    "variant": variant,
                    "mu_rms_log_worst": mu,
                    "mu_uncalibrated_rms_log_worst": mu_none,
                    **m,
                }
            )
            print(
                f"seed {seed} {name:13s} {scene:6s} {variant:9s} depth {m['depth_median_mm']:.3f}"
                f" mm (signed {m['depth_signed_median_mm']:+.3f}) coverage {m['coverage']:.3f}"
                f" mu {mu:.4f} (uncalibrated {mu_none:.4f}) ({time.time() - t0:.0f} s)",
                flush=True,
            )
    return rows


def main(argv=None) -> pd.DataFrame:
    from colourhs.synth.synthesise import PRESETS

    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--seeds", default="1-3", help="seeds, e.g. 1-5 (default 1-3)")
    p.add_argument("--size", default="320x240", help="image size WxH (default 320x240)")
    p.add_argument("--rungs", default=None, help="comma-separated subset of the rungs")
    p.add_argument(
        "--variants",
        default=",".join(VARIANTS),
        help="comma-separated variants (default ml_full,bayes_ph; bayes_nocalib shows"
        " which effect breaks the ablation link ml_full > bayes_nocalib)",
    )
    args = p.parse_args(argv)
    variants = parse_variants(args.variants)
    w, h = (int(v) for v in args.size.lower().split("x"))
    preset = replace(PRESETS["random-tiny"], name="ladder", width=w, height=h, sheet_frames=1)
    chosen = [r for r in rungs() if args.rungs is None or r[0] in args.rungs.split(",")]
    out = HERE / "results" / "nuisance_ladder.csv"
    out.parent.mkdir(exist_ok=True)

    def run(seed, root):
        return [
            row
            for name, nuisances in chosen
            for row in run_rung(seed, preset, name, nuisances, root, variants)
        ]

    rows = seeds_in_temp(_seeds(args.seeds), "colourhs-ladder", run, out)
    table = pd.DataFrame(rows)
    order = {name: i for i, (name, _) in enumerate(rungs())}
    summary = (
        table.groupby(["rung", "scene", "variant"])["depth_median_mm"]
        .agg(["median", "max"])
        .unstack(["scene", "variant"])
        .sort_index(key=lambda idx: idx.map(order))
    )
    print(summary.round(3).to_string())
    return table


if __name__ == "__main__":
    main()
