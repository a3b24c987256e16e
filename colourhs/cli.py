"""Command line: ``colourhs run`` (the whole workflow) and one subcommand per stage.

Each stage subcommand calls one function of the package; the Snakemake rules
call these subcommands.
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import subprocess
import sys
from pathlib import Path

import yaml

from colourhs.capture import LIT_THRESHOLD, MIN_SIGNAL, UnknownNameError, open_dataset, validate

PROJECT_ROOT = Path(__file__).resolve().parents[1]
SNAKEFILE = PROJECT_ROOT / "Snakefile"
NUISANCE_SWITCHES = ("light_falloff", "vignetting", "crosstalk", "noise", "saturate")


def _synth(args) -> int:
    from colourhs.synth.dataset import PRESETS, synthesise
    from colourhs.synth.rig import Nuisances

    if args.preset not in PRESETS:
        raise ValueError(f"unknown preset {args.preset!r}; presets: {', '.join(PRESETS)}")
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
    from colourhs.variants import parse_variants

    dataset = Path(args.dataset).resolve()
    if not (dataset / "rig.json").exists():
        raise FileNotFoundError(f"{dataset / 'rig.json'}: missing (not a capture-format dataset)")
    # Everything the command line names is checked before anything is written.
    reconstruction = {}
    if args.variants:
        reconstruction["variants"] = parse_variants(args.variants)
    if args.scenes:
        known = tuple(open_dataset(dataset, check_images=False).scenes)
        scenes = [v.strip() for v in args.scenes.split(",") if v.strip()]
        unknown = [v for v in scenes if v not in known]
        if unknown or not scenes:
            raise ValueError(
                f"unknown scene(s) {', '.join(map(repr, unknown)) or '(none given)'}"
                f" in {dataset}; scenes: {', '.join(known)}"
            )
        reconstruction["scenes"] = scenes
    name = args.name or dataset.name
    config_path = Path(args.directory) / "results" / name / "run-config.yaml"
    config = {"datasets": {name: {"path": str(dataset)}}, "only": [name]}
    if reconstruction:
        config["reconstruction"] = reconstruction
    config_path.parent.mkdir(parents=True, exist_ok=True)
    config_path.write_text(yaml.safe_dump(config))
    # Snakemake's own arguments (targets included) go before --configfile,
    # whose list of files would otherwise swallow them.
    cmd = [
        sys.executable,
        "-m",
        "snakemake",
        "--snakefile",
        str(SNAKEFILE),
        "--directory",
        str(Path(args.directory).resolve()),
        "--cores",
        str(args.cores),
        *args.snakemake_args,
        "--configfile",
        str(PROJECT_ROOT / "config.yaml"),
        str(config_path.resolve()),
    ]
    from colourhs.reportinfo import COMMAND_ENV  # the report names this command

    return subprocess.call(cmd, env={**os.environ, COMMAND_ENV: shlex.join(args.command_line)})


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
    if args.same_as:
        return _same_as(args.same_as, args.out)
    from colourhs.reconstruct.frame import reconstruct_frame

    params = {k: v for k, v in vars(args).items() if k in RECONSTRUCT_PARAMS and v is not None}
    params["progress"] = sys.stderr.isatty()  # a bar at a terminal, none in a rule's log
    result = reconstruct_frame(
        args.dataset,
        args.scene,
        args.frame,
        args.out,
        args.method,
        args.crosstalk,
        args.photometric,
        args.chromaticity,
        args.hull,
        noise_json=args.noise,
        **params,
    )
    info = result.info
    print(
        f"{args.scene}/{args.frame} {args.method}: {info['valid_pixels']} of {info['pixels']} "
        f"pixels, energy {info.get('energy', '-')}; wrote {args.out}"
    )
    return 0


def _same_as(src, out) -> int:
    """A result equal to one another job computed (colourhs.variants.same_as): a copy."""
    from colourhs.io import copy_output

    copy_output(src, out)
    print(f"wrote {out}: the same as {src}")
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

    info = visual_hull(
        args.dataset,
        args.scene,
        args.frame,
        args.out,
        voxel_m=args.voxel_m,
        threshold=args.threshold,
        out_depth_h5=args.depth,
    )
    print(json.dumps(info, indent=2, default=str))
    return 0


def _mesh(args) -> int:
    if args.same_as:
        return _same_as(args.same_as, args.out)
    from colourhs.mesh import frame_mesh

    info = frame_mesh(
        args.depth,
        args.out,
        hull_ply=args.hull,
        poisson_depth=args.poisson_depth,
        density_quantile=args.density_quantile,
    )
    print(json.dumps(info, indent=2, default=str))
    return 0


def _evaluate(args) -> int:
    if args.same_as:
        from colourhs.io import write_json

        info = json.loads(Path(args.same_as).read_text())
        info.update(variant=args.variant, same_as=info.get("variant", ""))
        if args.coloured:
            _same_as(Path(args.same_as).with_suffix(".ply"), args.coloured)
        write_json(args.out, info)
        print(f"wrote {args.out}: the same as {args.same_as}")
        return 0
    from colourhs.evaluate import evaluate_frame

    info = evaluate_frame(
        args.depth,
        args.mesh,
        args.gt,
        args.out,
        out_ply=args.coloured,
        scene=args.scene,
        frame=args.frame,
        variant=args.variant,
        vmax_mm=args.vmax_mm,
    )
    print(json.dumps(info, indent=2, default=str))
    return 0


def _metrics(args) -> int:
    from colourhs.evaluate import metrics_table

    table = metrics_table(args.json, args.out)
    print(f"wrote {args.out}: {len(table)} rows")
    return 0


def _figures(args) -> int:
    from colourhs.figures import scene_figures

    written = scene_figures(
        args.out,
        _pairs(args.depth, "--depth"),
        _pairs(args.mesh, "--mesh"),
        args.gt,
        _pairs(args.animate, "--animate"),
        coloured=_pairs(args.coloured, "--coloured"),
    )
    print(f"wrote {len(written)} figures into {args.out}")
    return 0


def _report(args) -> int:
    from colourhs.report import build_report, find_benchmarks
    from colourhs.reportinfo import resolve_config

    figures = _pairs(args.figures, "--figures")
    tsvs = find_benchmarks(args.benchmarks, args.name)
    config = yaml.safe_load(args.config.read_text()) or {} if args.config else {}
    config = resolve_config(config, _defaults("reconstruct"), _defaults("photometric"))
    dataset = open_dataset(args.dataset, check_images=False) if args.dataset else None
    build_report(
        args.out,
        args.name,
        args.metrics,
        args.calibration or [],
        figures,
        tsvs,
        config,
        embed_images=args.embed_images,
        dataset=dataset,
        results_dir=args.results,
        config_resolved=True,
    )
    print(f"wrote {args.out}")
    return 0


def _config(args) -> int:
    from colourhs.io import atomic_output

    with atomic_output(args.out) as tmp:
        tmp.write_text(yaml.safe_dump(json.loads(args.json)))
    print(f"wrote {args.out}")
    return 0


SAME_AS_HELP = (
    "an equal result another job computed: copy it (the workflow's bayes_full "
    "on a scene without a chromatic object)"
)

#: ``colourhs reconstruct`` tuning options: name -> (type, help); the default is
#: the package's (:func:`colourhs.reconstruct.frame.reconstruct`), shown by --help.
RECONSTRUCT_PARAMS = {
    "reference": (str, "reference camera (default: the first camera of rig.json)"),
    "n_labels": (int, "depth hypotheses of the labelling"),
    "alpha": (float, "weight of the data term in the Bayesian energy"),
    "tau": (float, "truncation of the depth-normal prior, labels"),
    "working_radius": (float, "depth hypotheses: working depth +- this fraction of it"),
    "working_radius_m": (float, "the same in metres, instead of --working-radius"),
    "data_weight": (float, "weight of the labelling in the initial surface"),
    "max_cost": (float, "pixels whose best hypothesis costs more are left out (sigma3/sigma2)"),
    "cost_scale": (float, "typical noise level of sigma3/sigma2 (the data term's unit)"),
    "erode_px": (int, "erosion of the Bayesian mask, pixels (default: 1 per 320 px of width)"),
    "edge_m": (float, "depth step that separates surfaces in the initial surface, metres"),
    "refine_passes": (int, "passes of the initial surface"),
    "min_component": (int, "smallest kept surface, pixels (default: 0.2 %% of the image)"),
    "link_m": (float, "tangent-plane distance that links neighbours into one surface, metres"),
    "surface_iterations": (int, "Levenberg-Marquardt steps before and after the depth search"),
    "spline_px": (float, "spline control spacing, pixels (default: 1/80 of the width)"),
}

#: ``colourhs photometric`` options: name -> (type, help); defaults in
#: :data:`colourhs.photometric.DEFAULTS`, shown by --help.
PHOTOMETRIC_PARAMS = {
    "grid_spacing_px": (float, "mu control-grid spacing, pixels (default: 1 deg of field)"),
    "step_px": (int, "sample spacing, pixels (default: the grid spacing / 7)"),
    "smoothness": (float, "curvature regulariser, relative to one eq. (6) row"),
    "coupling": (float, "gradient penalty on the difference of a camera's two maps"),
    "margin_m": (float, "margin around markers and board edges, metres (default 2 px)"),
    "min_cos": (float, "grazing limit: smallest cosine of incidence and view"),
    "min_signal": (float, "darkest usable intensity, fraction of full scale"),
}


def _defaults(command: str) -> dict:
    """The package's defaults of a stage's tuning options (imported only for --help)."""
    import inspect

    if command == "reconstruct":
        from colourhs.reconstruct.frame import reconstruct

        sig = inspect.signature(reconstruct).parameters
        return {k: sig[k].default for k in RECONSTRUCT_PARAMS if k in sig}
    from colourhs.photometric import DEFAULTS

    return dict(DEFAULTS)


def _tuning_options(parser, params: dict, defaults: dict | None) -> None:
    """One --option per tuning parameter, its help with its unit and default."""
    for name, (kind, text) in params.items():
        default = (defaults or {}).get(name)
        if defaults is not None and default is not None and "default" not in text:
            text = f"{text} (default {default:g})" if kind is not str else text
        parser.add_argument(
            "--" + name.replace("_", "-"),
            dest=name,
            type=kind,
            default=None,
            metavar=kind.__name__.upper(),
            help=text,
        )


def _frame_arguments(parser) -> None:
    """The positional DATASET SCENE FRAME of the per-frame stages."""
    parser.add_argument("dataset", type=Path, help="dataset folder (capture format)")
    parser.add_argument("scene", help="scene name (a folder under scenes/)")
    parser.add_argument("frame", help="frame: its folder name under frames/ (e.g. 000000)")


def build_parser(show_defaults: bool = False) -> argparse.ArgumentParser:
    """The command line; ``show_defaults`` imports the stages to show their
    tuning options' defaults (for --help only: it costs a second)."""
    p = argparse.ArgumentParser(prog="colourhs", description=__doc__)
    p.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    sub = p.add_subparsers(dest="command", required=True)

    s = sub.add_parser("synth", help="render a synthetic dataset in the capture format")
    s.add_argument("out", type=Path, help="dataset folder to create")
    s.add_argument(
        "--preset",
        default="demo",
        help="tiny, demo, paper, random, random-tiny or random-tiny-lens (default demo); the "
        "random presets draw a different rig, board, encoding and scene set for every --seed",
    )
    s.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    s.add_argument("--workers", type=int, default=None, help="processes (default: all cores)")
    s.add_argument("--overwrite", action="store_true", help="replace an existing dataset")
    s.add_argument(
        "--off", nargs="*", default=[], choices=NUISANCE_SWITCHES, help="nuisances to switch off"
    )
    s.set_defaults(func=_synth)

    v = sub.add_parser("validate", help="check a dataset against the capture format")
    v.add_argument("dataset", type=Path, help="dataset folder (capture format)")
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
    nz.add_argument("dataset", type=Path, help="dataset folder (capture format)")
    nz.add_argument("out", type=Path, help="noise model JSON to write")
    nz.set_defaults(func=_noise)

    x = sub.add_parser("crosstalk", help="calibrate each camera's channel mixing matrix")
    x.add_argument("dataset", type=Path, help="dataset folder (capture format)")
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
    ph.add_argument("dataset", type=Path, help="dataset folder (capture format)")
    ph.add_argument("poses", type=Path, help="marker poses table (colourhs markers)")
    ph.add_argument("out", type=Path, help="photometric.h5 to write")
    ph.add_argument("--crosstalk", type=Path, default=None, help="unmix with this calibration")
    ph.add_argument("--figure", type=Path, default=None, help="also write the heat maps PNG")
    _tuning_options(ph, PHOTOMETRIC_PARAMS, _defaults("photometric") if show_defaults else None)
    ph.set_defaults(func=_photometric)

    c = sub.add_parser("chromaticity", help="surface chromaticity maps of a chromatic object")
    c.add_argument("dataset", type=Path, help="dataset folder (capture format)")
    c.add_argument("object", help="chromatic object: a folder under chromatic/ (e.g. toy)")
    c.add_argument("out", type=Path, help="HDF5 file to write (one dataset per camera)")
    c.add_argument("--figure", type=Path, default=None, help="also write this PNG figure")
    c.add_argument(
        "--min-signal",
        type=float,
        default=MIN_SIGNAL,
        help=f"smallest usable intensity, fraction of full scale (default {MIN_SIGNAL})",
    )
    c.set_defaults(func=_chromaticity)

    rc = sub.add_parser("reconstruct", help="depth and normals of one frame (ML or Bayesian HS)")
    _frame_arguments(rc)
    rc.add_argument("out", type=Path, help="depth HDF5 to write")
    rc.add_argument(
        "--method",
        choices=("ml", "bayes"),
        default="bayes",
        help="ML HS or Bayesian HS (default bayes)",
    )
    rc.add_argument("--crosstalk", type=Path, default=None, help="unmix with this calibration")
    rc.add_argument("--photometric", type=Path, default=None, help="mu maps (photometric.h5)")
    rc.add_argument("--chromaticity", type=Path, default=None, help="chromaticity maps (.h5)")
    rc.add_argument(
        "--noise",
        type=Path,
        default=None,
        help="sensor noise model (colourhs noise); default: estimated from the frame",
    )
    rc.add_argument(
        "--hull",
        type=Path,
        default=None,
        help="visual hull PLY: depth hypotheses over its depth range",
    )
    rc.add_argument("--same-as", type=Path, default=None, help=SAME_AS_HELP)
    _tuning_options(rc, RECONSTRUCT_PARAMS, _defaults("reconstruct") if show_defaults else None)
    rc.set_defaults(func=_reconstruct)

    h = sub.add_parser("hull", help="visual hull of one frame from its silhouettes (PLY)")
    _frame_arguments(h)
    h.add_argument("out", type=Path, help="hull mesh PLY to write")
    h.add_argument("--depth", type=Path, default=None, help="also write the vh depth HDF5")
    h.add_argument(
        "--voxel-m",
        type=float,
        default=None,
        help="voxel size, metres (default: about two pixel footprints)",
    )
    h.add_argument(
        "--threshold",
        type=float,
        default=LIT_THRESHOLD,
        help="silhouettes of scenes without masks: lit pixels above this fraction "
        f"of full scale (default {LIT_THRESHOLD})",
    )
    h.set_defaults(func=_hull)

    me = sub.add_parser("mesh", help="oriented points of a depth file -> Poisson mesh (PLY)")
    me.add_argument("depth", type=Path, help="results-contract depth HDF5")
    me.add_argument("out", type=Path, help="mesh PLY to write")
    me.add_argument("--hull", type=Path, default=None, help="visual hull PLY to close the cloud")
    me.add_argument("--same-as", type=Path, default=None, help=SAME_AS_HELP)
    me.add_argument("--poisson-depth", type=int, default=8, help="octree depth (default 8)")
    me.add_argument(
        "--density-quantile",
        type=float,
        default=0.02,
        help="fraction of lowest-density vertices trimmed (default 0.02)",
    )
    me.set_defaults(func=_mesh)

    ev = sub.add_parser("evaluate", help="Hausdorff and depth/normal errors of one frame")
    ev.add_argument("depth", type=Path, help="results-contract depth HDF5")
    ev.add_argument("mesh", type=Path, help="the frame's mesh PLY (colourhs mesh)")
    ev.add_argument("out", type=Path, help="metrics JSON to write")
    ev.add_argument("--gt", type=Path, default=None, help="ground-truth mesh (none: empty metrics)")
    ev.add_argument("--coloured", type=Path, default=None, help="mesh coloured by its error")
    ev.add_argument(
        "--same-as",
        type=Path,
        default=None,
        help="metrics JSON of an equal result: copy it (and its coloured mesh)",
    )
    ev.add_argument("--scene", default="", help="scene name written into the metrics")
    ev.add_argument("--frame", default="", help="frame written into the metrics")
    ev.add_argument("--variant", default="", help="variant id written into the metrics")
    ev.add_argument(
        "--vmax-mm",
        type=float,
        default=None,
        help="top of the coloured mesh's error scale, mm (default: its p95)",
    )
    ev.set_defaults(func=_evaluate)

    mt = sub.add_parser("metrics", help="gather per-frame metrics JSON into metrics.csv")
    mt.add_argument("json", nargs="+", type=Path, help="per-frame metrics JSON (colourhs evaluate)")
    mt.add_argument("out", type=Path, help="metrics.csv to write")
    mt.set_defaults(func=_metrics)

    fg = sub.add_parser("figures", help="a scene's figures (Figure 7 grid, maps, animation)")
    fg.add_argument("out", type=Path, help="folder to write")
    fg.add_argument("--depth", nargs="+", default=[], help="VARIANT=depth.h5 ...")
    fg.add_argument("--mesh", nargs="+", default=[], help="VARIANT=mesh.ply ...")
    fg.add_argument("--gt", type=Path, default=None, help="ground-truth mesh PLY")
    fg.add_argument("--coloured", nargs="*", default=[], help="VARIANT=error-coloured mesh ...")
    fg.add_argument("--animate", nargs="*", default=[], help="FRAME=mesh.ply ... (dynamic scene)")
    fg.set_defaults(func=_figures)

    rp = sub.add_parser("report", help="the evaluation report (index.html)")
    rp.add_argument("out", type=Path, help="index.html to write")
    rp.add_argument("--name", required=True, help="the dataset's results name")
    rp.add_argument("--metrics", type=Path, required=True, help="metrics.csv (colourhs metrics)")
    rp.add_argument("--calibration", nargs="*", default=[], help="calibration figures (PNG)")
    rp.add_argument("--figures", nargs="*", default=[], help="SCENE=figure folder ...")
    rp.add_argument(
        "--benchmarks",
        type=Path,
        default=Path("benchmarks/snakemake"),
        help="Snakemake benchmark files (default benchmarks/snakemake)",
    )
    rp.add_argument("--config", type=Path, default=None, help="the run's configuration (YAML)")
    rp.add_argument("--dataset", type=Path, default=None, help="the dataset (rig, scene.json)")
    rp.add_argument("--results", type=Path, default=None, help="results/NAME: link its files")
    rp.add_argument("--embed-images", action="store_true", help="embed images (base64)")
    rp.set_defaults(func=_report)

    cf = sub.add_parser("config", help="write a run's configuration (JSON text) as YAML")
    cf.add_argument("json", help="the configuration as JSON text")
    cf.add_argument("out", type=Path, help="YAML file to write")
    cf.set_defaults(func=_config)

    r = sub.add_parser("run", help="run the whole workflow on a dataset")
    r.add_argument("dataset", type=Path, help="dataset folder (capture format)")
    r.add_argument("--name", default=None, help="results name (default: the folder's name)")
    r.add_argument("--cores", type=int, default=2, help="cores Snakemake may use (default 2)")
    r.add_argument(
        "--directory", default=".", help="where results/ and reports/ go (default: here)"
    )
    r.add_argument(
        "--variants",
        default=None,
        help="comma-separated variant ids (default: vh,ml_full,bayes_nocalib,bayes_ph,bayes_full)",
    )
    r.add_argument(
        "--scenes", default=None, help="comma-separated scenes to reconstruct (default: all)"
    )
    r.set_defaults(func=_run)
    r.epilog = "Arguments after `--` are passed on to snakemake."
    return p


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("colourhs")
    except PackageNotFoundError:
        return "unknown (not installed)"


