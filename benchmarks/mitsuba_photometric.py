"""Photometric calibration on board captures rendered by Mitsuba 3, against ground truth.

The calibration (paper section III-C) was written beside this project's own
renderer; this benchmark feeds it board poses that an independent renderer
made. For every seed it draws a ``random`` (or ``corner``) rig that Mitsuba's
camera and light can model (no lens distortion, square pixels, isotropic point
lights; light offsets ``--light-offset-mm``), renders its photometric
captures with :mod:`colourhs.synth.image_formation` and, for every ``--renders``
entry, again with Mitsuba (:mod:`colourhs.synth.mitsuba`), adding the same
channel sensitivity, cross-talk (off here, as in ``photometric_random``'s
``noxt``) and sensor noise (the same draw per image). Each dataset is
calibrated from its marker poses and scored against ``gt/photometric.h5``
like ``benchmarks/photometric_random.py``: the worst map's RMS log error (one
scale per pair removed), the pair ratio mu_a / mu_b on the held-out plane
pose, and the calibration's own check (the largest eq. (7) residual over the
part the noise explains; it warns above 1.3).

Renders (``--renders``, comma separated): ``ours``; ``diffuse-box`` (a
Lambertian board, box pixel filter: the same model as ours, so the two must
agree); ``diffuse-gaussian`` (Mitsuba's default pixel filter); ``glossy-box``
and ``glossy-gaussian`` (a white board under a GGX-rough dielectric coat,
``--roughness``: reciprocal, so with collocated lights eq. (6) still holds,
but its highlights saturate and with lights beside the lenses it breaks);
``spot-box`` (a Lambertian board lit by Mitsuba's spot lights along the
optical axes, ``--spot-rel CUTOFF,BEAM``: a profile flat to BEAM, then
linear in angle to zero at CUTOFF, both relative to the cameras' mean
half-diagonal field of view, so the kink falls inside the images on every
rig; no LED of the rig's own family has one; its true mu maps are written for
it); ``diffuse-floor`` (the Lambertian board above a white floor,
``--floor-rel`` of the working distance below the origin, path traced with
one bounce: light that reaches the board via the floor).

Run from the project root (needs ``pip install mitsuba``)::

    .venv/bin/python benchmarks/mitsuba_photometric.py --seeds 0-3
    .venv/bin/python benchmarks/mitsuba_photometric.py --seeds 0-3 --light-offset-mm 20,40

Writes ``benchmarks/results/mitsuba_photometric_<tag>.json`` (one row per
seed, render and map or pair) and prints the median and worst seed per render.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

from colourhs.calibration import photometric as ph
from colourhs.cli.commands import frame_indices

HERE = Path(__file__).parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
from photometric_random import poses_csvs, score  # noqa: E402

RENDERS = {
    "diffuse-box": dict(material="diffuse", pixel_filter="box"),
    "diffuse-gaussian": dict(material="diffuse", pixel_filter="gaussian"),
    "glossy-box": dict(material="roughplastic", pixel_filter="box"),
    "glossy-gaussian": dict(material="roughplastic", pixel_filter="gaussian"),
    "spot-box": dict(material="diffuse", pixel_filter="box", spot=True),
    "diffuse-floor": dict(material="diffuse", pixel_filter="box", floor=True),
}


def half_diagonal_deg(rig) -> float:
    """The cameras' mean angle between the optical axis and an image corner, degrees."""
    angles = [
        np.degrees(np.arctan(np.hypot(rig.width, rig.height) / 2 / cam.K[0, 0]))
        for cam in rig.cameras
    ]
    return float(np.mean(angles))


def render_ours(out: Path, preset, seed, nuis, ranges) -> Path:
    """Our renderer's photometric captures (and ground truth) of the seed."""
    from colourhs.synth.synthesise import DrawOverrides, RenderSelection, synthesise

    if not (out / "rig.json").exists():
        t = time.time()
        synthesise(
            out,
            preset,
            seed,
            nuis,
            selection=RenderSelection(parts=("photometric",)),
            draw=DrawOverrides(ranges=ranges),
            overwrite=True,
        )
        print(f"rendered {out.name} in {time.time() - t:.0f} s", flush=True)
    return out


def render_mitsuba(out: Path, ours: Path, d, seed: int, opts) -> Path:
    """A copy of ``ours`` whose photometric images Mitsuba rendered (cached)."""
    from colourhs.synth.mitsuba import photometric_dataset

    if not (out / "rig.json").exists():
        t = time.time()
        photometric_dataset(out, ours, d.rig, d.board, d.poses, seed, opts)
        print(f"rendered {out.name} with Mitsuba in {time.time() - t:.0f} s", flush=True)
    return out


