"""Command line: ``colourhs run`` (the whole workflow) and one subcommand per stage.

Each stage subcommand calls one function of the package; the Snakemake rules
call these subcommands. This module holds the parser, the input checks and
:func:`main`; the subcommands themselves are in :mod:`colourhs.cli.commands`.
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
from collections.abc import Collection
from pathlib import Path

from colourhs.capture import LIT_THRESHOLD, MIN_SIGNAL, UnknownNameError
from colourhs.cli.commands import (  # noqa: F401 (imported from here by users)
    PHOTOMETRIC_PARAMS,
    PROJECT_ROOT,
    RECONSTRUCT_PARAMS,
    SNAKEFILE,
    _board,
    _calibrate_rig,
    _chromaticity,
    _config,
    _crosstalk,
    _defaults,
    _evaluate,
    _figures,
    _hull,
    _markers,
    _mesh,
    _metrics,
    _noise,
    _pairs,
    _photometric,
    _reconstruct,
    _report,
    _run,
    _synth,
    _track_chromaticity,
    _validate,
    frame_indices,
)
from colourhs.common.progress import line_buffered, show_progress

DESCRIPTION = (
    "Colour Helmholtz Stereopsis, from raw captures to evaluated meshes. "
    "`colourhs run DATASET` runs the whole workflow; each other command runs one "
    "stage (what the workflow's rules call). `colourhs COMMAND --help` lists a "
    "command's options with their units and defaults."
)

NUISANCE_SWITCHES = ("light_falloff", "vignetting", "crosstalk", "noise", "saturate")


SAME_AS_HELP = (
    "an equal result another job computed: copy it (the workflow's bayes_full "
    "on a scene without a chromatic object)"
)


#: ``colourhs reconstruct`` tuning options: name -> (type, help); the default is
#: the package's (:func:`colourhs.reconstruct.frame.reconstruct`), shown by --help.
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
            help=text,
        )


def _command(sub, name: str, summary: str) -> argparse.ArgumentParser:
    """A subcommand whose line in ``colourhs --help`` is also its own description."""
    return sub.add_parser(name, help=summary, description=summary[0].upper() + summary[1:] + ".")


RIG_HELP = (
    "rig.json to use instead of the dataset's own (e.g. colourhs calibrate-rig's output "
    "from the dataset's geometric/ captures)"
)


def _rig_argument(parser) -> None:
    """--rig: the rig.json a stage reads instead of the dataset's."""
    parser.add_argument("--rig", type=Path, default=None, help=RIG_HELP)


def _frame_arguments(parser) -> None:
    """The positional DATASET SCENE FRAME of the per-frame stages."""
    parser.add_argument("dataset", type=Path, help="dataset folder (capture format)")
    parser.add_argument("scene", help="scene name (a folder under scenes/)")
    parser.add_argument("frame", help="frame: its folder name under frames/ (e.g. 000000)")


