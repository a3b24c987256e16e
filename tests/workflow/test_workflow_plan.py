"""colourhs.workflow.plan: what the Snakemake rules read, make and pass on.

On the capture tests' small dataset (tests/capture_helpers.py; scene toy: one frame,
masks, ground truth, the chromatic object slinky; scene wave: two frames, nothing
else), with a config validated as the Snakefile does (the schema's defaults set).
"""

from __future__ import annotations

import json
import os
import re
import shutil
from pathlib import Path

import pytest
from capture_helpers import add_geometric, make_dataset
from snakemake.utils import validate

from colourhs.cli.parser import PROJECT_ROOT
from colourhs.workflow.paths import (
    CHROMATICITY,
    CHROMATICITY_PNG,
    CONFIG,
    CROSSTALK,
    DEPTH,
    EVAL_JSON,
    EVAL_PLY,
    FIGURES,
    FRAME_RESULTS,
    HULL,
    MARKER_POSES,
    MESH,
    METRICS,
    NOISE,
    PHOTOMETRIC,
    PHOTOMETRIC_PNG,
    REPORT,
    SYNTH_DATASET,
    fill,
)
from colourhs.workflow.plan import MalformedDatasetError, WorkflowPlan

SCHEMA = str(PROJECT_ROOT / "workflow" / "schemas" / "config.schema.yaml")


class NotRendered(Exception):
    """Stands for Snakemake's IncompleteCheckpointException."""


def not_rendered(name: str) -> str:
    raise NotRendered(name)


def plan_of(config: dict, wait=not_rendered) -> WorkflowPlan:
    validate(config, SCHEMA, set_default=True)
    return WorkflowPlan(config, wait)


@pytest.fixture(scope="module")
def data(tmp_path_factory) -> Path:
    return make_dataset(tmp_path_factory.mktemp("plan") / "my data")


@pytest.fixture
def plan(data) -> WorkflowPlan:
    return plan_of({"datasets": {"d": {"path": str(data)}}})


def test_schema_defaults_and_the_calibration_layers(data):
    config = {
        "datasets": {
            "d": {
                "path": str(data),
                "calibration": {"unmix_crosstalk": False, "photometric": {"smoothness": 0.001}},
            },
            "s": {"synth": {"preset": "tiny"}},
        },
        "calibration": {"photometric": {"coupling": 0.2}},
    }
    plan = plan_of(config)
    assert config["reconstruction"] == {
        "variants": None,
        "scenes": None,
        "depth_from_hull": False,
        "params": {},
    }
    assert config["surfaces"] == {"hull": {}, "mesh": {}, "mesh_with_hull": False}
    assert config["evaluation"] == {} and config["datasets"]["s"]["synth"]["seed"] == 0
    # The dataset's own calibration overrides only what it names (no defaults of its own).
    assert set(config["datasets"]["d"]["calibration"]) == {"unmix_crosstalk", "photometric"}
    photometric = {"coupling": 0.2, "smoothness": 0.001}
    assert plan.calibration("d") == {
        "calibrate_rig": False,
        "rig_world": "base",
        "unmix_crosstalk": False,
        "chromaticity": {},
        "photometric": photometric,
    }
    assert plan.calibration("s") == {
        "calibrate_rig": False,
        "rig_world": "base",
        "unmix_crosstalk": True,
        "chromaticity": {},
        "photometric": {"coupling": 0.2},
    }
    # The cross-talk calibration where the dataset's images are unmixed (its input).
    assert plan.crosstalk_file("d") == [] and plan.crosstalk_file("s") == [
        "results/s/calib/crosstalk.json"
    ]
    assert plan.photometric_options("d") == "--coupling 0.2 --smoothness 0.001"
    assert plan.photometric_options("s") == (
        "--crosstalk results/s/calib/crosstalk.json --coupling 0.2"
    )
    assert plan.calibration_targets("d") == [
        "results/d/calib/marker_poses.csv",
        "results/d/calib/photometric.h5",
        "results/d/calib/noise.json",
        "results/d/calib/chromaticity/slinky.h5",
    ]