def run(args) -> pd.DataFrame:
    from colourhs.synth.mitsuba import BoardRender, mitsuba_draw

    rows = []
    offset_m = tuple(x / 1000 for x in args.light_offset_mm)
    for seed in args.seeds:
        p, ranges, nuis, d = mitsuba_draw(args.preset, seed, light_offset_m=offset_m)
        tag = f"{args.preset}-{seed}-off{args.light_offset_mm[0]:g}-{args.light_offset_mm[1]:g}"
        ours = render_ours(args.root / f"{tag}-ours", p, seed, nuis, ranges)
        board_poses = json.loads((ours / "gt" / "board_poses.json").read_text())
        gt = {k: (np.array(v["R"]), np.array(v["t"])) for k, v in board_poses.items()}
        for name in args.renders:
            data = ours
            if name != "ours":
                kw = dict(RENDERS[name])
                if kw.pop("spot", False):
                    half = half_diagonal_deg(d.rig)
                    kw["spot_cutoff_deg"], kw["spot_beam_deg"] = (r * half for r in args.spot_rel)
                if kw.pop("floor", False):
                    distance = np.mean([np.linalg.norm(c.centre) for c in d.rig.cameras])
                    kw["floor_m"] = args.floor_rel * float(distance)
                opts = BoardRender(**kw, roughness=args.roughness, samples_per_pixel=args.spp)
                data = render_mitsuba(args.root / f"{tag}-{name}", ours, d, seed, opts)
            truth = ph.read_mu_maps(data / "gt" / "photometric.h5")
            csvs = poses_csvs(data, args.root / "work" / data.name)
            rig, views = ph.load_views(data, csvs["marker"], None)
            t = time.time()
            try:
                result = ph.calibrate(rig, views)
            except ValueError as e:  # the calibration refused the captures: a result too
                rows.append({"seed": seed, "render": name, "kind": "refused", "error": str(e)})
                print(f"seed {seed} {name:17s} refused: {e}", flush=True)
                continue
            maps, pairs = score(result, truth, rig, gt, [v.name for v in views])
            ratio = max(
                result["residual_rms"][k] / result["noise_rms"][k] for k in result["noise_rms"]
            )
            base = {
                "seed": seed,
                "render": name,
                "light_offset_mm": list(args.light_offset_mm),
                "seconds": time.time() - t,
                "residual_over_noise": ratio,
                "warned": bool(result["warnings"]),
            }
            rows += [base | {"kind": "map"} | r for r in maps]
            rows += [base | {"kind": "pair"} | r for r in pairs]
            worst = max(r["rms_log_error"] for r in maps)
            plane = max(r["rms_log_error"] for r in pairs if r["points"] == "plane")
            print(
                f"seed {seed} {name:17s} worst map {100 * worst:.2f} %, "
                f"plane pair ratio {100 * plane:.3f} %, residual over noise {ratio:.2f}",
                flush=True,
            )
    return pd.DataFrame(rows)


def summary(df: pd.DataFrame) -> pd.DataFrame:
    """Per render: median and worst seed of the worst map and of the plane's pair ratio,
    the range of the residual-over-noise check, and the seeds whose captures the
    calibration refused."""
    out = []
    for name, g in df.groupby("render", sort=False):
        refused = int((g.kind == "refused").sum())
        g = g[g.kind != "refused"]
        m = g[g.kind == "map"].groupby("seed").rms_log_error.max()
        pr = g[(g.kind == "pair") & (g.points == "plane")].groupby("seed").rms_log_error.max()
        q = g.groupby("seed").residual_over_noise.max()
        out.append(
            {
                "render": name,
                "seeds": m.size,
                "refused": refused,
                "worst_map_median_%": 100 * m.median(),
                "worst_map_worst_%": 100 * m.max(),
                "pair_ratio_plane_median_%": 100 * pr.median(),
                "pair_ratio_plane_worst_%": 100 * pr.max(),
                "residual_over_noise_min": q.min(),
                "residual_over_noise_max": q.max(),
            }
        )
    return pd.DataFrame(out)


def main(argv=None) -> pd.DataFrame:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=frame_indices, default=frame_indices("0-3"))
    ap.add_argument("--preset", choices=("random", "corner", "random-tiny"), default="random")
    ap.add_argument(
        "--renders",
        type=lambda s: s.split(","),
        default=["ours", *RENDERS],
        help="ours and any of " + ", ".join(RENDERS),
    )
    ap.add_argument(
        "--light-offset-mm",
        type=lambda s: tuple(float(x) for x in (s.split(",") * 2)[:2]),
        default=(0.0, 0.0),
        help="range A,B of the lights' distance from the lens centres (mm)",
    )
    ap.add_argument(
        "--spot-rel",
        type=lambda s: tuple(float(x) for x in s.split(",")),
        default=(1.5, 0.5),
        help="spot-box's cutoff and beam width, of the cameras' half-diagonal field of view",
    )
    ap.add_argument(
        "--floor-rel",
        type=float,
        default=0.3,
        help="diffuse-floor's floor below the origin, of the working distance",
    )
    ap.add_argument("--roughness", type=float, default=0.2, help="GGX alpha of the glossy coat")
    ap.add_argument("--spp", type=int, default=16, help="Mitsuba's samples per pixel")
    ap.add_argument("--root", type=Path, default=ROOT / "data" / "mitsuba_photometric")
    ap.add_argument("--tag", default=None)
    args = ap.parse_args(argv)
    unknown = set(args.renders) - {"ours", *RENDERS}
    if unknown:
        ap.error(f"unknown renders {sorted(unknown)}")
    df = run(args)
    a, b = args.light_offset_mm
    tag = args.tag or f"{args.preset}_offset{a:g}-{b:g}"
    (HERE / "results").mkdir(exist_ok=True)
    path = HERE / "results" / f"mitsuba_photometric_{tag}.json"
    path.write_text(df.to_json(orient="records", indent=1))
    with pd.option_context("display.width", 200, "display.max_columns", 20):
        print(summary(df).round(3).to_string(index=False))
    print(f"wrote {path}")
    return df


if __name__ == "__main__":
    main(sys.argv[1:])
