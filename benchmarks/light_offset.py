"""What lights beside the lenses cost: the same rig and scenes with the light offset swept.

Run: ``.venv/bin/python benchmarks/light_offset.py [--preset corner] [--seeds 1,5]
[--offsets-mm 0,2,5,10,20,40] [--scenes sheet,statue,plane]``.

Helmholtz reciprocity (eq. 3) equates the BRDF of a reciprocal pair's two
readings only when each light sits at its camera's centre. With a light
beside the lens the two readings see the surface at half-vectors
:func:`colourhs.common.geometry.half_vector_defect` apart, which leaves matte
surfaces exact and moves glossy ones. For every seed of ``--preset`` the
rig, board, scenes and materials are drawn once; only the lights' offset
from the lens changes (the same directions, every camera's offset of each
magnitude in ``--offsets-mm``). To isolate that one effect every render has
sensor noise (the seed's sensor) but no cross-talk, and the reconstruction
has the TRUE calibration: mu maps (``gt/photometric.h5``, which with an
offset light are exact at the scene's depth only) and, for the coloured
statue, chromaticity; the noise model is the pipeline's
(:func:`colourhs.calibration.noise.calibrate_noise` on the board poses).

``--described-mm 0,10,20,30`` measures what a WRONG description costs: each
render keeps its true offset while the reconstruction reads a rig.json whose
lights sit at the described offset instead (the same directions; 0: the offset
ignored), so the depth and normal errors beyond the true description's are
the cost of measuring the offset that badly.

Writes ``benchmarks/results/light_offset.csv`` (with ``--described-mm``,
``light_offset_described.csv``, with a ``described_offset_mm`` column): one row
per seed x offset x scene with the rig's largest half-vector defect at its
fixation point (degrees), the median over the reconstructed points of each
point's largest pair defect, the depth median, signed median and RMS (mm), the
normals' median error (degrees), the median ``depth_sigma`` (mm), the shares of
pixels within 1 and 2 sigma, the coverage; and prints a median-over-seeds table.
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
from generalisation import seeds_in_temp

from colourhs.cli.commands import frame_indices
from colourhs.common.progress import show_progress

HERE = Path(__file__).parent
#: Scene -> the Bayesian variant a rig owner runs on it (white: bayes_ph; coloured:
#: bayes_full, here with the true chromaticity).
VARIANT = {"plane": "bayes_ph", "sheet": "bayes_ph", "statue": "bayes_full"}


def described_view(data: Path, offset_m: float) -> Path:
    """A view of dataset ``data`` (its folders linked) whose rig.json puts every light
    ``offset_m`` beside its lens in the direction the true offset has (0: at the lens)."""
    import json

    view = data.parent / f"{data.name}-described-{offset_m * 1e3:g}mm"
    view.mkdir(exist_ok=True)
    for entry in data.iterdir():
        if entry.name not in ("rig.json", "out") and not (view / entry.name).exists():
            (view / entry.name).symlink_to(entry)
    rig = json.loads((data / "rig.json").read_text())
    for cam in rig["cameras"]:
        true = np.asarray(cam["light"].get("offset", [0.0, 0.0, 0.0]), float)
        norm = float(np.linalg.norm(true))
        cam["light"]["offset"] = (true / norm * offset_m if norm else true).tolist()
    (view / "rig.json").write_text(json.dumps(rig))
    return view


def run_offset(
    seed: int, preset, offset_m: float, scenes, root: Path, described_m=(None,)
) -> list[dict]:
    """Render the seed's draw with every light ``offset_m`` beside its lens, reconstruct
    each scene with the true calibration (under a rig.json that describes the lights at
    each offset of ``described_m``; None: the true one), and measure it against the
    ground truth."""
    from colourhs.calibration.noise import calibrate_noise
    from colourhs.capture import load_rig
    from colourhs.synth.randomranges import RANGES_BY_NAME
    from colourhs.synth.simulated_rig import Nuisances
    from colourhs.synth.synthesise import DrawOverrides, RenderSelection, synthesise

    ranges = replace(RANGES_BY_NAME[preset.random_ranges], light_offset_m=(offset_m, offset_m))
    data = root / f"offset-{offset_m * 1e3:g}mm"
    synthesise(
        data,
        preset,
        seed=seed,
        nuisances=Nuisances().without("crosstalk"),
        # the capture format needs board poses, a coloured scene its chromatic captures
        selection=RenderSelection(
            parts=("photometric", "scenes", *(("chromatic",) if "statue" in scenes else ())),
            scenes=tuple(scenes),
        ),
        draw=DrawOverrides(ranges=ranges),
    )
    noise = data / "noise.json"
    calibrate_noise(data, noise)
    rig = load_rig(data)
    at_fixation = float(np.degrees(rig.reciprocity_defect(rig.fixation_point()).max()))
    rows = []
    for described in described_m:
        view = data if described is None else described_view(data, described)
        for row in _reconstruct_scenes(view, data, rig, scenes, noise):
            rows.append(
                {"preset": preset.name, "seed": seed, "offset_mm": offset_m * 1e3}
                | ({} if described is None else {"described_offset_mm": described * 1e3})
                | {"defect_fixation_deg": at_fixation}
                | row
            )
            print(
                f"seed {seed} offset {offset_m * 1e3:g} mm"
                + ("" if described is None else f" described {described * 1e3:g} mm")
                + f" {row['scene']}: depth median {row['depth_median_mm']:.3f} mm (signed "
                f"{row['depth_signed_median_mm']:+.3f}), normal {row['normal_median_deg']:.2f} "
                f"deg, sigma {row['depth_sigma_median_mm']:.3f} mm",
                flush=True,
            )
    return rows


def _reconstruct_scenes(view: Path, data: Path, rig, scenes, noise: Path) -> list[dict]:
    """Each scene of ``view`` reconstructed with the true calibration of ``data`` and
    measured against its ground truth (``rig``: the true rig)."""
    from colourhs.common.depthfile import read_depth
    from colourhs.common.ply import load_mesh
    from colourhs.evaluation.depth_errors import depth_errors
    from colourhs.reconstruct.frame import reconstruct_frame
    from colourhs.reconstruct.inputs import CalibrationFiles

    rows = []
    for scene in scenes:
        variant = VARIANT[scene]
        kw = {"photometric_h5": data / "gt" / "photometric.h5", "noise_json": noise}
        chroma = data / "scenes" / scene / "gt" / "chromaticity.h5"
        if variant == "bayes_full" and chroma.exists():
            kw["chromaticity_h5"] = chroma
        h5 = data / "out" / view.name / scene / f"{variant}.h5"
        reconstruct_frame(view, scene, "000000", h5, "bayes", CalibrationFiles(**kw))
        depth = read_depth(h5)
        gt = load_mesh(data / "scenes" / scene / "gt" / "000000.ply")
        err, ang, m = depth_errors(depth, *gt, rig.image.width, rig.image.height)
        ok = np.isfinite(err)
        e = err[ok] * 1e3
        sigma = np.asarray(depth.depth_sigma, float)[ok] * 1e3
        rows.append(
            {
                "scene": scene,
                "variant": variant,
                "defect_points_deg": _points_defect(rig, depth),
                "depth_median_mm": float(np.median(np.abs(e))),
                "depth_signed_median_mm": float(np.median(e)),
                "depth_rms_mm": float(np.sqrt(np.mean(e * e))),
                "depth_sigma_median_mm": float(np.nanmedian(sigma)),
                "sigma_within_1": float(np.mean(np.abs(e) <= sigma)),
                "sigma_within_2": float(np.mean(np.abs(e) <= 2 * sigma)),
                "normal_median_deg": float(np.nanmedian(np.asarray(ang)[ok])),
                "coverage": float(ok.sum() / m["truth_pixels"]),
            }
        )
    return rows


def _points_defect(rig, depth) -> float:
    """Median over the reconstructed points of each point's largest pair defect, degrees."""
    from colourhs.surfaces.poisson import oriented_points

    X, _ = oriented_points(depth)
    return float(np.degrees(np.median(rig.reciprocity_defect(X).max(axis=0))))