def build_parser(show_defaults: bool | Collection[str] = False) -> argparse.ArgumentParser:
    """The command line; ``show_defaults`` (True: every stage; or the names of the
    subcommands, e.g. ``{"reconstruct"}``) imports those stages to show their
    tuning options' defaults (for --help only: reconstruct's costs a second)."""

    def defaults_of(command: str) -> dict | None:
        wanted = show_defaults is True or (show_defaults is not False and command in show_defaults)
        return _defaults(command) if wanted else None

    p = argparse.ArgumentParser(prog="colourhs", description=DESCRIPTION)
    p.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    p.add_argument(
        "-q",
        "--quiet",
        action="store_true",
        help="hide the progress lines and bars on stderr (warnings and errors still "
        "show); give it before the command",
    )
    sub = p.add_subparsers(dest="command", required=True)

    s = _command(sub, "synth", "render a synthetic dataset in the capture format")
    s.add_argument("out", type=Path, help="dataset folder to create")
    s.add_argument(
        "--preset",
        default="demo",
        help="tiny, demo, paper, random, random-tiny, random-tiny-lens, corner, corner-tiny, "
        "dynamic, dynamic-tiny, random-dynamic, random-dynamic-tiny, corner-dynamic or "
        "corner-dynamic-tiny (default demo); the "
        "random and corner presets draw a different rig, board, encoding and scene set for "
        "every --seed (corner: the ranges' hard ends combined); the dynamic ones render "
        "moving coloured sequences (moving-toy, cloth, turning-metal) and the plane",
    )
    s.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    s.add_argument("--workers", type=int, default=None, help="processes (default: all cores)")
    s.add_argument("--overwrite", action="store_true", help="replace an existing dataset")
    s.add_argument(
        "--off",
        nargs="*",
        default=[],
        choices=NUISANCE_SWITCHES,
        help="nuisances to switch off (default: none, every nuisance on)",
    )
    s.add_argument(
        "--frames",
        type=frame_indices,
        default=None,
        help="render only these frames of the sequences (the sheet's; a dynamic preset's): "
        "first-last and single "
        "indices, comma-separated, from 0 (e.g. 40-59 for frames 000040 to 000059 of the "
        "paper preset's 201); each equals the same frame of a full render (default: all)",
    )
    s.add_argument(
        "--scenes",
        default=None,
        help="comma-separated scenes to render, of plane, statue, toy, sheet (a dynamic "
        "preset: plane, moving-toy, cloth, turning-metal), with their chromatic captures "
        "(default all); the calibration captures are always rendered",
    )
    s.add_argument(
        "--parts",
        default=None,
        help="comma-separated captures to render, of photometric, chromatic, scenes, "
        "geometric (default all; rig.json and gt/ are always written)",
    )
    s.set_defaults(func=_synth)

    v = _command(sub, "validate", "check a dataset against the capture format")
    v.add_argument("dataset", type=Path, help="dataset folder (capture format)")
    v.add_argument("--summary", type=Path, default=None, help="write a JSON summary here")
    v.add_argument(
        "--no-rig-check",
        action="store_true",
        help="skip checking rig.json's cameras and board against the photometric captures "
        "(the board's markers triangulated and reprojected)",
    )
    _rig_argument(v)
    v.set_defaults(func=_validate)

    m = _command(sub, "markers", "board poses and calibration planes from the ArUco markers")
    m.add_argument("dataset", type=Path, help="dataset folder (capture format)")
    m.add_argument("out", type=Path, help="CSV to write (one row per usable board pose)")
    m.add_argument(
        "--min-markers",
        type=int,
        default=3,
        help="markers seen by >= 2 cameras a pose needs (default 3)",
    )
    _rig_argument(m)
    m.set_defaults(func=_markers)

    bd = _command(sub, "board", "print a white marker board (or a ChArUco target) at true scale")
    bd.add_argument(
        "out",
        type=Path,
        help="print to write: .pdf, .png or .svg; its rig.json block goes beside it "
        "(for b.pdf: b.board.json, with --charuco b.geometric_board.json)",
    )
    bd.add_argument(
        "--dictionary",
        default="DICT_5X5_100",
        help="OpenCV ArUco dictionary of the markers (default DICT_5X5_100)",
    )
    bd.add_argument(
        "--size",
        type=float,
        nargs=2,
        default=None,
        help="board width and height, metres (default 0.30 0.22)",
    )
    bd.add_argument(
        "--markers",
        type=int,
        default=None,
        help="number of markers, ids 0 to MARKERS - 1 in a regular grid (default: the "
        "densest grid that fits)",
    )
    bd.add_argument(
        "--marker-length",
        type=float,
        default=None,
        help="side of every marker, metres (default 0.04; with --charuco 0.75 of the square)",
    )
    bd.add_argument(
        "--dpi",
        type=float,
        default=600,
        help="resolution of a PNG, dots per inch (default 600; PDF and SVG are vector)",
    )
    bd.add_argument(
        "--charuco",
        dest="squares",
        type=int,
        nargs=2,
        default=None,
        help="print instead a ChArUco target of SQUARES squares across and down (for the "
        "geometric calibration; needs --square-length)",
    )
    bd.add_argument(
        "--square-length", type=float, default=None, help="side of a ChArUco square, metres"
    )
    bd.set_defaults(func=_board)

    cr = _command(
        sub, "calibrate-rig", "calibrate the cameras from views of a ChArUco target (rig.json)"
    )
    cr.add_argument(
        "dataset", type=Path, help="dataset folder with geometric/POSE/CAMERA.png (capture format)"
    )
    cr.add_argument(
        "out",
        type=Path,
        help="rig.json to write: the calibrated cameras merged into the dataset's rig.json "
        "(or --base-rig), everything else kept",
    )
    cr.add_argument(
        "--world",
        default="reference",
        help="world frame: reference (the first camera of rig.json at R = I, t = 0), "
        "board:POSE (the target's frame in geometric/POSE) or base (the base rig.json's "
        "world, whose cameras must then be roughly right) (default reference)",
    )
    cr.add_argument(
        "--report",
        type=Path,
        default=None,
        help="also write the report here (JSON: reprojection RMS per camera and pose, "
        "corner coverage, pair angles and baselines)",
    )
    cr.add_argument(
        "--base-rig",
        type=Path,
        default=None,
        help="rig.json to merge into, with the names, lights, image encoding, lens model "
        "(the length of each dist) and geometric_board (default: the dataset's)",
    )
    cr.set_defaults(func=_calibrate_rig)

    nz = _command(sub, "noise", "sensor noise model of every camera channel (JSON)")
    nz.add_argument("dataset", type=Path, help="dataset folder (capture format)")
    nz.add_argument("out", type=Path, help="noise model JSON to write")
    _rig_argument(nz)
    nz.set_defaults(func=_noise)

    x = _command(sub, "crosstalk", "calibrate each camera's channel mixing matrix")
    x.add_argument("dataset", type=Path, help="dataset folder (capture format)")
    x.add_argument("out", type=Path, help="JSON file to write")
    x.add_argument(
        "--poses",
        type=Path,
        default=None,
        help="the markers stage's board poses: also fit the LED factor (the rig's own "
        "lights' channel mixing relative to the chromatic light)",
    )
    _rig_argument(x)
    x.set_defaults(func=_crosstalk)

    ph = _command(sub, "photometric", "mu maps of the Helmholtz cameras (eqs. 6-8)")
    ph.add_argument("dataset", type=Path, help="dataset folder (capture format)")
    ph.add_argument("poses", type=Path, help="marker poses table (colourhs markers)")
    ph.add_argument("out", type=Path, help="photometric.h5 to write")
    ph.add_argument("--crosstalk", type=Path, default=None, help="unmix with this calibration")
    ph.add_argument("--figure", type=Path, default=None, help="also write the heat maps PNG")
    _tuning_options(ph, PHOTOMETRIC_PARAMS, defaults_of("photometric"))
    _rig_argument(ph)
    ph.set_defaults(func=_photometric)

    c = _command(sub, "chromaticity", "surface chromaticity maps of a chromatic object")
    c.add_argument("dataset", type=Path, help="dataset folder (capture format)")
    c.add_argument("object", help="chromatic object: a folder under chromatic/ (e.g. toy)")
    c.add_argument("out", type=Path, help="HDF5 file to write (one dataset per camera)")
    c.add_argument("--figure", type=Path, default=None, help="also write this PNG figure")
    c.add_argument(
        "--noise",
        type=Path,
        default=None,
        help="the rig's noise model (colourhs noise): also write each band's sigma of log p",
    )
    c.add_argument(
        "--min-signal",
        type=float,
        default=MIN_SIGNAL,
        help=f"smallest usable intensity, fraction of full scale (default {MIN_SIGNAL})",
    )
    _rig_argument(c)
    c.set_defaults(func=_chromaticity)

    tc = _command(
        sub, "track-chromaticity", "a moving object's chromaticity maps in one frame (HDF5)"
    )
    _frame_arguments(tc)
    tc.add_argument("out", type=Path, help="HDF5 file to write (the chromaticity maps' layout)")
    tc.add_argument(
        "--calibrated",
        type=Path,
        required=True,
        help="the object's calibrated maps (colourhs chromaticity), of the chromatic frame",
    )
    tc.add_argument(
        "--neighbour",
        type=Path,
        default=None,
        help="this command's file of the next frame towards the chromatic frame (every "
        "frame but the chromatic one)",
    )
    _rig_argument(tc)
    tc.set_defaults(func=_track_chromaticity)

    rc = _command(sub, "reconstruct", "depth and normals of one frame (ML or Bayesian HS)")
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
    _tuning_options(rc, RECONSTRUCT_PARAMS, defaults_of("reconstruct"))
    _rig_argument(rc)
    rc.set_defaults(func=_reconstruct)

    h = _command(sub, "hull", "visual hull of one frame from its silhouettes (PLY)")
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
    _rig_argument(h)
    h.set_defaults(func=_hull)

    me = _command(sub, "mesh", "oriented points of a depth file -> Poisson mesh (PLY)")
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

    ev = _command(sub, "evaluate", "Hausdorff and depth/normal errors of one frame")
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

    mt = _command(sub, "metrics", "gather per-frame metrics JSON into metrics.csv")
    mt.add_argument("json", nargs="+", type=Path, help="per-frame metrics JSON (colourhs evaluate)")
    mt.add_argument("out", type=Path, help="metrics.csv to write")
    mt.set_defaults(func=_metrics)

    fg = _command(sub, "figures", "a scene's figures (Figure 7 grid, maps, animation)")
    fg.add_argument("out", type=Path, help="folder to write")
    fg.add_argument("--depth", nargs="+", default=[], help="VARIANT=depth.h5 ...")
    fg.add_argument("--mesh", nargs="+", default=[], help="VARIANT=mesh.ply ...")
    fg.add_argument("--gt", type=Path, default=None, help="ground-truth mesh PLY")
    fg.add_argument("--coloured", nargs="*", default=[], help="VARIANT=error-coloured mesh ...")
    fg.add_argument("--animate", nargs="*", default=[], help="FRAME=mesh.ply ... (dynamic scene)")
    fg.add_argument(
        "--chromaticity",
        nargs="*",
        default=[],
        help="FRAME=tracked chromaticity .h5 ... (colourhs track-chromaticity, a moving "
        "coloured object): its animation and drift plot",
    )
    fg.add_argument(
        "--gt-chromaticity", nargs="*", default=[], help="FRAME=true chromaticity .h5 ..."
    )
    fg.add_argument(
        "--calibrated-chromaticity",
        type=Path,
        default=None,
        help="the object's calibrated maps, for the drift plot's unchanged-map line",
    )
    fg.set_defaults(func=_figures)

    rp = _command(sub, "report", "the evaluation report (index.html)")
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
    rp.add_argument(
        "--calib",
        type=Path,
        default=None,
        help="results/NAME/calib: tables of the calibration's diagnostics (marker "
        "reprojection RMS, cross-talk matrices, photometric residual; the mu error "
        "when --dataset has gt/photometric.h5)",
    )
    rp.add_argument("--embed-images", action="store_true", help="embed images (base64)")
    rp.add_argument(
        "--link-outside",
        action="store_true",
        help="link the images and result files outside the report's folder where they are "
        "(../../results/...) instead of copying the images into its assets/ and naming the "
        "result files: the page then works only beside results/",
    )
    rp.add_argument(
        "--view",
        action="store_true",
        help="embed each scene's first-frame error-coloured meshes from --results, "
        "simplified to 3000 triangles, in an offline 3D viewer",
    )
    _rig_argument(rp)
    rp.set_defaults(func=_report)

    cf = _command(sub, "config", "write a run's configuration (JSON text) as YAML")
    cf.add_argument("json", help="the configuration as JSON text")
    cf.add_argument("out", type=Path, help="YAML file to write")
    cf.set_defaults(func=_config)

    r = _command(sub, "run", "run the whole workflow on a dataset")
    r.add_argument("dataset", type=Path, help="dataset folder (capture format)")
    r.add_argument("--name", default=None, help="results name (default: the folder's name)")
    r.add_argument("--cores", type=int, default=2, help="cores Snakemake may use (default 2)")
    r.add_argument(
        "--directory", default=".", help="where results/ and reports/ go (default: here)"
    )
    r.add_argument(
        "--variants",
        default=None,
        help="comma-separated variant ids (default: vh,ml_full,bayes_nocalib,bayes_ph,bayes_full, "
        "and bayes_dyn where a scene is a sequence of a chromatic object)",
    )
    r.add_argument(
        "--scenes", default=None, help="comma-separated scenes to reconstruct (default: all)"
    )
    r.add_argument(
        "--calibrate-rig",
        action="store_true",
        help="calibrate the cameras from the dataset's geometric/ captures and run every "
        "stage with that rig (results/NAME/calib/rig.json, in the world of the dataset's "
        "rig.json) instead of the dataset's rig.json",
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
    "validate": ("dataset", "rig"),
    "markers": ("dataset", "rig"),
    "calibrate-rig": ("dataset", "base_rig"),
    "noise": ("dataset", "rig"),
    "crosstalk": ("dataset", "rig", "poses"),
    "photometric": ("dataset", "rig", "poses", "crosstalk"),
    "chromaticity": ("dataset", "rig", "noise"),
    "track-chromaticity": ("dataset", "rig", "calibrated", "neighbour"),
    "reconstruct": (
        "dataset",
        "rig",
        "crosstalk",
        "photometric",
        "chromaticity",
        "noise",
        "hull",
        "same_as",
    ),
    "hull": ("dataset", "rig"),
    "mesh": ("depth", "hull", "same_as"),
    "evaluate": ("depth", "mesh", "gt", "same_as"),
    "metrics": ("json",),
    "figures": (
        "depth",
        "mesh",
        "gt",
        "coloured",
        "animate",
        "chromaticity",
        "gt_chromaticity",
        "calibrated_chromaticity",
    ),
    "report": ("metrics", "calibration", "config", "dataset", "rig", "calib"),
}

