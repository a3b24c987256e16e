"""Command line: ``colourhs run`` (the whole workflow) and one subcommand per stage.

Each stage subcommand calls one function of the package; the Snakemake rules
call these subcommands.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import yaml

from colourhs.capture import validate

PROJECT_ROOT = Path(__file__).resolve().parents[1]
SNAKEFILE = PROJECT_ROOT / "Snakefile"
NUISANCE_SWITCHES = ("light_falloff", "vignetting", "crosstalk", "noise", "saturate")


def _synth(args) -> int:
    from colourhs.synth.dataset import PRESETS, synthesise
    from colourhs.synth.rig import Nuisances

    if args.preset not in PRESETS:
        print(f"colourhs synth: unknown preset {args.preset!r}; choose from {sorted(PRESETS)}")
        return 2
    nuisances = Nuisances().without(*args.off)
    synthesise(
        args.out,
        args.preset,
        seed=args.seed,
        nuisances=nuisances,
        overwrite=args.overwrite,
        workers=args.workers,
    )
    print(f"wrote {args.out}")
    return 0


def _validate(args) -> int:
    summary = validate(args.dataset, args.summary)
    print(json.dumps(summary, indent=2))
    return 0


def _run(args) -> int:
    dataset = Path(args.dataset).resolve()
    if not (dataset / "rig.json").exists():
        print(f"colourhs run: {dataset / 'rig.json'}: missing (not a capture-format dataset)")
        return 2
    name = args.name or dataset.name
    config_path = Path(args.directory) / "results" / name / "run-config.yaml"
    config_path.parent.mkdir(parents=True, exist_ok=True)
    config = {"datasets": {name: {"path": str(dataset)}}, "only": [name]}
    if args.variants:
        config["reconstruction"] = {"variants": [v.strip() for v in args.variants.split(",")]}
    config_path.write_text(yaml.safe_dump(config))
    # Snakemake's own arguments (targets included) go before --configfile,
    # whose list of files would otherwise swallow them.
    cmd = [
        sys.executable, "-m", "snakemake", "--snakefile", str(SNAKEFILE),
        "--directory", str(Path(args.directory).resolve()), "--cores", str(args.cores),
        *args.snakemake_args,
        "--configfile", str(PROJECT_ROOT / "config.yaml"), str(config_path.resolve()),
    ]  # fmt: skip
    return subprocess.call(cmd)


def _markers(args) -> int:
    from colourhs.markers import marker_poses

    table = marker_poses(args.dataset, args.out, min_markers=args.min_markers)
    print(f"wrote {args.out}: {len(table)} board poses, rms <= {table['rms_px'].max():.3f} px")
    return 0


def _noise(args) -> int:
    from colourhs.noise import calibrate_noise

    model = calibrate_noise(args.dataset, args.out)
    for cam, gain in model.gain.items():
        wells = ", ".join(f"{1 / g:.0f}" if g > 0 else "-" for g in gain)
        print(f"{cam}: full well (electrons per full scale, R G B) {wells}")
    print(f"wrote {args.out}")
    return 0


def _crosstalk(args) -> int:
    from colourhs.crosstalk import calibrate_crosstalk

    result = calibrate_crosstalk(args.dataset, args.out, poses_csv=args.poses)
    print(json.dumps(result, indent=2))
    return 0


def _photometric(args) -> int:
    from colourhs.photometric import photometric_maps

    params = {k: v for k, v in vars(args).items() if k in PHOTOMETRIC_PARAMS and v is not None}
    result = photometric_maps(
        args.dataset, args.poses, args.out, args.crosstalk, args.figure, **params
    )
    for key, n in result["counts"].items():
        rms = result["residual_rms"][key]
        print(f"{key}: {n} eq. (7) constraints, residual RMS {rms:.4f} (log mu)")
    print(f"wrote {args.out}")
    return 0


def _chromaticity(args) -> int:
    import numpy as np

    from colourhs.chromaticity import chromaticity_maps

    maps = chromaticity_maps(
        args.dataset, args.object, args.out, figure_png=args.figure, min_signal=args.min_signal
    )
    for camera, p in maps.items():
        print(f"{camera}: {int(np.isfinite(p[..., 0]).sum())} pixels with a chromaticity")
    print(f"wrote {args.out}")
    return 0


def _reconstruct(args) -> int:
    from colourhs.reconstruct.frame import reconstruct_frame

    params = {k: v for k, v in vars(args).items() if k in RECONSTRUCT_PARAMS and v is not None}
    params["progress"] = sys.stderr.isatty()  # a bar at a terminal, none in a rule's log
    result = reconstruct_frame(
        args.dataset, args.scene, args.frame, args.out, args.method, args.crosstalk,
        args.photometric, args.chromaticity, args.hull, noise_json=args.noise, **params,
    )  # fmt: skip
    info = result.info
    print(f"{args.scene}/{args.frame} {args.method}: {info['valid_pixels']} of {info['pixels']} "
          f"pixels, energy {info.get('energy', '-')}; wrote {args.out}")  # fmt: skip
    return 0


def _pairs(items: list[str], what: str) -> dict[str, str]:
    """``KEY=VALUE`` arguments as an ordered dict."""
    out = {}
    for item in items or []:
        key, sep, value = item.partition("=")
        if not sep or not key or not value:
            raise ValueError(f"{what}: expected KEY=PATH, got {item!r}")
        out[key] = value
    return out


def _hull(args) -> int:
    from colourhs.hull import visual_hull

    info = visual_hull(args.dataset, args.scene, args.frame, args.out, voxel_m=args.voxel_m,
                       threshold=args.threshold, out_depth_h5=args.depth)  # fmt: skip
    print(json.dumps(info, indent=2, default=str))
    return 0


def _mesh(args) -> int:
    from colourhs.mesh import frame_mesh

    info = frame_mesh(args.depth, args.out, hull_ply=args.hull, poisson_depth=args.poisson_depth,
                      density_quantile=args.density_quantile)  # fmt: skip
    print(json.dumps(info, indent=2, default=str))
    return 0


def _evaluate(args) -> int:
    from colourhs.evaluate import evaluate_frame

    info = evaluate_frame(args.depth, args.mesh, args.gt, args.out, out_ply=args.coloured,
                          scene=args.scene, frame=args.frame, variant=args.variant,
                          vmax_mm=args.vmax_mm)  # fmt: skip
    print(json.dumps(info, indent=2, default=str))
    return 0


def _metrics(args) -> int:
    from colourhs.evaluate import metrics_table

    table = metrics_table(args.json, args.out)
    print(f"wrote {args.out}: {len(table)} rows")
    return 0


def _figures(args) -> int:
    from colourhs.figures import scene_figures

    written = scene_figures(args.out, _pairs(args.depth, "--depth"), _pairs(args.mesh, "--mesh"),
                            args.gt, _pairs(args.animate, "--animate"),
                            coloured=_pairs(args.coloured, "--coloured"))  # fmt: skip
    print(f"wrote {len(written)} figures into {args.out}")
    return 0


def _report(args) -> int:
    from colourhs.report import build_report, find_benchmarks

    figures = _pairs(args.figures, "--figures")
    tsvs = find_benchmarks(args.benchmarks, args.name)
    config = args.config if args.config else {}
    build_report(args.out, args.name, args.metrics, args.calibration or [], figures, tsvs, config)
    print(f"wrote {args.out}")
    return 0


def _config(args) -> int:
    from colourhs.io import atomic_output

    with atomic_output(args.out) as tmp:
        tmp.write_text(yaml.safe_dump(json.loads(args.json)))
    print(f"wrote {args.out}")
    return 0


RECONSTRUCT_PARAMS = {"reference": str, "n_labels": int, "alpha": float, "tau": float,
                      "working_radius": float, "working_radius_m": float,
                      "data_weight": float, "max_cost": float, "cost_scale": float,
                      "erode_px": int, "edge_m": float,
                      "refine_passes": int, "min_component": int, "link_m": float,
                      "surface_iterations": int, "spline_px": float}  # fmt: skip

PHOTOMETRIC_PARAMS = ("grid_spacing_px", "step_px", "smoothness", "coupling", "margin_m",
                      "min_cos", "min_signal")  # fmt: skip


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="colourhs", description=__doc__)
    sub = p.add_subparsers(dest="command", required=True)

    s = sub.add_parser("synth", help="render a synthetic dataset in the capture format")
    s.add_argument("out", type=Path, help="dataset folder to create")
    s.add_argument(
        "--preset",
        default="demo",
        help="tiny, demo, paper, random or random-tiny (default demo); the random presets "
        "draw a different rig, board, encoding and scene set for every --seed",
    )
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--workers", type=int, default=None, help="processes (default: all cores)")
    s.add_argument("--overwrite", action="store_true", help="replace an existing dataset")
    s.add_argument(
        "--off", nargs="*", default=[], choices=NUISANCE_SWITCHES, help="nuisances to switch off"
    )
    s.set_defaults(func=_synth)

    v = sub.add_parser("validate", help="check a dataset against the capture format")
    v.add_argument("dataset", type=Path)
    v.add_argument("--summary", type=Path, default=None, help="write a JSON summary here")
    v.set_defaults(func=_validate)

    m = sub.add_parser("markers", help="board poses and calibration planes from the ArUco markers")
    m.add_argument("dataset", type=Path, help="dataset folder (capture format)")
    m.add_argument("out", type=Path, help="CSV to write (one row per usable board pose)")
    m.add_argument(
        "--min-markers", type=int, default=3, help="markers seen by >= 2 cameras a pose needs"
    )
    m.set_defaults(func=_markers)

    nz = sub.add_parser("noise", help="sensor noise model of every camera channel (JSON)")
    nz.add_argument("dataset", type=Path)
    nz.add_argument("out", type=Path, help="noise model JSON to write")
    nz.set_defaults(func=_noise)

    x = sub.add_parser("crosstalk", help="calibrate each camera's channel mixing matrix")
    x.add_argument("dataset", type=Path)
    x.add_argument("out", type=Path, help="JSON file to write")
    x.add_argument(
        "--poses",
        type=Path,
        default=None,
        help="the markers stage's board poses: also fit the LED factor (the rig's own "
        "lights' channel mixing relative to the chromatic light)",
    )
    x.set_defaults(func=_crosstalk)

    ph = sub.add_parser("photometric", help="mu maps of the Helmholtz cameras (eqs. 6-8)")
    ph.add_argument("dataset", type=Path)
    ph.add_argument("poses", type=Path, help="marker poses table (colourhs markers)")
    ph.add_argument("out", type=Path, help="photometric.h5 to write")
    ph.add_argument("--crosstalk", type=Path, default=None, help="unmix with this calibration")
    ph.add_argument("--figure", type=Path, default=None, help="also write the heat maps PNG")
    for name in PHOTOMETRIC_PARAMS:
        kind = int if name == "step_px" else float
        ph.add_argument("--" + name.replace("_", "-"), dest=name, type=kind, default=None)
    ph.set_defaults(func=_photometric)

    c = sub.add_parser("chromaticity", help="surface chromaticity maps of a chromatic object")
    c.add_argument("dataset", type=Path, help="dataset folder (capture format)")
    c.add_argument("object", help="chromatic object: a folder under chromatic/ (e.g. toy)")
    c.add_argument("out", type=Path, help="HDF5 file to write (one dataset per camera)")
    c.add_argument("--figure", type=Path, default=None, help="also write this PNG figure")
    c.add_argument(
        "--min-signal",
        type=float,
        default=0.01,
        help="smallest usable intensity, fraction of full scale (default 0.01)",
    )
    c.set_defaults(func=_chromaticity)

    rc = sub.add_parser("reconstruct", help="depth and normals of one frame (ML or Bayesian HS)")
    rc.add_argument("dataset", type=Path)
    rc.add_argument("scene")
    rc.add_argument("frame", help="6-digit frame index")
    rc.add_argument("out", type=Path, help="depth HDF5 to write")
    rc.add_argument("--method", choices=("ml", "bayes"), default="bayes")
    rc.add_argument("--crosstalk", type=Path, default=None, help="unmix with this calibration")
    rc.add_argument("--photometric", type=Path, default=None, help="mu maps (photometric.h5)")
    rc.add_argument("--chromaticity", type=Path, default=None, help="chromaticity maps (.h5)")
    rc.add_argument(
        "--noise",
        type=Path,
        default=None,
        help="sensor noise model (colourhs noise); default: estimated from the frame",
    )
    rc.add_argument("--hull", type=Path, default=None,
                    help="visual hull PLY: depth hypotheses over its depth range")  # fmt: skip
    for name, kind in RECONSTRUCT_PARAMS.items():
        rc.add_argument("--" + name.replace("_", "-"), dest=name, type=kind, default=None)
    rc.set_defaults(func=_reconstruct)

    h = sub.add_parser("hull", help="visual hull of one frame from its silhouettes (PLY)")
    h.add_argument("dataset", type=Path)
    h.add_argument("scene")
    h.add_argument("frame")
    h.add_argument("out", type=Path, help="hull mesh PLY to write")
    h.add_argument("--depth", type=Path, default=None, help="also write the vh depth HDF5")
    h.add_argument("--voxel-m", type=float, default=None, help="voxel size, metres")
    h.add_argument("--threshold", type=float, default=0.02, help="silhouette threshold")
    h.set_defaults(func=_hull)

    me = sub.add_parser("mesh", help="oriented points of a depth file -> Poisson mesh (PLY)")
    me.add_argument("depth", type=Path, help="results-contract depth HDF5")
    me.add_argument("out", type=Path, help="mesh PLY to write")
    me.add_argument("--hull", type=Path, default=None, help="visual hull PLY to close the cloud")
    me.add_argument("--poisson-depth", type=int, default=8)
    me.add_argument("--density-quantile", type=float, default=0.02)
    me.set_defaults(func=_mesh)

    ev = sub.add_parser("evaluate", help="Hausdorff and depth/normal errors of one frame")
    ev.add_argument("depth", type=Path)
    ev.add_argument("mesh", type=Path)
    ev.add_argument("out", type=Path, help="metrics JSON to write")
    ev.add_argument("--gt", type=Path, default=None, help="ground-truth mesh (none: empty metrics)")
    ev.add_argument("--coloured", type=Path, default=None, help="mesh coloured by its error")
    ev.add_argument("--scene", default="")
    ev.add_argument("--frame", default="")
    ev.add_argument("--variant", default="")
    ev.add_argument("--vmax-mm", type=float, default=None)
    ev.set_defaults(func=_evaluate)

    mt = sub.add_parser("metrics", help="gather per-frame metrics JSON into metrics.csv")
    mt.add_argument("out", type=Path)
    mt.add_argument("json", nargs="+", type=Path)
    mt.set_defaults(func=_metrics)

    fg = sub.add_parser("figures", help="a scene's figures (Figure 7 grid, maps, animation)")
    fg.add_argument("out", type=Path, help="folder to write")
    fg.add_argument("--depth", nargs="+", default=[], help="VARIANT=depth.h5 ...")
    fg.add_argument("--mesh", nargs="+", default=[], help="VARIANT=mesh.ply ...")
    fg.add_argument("--gt", type=Path, default=None)
    fg.add_argument("--coloured", nargs="*", default=[], help="VARIANT=error-coloured mesh ...")
    fg.add_argument("--animate", nargs="*", default=[], help="FRAME=mesh.ply ... (dynamic scene)")
    fg.set_defaults(func=_figures)

    rp = sub.add_parser("report", help="the evaluation report (index.html)")
    rp.add_argument("out", type=Path)
    rp.add_argument("--name", required=True)
    rp.add_argument("--metrics", type=Path, required=True)
    rp.add_argument("--calibration", nargs="*", default=[], help="calibration figures (PNG)")
    rp.add_argument("--figures", nargs="*", default=[], help="SCENE=figure folder ...")
    rp.add_argument("--benchmarks", type=Path, default=Path("benchmarks/snakemake"))
    rp.add_argument("--config", type=Path, default=None, help="the run's configuration (YAML)")
    rp.set_defaults(func=_report)

    cf = sub.add_parser("config", help="write a run's configuration (JSON text) as YAML")
    cf.add_argument("out", type=Path)
    cf.add_argument("json")
    cf.set_defaults(func=_config)

    r = sub.add_parser("run", help="run the whole workflow on a dataset")
    r.add_argument("dataset", type=Path)
    r.add_argument("--name", default=None, help="results name (default: the folder's name)")
    r.add_argument("--cores", type=int, default=2)
    r.add_argument("--directory", default=".", help="where results/ and reports/ go")
    r.add_argument("--variants", default=None,
                   help="comma-separated variant ids (default: vh,ml_full,bayes_nocalib,"
                        "bayes_ph,bayes_full)")  # fmt: skip
    r.set_defaults(func=_run)
    r.epilog = "Arguments after `--` are passed on to snakemake."
    return p


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    extra = []
    if "--" in argv:
        k = argv.index("--")
        argv, extra = argv[:k], argv[k + 1 :]
    args = build_parser().parse_args(argv)
    args.snakemake_args = extra
    try:
        return args.func(args)
    except (ValueError, FileExistsError) as e:  # CaptureFormatError is a ValueError
        print(f"colourhs {args.command}: {e}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