def main(argv=None) -> pd.DataFrame:
    from colourhs.synth.synthesise import PRESETS

    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--preset", default="corner", help="a randomised preset (default corner)")
    p.add_argument("--seeds", default="1,5", help="seeds, e.g. 1-3 or 1,5 (default 1,5)")
    p.add_argument("--offsets-mm", default="0,2,5,10,20,40", help="light offsets, mm")
    p.add_argument("--scenes", default="sheet,statue,plane", help="of plane, sheet, statue")
    p.add_argument(
        "--described-mm",
        default=None,
        help="light offsets rig.json states, mm (each render keeps its true offset)",
    )
    args = p.parse_args(argv)
    show_progress()  # the calibration stages' progress on stderr, as the CLI shows it
    preset = replace(PRESETS[args.preset], sheet_frames=1)
    offsets = [float(v) * 1e-3 for v in args.offsets_mm.split(",")]
    scenes = args.scenes.split(",")
    described = (None,)
    if args.described_mm is not None:
        described = tuple(float(v) * 1e-3 for v in args.described_mm.split(","))
    name = "light_offset.csv" if described == (None,) else "light_offset_described.csv"
    out = HERE / "results" / name
    out.parent.mkdir(exist_ok=True)

    def run(seed, root):
        return [
            row for o in offsets for row in run_offset(seed, preset, o, scenes, root, described)
        ]

    rows = seeds_in_temp(frame_indices(args.seeds), "colourhs-offset", run, out)
    table = pd.DataFrame(rows)
    cols = ["defect_points_deg", "depth_median_mm", "depth_signed_median_mm"]
    cols += ["normal_median_deg", "depth_sigma_median_mm", "sigma_within_1"]
    keys = ["scene", "offset_mm", *(["described_offset_mm"] if described != (None,) else [])]
    print(table.groupby(keys)[cols].median().round(3).to_string())
    return table


if __name__ == "__main__":
    main()