#: Input files whose contents are checked before a subcommand runs, by kind:
#: ``depth`` (a results-contract depth file, read in full by its reader
#: :func:`colourhs.common.depthfile.read_depth`), ``hdf5`` (an HDF5 file whose datasets all
#: read to the end), ``ply`` (starts with a PLY header), ``json`` or ``yaml``
#: (parses). Folders are refused.
INPUT_KINDS = {
    "base_rig": "json",
    "rig": "json",
    "crosstalk": "json",
    "noise": "json",
    "photometric": "hdf5",
    "chromaticity": "hdf5",
    "calibrated": "hdf5",
    "neighbour": "hdf5",
    "gt_chromaticity": "hdf5",
    "calibrated_chromaticity": "hdf5",
    "depth": "depth",
    "config": "yaml",
    "json": "json",
    "hull": "ply",
    "mesh": "ply",
    "gt": "ply",
    "coloured": "ply",
    "animate": "ply",
}
#: What --same-as copies: a depth file (reconstruct), a metrics JSON (evaluate), a PLY (mesh).
SAME_AS_KINDS = {"reconstruct": "depth", "evaluate": "json", "mesh": "ply"}
#: Input arguments that are positional (named without --): NAME in every subcommand,
#: COMMAND:NAME in that one (figures --depth and --mesh are options).
POSITIONAL = {
    "dataset",
    "json",
    "mesh:depth",
    "evaluate:depth",
    "evaluate:mesh",
    "photometric:poses",
}
#: Input arguments given as KEY=PATH (a variant's or a frame's file), per subcommand.
KEY_PATHS = {
    "figures:depth",
    "figures:mesh",
    "figures:coloured",
    "figures:animate",
    "figures:chromaticity",
    "figures:gt_chromaticity",
}
#: Inputs that may be folders: the dataset, report --calibration (figures) and --calib.
FOLDER_INPUTS = ("dataset", "calibration", "calib")

