"""colourhs: the Colour Helmholtz Stereopsis workflow.

Stages (one rule file each under workflow/rules/): raw captures -> validation
-> marker poses -> photometric maps -> chromaticity maps -> per-frame
depth/normal -> visual hull and Poisson meshes -> evaluation -> figures and
report (reports/NAME/index.html).
"""

from snakemake.utils import min_version, validate

min_version("9.0")


configfile: "config.yaml"


# The schema's defaults fill in what the config leaves out (common.smk reads them).
validate(config, "workflow/schemas/config.schema.yaml", set_default=True)


# Dataset and scene names are single path components, so a dataset's own files
# (data/synthetic/demo/rig.json) never match a rule's output pattern.
wildcard_constraints:
    name="[A-Za-z0-9_-]+",
    scene="[A-Za-z0-9_-]+",


include: "workflow/rules/common.smk"
include: "workflow/rules/synth.smk"
include: "workflow/rules/capture.smk"
include: "workflow/rules/calibration.smk"
include: "workflow/rules/reconstruct.smk"
include: "workflow/rules/surfaces.smk"
include: "workflow/rules/evaluate.smk"
include: "workflow/rules/report.smk"


report: "workflow/report/workflow.rst"


# A malformed dataset stops the run before any stage, with the validator's
# message (the file and the problem): common.smk's check_captures. Checked here
# rather than by making every rule depend on validate_dataset's summary: as an
# `ancient` input that stops Snakemake 9.27 from rerunning a changed image's own
# jobs (it masks the dependents of a job that must run, then skips them for the
# ancient input), and as a plain input every stage would rerun whenever any
# capture file changes.
onstart:
    check_captures()


rule all:
    default_target: True
    input:
        expand(CAPTURE_SUMMARY, name=DATASETS),
        [t for name in DATASETS for t in calibration_targets(name)],
        lambda w: [t for name in DATASETS for t in reconstruction_targets(name)],
        lambda w: [t for name in DATASETS for t in report_targets(name)],