def test_inputs_are_the_files_of_the_capture_format(plan, data):
    rig = str(data / "rig.json")
    files = sorted(str(p) for p in data.rglob("*") if p.is_file())
    # Everything but the file the format does not list (notes.txt).
    assert plan.capture_files("d") == [f for f in files if not f.endswith("notes.txt")]
    assert len(plan.capture_files("d")) == 1 + 9 + 18 + 3 + 3 + 6 + 2 + 1
    assert plan.photometric_inputs("d")[0] == rig and len(plan.photometric_inputs("d")) == 10
    chroma = plan.chromaticity_inputs("d", "slinky")
    assert chroma[:2] == [rig, str(data / "chromatic/slinky/blue/cam1.png")] and len(chroma) == 24
    assert chroma[-5:] == [str(data / f"scenes/{s}/scene.json") for s in ("toy", "wave")] + [
        str(data / f"scenes/toy/masks/000000/cam{i}.png") for i in (1, 2, 3)
    ]
    # No chromatic/white when a dataset has none: just rig.json.
    assert plan.chromatic_inputs("d", "nosuch") == [rig]
    # rig.json, the scene's scene.json (opening the dataset reads it), the masks
    # or, without masks, the images.
    assert plan.silhouette_inputs("d", "toy", "000000")[1:] == [
        str(data / "scenes/toy/scene.json")
    ] + [str(data / f"scenes/toy/masks/000000/cam{i}.png") for i in (1, 2, 3)]
    assert plan.silhouette_inputs("d", "wave", "000001")[1:] == [
        str(data / "scenes/wave/scene.json")
    ] + [str(data / f"scenes/wave/frames/000001/cam{i}.png") for i in (1, 2, 3)]
    assert len(plan.frame_inputs("d", "toy", "000000")) == 8  # rig, scene, 3 images, 3 masks
    assert len(plan.frame_inputs("d", "wave", "000000")) == 5
    assert plan.gt_mesh("d", "toy", "000000") == [str(data / "scenes/toy/gt/000000.ply")]
    assert plan.gt_mesh("d", "wave", "000000") == []
    with pytest.raises(KeyError, match="000000, 000001"):
        plan.frame_inputs("d", "wave", "000002")


def test_calibrate_rig_puts_the_calibrated_rig_under_every_stage(data, tmp_path):
    """calibration.calibrate_rig: every input list that held the dataset's rig.json holds
    results/NAME/calib/rig.json instead, the stages get --rig, rule calibrate_rig reads
    the geometric and photometric captures and the dataset's rig.json; a dataset
    without geometric captures is named before any job. Off: the dataset's rig.json,
    no --rig, and a synthetic dataset is rendered without geometric/."""
    from colourhs.synth.synthesise import PARTS

    config = {
        "datasets": {
            "d": {"path": str(data), "calibration": {"calibrate_rig": True}},
            "s": {"synth": {"preset": "tiny"}},
            "g": {"synth": {"preset": "tiny"}, "calibration": {"calibrate_rig": True}},
        }
    }
    plan = plan_of(config)
    rig = "results/d/calib/rig.json"
    assert plan.calibrates_rig("d") and not plan.calibrates_rig("s")
    assert plan.rig_file("d") == rig and plan.rig_option("d") == f"--rig {rig}"
    assert plan.photometric_inputs("d")[0] == rig
    assert plan.chromatic_inputs("d", "slinky")[0] == rig
    assert plan.frame_inputs("d", "toy", "000000")[0] == rig
    assert plan.silhouette_inputs("d", "wave", "000001")[0] == rig
    assert plan.report_inputs("d")["dataset"][0] == rig
    assert str(data / "rig.json") not in plan.frame_inputs("d", "toy", "000000")
    assert rig in plan.calibration_targets("d")
    with pytest.raises(MalformedDatasetError, match="no geometric captures"):
        plan.geometric_inputs("d")
    assert plan.synth_settings("g")["parts"] == ",".join(PARTS)
    assert "geometric" not in plan.synth_settings("s")["parts"].split(",")
    assert plan.rig_option("s") == ""
    with_views = add_geometric(shutil.copytree(data, tmp_path / "with views"))
    config["datasets"]["d"]["path"] = str(with_views)
    inputs = plan_of(config).geometric_inputs("d")
    assert inputs[0] == str(with_views / "rig.json")
    assert inputs[1:4] == [str(with_views / f"geometric/p0/cam{i}.png") for i in (1, 2, 3)]
    assert len(inputs) == 1 + 2 * 3 + 3 * 3  # rig.json, 2 views and 3 board poses x 3 cameras


