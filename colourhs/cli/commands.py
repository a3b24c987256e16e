"""The stage subcommands of ``colourhs`` (:mod:`colourhs.cli.parser`): one small
function per subcommand, each calling one function of the package with the
parsed arguments (the Snakemake rules call these subcommands)."""

from __future__ import annotations

import argparse
import json
import os
import shlex
import subprocess
import sys
from pathlib import Path

PROJECT_ROOT = Path(__file__).resolve().parents[2]
SNAKEFILE = PROJECT_ROOT / "Snakefile"


RECONSTRUCT_PARAMS = {
    "reference": (str, "reference camera (default: the first camera of rig.json)"),
    "n_labels": (int, "depth hypotheses of the labelling"),
    "alpha": (float, "weight of the data term in the Bayesian energy"),
    "tau": (float, "truncation of the depth-normal prior, labels"),
    "working_radius": (float, "depth hypotheses: working depth +- this fraction of it"),
    "working_radius_m": (
        float,
        "the same in metres, instead of --working-radius (default: none, the fraction applies)",
    ),
    "data_weight": (float, "weight of the labelling in the initial surface"),
    "max_cost": (float, "pixels whose best hypothesis costs more are left out (sigma3/sigma2)"),
    "cost_scale": (float, "typical noise level of sigma3/sigma2 (the data term's unit)"),
    "erode_px": (int, "erosion of the Bayesian mask, pixels (default: 1 per 320 of width)"),
    "edge_m": (float, "depth step that separates surfaces in the initial surface, metres"),
    "refine_passes": (int, "passes of the initial surface"),
    "min_component": (int, "smallest kept surface, pixels (default: 0.2 %% of the image)"),
    "link_m": (float, "tangent-plane distance that links neighbours into one surface, metres"),
    "surface_iterations": (int, "Levenberg-Marquardt steps before and after the depth search"),
    "spline_px": (float, "spline control spacing, pixels (default: 1/120 of the width)"),
    "blur_px": (float, "Gaussian blur of the Helmholtz sides, pixels (default 1)"),
    "max_sigma_mm": (
        float,
        "a depth less certain than this (1 sigma, mm) is flagged (default: 5 %% of the depth)",
    ),
}

#: ``colourhs photometric`` options: name -> (type, help); defaults in
#: :data:`colourhs.calibration.photometric.DEFAULTS`, shown by --help.
PHOTOMETRIC_PARAMS = {
    "grid_spacing_px": (float, "mu control-grid spacing, pixels (default: 1 deg of field)"),
    "step_px": (int, "sample spacing, pixels (default: the grid spacing / 7)"),
    "box_px": (int, "each reading the mean of a box this wide, pixels (default: the step, odd)"),
    "smoothness": (float, "curvature regulariser, relative to one eq. (6) row"),
    "coupling": (float, "gradient penalty on the difference of a camera's two maps"),
    "margin_m": (
        float,
        "margin around markers and board edges, metres (default: two pixel footprints)",
    ),
    "min_cos": (float, "grazing limit: smallest cosine of incidence and view"),
    "min_signal": (float, "darkest usable intensity, fraction of full scale"),
}


def _defaults(command: str) -> dict:
    """The package's defaults of a stage's tuning options (imported only for --help)."""
    import dataclasses
    import inspect

    if command == "reconstruct":
        from colourhs.reconstruct.frame import ReconstructOptions, reconstruct

        sig = inspect.signature(reconstruct).parameters
        defaults = {k: p.default for k, p in sig.items() if p.default is not p.empty}
        defaults |= {f.name: f.default for f in dataclasses.fields(ReconstructOptions)}
        return {k: defaults[k] for k in RECONSTRUCT_PARAMS if k in defaults}
    from colourhs.calibration.photometric import DEFAULTS

    return dict(DEFAULTS)


def frame_indices(text: str) -> tuple[int, ...]:
    """Frame indices from ``"40-59"``, ``"3"`` or ``"0-2,7"`` (ranges inclusive), sorted."""
    out = set()
    for item in text.split(","):
        first, sep, last = item.strip().partition("-")
        if not first.isdigit() or (sep and not last.isdigit()):
            raise argparse.ArgumentTypeError(
                f"frames {text!r}: expected FIRST-LAST or INDEX, comma-separated"
            )
        out.update(range(int(first), int(last if sep else first) + 1))
    if not out:
        raise argparse.ArgumentTypeError(f"frames {text!r}: an empty range")
    return tuple(sorted(out))


def _dataset(args, scenes=()):
    """What a stage takes as its dataset: the folder, or with ``--rig`` the dataset opened
    with that rig.json instead of its own (reading only ``scenes``; None: every one)."""
    if getattr(args, "rig", None) is None:
        return args.dataset
    from colourhs.capture import open_dataset

    return open_dataset(args.dataset, check_images=False, scenes=scenes, rig_json=args.rig)


