# Evaluation (paper section IV): RMS Hausdorff distance of each mesh to the
# ground truth over what the reference camera saw, depth and normal errors,
# and the tidy table reports/NAME/metrics.csv.


rule evaluate_frame:
    input:
        depth=DEPTH,
        mesh=MESH,
        gt=lambda w: gt_mesh(w.name, w.scene, w.frame),
        same=lambda w: same_result(w.name, w.scene, w.variant, w.frame, "eval"),
        # The equal result's error-coloured mesh, copied with its metrics JSON.
        same_ply=lambda w: same_result(w.name, w.scene, w.variant, w.frame, "coloured"),
    output:
        json=EVAL_JSON,
        ply=EVAL_PLY,
    log:
        LOGS["evaluate_frame"],
    benchmark:
        BENCHMARKS["evaluate_frame"]
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
            METRICS,
            caption="../report/metrics.rst",
            category="Evaluation",
        ),
    log:
        LOGS["metrics_table"],
    benchmark:
        BENCHMARKS["metrics_table"]
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    shell:
        '"$COLOURHS_PYTHON" -m colourhs metrics {input:q} {output:q} > {log:q} 2>&1'
