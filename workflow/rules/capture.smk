# Raw captures: validate every dataset against the capture format.


rule validate_dataset:
    input:
        lambda w: capture_files(w.name),
    output:
        CAPTURE_SUMMARY,
    log:
        LOGS["validate_dataset"],
    benchmark:
        BENCHMARKS["validate_dataset"]
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    params:
        dataset=lambda w: dataset_path(w.name),
    shell:
        '"$COLOURHS_PYTHON" -m colourhs validate {params.dataset:q} --summary {output:q} > {log:q} 2>&1'
