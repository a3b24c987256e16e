# Evaluation (paper section IV): RMS Hausdorff distance of each mesh to the
# ground truth over what the reference camera saw, depth and normal errors,
# and the tidy table reports/NAME/metrics.csv.


rule evaluate_frame:
    input:
        depth="results/{name}/{scene}/{variant}/depth/{frame}.h5",
        mesh="results/{name}/{scene}/{variant}/mesh/{frame}.ply",
        gt=lambda w: gt_mesh(w.name, w.scene, w.frame),
        same=lambda w: same_result(w.name, w.scene, w.variant, w.frame, "eval"),
        # The equal result's error-coloured mesh, copied with its metrics JSON.
        same_ply=lambda w: [
            str(Path(p).with_suffix(".ply"))
            for p in same_result(w.name, w.scene, w.variant, w.frame, "eval")
        ],
    output:
        json="results/{name}/{scene}/{variant}/eval/{frame}.json",
        ply="results/{name}/{scene}/{variant}/eval/{frame}.ply",
    log:
        "logs/evaluate/{name}/{scene}/{variant}/{frame}.log",
    benchmark:
        "benchmarks/snakemake/evaluate_frame/{name}/{scene}/{variant}/{frame}.tsv"
    wildcard_constraints:
        frame="[0-9]{6}",
    threads: 1
    # Resources cover one job at the paper preset's 1280x960 (benchmarks/bench_paper.py
    # measures every rule's memory and time).
    resources:
        mem_mb=1500,
        runtime=10,
    params:
        gt=lambda w, input: f"--gt {shlex.quote(str(input.gt))}" if input.gt else "",
        options=lambda w: cli_options(config["evaluation"]),
        same=lambda w, input: same_option(input),
    shell:
        '"$COLOURHS_PYTHON" -m colourhs evaluate {input.depth:q} {input.mesh:q} {output.json:q} {params.gt} '
        "--coloured {output.ply:q} --scene {wildcards.scene} --frame {wildcards.frame} "
        "--variant {wildcards.variant} {params.options} {params.same} > {log:q} 2>&1"


rule metrics_table:
    input:
        lambda w: evaluation_targets(w.name),
    output:
        report(
            "reports/{name}/metrics.csv",
            caption="../report/metrics.rst",
            category="Evaluation",
        ),
    log:
        "logs/evaluate/{name}/metrics.log",
    benchmark:
        "benchmarks/snakemake/metrics_table/{name}.tsv"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    shell:
        '"$COLOURHS_PYTHON" -m colourhs metrics {input:q} {output:q} > {log:q} 2>&1'
