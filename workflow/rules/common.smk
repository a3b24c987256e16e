# The rules' helpers: colourhs.workflow.plan.WorkflowPlan (dataset discovery with
# colourhs.capture.open_dataset, targets, inputs, command-line options) bound to
# this run's config, which the Snakefile validated with the schema's defaults set;
# every path a rule writes is a template of colourhs.workflow.paths (the results
# layout, docs/results-layout.md), which the plan fills in for the same files.
import json
import shlex
import sys
from pathlib import Path

from colourhs.workflow.paths import (
    BENCHMARK_ROOT,
    BENCHMARKS,
    CALIB_DIR,
    CAPTURE_SUMMARY,
    CHROMATICITY,
    CHROMATICITY_PNG,
    CONFIG,
    CROSSTALK,
    DEPTH,
    EVAL_JSON,
    EVAL_PLY,
    FIGURES,
    HULL,
    LOGS,
    MARKER_POSES,
    MESH,
    METRICS,
    NOISE,
    PHOTOMETRIC,
    PHOTOMETRIC_PNG,
    REPORT,
    REPORT_ASSETS,
    RESULTS_DIR,
    RIG,
    RIG_REPORT,
    SYNTH_DATASET,
    TRACKED_CHROMATICITY,
    VH_DEPTH,
)
from colourhs.workflow.plan import (
    HS_VARIANT_PATTERN,
    MalformedDatasetError,
    WorkflowPlan,
    cli_options,
    same_option,
)

# Rules run the package with the Python that runs Snakemake (the project's venv,
# which on a cluster sits on the shared file system and serves every node); the
# path is quoted, so it may contain spaces. There is no conda environment: no
# conda channel is reachable where the project is built and tested (README).
shell.prefix(f"export COLOURHS_PYTHON={shlex.quote(sys.executable)}; ")

# A synthetic dataset's folder exists once its checkpoint (synth.smk) has run.
PLAN = WorkflowPlan(
    config, wait=lambda name: checkpoints.synth_dataset.get(name=name).output[0]
)
# A path dataset's folders, rig.json and scene.json files are checked before the
# jobs are planned (cheap: no image is opened; check_captures opens them).
PLAN.check_layouts()
DATASETS = PLAN.datasets

# What the rules call (documented in colourhs/workflow/plan.py).
dataset_path = PLAN.dataset_path
synth_settings = PLAN.synth_settings
capture_files = PLAN.capture_files
photometric_inputs = PLAN.photometric_inputs
chromatic_inputs = PLAN.chromatic_inputs
chromaticity_inputs = PLAN.chromaticity_inputs
calibration = PLAN.calibration
geometric_inputs = PLAN.geometric_inputs
rig_option = PLAN.rig_option
crosstalk_file = PLAN.crosstalk_file
photometric_options = PLAN.photometric_options
calibration_targets = PLAN.calibration_targets
frame_inputs = PLAN.frame_inputs
variant_calibration = PLAN.variant_calibration
tracking_inputs = PLAN.tracking_inputs
reconstruction_hull = PLAN.reconstruction_hull
reconstruct_options = PLAN.reconstruct_options
same_result = PLAN.same_result
reconstruction_targets = PLAN.reconstruction_targets
silhouette_inputs = PLAN.silhouette_inputs
mesh_hull = PLAN.mesh_hull
gt_mesh = PLAN.gt_mesh
evaluation_targets = PLAN.evaluation_targets
figure_inputs = PLAN.figure_inputs
figure_options = PLAN.figure_options
report_inputs = PLAN.report_inputs
report_targets = PLAN.report_targets


def check_captures():
    """The onstart check: every path dataset whose validation summary is missing or
    stale is validated; a malformed one stops the run with the validator's message."""
    from snakemake.exceptions import WorkflowError

    try:
        PLAN.check_captures()
    except MalformedDatasetError as e:
        raise WorkflowError(str(e))
