# Raw captures: validate every dataset against the capture format.


rule validate_dataset:
    input:
        lambda w: dataset_path(w.name),
    output:
        "results/{name}/capture/summary.json",
    log:
        "logs/capture/{name}.log",
    conda:
        "../envs/colourhs.yaml"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    shell:
        "$COLOURHS_PYTHON -m colourhs validate {input} --summary {output} > {log} 2>&1"
