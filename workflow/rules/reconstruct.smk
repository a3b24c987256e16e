# Reconstruction: one job per scene x frame x variant (results contract ids).


rule reconstruct_frame:
    input:
        images=lambda w: frame_inputs(w.name, w.scene, w.frame),
        calib=lambda w: variant_calibration(
            w.name, w.scene, w.variant, w.frame
        ).values(),
        hull=lambda w: reconstruction_hull(w.name, w.scene, w.frame),
        same=lambda w: same_result(w.name, w.scene, w.variant, w.frame, "depth"),
    output:
        DEPTH,
    log:
        LOGS["reconstruct_frame"],
    benchmark:
        BENCHMARKS["reconstruct_frame"]
    wildcard_constraints:
        variant=HS_VARIANT_PATTERN,
        frame="[0-9]{6}",
    # The longest jobs of the workflow start first (after the hulls they read),
    # so the run does not end on one reconstruction with a core idle.
    priority: 1
    # One thread: two frames at once keep both cores busy (the solver and the
    # refinement are serial); raise with --set-threads reconstruct_frame=N.
    threads: 1
    # Resources cover one job at the paper preset's 1280x960 (benchmarks/bench_paper.py
    # measures every rule's memory and time).
    resources:
        mem_mb=3000,
        runtime=10,
    params:
        dataset=lambda w: dataset_path(w.name),
        rig=lambda w: rig_option(w.name),
        options=lambda w: reconstruct_options(w.name, w.scene, w.variant, w.frame),
        hull=lambda w, input: (
            f"--hull {shlex.quote(str(input.hull))}" if input.hull else ""
        ),
        same=lambda w, input: same_option(input),
    shell:
        'NUMBA_NUM_THREADS={threads} "$COLOURHS_PYTHON" -m colourhs reconstruct {params.dataset:q} {params.rig} {wildcards.scene} {wildcards.frame} '
        "{output:q} {params.options} {params.hull} {params.same} > {log:q} 2>&1"