def _synth(args) -> int:
    from colourhs.synth.simulated_rig import Nuisances
    from colourhs.synth.synthesise import PARTS, PRESETS, RenderSelection, synthesise

    if args.preset not in PRESETS:
        raise ValueError(f"unknown preset {args.preset!r}; presets: {', '.join(PRESETS)}")
    nuisances = Nuisances().without(*args.off)
    scenes = None if args.scenes is None else tuple(s.strip() for s in args.scenes.split(","))
    parts = PARTS if args.parts is None else tuple(s.strip() for s in args.parts.split(","))
    synthesise(
        args.out,
        args.preset,
        seed=args.seed,
        nuisances=nuisances,
        selection=RenderSelection(parts=parts, scenes=scenes, frames=args.frames),
        overwrite=args.overwrite,
        workers=args.workers,
    )
    print(f"wrote {args.out}")
    return 0


def _validate(args) -> int:
    from colourhs.calibration.rig_check import validate_rig
    from colourhs.capture import open_dataset, validate
    from colourhs.common.files import write_json

    summary = validate(args.dataset, rig_json=args.rig)
    if not args.no_rig_check:  # rig.json against the photometric captures
        ds = open_dataset(args.dataset, check_images=False, scenes=(), rig_json=args.rig)
        summary["rig_check"] = validate_rig(ds)
    if args.summary:
        write_json(args.summary, summary)
    for warning in summary["warnings"]:
        print(f"warning: {warning}", file=sys.stderr)
    scenes = summary["scenes"]
    print(
        f"{summary['dataset']}: valid: {summary['images']} images of "
        f"{len(summary['cameras'])} cameras, {len(summary['poses'])} board poses, "
        f"{len(summary['chromatic_objects'])} chromatic objects, {len(scenes)} scenes "
        f"({sum(s['frames'] for s in scenes.values())} frames)"
        + (f", {len(summary['warnings'])} warning(s)" if summary["warnings"] else "")
    )
    print(json.dumps(summary, indent=2))
    return 0


def _run(args) -> int:
    import yaml

    from colourhs.capture import open_dataset
    from colourhs.workflow.variants import parse_variants

    dataset = Path(args.dataset).resolve()
    if not dataset.is_dir():
        what = "not a folder" if dataset.exists() else "no such folder"
        raise FileNotFoundError(f"{dataset}: {what} (a dataset in the capture format)")
    if not (dataset / "rig.json").exists():
        raise FileNotFoundError(f"{dataset / 'rig.json'}: missing (not a capture-format dataset)")
    # Everything the command line names, and the dataset's layout and rig.json, are
    # checked before anything is written (the images when the workflow starts).
    known = tuple(open_dataset(dataset, check_images=False).scenes)
    reconstruction = {}
    if args.variants is not None:  # "" too: an empty list is refused
        reconstruction["variants"] = parse_variants(args.variants)
    if args.scenes is not None:
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
    if args.calibrate_rig:
        config["calibration"] = {"calibrate_rig": True}
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
    from colourhs.report.provenance import COMMAND_ENV  # the report names this command

    return subprocess.call(cmd, env={**os.environ, COMMAND_ENV: shlex.join(args.command_line)})


def _markers(args) -> int:
    from colourhs.calibration.markers import marker_poses

    table = marker_poses(_dataset(args), args.out, min_markers=args.min_markers)
    print(f"wrote {args.out}: {len(table)} board poses, rms <= {table['rms_px'].max():.3f} px")
    return 0


def _board(args) -> int:
    from colourhs.calibration import board

    length = args.marker_length
    if args.squares is not None:  # a ChArUco target: its size follows from its squares
        given = (("--size", args.size), ("--markers", args.markers))
        extra = [option for option, value in given if value is not None]
        if extra:
            raise ValueError(f"--charuco sets the board's layout: drop {' and '.join(extra)}")
        if args.square_length is None:
            raise ValueError("--charuco needs --square-length (metres)")
        if length is None:
            length = board.CHARUCO_MARKER_FRACTION * args.square_length
        target = board.charuco_layout(*args.squares, args.square_length, length, args.dictionary)
    else:
        if args.square_length is not None:
            raise ValueError("--square-length is a ChArUco square's: give --charuco too")
        target = board.board_layout(
            args.dictionary,
            board.DEFAULT_SIZE if args.size is None else args.size,
            board.DEFAULT_MARKER_LENGTH if length is None else length,
            args.markers,
        )
    out, block = board.write_board(target, args.out, dpi=args.dpi)
    print(f"wrote {out} and {block} (the rig.json block of the printed board)")
    return 0


