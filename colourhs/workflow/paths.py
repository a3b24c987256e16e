"""Every path the workflow writes, as Snakemake path templates: the results layout.

One table of the files that ``docs/results-layout.md`` lists (its contract), for
the rules (``workflow/rules/*.smk`` take the templates as their outputs, inputs,
logs and benchmarks) and for :class:`colourhs.workflow.plan.WorkflowPlan` (which
fills them in with :func:`fill` for the jobs' targets and inputs), so that a rule and
the plan cannot name one file two ways. Paths are relative to the folder the workflow
runs in.

A template names its wildcards as Snakemake does: ``{name}`` (the dataset),
``{object}`` (a chromatic object), ``{scene}``, ``{variant}`` (an id of
:data:`colourhs.workflow.variants.VARIANTS`) and ``{frame}``; what each wildcard may
match is the rules' business (``wildcard_constraints``).
"""

from __future__ import annotations

import re

# ---------------------------------------------------------------- results/NAME

#: A dataset's results folder (the report links its files).
RESULTS_DIR = "results/{name}"
#: ``colourhs run``'s configuration overlay.
RUN_CONFIG = "results/{name}/run-config.yaml"
#: The run's effective configuration (rule effective_config).
CONFIG = "results/{name}/config.yaml"
#: The capture's validation summary (rule validate_dataset).
CAPTURE_SUMMARY = "results/{name}/capture/summary.json"

#: The calibration folder (the report's diagnostics read it).
CALIB_DIR = "results/{name}/calib"
#: The rig calibrated from the dataset's geometric/ captures and its report (rule
#: calibrate_rig, when calibration.calibrate_rig is on: every stage then reads it).
RIG = "results/{name}/calib/rig.json"
RIG_REPORT = "results/{name}/calib/rig_report.json"
#: One row per usable board pose (rule marker_poses).
MARKER_POSES = "results/{name}/calib/marker_poses.csv"
#: Channel mixing per camera (rule crosstalk).
CROSSTALK = "results/{name}/calib/crosstalk.json"
#: The sensor noise model (rule noise_model).
NOISE = "results/{name}/calib/noise.json"
#: The mu maps and their heat maps (rule photometric_maps).
PHOTOMETRIC = "results/{name}/calib/photometric.h5"
PHOTOMETRIC_PNG = "results/{name}/calib/photometric.png"
#: A chromatic object's chromaticity maps and their figure (rule chromaticity_map).
CHROMATICITY = "results/{name}/calib/chromaticity/{object}.h5"
CHROMATICITY_PNG = "results/{name}/calib/chromaticity/{object}.png"

#: A frame's chromaticity maps, carried from the chromatic frame (rule
#: track_chromaticity; variant bayes_dyn reads them).
TRACKED_CHROMATICITY = "results/{name}/{scene}/chromaticity/{frame}.h5"
#: A frame's visual hull mesh (rule visual_hull).
HULL = "results/{name}/{scene}/hull/{frame}.ply"
#: A variant's depth file of a frame (rule reconstruct_frame; visual_hull for vh).
DEPTH = "results/{name}/{scene}/{variant}/depth/{frame}.h5"
#: A variant's Poisson mesh of a frame (rule frame_mesh).
MESH = "results/{name}/{scene}/{variant}/mesh/{frame}.ply"
#: A variant's metrics of a frame and its mesh coloured by the error (rule evaluate_frame).
EVAL_JSON = "results/{name}/{scene}/{variant}/eval/{frame}.json"
EVAL_PLY = "results/{name}/{scene}/{variant}/eval/{frame}.ply"

#: The visual hull variant's depth file (rule visual_hull writes it with the hull mesh).
VH_DEPTH = DEPTH.replace("{variant}", "vh")

#: A frame's result of one variant by kind (a folder of results/NAME/SCENE/VARIANT/;
#: ``coloured``: the error-coloured mesh beside ``eval``'s metrics).
FRAME_RESULTS = {"depth": DEPTH, "mesh": MESH, "eval": EVAL_JSON, "coloured": EVAL_PLY}

# ---------------------------------------------------------------- reports/NAME

#: The tidy metrics table, one row per scene, frame and variant (rule metrics_table).
METRICS = "reports/{name}/metrics.csv"
#: A scene's figures folder (rule scene_figures).
FIGURES = "reports/{name}/figures/{scene}"
#: The evaluation report (rule report).
REPORT = "reports/{name}/index.html"
#: Its copies of the images it shows from outside its folder (rule report).
REPORT_ASSETS = "reports/{name}/assets"

