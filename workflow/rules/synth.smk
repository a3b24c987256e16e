# Synthetic datasets: rendered into data/synthetic/<name> only when absent.


checkpoint synth_dataset:
    output:
        directory(SYNTH_DATASET),
    log:
        LOGS["synth_dataset"],
    benchmark:
        BENCHMARKS["synth_dataset"]
    threads: 2
    resources:
        mem_mb=4000,
        runtime=30,
    params:
        preset=lambda w: synth_settings(w.name)["preset"],
        seed=lambda w: synth_settings(w.name)["seed"],
        parts=lambda w: synth_settings(w.name)["parts"],
    shell:
        '"$COLOURHS_PYTHON" -m colourhs synth --preset {params.preset} --seed {params.seed} '
        "--parts {params.parts} --workers {threads} {output:q} 2> {log:q}"