def _calibrate_rig(args) -> int:
    from colourhs.calibration.geometric import calibrate_rig, report_summary

    report = calibrate_rig(
        args.dataset, args.out, world=args.world, base_rig=args.base_rig, report_json=args.report
    )
    for warning in report["warnings"]:
        print(f"warning: {warning}", file=sys.stderr)
    print(report_summary(report))
    print(f"wrote {args.out}" + (f" and {args.report}" if args.report else ""))
    return 0


def _noise(args) -> int:
    from colourhs.calibration.noise import calibrate_noise

    model = calibrate_noise(_dataset(args), args.out)
    for cam, gain in model.gain.items():
        wells = ", ".join(f"{1 / g:.0f}" if g > 0 else "-" for g in gain)
        print(f"{cam}: full well (electrons per full scale, R G B) {wells}")
    print(f"wrote {args.out}")
    return 0


def _crosstalk(args) -> int:
    from colourhs.calibration.crosstalk import calibrate_crosstalk

    result = calibrate_crosstalk(_dataset(args), args.out, poses_csv=args.poses)
    print(json.dumps(result, indent=2))
    return 0


def _photometric(args) -> int:
    from colourhs.calibration.photometric import photometric_maps

    params = {k: v for k, v in vars(args).items() if k in PHOTOMETRIC_PARAMS and v is not None}
    result = photometric_maps(_dataset(args), args.poses, args.out, args.crosstalk, **params)
    if args.figure:
        from colourhs.report.figures import mu_maps_figure

        _figure_or_none(
            args.out, lambda: mu_maps_figure(result["maps"], result["calibrated"], args.figure)
        )
    for key, n in result["counts"].items():
        rms = result["residual_rms"][key]
        print(f"{key}: {n} eq. (7) constraints, residual RMS {rms:.4f} (log mu)")
    print(f"wrote {args.out}")
    return 0


def _figure_or_none(written: str | Path, draw) -> None:
    """Run ``draw()`` (a calibration figure, written atomically by the figure's own
    function); if it fails, remove the calibration file ``written`` too, so a failed
    command leaves neither."""
    try:
        draw()
    except BaseException:
        Path(written).unlink(missing_ok=True)
        raise


def _chromaticity(args) -> int:
    import numpy as np

    from colourhs.calibration.chromaticity import chromaticity_maps

    result = chromaticity_maps(
        _dataset(args, None),
        args.object,
        args.out,
        min_signal=args.min_signal,
        noise_json=args.noise,
    )
    if args.figure:
        from colourhs.report.figures import chromaticity_figure

        _figure_or_none(
            args.out,
            lambda: chromaticity_figure(
                result.intensity,
                result.maps,
                args.figure,
                title=args.object,
                intensity_label=result.camera,
            ),
        )
    for camera, p in result.maps.items():
        print(f"{camera}: {int(np.isfinite(p[..., 0]).sum())} pixels with a chromaticity")
    print(f"wrote {args.out}")
    return 0


def _track_chromaticity(args) -> int:
    from colourhs.calibration.chromaticity_tracking import track_chromaticity

    info = track_chromaticity(
        _dataset(args, [args.scene]),
        args.scene,
        args.frame,
        args.calibrated,
        args.out,
        neighbour_h5=args.neighbour,
    )
    for cam, share in json.loads(info["tracked"]).items():
        print(f"{cam}: a p for {share:.1%} as many pixels as the calibrated map")
    print(f"wrote {args.out}")
    return 0


def check_reconstruct_params(params: dict) -> None:
    """Tuning options of ``reconstruct`` against the ranges of the workflow's config
    schema (``reconstruction.params`` in workflow/schemas/config.schema.yaml, the one
    place they are written): a ValueError naming the option, before any stage runs."""
    import jsonschema
    import yaml

    schema = yaml.safe_load(
        (PROJECT_ROOT / "workflow" / "schemas" / "config.schema.yaml").read_text()
    )
    specs = schema["properties"]["reconstruction"]["properties"]["params"]["properties"]
    for key, value in params.items():
        try:
            jsonschema.validate(value, specs.get(key, {}))
        except jsonschema.ValidationError as e:
            raise ValueError(f"--{key.replace('_', '-')} {value}: {e.message}") from None


def _reconstruct(args) -> int:
    if args.same_as:
        return _same_as(args.same_as, args.out)
    from colourhs.reconstruct.frame import reconstruct_frame
    from colourhs.reconstruct.inputs import CalibrationFiles

    params = {k: v for k, v in vars(args).items() if k in RECONSTRUCT_PARAMS and v is not None}
    check_reconstruct_params(params)
    calibration = CalibrationFiles(args.crosstalk, args.photometric, args.chromaticity, args.noise)
    result = reconstruct_frame(
        _dataset(args, [args.scene]),
        args.scene,
        args.frame,
        args.out,
        args.method,
        calibration,
        args.hull,
        **params,
    )
    info = result.info
    print(
        f"{args.scene}/{args.frame} {args.method}: {info['valid_pixels']} of {info['pixels']} "
        f"pixels, energy {info.get('energy', '-')}; wrote {args.out}"
    )
    return 0