#: Errors of the user's input (a file, a name, a value), not of the program:
#: one line on stderr, exit status 1. Anything else is a bug and keeps its traceback.
#: OSError: a file that cannot be read or written (a folder, no permission, a full disk).
USER_ERRORS = (ValueError, OSError, UnknownNameError)


def _input_problem(path: Path, kind: str | None, folder_ok: bool, maps=None) -> str:
    """What is wrong with input ``path`` ("" when nothing): missing, a folder where a
    file belongs, or contents that are not ``kind`` (:data:`INPUT_KINDS`). A depth
    file that reads goes into ``maps`` (a dict, path -> DepthMap) when given."""
    if not path.exists():
        return "no such file or folder"
    if path.is_dir():
        return "" if folder_ok else "a folder, not a file"
    if kind == "depth":
        return _depth_problem(path, maps)
    if kind == "hdf5":
        return _hdf5_problem(path)
    if kind == "ply":
        with open(path, "rb") as f:
            return "" if f.read(4) in (b"ply\n", b"ply\r") else "not a PLY file"
    if kind in ("json", "yaml"):
        import json

        import yaml

        try:
            text = path.read_text(encoding="utf-8")
            if kind == "json":
                json.loads(text)
            else:
                yaml.safe_load(text)
        except (UnicodeDecodeError, ValueError, yaml.YAMLError) as e:
            return f"not {kind.upper()} ({' '.join(str(e).split())})"
    return ""


