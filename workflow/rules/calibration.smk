# Calibration stages (paper sections III-C and III-D, and channel cross-talk):
# marker poses -> photometric (mu) maps; chromaticity maps per coloured object.


rule marker_poses:
    input:
        lambda w: photometric_inputs(w.name),
    output:
        "results/{name}/calib/marker_poses.csv",
    log:
        "logs/calib/{name}/marker_poses.log",
    benchmark:
        "benchmarks/snakemake/marker_poses/{name}.tsv"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    params:
        dataset=lambda w: dataset_path(w.name),
    shell:
        '"$COLOURHS_PYTHON" -m colourhs markers {params.dataset:q} {output:q} > {log:q} 2>&1'


rule crosstalk:
    input:
        images=lambda w: chromatic_inputs(w.name, "white") + photometric_inputs(w.name),
        poses="results/{name}/calib/marker_poses.csv",
    output:
        "results/{name}/calib/crosstalk.json",
    log:
        "logs/calib/{name}/crosstalk.log",
    benchmark:
        "benchmarks/snakemake/crosstalk/{name}.tsv"
    threads: 1
    # Resources cover one job at the paper preset's 1280x960 (benchmarks/bench_paper.py
    # measures every rule's memory and time).
    resources:
        mem_mb=2500,
        runtime=5,
    params:
        dataset=lambda w: dataset_path(w.name),
    shell:
        '"$COLOURHS_PYTHON" -m colourhs crosstalk {params.dataset:q} {output:q} --poses {input.poses:q} > {log:q} 2>&1'


rule noise_model:
    input:
        lambda w: photometric_inputs(w.name) + chromatic_inputs(w.name, "white"),
    output:
        "results/{name}/calib/noise.json",
    log:
        "logs/calib/{name}/noise.log",
    benchmark:
        "benchmarks/snakemake/noise_model/{name}.tsv"
    threads: 1
    # Resources cover one job at the paper preset's 1280x960 (benchmarks/bench_paper.py
    # measures every rule's memory and time).
    resources:
        mem_mb=1000,
        runtime=5,
    params:
        dataset=lambda w: dataset_path(w.name),
    shell:
        '"$COLOURHS_PYTHON" -m colourhs noise {params.dataset:q} {output:q} > {log:q} 2>&1'


rule photometric_maps:
    input:
        images=lambda w: photometric_inputs(w.name),
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
        "benchmarks/snakemake/photometric_maps/{name}.tsv"
    threads: 1
    # Resources cover one job at the paper preset's 1280x960 (benchmarks/bench_paper.py
    # measures every rule's memory and time).
    resources:
        mem_mb=2000,
        runtime=20,
    params:
        dataset=lambda w: dataset_path(w.name),
        options=lambda w, input: photometric_options(w.name, input.crosstalk),
    shell:
        '"$COLOURHS_PYTHON" -m colourhs photometric {params.dataset:q} {input.poses:q} {output.h5:q} '
        "--figure {output.png:q} {params.options} > {log:q} 2>&1"


rule chromaticity_map:
    input:
        lambda w: chromaticity_inputs(w.name, w.object),
    output:
        h5="results/{name}/calib/chromaticity/{object}.h5",
        png="results/{name}/calib/chromaticity/{object}.png",
    log:
        "logs/calib/{name}/chromaticity/{object}.log",
    benchmark:
        "benchmarks/snakemake/chromaticity_map/{name}/{object}.tsv"
    wildcard_constraints:
        object="[A-Za-z0-9_-]+",
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    params:
        dataset=lambda w: dataset_path(w.name),
        options=lambda w: cli_options(calibration(w.name)["chromaticity"]),
    shell:
        '"$COLOURHS_PYTHON" -m colourhs chromaticity {params.dataset:q} {wildcards.object} {output.h5:q} '
        "--figure {output.png:q} {params.options} > {log:q} 2>&1"