def _same_as(src, out) -> int:
    """A result equal to one another job computed (colourhs.workflow.variants.same_as): a copy."""
    from colourhs.common.files import copy_output

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


def _depth_input(args, path):
    """The DepthMap that :func:`colourhs.cli.parser._check_inputs` read from depth file
    ``path`` (``args.depth_maps``), or ``path`` when it read none: the stage reads
    each depth file once."""
    return getattr(args, "depth_maps", {}).get(str(path), path)


def _hull(args) -> int:
    from colourhs.surfaces.hull import HullOptions, visual_hull

    info = visual_hull(
        _dataset(args, [args.scene]),
        args.scene,
        args.frame,
        args.out,
        options=HullOptions(voxel_m=args.voxel_m, threshold=args.threshold),
        out_depth_h5=args.depth,
    )
    print(json.dumps(info, indent=2, default=str))
    return 0


def _mesh(args) -> int:
    if args.same_as:
        return _same_as(args.same_as, args.out)
    from colourhs.surfaces.poisson import frame_mesh

    info = frame_mesh(
        _depth_input(args, args.depth),
        args.out,
        hull_ply=args.hull,
        poisson_depth=args.poisson_depth,
        density_quantile=args.density_quantile,
    )
    print(json.dumps(info, indent=2, default=str))
    return 0


def _evaluate(args) -> int:
    if args.same_as:
        from colourhs.common.files import write_json

        info = json.loads(Path(args.same_as).read_text())
        info.update(variant=args.variant, same_as=info.get("variant", ""))
        if args.coloured:
            _same_as(Path(args.same_as).with_suffix(".ply"), args.coloured)
        write_json(args.out, info)
        print(f"wrote {args.out}: the same as {args.same_as}")
        return 0
    from colourhs.evaluation.accuracy import EvaluationOptions, FrameKey, evaluate_frame

    info = evaluate_frame(
        _depth_input(args, args.depth),
        args.mesh,
        args.gt,
        args.out,
        out_ply=args.coloured,
        key=FrameKey(args.scene, args.frame, args.variant),
        options=EvaluationOptions(vmax_mm=args.vmax_mm),
    )
    print(json.dumps(info, indent=2, default=str))
    return 0


def _metrics(args) -> int:
    from colourhs.common.metrics_csv import metrics_table

    table = metrics_table(args.json, args.out)
    print(f"wrote {args.out}: {len(table)} rows")
    return 0


def _figures(args) -> int:
    from colourhs.report.figures import scene_figures

    written = scene_figures(
        args.out,
        {k: _depth_input(args, p) for k, p in _pairs(args.depth, "--depth").items()},
        _pairs(args.mesh, "--mesh"),
        args.gt,
        _pairs(args.animate, "--animate"),
        coloured=_pairs(args.coloured, "--coloured"),
        chromaticity=_pairs(args.chromaticity, "--chromaticity"),
        gt_chromaticity=_pairs(args.gt_chromaticity, "--gt-chromaticity"),
        calibrated_chromaticity=args.calibrated_chromaticity,
    )
    print(f"wrote {len(written)} figures into {args.out}")
    return 0


def _report(args) -> int:
    import yaml

    from colourhs.capture import open_dataset
    from colourhs.report.page import PageOptions, ReportInputs, build_report, find_benchmarks
    from colourhs.report.provenance import resolve_config

    figures = _pairs(args.figures, "--figures")
    tsvs = find_benchmarks(args.benchmarks, args.name)
    config = yaml.safe_load(args.config.read_text()) or {} if args.config else {}
    config = resolve_config(config, _defaults("reconstruct"), _defaults("photometric"))
    dataset = (
        open_dataset(args.dataset, check_images=False, rig_json=args.rig) if args.dataset else None
    )
    build_report(
        args.out,
        args.name,
        ReportInputs(args.metrics, args.calibration or [], figures, tsvs, config),
        PageOptions(
            embed_images=args.embed_images,
            link_outside=args.link_outside,
            config_resolved=True,
            views=args.view,
        ),
        dataset=dataset,
        results_dir=args.results,
        calibration_dir=args.calib,
    )
    print(f"wrote {args.out}")
    return 0


def _config(args) -> int:
    import yaml

    from colourhs.common.files import atomic_output

    with atomic_output(args.out) as tmp:
        tmp.write_text(yaml.safe_dump(json.loads(args.json)))
    print(f"wrote {args.out}")
    return 0
