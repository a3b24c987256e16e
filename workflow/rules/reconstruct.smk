# Reconstruction: one job per scene x frame x variant (results contract ids).


rule reconstruct_frame:
    input:
        dataset=lambda w: dataset_path(w.name),
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
    threads: 2
    resources:
        mem_mb=3000,
        runtime=10,
    params:
        options=lambda w: reconstruct_options(w.name, w.scene, w.variant),
    shell:
        "{PYTHON} -m colourhs reconstruct {input.dataset} {wildcards.scene} {wildcards.frame} "
        "{output} {params.options} > {log} 2>&1"
