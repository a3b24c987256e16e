# Figures and the evaluation report reports/NAME/index.html.


rule effective_config:
    output:
        CONFIG,
    log:
        LOGS["effective_config"],
    threads: 1
    resources:
        mem_mb=500,
        runtime=2,
    params:
        config=lambda w: json.dumps(config, sort_keys=True),
    shell:
        '"$COLOURHS_PYTHON" -m colourhs config {params.config:q} {output:q} > {log:q} 2>&1'


rule scene_figures:
    input:
        unpack(lambda w: figure_inputs(w.name, w.scene)),
    output:
        report(
            directory(FIGURES),
            patterns=["{fig}.png"],
            caption="../report/scene_figures.rst",
            category="Figures",
            subcategory="{scene}",
        ),
    log:
        LOGS["scene_figures"],
    benchmark:
        BENCHMARKS["scene_figures"]
    threads: 1
    # Resources cover one job at the paper preset's 1280x960 (benchmarks/bench_paper.py
    # measures every rule's memory and time).
    resources:
        mem_mb=1500,
        runtime=10,
    params:
        options=lambda w: figure_options(w.name, w.scene),
    shell:
        '"$COLOURHS_PYTHON" -m colourhs figures {output:q} {params.options} > {log:q} 2>&1'


rule report:
    input:
        unpack(lambda w: report_inputs(w.name)),
    output:
        html=report(
            REPORT,
            caption="../report/index.rst",
            category="Evaluation",
        ),
        # the images it shows from outside its folder, copied: the folder stands alone
        assets=directory(REPORT_ASSETS),
    log:
        LOGS["report"],
    threads: 1
    # Resources cover one job at the paper preset's 1280x960 (benchmarks/bench_paper.py
    # measures every rule's memory and time).
    resources:
        mem_mb=1000,
        runtime=5,
    params:
        figures=lambda w: " ".join(
            shlex.quote(f"{Path(d).name}={d}")
            for d in report_inputs(w.name)["figures"]
        ),
        dataset=lambda w: dataset_path(w.name),
        rig=lambda w: rig_option(w.name),
        results=RESULTS_DIR,
        calib=CALIB_DIR,
        benchmarks=BENCHMARK_ROOT,
    shell:
        '"$COLOURHS_PYTHON" -m colourhs report {output.html:q} --name {wildcards.name} '
        "--metrics {input.metrics:q} --config {input.config:q} "
        "--calibration {input.calibration:q} --figures {params.figures} "
        "--dataset {params.dataset:q} {params.rig} --results {params.results:q} "
        "--calib {params.calib:q} --view "
        "--benchmarks {params.benchmarks:q} > {log:q} 2>&1"