def test_variants_targets_and_options(data):
    plan = plan_of(
        {
            "datasets": {"d": {"path": str(data)}},
            "reconstruction": {"variants": ["vh", "bayes_full"], "params": {"n_labels": 7}},
            "surfaces": {"mesh_with_hull": False},
        }
    )
    assert plan.reconstruction_targets("d") == [
        "results/d/toy/vh/depth/000000.h5",
        "results/d/toy/bayes_full/depth/000000.h5",
        "results/d/wave/vh/depth/000000.h5",
        "results/d/wave/vh/depth/000001.h5",
        "results/d/wave/bayes_full/depth/000000.h5",
        "results/d/wave/bayes_full/depth/000001.h5",
    ]
    assert len(plan.evaluation_targets("d")) == 6
    assert plan.reconstruct_options("d", "toy", "bayes_full") == (
        "--method bayes --noise results/d/calib/noise.json --photometric "
        "results/d/calib/photometric.h5 --crosstalk results/d/calib/crosstalk.json "
        "--chromaticity results/d/calib/chromaticity/slinky.h5 --n-labels 7"
    )
    assert plan.reconstruct_options("d", "wave", "vh") == "--method vh --n-labels 7"
    # The paper's ablation without calibration: the noise model only (the whole-job
    # tests in test_workflow.py leave this variant out for time).
    assert plan.variant_calibration("d", "toy", "bayes_nocalib") == {
        "noise": "results/d/calib/noise.json"
    }
    assert plan.reconstruct_options("d", "toy", "bayes_nocalib") == (
        "--method bayes --noise results/d/calib/noise.json --n-labels 7"
    )
    assert plan.same_result("d", "toy", "bayes_nocalib", "000000", "depth") == []
    # bayes_full on wave (no chromatic object) is bayes_ph: computed once, copied.
    assert plan.same_result("d", "wave", "bayes_full", "000001", "mesh") == [
        "results/d/wave/bayes_ph/mesh/000001.ply"
    ]
    assert plan.same_result("d", "toy", "bayes_full", "000000", "eval") == []
    assert plan.reconstruction_hull("d", "toy", "000000") == []
    assert plan.mesh_uses_hull("vh") and not plan.mesh_uses_hull("bayes_full")
    assert plan.figure_options("d", "toy") == (
        "--depth vh=results/d/toy/vh/depth/000000.h5 "
        "bayes_full=results/d/toy/bayes_full/depth/000000.h5 "
        "--mesh vh=results/d/toy/vh/mesh/000000.ply "
        "bayes_full=results/d/toy/bayes_full/mesh/000000.ply "
        f"--gt '{data}/scenes/toy/gt/000000.ply' --coloured vh=results/d/toy/vh/eval/000000.ply "
        "bayes_full=results/d/toy/bayes_full/eval/000000.ply"
    )
    assert plan.figure_inputs("d", "wave")["animation"] == [
        "results/d/wave/bayes_full/mesh/000000.ply",
        "results/d/wave/bayes_full/mesh/000001.ply",
    ]
    assert plan.report_inputs("d")["calibration"] == [
        "results/d/calib/photometric.png",
        "results/d/calib/chromaticity/slinky.png",
    ]
    # The report's calibration diagnostics and 3D views read these.
    assert plan.report_inputs("d")["calib"][:3] == [
        "results/d/calib/marker_poses.csv",
        "results/d/calib/photometric.h5",
        "results/d/calib/crosstalk.json",
    ]
    assert plan.report_inputs("d")["views"] == [
        "results/d/toy/vh/eval/000000.ply",
        "results/d/toy/bayes_full/eval/000000.ply",
        "results/d/wave/vh/eval/000000.ply",
        "results/d/wave/bayes_full/eval/000000.ply",
    ]