#: Input paths of each subcommand (argument names): they must exist before it runs.
INPUTS = {
    "validate": ("dataset",),
    "markers": ("dataset",),
    "noise": ("dataset",),
    "crosstalk": ("dataset", "poses"),
    "photometric": ("dataset", "poses", "crosstalk"),
    "chromaticity": ("dataset",),
    "reconstruct": (
        "dataset",
        "crosstalk",
        "photometric",
        "chromaticity",
        "noise",
        "hull",
        "same_as",
    ),
    "hull": ("dataset",),
    "mesh": ("depth", "hull", "same_as"),
    "evaluate": ("depth", "mesh", "gt", "same_as"),
    "metrics": ("json",),
    "report": ("metrics", "calibration", "config", "dataset"),
}

#: Errors of the user's input (a file, a name, a value), not of the program:
#: one line on stderr, exit status 1. Anything else is a bug and keeps its traceback.
USER_ERRORS = (ValueError, FileExistsError, FileNotFoundError, UnknownNameError)


def _check_inputs(args) -> None:
    for name in INPUTS.get(args.command, ()):
        value = getattr(args, name, None)
        for path in value if isinstance(value, list) else [value]:
            if path is not None and not Path(path).exists():
                option = name if name in ("dataset", "depth", "mesh", "json") else f"--{name}"
                raise FileNotFoundError(f"{option} {path}: no such file or folder")


def main(argv: list[str] | None = None) -> int:
    """Run a subcommand. Exit status: 0 done; 1 an error in the input (one line on
    stderr naming the file or name and what exists); 2 a usage error (argparse)."""
    if os.environ.get("COLOURHS_AUDIT_READS"):  # opt-in, for tests (tests/test_workflow.py)
        from colourhs.io import record_reads

        record_reads(os.environ["COLOURHS_AUDIT_READS"])
    argv = list(sys.argv[1:] if argv is None else argv)
    command_line, extra = ["colourhs", *argv], []
    if "--" in argv:
        k = argv.index("--")
        argv, extra = argv[:k], argv[k + 1 :]
    args = build_parser(show_defaults=bool({"-h", "--help"} & set(argv))).parse_args(argv)
    args.snakemake_args, args.command_line = extra, command_line
    try:
        _check_inputs(args)
        return args.func(args)
    except USER_ERRORS as e:  # CaptureFormatError is a ValueError
        print(f"colourhs {args.command}: {e}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