def _depth_problem(path: Path, maps=None) -> str:
    """What :func:`colourhs.common.depthfile.read_depth` finds wrong with depth file ``path``
    (truncated, a dataset or attribute missing, shapes that disagree, no pixel), without
    the file name it starts with; "" when it reads, and then its DepthMap goes into
    ``maps[str(path)]`` when ``maps`` is given (the stage is given it: read once)."""
    from colourhs.common.depthfile import read_depth

    try:
        depth_map = read_depth(path)
    except ValueError as e:  # read_depth names every problem, h5py's too, as a ValueError
        return " ".join(str(e).removeprefix(f"{path}: ").split())
    if maps is not None:
        maps[str(path)] = depth_map
    return ""


def _hdf5_problem(path: Path) -> str:
    """What is wrong with HDF5 file ``path`` ("" when nothing): not HDF5, or a dataset
    that does not read to its end (a truncated or half-written file), with h5py's reason.
    Its keys and shapes are :func:`_check_maps`'s to check."""
    import h5py

    if not h5py.is_hdf5(path):
        return "not an HDF5 file"
    try:
        with h5py.File(path, "r") as f:
            f.visititems(_read_dataset)
    except (OSError, KeyError, RuntimeError) as e:
        return f"not a readable HDF5 file ({' '.join(str(e).split())})"
    return ""