# ---------------------------------------------------------------- datasets

#: A synthetic dataset's folder, rendered when absent (checkpoint synth_dataset).
SYNTH_DATASET = "data/synthetic/{name}"

# ---------------------------------------------------------------- logs and benchmarks

#: Rule -> its job's log.
LOGS = {
    "synth_dataset": "logs/synth/{name}.log",
    "validate_dataset": "logs/capture/{name}.log",
    "calibrate_rig": "logs/calib/{name}/rig.log",
    "marker_poses": "logs/calib/{name}/marker_poses.log",
    "crosstalk": "logs/calib/{name}/crosstalk.log",
    "noise_model": "logs/calib/{name}/noise.log",
    "photometric_maps": "logs/calib/{name}/photometric.log",
    "chromaticity_map": "logs/calib/{name}/chromaticity/{object}.log",
    "track_chromaticity": "logs/calib/{name}/{scene}/chromaticity/{frame}.log",
    "visual_hull": "logs/surfaces/{name}/{scene}/hull/{frame}.log",
    "reconstruct_frame": "logs/reconstruct/{name}/{scene}/{variant}/{frame}.log",
    "frame_mesh": "logs/surfaces/{name}/{scene}/{variant}/mesh/{frame}.log",
    "evaluate_frame": "logs/evaluate/{name}/{scene}/{variant}/{frame}.log",
    "metrics_table": "logs/evaluate/{name}/metrics.log",
    "effective_config": "logs/report/{name}/config.log",
    "scene_figures": "logs/report/{name}/figures/{scene}.log",
    "report": "logs/report/{name}/index.log",
}

#: Snakemake's timings of every job, one folder per rule (the report's table of run
#: times reads them all).
BENCHMARK_ROOT = "benchmarks/snakemake"


def _benchmark(folder: str, job: str) -> str:
    """A rule's benchmark template: BENCHMARK_ROOT/<folder>/<the job's wildcards>.tsv."""
    return f"{BENCHMARK_ROOT}/{folder}/{job}.tsv"


#: Rule -> its job's benchmark file (the rules whose timings the report shows).
BENCHMARKS = {
    "synth_dataset": _benchmark("synth", "{name}"),
    "validate_dataset": _benchmark("validate_dataset", "{name}"),
    "calibrate_rig": _benchmark("calibrate_rig", "{name}"),
    "marker_poses": _benchmark("marker_poses", "{name}"),
    "crosstalk": _benchmark("crosstalk", "{name}"),
    "noise_model": _benchmark("noise_model", "{name}"),
    "photometric_maps": _benchmark("photometric_maps", "{name}"),
    "chromaticity_map": _benchmark("chromaticity_map", "{name}/{object}"),
    "track_chromaticity": _benchmark("track_chromaticity", "{name}/{scene}/{frame}"),
    "visual_hull": _benchmark("visual_hull", "{name}/{scene}/{frame}"),
    "reconstruct_frame": _benchmark("reconstruct_frame", "{name}/{scene}/{variant}/{frame}"),
    "frame_mesh": _benchmark("frame_mesh", "{name}/{scene}/{variant}/{frame}"),
    "evaluate_frame": _benchmark("evaluate_frame", "{name}/{scene}/{variant}/{frame}"),
    "metrics_table": _benchmark("metrics_table", "{name}"),
    "scene_figures": _benchmark("scene_figures", "{name}/{scene}"),
}

# ---------------------------------------------------------------- formatting

_WILDCARD = re.compile(r"\{(\w+)\}")


def wildcards(template: str) -> list[str]:
    """A template's wildcard names, in order of appearance."""
    return _WILDCARD.findall(template)


def fill(template: str, **values: str) -> str:
    """The concrete path of ``template`` for one value per wildcard.

    Every wildcard of the template must be given and nothing else, so that a
    misspelt or forgotten one fails here rather than naming a file no rule makes.

    Parameters
    ----------
    template : str
        A template of this module (``results/{name}/calib/noise.json``).
    **values : str
        The wildcards' values (``name="demo"``).

    Returns
    -------
    str
        The path (``results/demo/calib/noise.json``).
    """
    names = set(wildcards(template))
    if names != set(values):
        missing, unknown = sorted(names - set(values)), sorted(set(values) - names)
        raise ValueError(f"{template}: missing wildcards {missing}, unknown {unknown}")
    return _WILDCARD.sub(lambda m: str(values[m.group(1)]), template)
