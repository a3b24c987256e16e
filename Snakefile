"""colourhs: the Colour Helmholtz Stereopsis workflow.

Stages (one rule file each under workflow/rules/): raw captures -> validation
-> marker poses -> photometric maps -> chromaticity maps -> per-frame
depth/normal -> visual hull and Poisson meshes -> evaluation -> figures and
report (reports/NAME/index.html).
"""

from snakemake.utils import min_version, validate

min_version("9.0")


configfile: "config.yaml"


validate(config, "workflow/schemas/config.schema.yaml")


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


rule all:
    default_target: True
    input:
        expand("results/{name}/capture/summary.json", name=DATASETS),
        [t for name in DATASETS for t in calibration_targets(name)],
        lambda w: [t for name in DATASETS for t in reconstruction_targets(name)],
        lambda w: [t for name in DATASETS for t in report_targets(name)],