def _read_dataset(_name: str, item) -> None:
    """Read ``item`` in full if it is a dataset; None, so ``visititems`` visits them all."""
    import h5py

    if isinstance(item, h5py.Dataset):
        item[()]


def _check_inputs(args) -> dict:
    """Every input path of the subcommand exists, is a file (or an allowed folder)
    and, for the kinds of :data:`INPUT_KINDS`, reads as one; ValueError otherwise.
    Returns the depth files it read, path (str, as given) -> DepthMap, which the
    stage is given instead of reading them again."""
    maps = {}
    for name in INPUTS.get(args.command, ()):
        value = getattr(args, name, None)
        kind = SAME_AS_KINDS.get(args.command) if name == "same_as" else INPUT_KINDS.get(name)
        positional = name in POSITIONAL or f"{args.command}:{name}" in POSITIONAL
        option = name if positional else "--" + name.replace("_", "-")
        paths = value if isinstance(value, list) else [value]
        if f"{args.command}:{name}" in KEY_PATHS:
            paths = list(_pairs(paths, option).values())
        for path in paths:
            if path is None:
                continue
            problem = _input_problem(Path(path), kind, name in FOLDER_INPUTS, maps)
            if problem:
                raise ValueError(f"{option} {path}: {problem}")
    if args.command == "reconstruct":
        _check_maps(args)
    return maps


