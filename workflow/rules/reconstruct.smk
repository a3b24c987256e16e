# Reconstruction: one job per scene x frame x variant (results contract ids).


rule reconstruct_frame:
    input:
        images=lambda w: frame_inputs(w.name, w.scene, w.frame),
        calib=lambda w: variant_calibration(w.name, w.scene, w.variant).values(),
    output:
        "results/{name}/{scene}/{variant}/depth/{frame}.h5",
    log:
        "logs/reconstruct/{name}/{scene}/{variant}/{frame}.log",
    benchmark:
        "benchmarks/snakemake/reconstruct/{name}/{scene}/{variant}/{frame}.tsv"
    wildcard_constraints:
        variant="ml_full|bayes_nocalib|bayes_ph|bayes_full",
        frame="[0-9]{6}",
    conda:
        "../envs/colourhs.yaml"
    threads: 2
    resources:
        mem_mb=3000,
        runtime=10,
    params:
        dataset=lambda w: dataset_path(w.name),
        options=lambda w: reconstruct_options(w.name, w.scene, w.variant),
    shell:
        "$COLOURHS_PYTHON -m colourhs reconstruct {params.dataset} {wildcards.scene} {wildcards.frame} "
        "{output} {params.options} > {log} 2>&1"
