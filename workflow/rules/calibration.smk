# Calibration stages (paper sections III-C and III-D, and channel cross-talk):
# marker poses -> photometric (mu) maps; chromaticity maps per coloured object.


rule marker_poses:
    input:
        dataset=lambda w: dataset_path(w.name),
    output:
        "results/{name}/calib/marker_poses.csv",
    log:
        "logs/calib/{name}/marker_poses.log",
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    shell:
        "{PYTHON} -m colourhs markers {input.dataset} {output} > {log} 2>&1"


rule crosstalk:
    input:
        dataset=lambda w: dataset_path(w.name),
    output:
        "results/{name}/calib/crosstalk.json",
    log:
        "logs/calib/{name}/crosstalk.log",
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    shell:
        "{PYTHON} -m colourhs crosstalk {input.dataset} {output} > {log} 2>&1"


rule photometric_maps:
    input:
        dataset=lambda w: dataset_path(w.name),
        poses="results/{name}/calib/marker_poses.csv",
        crosstalk=lambda w: (
            f"results/{w.name}/calib/crosstalk.json" if unmix_crosstalk(w.name) else []
        ),
    output:
        h5="results/{name}/calib/photometric.h5",
        png="results/{name}/calib/photometric.png",
    log:
        "logs/calib/{name}/photometric.log",
    benchmark:
        "benchmarks/snakemake/photometric/{name}.tsv"
    threads: 1
    resources:
        mem_mb=4000,
        runtime=20,
    params:
        options=lambda w, input: photometric_options(w.name, input.crosstalk),
    shell:
        "{PYTHON} -m colourhs photometric {input.dataset} {input.poses} {output.h5} "
        "--figure {output.png} {params.options} > {log} 2>&1"


rule chromaticity_map:
    input:
        dataset=lambda w: dataset_path(w.name),
    output:
        h5="results/{name}/calib/chromaticity/{object}.h5",
        png="results/{name}/calib/chromaticity/{object}.png",
    log:
        "logs/calib/{name}/chromaticity/{object}.log",
    wildcard_constraints:
        object="[A-Za-z0-9_-]+",
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    params:
        min_signal=lambda w: calibration(w.name)["chromaticity"]["min_signal"],
    shell:
        "{PYTHON} -m colourhs chromaticity {input.dataset} {wildcards.object} {output.h5} "
        "--figure {output.png} --min-signal {params.min_signal} > {log} 2>&1"