def _check_maps(args) -> None:
    """reconstruct's --photometric and --chromaticity hold a map of the image size for
    every Helmholtz camera (``<camera>/<colour>``) or camera (``<camera>``) of the
    dataset's rig (docs/results-layout.md); ValueError naming what is missing."""
    if args.photometric is None and args.chromaticity is None:
        return
    import h5py

    from colourhs.capture import COLOURS, load_rig

    rig = load_rig(args.rig or Path(args.dataset) / "rig.json")
    pairs = rig.reciprocal_pairs()
    need = {
        "photometric": [f"{p.cam_a}/{COLOURS[p.channel_a]}" for p in pairs]
        + [f"{p.cam_b}/{COLOURS[p.channel_b]}" for p in pairs],
        "chromaticity": list(rig.camera_names),
    }
    size = (rig.image.height, rig.image.width)
    for name, keys in need.items():
        path = getattr(args, name)
        if path is None:
            continue
        with h5py.File(path, "r") as f:
            missing = [k for k in keys if not isinstance(f.get(k), h5py.Dataset)]
            shapes = {k: f[k].shape[:2] for k in keys if k not in missing}
            holds = ", ".join(sorted(f))
        if missing:
            raise ValueError(
                f"--{name} {path}: no map {', '.join(missing)} of this rig's cameras "
                f"(the file holds: {holds or 'nothing'})"
            )
        wrong = [f"{k} {h}x{w}" for k, (h, w) in shapes.items() if (h, w) != size]
        if wrong:
            raise ValueError(
                f"--{name} {path}: maps of another image size ({', '.join(wrong)} pixels, "
                f"rig.json says {size[0]}x{size[1]})"
            )


def main(argv: list[str] | None = None) -> int:
    """Run a subcommand. Exit status: 0 done; 1 an error in the input (one line on
    stderr naming the file or name and what exists); 2 a usage error (argparse)."""
    if os.environ.get("COLOURHS_AUDIT_READS"):  # opt-in, for tests/workflow/test_workflow.py
        from colourhs.common.files import record_reads

        record_reads(os.environ["COLOURHS_AUDIT_READS"])
    line_buffered()  # stdout reaches a job's log line by line, beside stderr's progress
    argv = list(sys.argv[1:] if argv is None else argv)
    command_line, extra = ["colourhs", *argv], []
    if "--" in argv:
        k = argv.index("--")
        argv, extra = argv[:k], argv[k + 1 :]
    # --help of reconstruct or photometric shows their defaults (imports that stage only).
    asks_help = bool({"-h", "--help"} & set(argv))
    args = build_parser(show_defaults=set(argv) if asks_help else False).parse_args(argv)
    args.snakemake_args, args.command_line = extra, command_line
    # Every stage's progress lines and bars on stderr: at a terminal, and in a rule's log.
    show_progress(level=logging.WARNING if args.quiet else logging.INFO)
    try:
        args.depth_maps = _check_inputs(args)  # read once: the stage is given them
        return args.func(args)
    except USER_ERRORS as e:  # CaptureFormatError is a ValueError
        print(f"colourhs {args.command}: {e}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
