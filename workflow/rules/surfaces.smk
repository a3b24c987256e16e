# Surfaces (paper section IV-A): the visual hull of each frame (the `vh`
# variant, and the closing points of the meshes), then one Poisson mesh per
# scene x frame x variant from the oriented points of its depth file.


rule visual_hull:
    input:
        lambda w: silhouette_inputs(w.name, w.scene, w.frame),
    output:
        ply=HULL,
        depth=VH_DEPTH,
    log:
        LOGS["visual_hull"],
    benchmark:
        BENCHMARKS["visual_hull"]
    wildcard_constraints:
        frame="[0-9]{6}",
    # Before the reconstructions (priority 1) that read it.
    priority: 2
    threads: 1
    # Resources cover one job at the paper preset's 1280x960 (benchmarks/bench_paper.py
    # measures every rule's memory and time).
    resources:
        mem_mb=3000,
        runtime=10,
    params:
        dataset=lambda w: dataset_path(w.name),
        rig=lambda w: rig_option(w.name),
        options=lambda w: cli_options(config["surfaces"]["hull"]),
    shell:
        '"$COLOURHS_PYTHON" -m colourhs hull {params.dataset:q} {params.rig} {wildcards.scene} {wildcards.frame} '
        "{output.ply:q} --depth {output.depth:q} {params.options} > {log:q} 2>&1"


rule frame_mesh:
    input:
        depth=DEPTH,
        hull=lambda w: mesh_hull(w.name, w.scene, w.variant, w.frame),
        same=lambda w: same_result(w.name, w.scene, w.variant, w.frame, "mesh"),
    output:
        MESH,
    log:
        LOGS["frame_mesh"],
    benchmark:
        BENCHMARKS["frame_mesh"]
    wildcard_constraints:
        frame="[0-9]{6}",
    threads: 1
    # Resources cover one job at the paper preset's 1280x960 (benchmarks/bench_paper.py
    # measures every rule's memory and time).
    resources:
        mem_mb=1000,
        runtime=10,
    params:
        hull=lambda w, input: (
            f"--hull {shlex.quote(str(input.hull))}" if input.hull else ""
        ),
        options=lambda w: cli_options(config["surfaces"]["mesh"]),
        same=lambda w, input: same_option(input),
    shell:
        '"$COLOURHS_PYTHON" -m colourhs mesh {input.depth:q} {output:q} {params.hull} {params.options} '
        "{params.same} > {log:q} 2>&1"
