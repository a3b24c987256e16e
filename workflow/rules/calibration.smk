# Calibration stages (paper sections III-C and III-D, and channel cross-talk):
# marker poses -> photometric (mu) maps; chromaticity maps per coloured object.
# With calibration.calibrate_rig, the cameras first (beyond the paper): every
# stage then reads results/NAME/calib/rig.json (--rig) instead of the dataset's.


rule calibrate_rig:
    input:
        lambda w: geometric_inputs(w.name),
    output:
        rig=RIG,
        report=RIG_REPORT,
    log:
        LOGS["calibrate_rig"],
    benchmark:
        BENCHMARKS["calibrate_rig"]
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    params:
        dataset=lambda w: dataset_path(w.name),
        world=lambda w: calibration(w.name)["rig_world"],
    shell:
        '"$COLOURHS_PYTHON" -m colourhs calibrate-rig {params.dataset:q} {output.rig:q} '
        "--world {params.world:q} --report {output.report:q} > {log:q} 2>&1"


rule marker_poses:
    input:
        lambda w: photometric_inputs(w.name),
    output:
        MARKER_POSES,
    log:
        LOGS["marker_poses"],
    benchmark:
        BENCHMARKS["marker_poses"]
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    params:
        dataset=lambda w: dataset_path(w.name),
        rig=lambda w: rig_option(w.name),
    shell:
        '"$COLOURHS_PYTHON" -m colourhs markers {params.dataset:q} {params.rig} {output:q} > {log:q} 2>&1'


rule crosstalk:
    input:
        images=lambda w: chromatic_inputs(w.name, "white") + photometric_inputs(w.name),
        poses=MARKER_POSES,
    output:
        CROSSTALK,
    log:
        LOGS["crosstalk"],
    benchmark:
        BENCHMARKS["crosstalk"]
    threads: 1
    # Resources cover one job at the paper preset's 1280x960 (benchmarks/bench_paper.py
    # measures every rule's memory and time).
    resources:
        mem_mb=2500,
        runtime=5,
    params:
        dataset=lambda w: dataset_path(w.name),
        rig=lambda w: rig_option(w.name),
    shell:
        '"$COLOURHS_PYTHON" -m colourhs crosstalk {params.dataset:q} {params.rig} {output:q} --poses {input.poses:q} > {log:q} 2>&1'


rule noise_model:
    input:
        lambda w: photometric_inputs(w.name) + chromatic_inputs(w.name, "white"),
    output:
        NOISE,
    log:
        LOGS["noise_model"],
    benchmark:
        BENCHMARKS["noise_model"]
    threads: 1
    # Resources cover one job at the paper preset's 1280x960 (benchmarks/bench_paper.py
    # measures every rule's memory and time).
    resources:
        mem_mb=1000,
        runtime=5,
    params:
        dataset=lambda w: dataset_path(w.name),
        rig=lambda w: rig_option(w.name),
    shell:
        '"$COLOURHS_PYTHON" -m colourhs noise {params.dataset:q} {params.rig} {output:q} > {log:q} 2>&1'


rule photometric_maps:
    input:
        images=lambda w: photometric_inputs(w.name),
        poses=MARKER_POSES,
        crosstalk=lambda w: crosstalk_file(w.name),
    output:
        h5=PHOTOMETRIC,
        png=PHOTOMETRIC_PNG,
    log:
        LOGS["photometric_maps"],
    benchmark:
        BENCHMARKS["photometric_maps"]
    threads: 1
    # Resources cover one job at the paper preset's 1280x960 (benchmarks/bench_paper.py
    # measures every rule's memory and time).
    resources:
        mem_mb=2000,
        runtime=20,
    params:
        dataset=lambda w: dataset_path(w.name),
        rig=lambda w: rig_option(w.name),
        options=lambda w: photometric_options(w.name),
    shell:
        '"$COLOURHS_PYTHON" -m colourhs photometric {params.dataset:q} {params.rig} {input.poses:q} {output.h5:q} '
        "--figure {output.png:q} {params.options} > {log:q} 2>&1"


rule chromaticity_map:
    input:
        captures=lambda w: chromaticity_inputs(w.name, w.object),
        noise=NOISE,
    output:
        h5=CHROMATICITY,
        png=CHROMATICITY_PNG,
    log:
        LOGS["chromaticity_map"],
    benchmark:
        BENCHMARKS["chromaticity_map"]
    wildcard_constraints:
        object="[A-Za-z0-9_-]+",
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    params:
        dataset=lambda w: dataset_path(w.name),
        rig=lambda w: rig_option(w.name),
        options=lambda w: cli_options(calibration(w.name)["chromaticity"]),
    shell:
        '"$COLOURHS_PYTHON" -m colourhs chromaticity {params.dataset:q} {params.rig} {wildcards.object} {output.h5:q} '
        "--noise {input.noise:q} --figure {output.png:q} {params.options} > {log:q} 2>&1"


# Beyond the paper: a moving object's chromaticity carried from its chromatic frame
# to each frame of the sequence, in frame order (each frame reads its neighbour's
# maps towards the chromatic frame: a changed frame reruns it and those after it).
rule track_chromaticity:
    input:
        unpack(lambda w: tracking_inputs(w.name, w.scene, w.frame)),
    output:
        TRACKED_CHROMATICITY,
    log:
        LOGS["track_chromaticity"],
    benchmark:
        BENCHMARKS["track_chromaticity"]
    wildcard_constraints:
        frame="[0-9]{6}",
    threads: 1
    resources:
        mem_mb=1500,
        runtime=5,
    params:
        dataset=lambda w: dataset_path(w.name),
        rig=lambda w: rig_option(w.name),
        neighbour=lambda w, input: (
            f"--neighbour {shlex.quote(str(input.neighbour))}"
            if "neighbour" in input.keys()
            else ""
        ),
    shell:
        '"$COLOURHS_PYTHON" -m colourhs track-chromaticity {params.dataset:q} {params.rig} '
        "{wildcards.scene} {wildcards.frame} {output:q} --calibrated {input.calibrated:q} "
        "{params.neighbour} > {log:q} 2>&1"