def test_the_plans_paths_are_the_layouts_templates_filled_in(data):
    """What the plan names under results/ and reports/ is a template of
    colourhs.workflow.paths (the rules' outputs) filled in: the same files."""
    variants = ["vh", "bayes_ph", "bayes_full"]
    plan = plan_of(
        {
            "datasets": {"d": {"path": str(data)}},
            "reconstruction": {"variants": variants, "depth_from_hull": True},
        }
    )
    frames = {"toy": ["000000"], "wave": ["000000", "000001"]}

    def every(template: str) -> list[str]:
        return [
            fill(template, name="d", scene=s, variant=v, frame=f)
            for s, fs in frames.items()
            for v in variants
            for f in fs
        ]

    def first(template: str, scene: str) -> list[str]:
        return [fill(template, name="d", scene=scene, variant=v, frame="000000") for v in variants]

    calib = [fill(t, name="d") for t in (MARKER_POSES, PHOTOMETRIC, NOISE, CROSSTALK)]
    slinky = fill(CHROMATICITY, name="d", object="slinky")
    assert plan.calibration_targets("d") == calib[:3] + calib[3:] + [slinky]
    assert plan.reconstruction_targets("d") == every(DEPTH)
    assert plan.evaluation_targets("d") == every(EVAL_JSON)
    assert plan.report_targets("d") == [fill(REPORT, name="d")]
    assert plan.variant_calibration("d", "toy", "bayes_full") == dict(
        noise=calib[2], photometric=calib[1], crosstalk=calib[3], chromaticity=slinky
    )
    hull = fill(HULL, name="d", scene="wave", frame="000001")
    assert plan.reconstruction_hull("d", "wave", "000001") == [hull]
    assert plan.mesh_hull("d", "wave", "vh", "000001") == [hull]
    assert plan.mesh_hull("d", "wave", "bayes_ph", "000001") == []
    for kind, template in FRAME_RESULTS.items():
        equal = fill(template, name="d", scene="wave", variant="bayes_ph", frame="000001")
        assert plan.same_result("d", "wave", "bayes_full", "000001", kind) == [equal]
    toy, wave = plan.figure_inputs("d", "toy"), plan.figure_inputs("d", "wave")
    assert [toy[k] for k in ("depth", "mesh", "coloured", "scale")] == [
        first(t, "toy") for t in (DEPTH, MESH, EVAL_PLY, EVAL_JSON)
    ]
    assert wave["coloured"] == wave["scale"] == []  # no ground truth
    assert wave["animation"] == [
        fill(MESH, name="d", scene="wave", variant="bayes_full", frame=f) for f in frames["wave"]
    ]
    report = plan.report_inputs("d")
    assert report["metrics"] == fill(METRICS, name="d")
    assert report["config"] == fill(CONFIG, name="d")
    assert report["calibration"] == [
        fill(PHOTOMETRIC_PNG, name="d"),
        fill(CHROMATICITY_PNG, name="d", object="slinky"),
    ]
    assert report["figures"] == [fill(FIGURES, name="d", scene=s) for s in frames]
    assert report["calib"] == [calib[0], calib[1], calib[3]]  # no true mu maps here
    assert report["views"] == first(EVAL_PLY, "toy") + first(EVAL_PLY, "wave")
    synthetic = plan_of({"datasets": {"s": {"synth": {"preset": "tiny"}}}})
    assert synthetic.dataset_path("s") == fill(SYNTH_DATASET, name="s")


def test_a_synthetic_dataset_waits_for_its_checkpoint(data, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # no data/synthetic/s here
    plan = plan_of({"datasets": {"s": {"synth": {"preset": "demo"}}}})
    assert plan.datasets == ["s"] and plan.dataset_path("s") == "data/synthetic/s"
    plan.check_layouts()  # nothing to check before it is rendered
    assert plan.unvalidated_captures() == []  # its own rule validates it
    with pytest.raises(NotRendered):
        plan.reconstruction_targets("s")
    # Known before the run: the preset's objects.
    assert plan.chromatic_objects("s") == ["statue", "toy"]
    moving = plan_of({"datasets": {"m": {"synth": {"preset": "random-dynamic-tiny"}}}})
    assert moving.chromatic_objects("m") == ["cloth", "moving-toy", "turning-metal"]
    rendered = plan_of({"datasets": {"s": {"synth": {"preset": "demo"}}}}, wait=lambda n: str(data))
    assert len(rendered.reconstruction_targets("s")) == 3 * 5


def test_config_and_dataset_errors(data, tmp_path):
    with pytest.raises(ValueError, match=r"`only` names unknown datasets \['x'\]"):
        plan_of({"datasets": {"d": {"path": str(data)}}, "only": ["x"]})
    with pytest.raises(ValueError, match="lives at data/synthetic/s; drop `path`"):
        plan_of({"datasets": {"s": {"path": "elsewhere", "synth": {"preset": "tiny"}}}})
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "rig.json").write_text((data / "rig.json").read_text())
    plan = plan_of({"datasets": {"d": {"path": str(data)}, "b": {"path": str(bad)}}, "only": ["d"]})
    plan.check_layouts()  # only the datasets to process
    with pytest.raises(MalformedDatasetError, match="dataset 'b' is malformed.*photometric"):
        plan.layout("b")


def test_captures_are_validated_when_their_summary_is_stale(data, tmp_path, monkeypatch):
    copy = Path(shutil.copytree(data, tmp_path / "copy"))
    monkeypatch.chdir(tmp_path)
    plan = plan_of({"datasets": {"d": {"path": str(copy)}}})
    assert plan.unvalidated_captures() == ["d"]  # no summary
    summary = tmp_path / "results/d/capture/summary.json"
    summary.parent.mkdir(parents=True)
    summary.write_text("{}")
    newest = max(p.stat().st_mtime for p in copy.rglob("*"))
    os.utime(summary, (newest + 1, newest + 1))
    assert plan.unvalidated_captures() == []
    image = copy / "scenes/wave/frames/000001/cam2.png"
    image.write_bytes(image.read_bytes()[:100])  # truncated, newer than the summary
    os.utime(image, (newest + 2, newest + 2))
    assert plan.unvalidated_captures() == ["d"]
    message = f"dataset 'd' is malformed, no stage was run: {image}"
    with pytest.raises(MalformedDatasetError, match=re.escape(message)):
        plan.check_captures()


def test_rules_run_the_python_that_runs_snakemake(data, tmp_path, monkeypatch):
    """common.smk's shell prefix exports the interpreter running Snakemake,
    quoted: a path with a space and a quote survives (no conda environment: README;
    test_cli.py's lint test checks no rule declares one). Loading the workflow with
    Snakemake's public API (tests/read_audit.py) sets the prefix snakemake.shell
    puts before every rule's command. Measured: 0.2 s with snakemake.api imported
    (test_workflow.py imports it first), 10 s alone (importing it)."""
    import sys

    import yaml
    from read_audit import quiet_workflow
    from snakemake.shell import shell

    python = str(tmp_path / "my env's python" / "bin" / "python")
    monkeypatch.setattr(sys, "executable", python)  # what common.smk reads
    monkeypatch.setattr(shell, "_process_prefix", None)  # restored after the test
    config = tmp_path / "config.yaml"
    config.write_text(yaml.safe_dump({"datasets": {"d": {"path": str(data)}}}))
    with quiet_workflow(tmp_path, [config]) as (workflow, rules):
        workflow.list_rules()
    assert len(rules.getvalue().split()) == 18  # the workflow was read: 17 rules and all
    assert shell('printf %s "$COLOURHS_PYTHON"', read=True) == python


def test_config_yaml_states_the_package_defaults():
    """One value for each default: what config.yaml writes out for the
    calibration and surfaces is the package's own default, and the command line's
    option defaults are the same (the mesh options repeat frame_mesh's: the command
    line must not import open3d). Measured: 1.5 s (importing colourhs.surfaces.poisson)."""
    import inspect

    import yaml

    from colourhs.calibration.chromaticity import MIN_SIGNAL
    from colourhs.calibration.photometric import DEFAULTS
    from colourhs.cli.parser import build_parser
    from colourhs.surfaces.poisson import frame_mesh
    from colourhs.surfaces.silhouettes import DEFAULT_THRESHOLD

    config = yaml.safe_load((PROJECT_ROOT / "config.yaml").read_text())
    photometric = config["calibration"]["photometric"]
    assert len(photometric) == 5 and photometric == {k: DEFAULTS[k] for k in photometric}
    assert config["calibration"]["chromaticity"] == {"min_signal": MIN_SIGNAL}
    assert config["surfaces"]["hull"] == {"voxel_m": None, "threshold": DEFAULT_THRESHOLD}
    signature = inspect.signature(frame_mesh).parameters
    mesh = {k: signature[k].default for k in ("poisson_depth", "density_quantile")}
    assert config["surfaces"]["mesh"] == mesh
    parse = build_parser().parse_args
    assert vars(parse(["mesh", "d.h5", "m.ply"])).items() >= mesh.items()
    hull = parse(["hull", "data", "scene", "000000", "h.ply"])
    assert (hull.threshold, hull.voxel_m) == (DEFAULT_THRESHOLD, None)
    assert parse(["chromaticity", "data", "toy", "c.h5"]).min_signal == MIN_SIGNAL


def test_schema_refuses_a_spline_spacing_under_one_pixel(data):
    """The refinement's Gram kernel needs a control spacing of at least one pixel
    (colourhs.reconstruct.bayes.gram): the config is refused before any stage runs."""
    ok = {"datasets": {"d": {"path": str(data)}}, "reconstruction": {"params": {"spline_px": 1}}}
    plan_of(ok)
    bad = {"datasets": {"d": {"path": str(data)}}, "reconstruction": {"params": {"spline_px": 0.5}}}
    with pytest.raises(Exception, match="less than the minimum of 1") as err:
        plan_of(bad)
    assert "spline_px" in str(err.value)


def test_bayes_dyn_reads_each_frames_tracked_chromaticity(data, tmp_path):
    """bayes_dyn (beyond the paper): on a sequence with a chromatic object each frame's
    tracked maps (rule track_chromaticity, in frame order from the chromatic frame:
    each frame reads its neighbour's); on a static scene it is bayes_full's copy, on a
    white one bayes_ph's."""
    moving = shutil.copytree(data, tmp_path / "moving")
    meta = {"dynamic": True, "chromatic": "slinky", "chromatic_frame": "000001"}
    (moving / "scenes/wave/scene.json").write_text(json.dumps(meta))
    plan = plan_of({"datasets": {"d": {"path": str(moving)}}})
    assert plan.tracks_chromaticity("d", "wave") and not plan.tracks_chromaticity("d", "toy")
    tracked = "results/d/wave/chromaticity/{}.h5"
    calib = plan.variant_calibration("d", "wave", "bayes_dyn", "000000")
    assert calib["chromaticity"] == tracked.format("000000")
    assert plan.variant_calibration("d", "wave", "bayes_full")["chromaticity"] == (
        "results/d/calib/chromaticity/slinky.h5"
    )
    assert f"--chromaticity {tracked.format('000000')}" in plan.reconstruct_options(
        "d", "wave", "bayes_dyn", "000000"
    )
    assert plan.same_result("d", "wave", "bayes_dyn", "000000", "depth") == []
    assert plan.same_result("d", "toy", "bayes_dyn", "000000", "depth") == [
        "results/d/toy/bayes_full/depth/000000.h5"
    ]
    first = plan.tracking_inputs("d", "wave", "000000")
    assert first["neighbour"] == tracked.format("000001")
    assert first["calibrated"] == "results/d/calib/chromaticity/slinky.h5"
    images = [
        str(moving / f"scenes/wave/frames/{f}/cam{i}.png")
        for f in ("000000", "000001")
        for i in (1, 2, 3)
    ]
    assert first["images"] == [
        str(moving / "rig.json"),
        str(moving / "scenes/wave/scene.json"),
        *images,
    ]
    assert "neighbour" not in plan.tracking_inputs("d", "wave", "000001")
    # The report: every frame's tracked maps (variants null: bayes_dyn is among them).
    assert plan.variants("d")[-1] == "bayes_dyn"
    figures = plan.figure_inputs("d", "wave")
    assert figures["chromaticity"] == [tracked.format(f) for f in ("000000", "000001")]
    assert figures["calibrated_chromaticity"] == ["results/d/calib/chromaticity/slinky.h5"]
    assert figures["gt_chromaticity"] == []  # the dataset has no true maps per frame
    assert "--chromaticity 000000=results/d/wave/chromaticity/000000.h5" in (
        plan.figure_options("d", "wave")
    )
    assert plan.figure_inputs("d", "toy")["chromaticity"] == []
    white = plan_of({"datasets": {"d": {"path": str(data)}}})
    assert "bayes_dyn" not in white.variants("d")  # nothing moves: it would only copy
    assert white.same_result("d", "wave", "bayes_dyn", "000001", "depth") == [
        "results/d/wave/bayes_ph/depth/000001.h5"
    ]


def test_a_chromatic_objects_silhouette_is_its_chromatic_frames_mask(data, tmp_path):
    """The chromatic captures show the object in the chromatic frame's pose, so its
    silhouette is that frame's mask (chromaticity.object_silhouette), which the rule
    declares: not the first frame's."""
    from colourhs.calibration.chromaticity import object_silhouette
    from colourhs.capture import open_dataset

    moving = shutil.copytree(data, tmp_path / "moving")
    (moving / "scenes/toy/scene.json").write_text(json.dumps({"dynamic": False}))
    wave = {"dynamic": True, "chromatic": "slinky", "chromatic_frame": "000001"}
    (moving / "scenes/wave/scene.json").write_text(json.dumps(wave))
    for f in ("000000", "000001"):
        shutil.copytree(moving / "scenes/toy/masks/000000", moving / f"scenes/wave/masks/{f}")
    mask = moving / "scenes/wave/masks/000001/cam2.png"
    assert object_silhouette(open_dataset(moving), "slinky", "cam2") == mask
    inputs = plan_of({"datasets": {"d": {"path": str(moving)}}}).chromaticity_inputs("d", "slinky")
    assert str(mask) in inputs and str(moving / "scenes/wave/masks/000000/cam2.png") not in inputs
