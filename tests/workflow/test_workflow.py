"""Caching and incremental reruns of the Snakemake workflow (its public API and CLI).

The session's one real run of the whole workflow (conftest's ``whole_job``,
tests/whole_job.py: `colourhs run` on a copy of the tiny dataset, variants vh,
bayes_ph and bayes_full, all four scenes, paths with spaces), then, in file order:
that every job read only its declared inputs (tests/read_audit.py), what the run
made, what a second run would do, what replacing one board image / one frame image /
one reconstruction parameter / one mask would rerun (dry runs, the change undone
afterwards), and a failing stage and its resumed run (real runs, on a copy of the
run's folder). Every test leaves the run as it found it; all the tests of the run are
here, so that pytest-xdist runs them on one worker (``--dist loadfile``).
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import time
from collections import Counter
from collections.abc import Iterable
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import cv2
import pandas as pd
import pytest
import yaml
from read_audit import summary
from snakemake.api import SnakemakeApi
from snakemake.settings.types import (
    ConfigSettings,
    DAGSettings,
    ExecutionSettings,
    OutputSettings,
    ResourceSettings,
)
from whole_job import NAME, VARIANTS, WholeJob, copy_run, snapshot

from colourhs.cli.parser import SNAKEFILE

# The tiny preset's scenes and frames (sheet: 3 frames, the others one).
FRAMES = {
    "plane": ("000000",),
    "sheet": ("000000", "000001", "000002"),
    "statue": ("000000",),
    "toy": ("000000",),
}
SCENES = tuple(FRAMES)
# The Helmholtz-stereo variants of the run (reconstruct_frame jobs); bayes_full on
# the scenes without a chromatic object (plane, sheet) is bayes_ph's copy.
HS_VARIANTS = tuple(v for v in VARIANTS if v != "vh")


# --------------------------------------------------------------------------- Snakemake API


def _snakemake(workdir: Path, configfiles, *, keep_going: bool = False):
    """Run the default target: (succeeded, None, the files Snakemake reports updated)."""
    updated: list[str] = []
    try:
        with SnakemakeApi(OutputSettings()) as api:
            workflow_api = api.workflow(
                resource_settings=ResourceSettings(cores=2),
                config_settings=ConfigSettings(configfiles=[Path(p) for p in configfiles]),
                snakefile=SNAKEFILE,
                workdir=workdir,
            )
            workflow_api.dag(DAGSettings()).execute_workflow(
                executor="local",
                execution_settings=ExecutionSettings(keep_going=keep_going),
                updated_files=updated,
            )
    except Exception as e:  # a failed job: WorkflowError
        print(f"snakemake failed: {e}")
        return False, None, updated
    return True, None, updated


@dataclass(frozen=True)
class Plan:
    """What Snakemake would run now: one (rule, output path) per output file."""

    outputs: frozenset[tuple[str, str]]
    rules: Counter  # rule name -> number of jobs

    def __bool__(self) -> bool:
        return bool(self.outputs)

    def of(self, rule: str) -> set[str]:
        return {path for r, path in self.outputs if r == rule}


def planned_jobs(workdir: Path, configfiles) -> Plan:
    """The jobs Snakemake would run now (the `all` target left out), from its public
    summary: every output file with its rule, log file and plan ("update pending" or
    "no update"); one log file per job tells the jobs apart."""
    rows = summary(workdir, configfiles)
    pending = [(r[2], r[0], r[3]) for r in rows if r[-1] == "update pending" and r[2] != "all"]
    outputs = frozenset((rule, path) for rule, path, _ in pending)
    jobs = {(rule, log) for rule, _, log in pending}
    return Plan(outputs, Counter(rule for rule, _ in jobs))


def assert_plan(plan: Plan, required: set, optional: Iterable = ()) -> None:
    """Every required job output is planned, and nothing beyond required + optional."""
    planned = set(plan.outputs)
    missing = required - planned
    extra = planned - required - set(optional)
    assert not missing and not extra, f"missing: {sorted(missing)}\nunexpected: {sorted(extra)}"


# --------------------------------------------------------------------------- expected jobs


def hs_jobs(scene: str, frame: str, variant: str = "bayes_ph") -> set[tuple[str, str]]:
    """A Helmholtz-stereo frame's reconstruction, mesh and evaluation."""
    base = f"results/{NAME}/{scene}/{variant}"
    return {
        ("reconstruct_frame", f"{base}/depth/{frame}.h5"),
        ("frame_mesh", f"{base}/mesh/{frame}.ply"),
        ("evaluate_frame", f"{base}/eval/{frame}.json"),
        ("evaluate_frame", f"{base}/eval/{frame}.ply"),
    }


def vh_jobs(scene: str, frame: str) -> set[tuple[str, str]]:
    """A frame's visual hull (the vh variant's depth), its mesh and evaluation."""
    base = f"results/{NAME}/{scene}"
    return {
        ("visual_hull", f"{base}/hull/{frame}.ply"),
        ("visual_hull", f"{base}/vh/depth/{frame}.h5"),
        ("frame_mesh", f"{base}/vh/mesh/{frame}.ply"),
        ("evaluate_frame", f"{base}/vh/eval/{frame}.json"),
        ("evaluate_frame", f"{base}/vh/eval/{frame}.ply"),
    }


def all_hs_jobs() -> set[tuple[str, str]]:
    """Every frame's Helmholtz-stereo jobs, both variants (24 jobs, 48 outputs)."""
    return {
        job
        for scene, frames in FRAMES.items()
        for f in frames
        for v in HS_VARIANTS
        for job in hs_jobs(scene, f, v)
    }


def report_jobs(*scenes: str) -> set[tuple[str, str]]:
    """The metrics table, the named scenes' figures and the report."""
    return {
        ("metrics_table", f"reports/{NAME}/metrics.csv"),
        ("report", f"reports/{NAME}/index.html"),
        ("report", f"reports/{NAME}/assets"),
        *{("scene_figures", f"reports/{NAME}/figures/{s}") for s in scenes},
    }


# Capture validation reads the whole dataset folder: whether a changed image reruns
# it is test_validation_follows_the_capture_files's business, not the others'.
VALIDATION = {("validate_dataset", f"results/{NAME}/capture/summary.json")}
CALIBRATION_RULES = {
    "marker_poses",
    "photometric_maps",
    "crosstalk",
    "chromaticity_map",
    "noise_model",
}


# --------------------------------------------------------------------------- files


def changed(before: dict[str, int], after: dict[str, int]) -> set[str]:
    """Files written, removed or created between two snapshots."""
    return {p for p in before.keys() | after.keys() if before.get(p) != after.get(p)}


def under(paths: Iterable[str], jobs: set[tuple[str, str]]) -> set[str]:
    """The paths that are (or lie inside) one of the jobs' outputs."""
    outs = {path for _, path in jobs}
    return {p for p in paths if p in outs or any(p.startswith(o + "/") for o in outs)}


def newest_output(workdir: Path) -> float:
    return max(os.stat(workdir / p).st_mtime for p in snapshot(workdir))


def make_newest(path: Path, workdir: Path) -> None:
    """Date ``path`` 1 s after the newest output (itself too, when it is one) and wait
    till that time has passed: a job that reads it and finishes within the second
    would otherwise write an output older than its input, which Snakemake refuses
    ("clock skew"; measured: bayes_full's copies of a depth file take 0.41-0.45 s)."""
    stamp = newest_output(workdir) + 1.0
    os.utime(path, (stamp, stamp))
    time.sleep(max(0.0, stamp - time.time()))


def tweak_png(path: Path) -> None:
    """Re-encode a 16-bit PNG with its first pixel's lowest bit flipped."""
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    assert img is not None and img.dtype.name == "uint16"
    img[0, 0, 0] ^= 1
    assert cv2.imwrite(str(path), img)


@contextmanager
def replaced(path: Path, change, workdir: Path):
    """Change a dataset file (newer than every output); put it back, bytes and times."""
    original, st = path.read_bytes(), path.stat()
    try:
        change(path)
        assert path.read_bytes() != original
        make_newest(path, workdir)
        yield path
    finally:
        path.write_bytes(original)
        os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns))


# --------------------------------------------------------------------------- the run


@pytest.fixture(scope="module")
def run(whole_job) -> WholeJob:
    """The session's run of the whole workflow (tests/whole_job.py), succeeded."""
    done = whole_job.done
    assert done.returncode == 0, "the run of the workflow failed: " + done.stderr[-2000:]
    assert f"reports/{NAME}/index.html" in whole_job.first
    return whole_job


# --------------------------------------------------------------------------- tests


def test_first_run_made_every_output(run):
    files = set(run.first)
    assets = f"reports/{NAME}/assets"  # a folder: the calibration figures the report copies
    assert {f for f in files if f.startswith(f"{assets}/")} - {
        f"{assets}/.snakemake_timestamp"
    } == {
        f"{assets}/photometric.png",
        *(f"{assets}/chromaticity/{obj}.png" for obj in ("statue", "toy")),
    }
    expected = {path for _, path in all_hs_jobs() | report_jobs() | VALIDATION} - {assets}
    expected |= {
        path for scene, frames in FRAMES.items() for f in frames for _, path in vh_jobs(scene, f)
    }
    expected |= {
        f"results/{NAME}/calib/{f}"
        for f in (
            "marker_poses.csv",
            "photometric.h5",
            "photometric.png",
            "crosstalk.json",
            "noise.json",
            *(f"chromaticity/{obj}.{ext}" for obj in ("statue", "toy") for ext in ("h5", "png")),
        )
    }
    expected |= {f"results/{NAME}/config.yaml"}
    assert expected <= files, sorted(expected - files)
    for scene in FRAMES:  # directory outputs
        assert any(p.startswith(f"reports/{NAME}/figures/{scene}/") for p in files)
    assert not [p for p in files if ".tmp" in Path(p).name]


def test_every_job_reads_only_its_declared_inputs(run):
    """The read audit (tests/read_audit.py): every job of the first run read, under the
    dataset and the run's folder, only its inputs, outputs and log."""
    n_jobs, problems = run.audit
    # 69 but `all`: 8 before the frames (validation, 6 calibrations, the recorded
    # config), 9 per frame (hull, 2 HS depths, 3 meshes, 3 evaluations) x 6 frames,
    # then the metrics table, 4 scenes' figures and the report.
    assert n_jobs == 8 + 9 * 6 + 1 + 4 + 1 == 68
    assert not problems, "\n".join(sorted(problems))


# What the run made (the CLI's `colourhs run`, tests/whole_job.py): variants vh, bayes_ph
# and bayes_full. ml_full and bayes_nocalib are left out for the suite's time: ML HS is
# tested in test_exact.py and test_reconstruct.py, the uncalibrated variant and the
# ablation in test_reconstruct.py (test_calibrations_help), their workflow inputs in
# test_workflow_plan.py.


def test_the_run_saw_every_capture(run):
    """7 poses x 3 cameras, 3 chromatic objects x 3 colours x 3 cameras, 6 frames x 3
    cameras and their 18 masks, 15 geometric poses x 3 cameras."""
    path = run.workdir / "results" / NAME / "capture" / "summary.json"
    assert json.loads(path.read_text())["images"] == 21 + 27 + 18 + 18 + 45


def _metrics(run: WholeJob) -> pd.DataFrame:
    return pd.read_csv(run.workdir / "reports" / NAME / "metrics.csv", dtype={"frame": str})


def test_whole_job_writes_a_metrics_row_and_a_mesh_per_frame_and_variant(run):
    """4 scenes, 6 frames, the 3 variants: one metrics row and one mesh each."""
    metrics = _metrics(run)
    assert len(metrics) == 6 * len(VARIANTS)
    assert set(metrics["variant"]) == set(VARIANTS)
    res = run.workdir / "results" / NAME
    for scene, frame, variant in metrics[["scene", "frame", "variant"]].itertuples(index=False):
        assert (res / scene / variant / "mesh" / f"{frame}.ply").exists()


def test_whole_job_accuracy_against_ground_truth(run):
    """The sheet with Bayesian HS and photometric calibration (Hausdorff RMS measured
    0.44 mm) is a hundred times better than the visual hull (121 mm); bayes_full,
    with the pipeline's own chromaticity maps, beats bayes_ph on the coloured objects
    (statue 1.77 against 7.36 mm, toy 1.87 against 16.5 mm)."""
    metrics = _metrics(run)
    sheet = metrics[metrics["scene"] == "sheet"].groupby("variant")["hausdorff_rms_mm"].mean()
    assert sheet["bayes_ph"] < 0.7
    assert 100 * sheet["bayes_ph"] < sheet["vh"]
    chromatic = metrics.set_index(["scene", "variant"])["hausdorff_rms_mm"]
    for scene in ("statue", "toy"):
        full, ph = chromatic[(scene, "bayes_full")], chromatic[(scene, "bayes_ph")]
        assert full < 2.5 and 3 * full < ph, (scene, full, ph)


def test_whole_job_copies_bayes_full_where_there_is_no_chromatic_object(run):
    """bayes_full on the scenes without a chromatic object (plane, sheet) is
    bayes_ph, computed once and copied byte for byte; the chromatic ones are
    computed."""
    full = _metrics(run)
    full = full[full["variant"] == "bayes_full"].set_index(["scene", "frame"])
    copied = full["same_as"].fillna("")
    assert set(copied[copied == "bayes_ph"].index.get_level_values(0)) == {"plane", "sheet"}
    assert set(copied[copied == ""].index.get_level_values(0)) == {"statue", "toy"}
    res = run.workdir / "results" / NAME
    for scene, frame in copied[copied == "bayes_ph"].index:
        for kind in (f"depth/{frame}.h5", f"mesh/{frame}.ply"):
            a, b = res / scene / "bayes_full" / kind, res / scene / "bayes_ph" / kind
            assert a.read_bytes() == b.read_bytes()


def test_whole_job_report_has_provenance_diagnostics_views_and_timings(run):
    """The report links its figures, names the workflow command and the rig, has
    the calibration diagnostics and a 3D view per scene (the report rule passes
    --calib and --view), times every stage under its rule's name, and says where
    bayes_full is bayes_ph; the sheet gets its animation."""
    work = run.workdir
    html = (work / "reports" / NAME / "index.html").read_text()
    assert "bayes_full" in html and "base64," not in html and 'src="figures/sheet/' in html
    assert "workflow command" in html and "frames per scene" in html  # provenance, rig
    assert '<div class="diagnostics">' in html and "marker" in html
    assert html.count('<div class="viewer"') == 4
    bench = work / "benchmarks" / "snakemake"
    for rule in ("validate_dataset", "marker_poses", "crosstalk", "noise_model"):
        assert (bench / rule / f"{NAME}.tsv").exists(), rule
    assert (bench / "reconstruct_frame" / NAME / "sheet" / "bayes_ph" / "000000.tsv").exists()
    assert "<td>reconstruct_frame</td>" in html or ">reconstruct_frame<" in html
    assert "<code>bayes_full</code> is <code>bayes_ph</code> on this scene" in html
    assert (work / "reports" / NAME / "figures" / "sheet" / "animation.gif").exists()


def test_whole_job_second_run_does_nothing_and_snakemake_reports_it(run):
    """A second run does nothing; Snakemake's own report (with the captions on the key
    outputs) builds; neither writes an output (the tests here share the run)."""
    work, cmd = run.workdir, run.cmd
    again = subprocess.run(cmd, capture_output=True, text=True)
    assert again.returncode == 0
    assert "Nothing to be done" in again.stdout + again.stderr
    report = work / "snakemake_report.html"
    done = subprocess.run(cmd + ["--", "--report", str(report)], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-2000:]
    assert report.stat().st_size > 10000
    assert snapshot(work) == run.first


def test_second_run_does_nothing(run):
    assert not planned_jobs(run.workdir, run.configfiles)
    ok, _, updated = _snakemake(run.workdir, run.configfiles)
    assert ok and updated == []
    assert snapshot(run.workdir) == run.first


def test_board_image_reruns_photometric_maps_and_downstream(run):
    pose = sorted((run.data / "photometric").iterdir())[3]
    with replaced(pose / "cam1.png", tweak_png, run.workdir):
        plan = planned_jobs(run.workdir, run.configfiles)
    calib = f"results/{NAME}/calib"
    required = {
        ("marker_poses", f"{calib}/marker_poses.csv"),
        ("photometric_maps", f"{calib}/photometric.h5"),
        ("photometric_maps", f"{calib}/photometric.png"),
        ("noise_model", f"{calib}/noise.json"),  # estimated from the board images too
        ("crosstalk", f"{calib}/crosstalk.json"),  # its LED factor: from the board poses
        # the chromaticity maps' sigma of log p comes from the noise model
        *{
            ("chromaticity_map", f"{calib}/chromaticity/{obj}.{ext}")
            for obj in ("statue", "toy")
            for ext in ("h5", "png")
        },
        # bayes_ph and bayes_full read photometric.h5, noise.json and crosstalk.json
        # (bayes_full on plane and sheet copies bayes_ph: reruns with it); vh reads
        # no calibration.
        *all_hs_jobs(),
        *report_jobs(*SCENES),
    }
    assert_plan(plan, required, optional=VALIDATION)
    assert plan.rules["reconstruct_frame"] == 6 * 2  # every frame, both HS variants
    assert plan.rules["frame_mesh"] == plan.rules["evaluate_frame"] == 12
    assert not {"visual_hull", "effective_config"} & set(plan.rules)
    assert not [p for p in plan.of("frame_mesh") if "/vh/" in p]
    # Undone: nothing to do again.
    assert not planned_jobs(run.workdir, run.configfiles)


def test_frame_image_reruns_that_frame_only(run):
    image = run.data / "scenes" / "sheet" / "frames" / "000001" / "cam2.png"
    with replaced(image, tweak_png, run.workdir):
        plan = planned_jobs(run.workdir, run.configfiles)
    # bayes_full (the animated variant) copies bayes_ph's results of the sheet.
    required = hs_jobs("sheet", "000001") | hs_jobs("sheet", "000001", "bayes_full")
    required |= report_jobs("sheet")
    # The sheet has masks, so its hull reads no frame image (silhouette_inputs).
    assert_plan(plan, required, optional=VALIDATION)
    assert plan.of("reconstruct_frame") == {
        f"results/{NAME}/sheet/{v}/depth/000001.h5" for v in ("bayes_ph", "bayes_full")
    }
    assert plan.of("scene_figures") == {f"reports/{NAME}/figures/sheet"}
    assert not [path for _, path in plan.outputs if re.search("/(plane|statue|toy)/", path)]
    assert not [path for _, path in plan.outputs if re.search(r"/00000[02]\.", path)]
    assert not CALIBRATION_RULES & set(plan.rules)
    assert not planned_jobs(run.workdir, run.configfiles)


@pytest.mark.parametrize(
    "change", [{"params": {"n_labels": 7}}, {"depth_from_hull": True}], ids=["n_labels", "hull"]
)
def test_reconstruction_parameter_reruns_reconstruction_and_downstream(run, change, tmp_path):
    config = yaml.safe_load(run.configfiles[1].read_text())
    config["reconstruction"].update(change)
    changed_config = tmp_path / f"run-config-{'-'.join(change)}.yaml"
    changed_config.write_text(yaml.safe_dump(config))
    plan = planned_jobs(run.workdir, [run.configfiles[0], changed_config])
    required = all_hs_jobs() | report_jobs(*SCENES)
    # The run's recorded configuration changes with it.
    required |= {("effective_config", f"results/{NAME}/config.yaml")}
    assert_plan(plan, required)
    assert plan.rules["reconstruct_frame"] == 6 * 2  # every frame, both HS variants
    assert not (CALIBRATION_RULES | {"visual_hull", "validate_dataset"}) & set(plan.rules)
    assert not planned_jobs(run.workdir, run.configfiles)


def test_malformed_capture_stops_the_run_before_any_stage(run, capsys):
    """A truncated frame image: the run stops before any job with the validator's
    message naming the file (common.smk's onstart), and nothing is written."""
    image = run.data / "scenes" / "sheet" / "frames" / "000001" / "cam1.png"
    before = snapshot(run.workdir)
    with replaced(image, lambda p: p.write_bytes(p.read_bytes()[:200]), run.workdir):
        capsys.readouterr()
        ok, _, updated = _snakemake(run.workdir, run.configfiles, keep_going=True)
        message = capsys.readouterr().out
        after = snapshot(run.workdir)
    assert not ok, "the run with a truncated frame image succeeded"
    assert "malformed" in message and str(image) in message, message[-2000:]
    assert after == before  # (updated lists what was planned, not written)
    assert not planned_jobs(run.workdir, run.configfiles)


def test_failed_stage_leaves_no_partial_output_and_rerun_resumes(run, tmp_path):
    """A corrupt depth file (a stage's output, not a capture): its mesh job fails,
    nothing after it runs, and the rerun does the failed job and what follows.

    On a copy of the run's folder (tests/whole_job.py's copy_run, up to date: the
    same dataset, times kept), so the shared run stays as it was."""
    work = copy_run(run, tmp_path / "my run")
    res = f"results/{NAME}/sheet"
    depth = work / f"{res}/bayes_ph/depth/000001.h5"
    failed_mesh = f"{res}/bayes_ph/mesh/000001.ply"
    # bayes_full's depth of the sheet copies this file (--same-as): that job reads the
    # corrupt file too; its mesh and evaluation copy the failed mesh's and its eval's.
    copied_depth = ("reconstruct_frame", f"{res}/bayes_full/depth/000001.h5")
    failed_jobs = hs_jobs("sheet", "000001") | hs_jobs("sheet", "000001", "bayes_full")
    failed_jobs -= {("reconstruct_frame", f"{res}/bayes_ph/depth/000001.h5")}
    downstream = (failed_jobs | report_jobs("sheet")) - {("frame_mesh", failed_mesh)}
    downstream -= {copied_depth}  # not downstream of the failed mesh job
    before = snapshot(work)
    original = depth.read_bytes()
    with replaced(depth, lambda p: p.write_bytes(p.read_bytes()[:200]), work):
        ok, _, _ = _snakemake(work, run.configfiles, keep_going=True)
        failed = snapshot(work)
    # The good depth file back, newer than what reads it (as when its stage reruns).
    depth.write_bytes(original)
    make_newest(depth, work)
    assert not ok, "the run with a truncated depth file succeeded"
    assert not (work / failed_mesh).exists()
    # Nothing downstream of the failure was written (the old files are still there, stale).
    assert not under(changed(before, failed), downstream)
    assert all(failed[p] == before[p] for p in under(before, downstream))
    # Nothing else: bayes_full's copy job (--same-as) refuses the truncated file at its
    # input check (before, h5py.is_hdf5 passed it and the job copied it), so
    # its old output is at most removed (a failed job's), never rewritten.
    written = changed(before, failed) - {failed_mesh, depth.relative_to(work).as_posix()}
    assert written <= {copied_depth[1]}
    assert failed.get(copied_depth[1]) in (None, before[copied_depth[1]])
    assert not [p for p in failed if ".tmp" in Path(p).name]

    # The rerun does the failed job and what follows, nothing else.
    plan = planned_jobs(work, run.configfiles)
    assert_plan(plan, failed_jobs | report_jobs("sheet"))
    ok, _, updated = _snakemake(work, run.configfiles)
    assert ok
    assert set(updated) == {path for _, path in plan.outputs}
    after = snapshot(work)
    assert set(after) == set(run.first)  # every output exists again
    rerun = changed(failed, after)
    assert failed_mesh in rerun
    assert rerun - {depth.relative_to(work).as_posix()} <= under(after, plan.outputs)
    assert under(rerun, downstream) == under(after, downstream)  # all rewritten
    assert (work / copied_depth[1]).read_bytes() == original  # the good file copied
    assert not [p for p in after if ".tmp" in Path(p).name]
    assert not planned_jobs(work, run.configfiles)


def test_validation_follows_the_capture_files(run):
    image = run.data / "scenes" / "sheet" / "frames" / "000001" / "cam3.png"
    with replaced(image, tweak_png, run.workdir):
        plan = planned_jobs(run.workdir, run.configfiles)
    assert plan.of("validate_dataset") == {path for _, path in VALIDATION}


def test_object_mask_reruns_its_chromaticity_map(run):
    """The chromaticity map reads the object's silhouette (the first frame's masks
    of the scene that shows it): a changed mask reruns that map and no other
    calibration, and that frame's hull and reconstructions (which read its masks)."""
    import json

    scenes = sorted((run.data / "scenes").iterdir())
    obj, scene = next(
        (json.loads((d / "scene.json").read_text()).get("chromatic"), d)
        for d in scenes
        if json.loads((d / "scene.json").read_text()).get("chromatic")
    )
    first = sorted((scene / "masks").iterdir())[0]

    def tweak_mask(path: Path) -> None:  # one corner pixel flipped (masks are 8 bit)
        img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        img[0, 0] = 255 - img[0, 0]
        assert cv2.imwrite(str(path), img)

    with replaced(first / "cam2.png", tweak_mask, run.workdir):
        plan = planned_jobs(run.workdir, run.configfiles)
    calib = f"results/{NAME}/calib/chromaticity"
    assert plan.of("chromaticity_map") == {f"{calib}/{obj}.h5", f"{calib}/{obj}.png"}
    assert not (CALIBRATION_RULES - {"chromaticity_map"}) & set(plan.rules)
    # The scene is reconstructed: the mask is its frame's silhouette (the hull's and
    # both HS variants' input; bayes_full reads the map too) and the report shows the map.
    s, f = scene.name, first.name
    required = {("chromaticity_map", f"{calib}/{obj}.{ext}") for ext in ("h5", "png")}
    required |= vh_jobs(s, f) | hs_jobs(s, f) | hs_jobs(s, f, "bayes_full") | report_jobs(s)
    assert_plan(plan, required, optional=VALIDATION)
    assert not planned_jobs(run.workdir, run.configfiles)


def test_geometric_image_reruns_nothing_without_calibrate_rig(run):
    """The ChArUco views are read by rule calibrate_rig only, which runs only with
    calibration.calibrate_rig on: otherwise a changed view reruns no stage."""
    pose = sorted((run.data / "geometric").iterdir())[2]
    with replaced(pose / "cam2.png", tweak_png, run.workdir):
        plan = planned_jobs(run.workdir, run.configfiles)
    assert_plan(plan, set(), optional=VALIDATION)


def test_calibrate_rig_runs_every_stage_on_the_rig_calibrated_from_the_captures(run, tmp_path):
    """calibration.calibrate_rig: the cameras calibrated from geometric/ (rule
    calibrate_rig, in the dataset's world: calibration.rig_world base) are what every
    stage that reads the rig reads (--rig): switching it on reruns them all; a changed
    ChArUco view reruns the calibration and everything after it. A real run of one
    scene and variant on a copy of the run's folder: its depth against the true rig's."""
    import json

    work = copy_run(run, tmp_path / "my run")
    config = yaml.safe_load(run.configfiles[1].read_text())
    config.setdefault("calibration", {})["calibrate_rig"] = True
    on = tmp_path / "calibrate-rig.yaml"
    on.write_text(yaml.safe_dump(config))
    calib = f"results/{NAME}/calib"
    rig = {("calibrate_rig", f"{calib}/rig.json"), ("calibrate_rig", f"{calib}/rig_report.json")}
    plan = planned_jobs(work, [run.configfiles[0], on])
    every_frame = {
        job for scene, frames in FRAMES.items() for f in frames for job in vh_jobs(scene, f)
    }
    required = rig | run_outputs(run) | all_hs_jobs() | every_frame | report_jobs(*SCENES)
    recorded = {("effective_config", f"results/{NAME}/config.yaml")}  # the changed config
    assert_plan(plan, required, optional=recorded | VALIDATION)

    config["reconstruction"].update(scenes=["plane"], variants=["bayes_ph"])
    one = tmp_path / "calibrate-rig-plane.yaml"
    one.write_text(yaml.safe_dump(config))
    ok, _, _ = _snakemake(work, [run.configfiles[0], one])
    assert ok
    report = json.loads((work / calib / "rig_report.json").read_text())
    assert report["world"] == "base" and report["rig_check"]["tolerance_px"] > 0
    assert max(report["rig_check"]["third_px"].values()) < report["rig_check"]["tolerance_px"]
    evals = "plane/bayes_ph/eval/000000.json"
    true_rig = json.loads((run.workdir / f"results/{NAME}" / evals).read_text())
    calibrated = json.loads((work / f"results/{NAME}" / evals).read_text())
    print(
        "plane bayes_ph depth median: true rig",
        true_rig["depth_median_mm"],
        "calibrated",
        calibrated["depth_median_mm"],
    )
    assert calibrated["depth_median_mm"] < 1.1 * true_rig["depth_median_mm"]
    assert calibrated["coverage"] > 0.95 * true_rig["coverage"]

    pose = sorted((run.data / "geometric").iterdir())[2]
    with replaced(pose / "cam2.png", tweak_png, work):
        plan = planned_jobs(work, [run.configfiles[0], one])
    required = rig | run_outputs(run) | hs_jobs("plane", "000000") | report_jobs("plane")
    assert_plan(plan, required, optional=VALIDATION)
    assert not planned_jobs(work, [run.configfiles[0], one])


def run_outputs(run) -> set[tuple[str, str]]:
    """(rule, output) of every calibration file of the run (each reads the rig)."""
    calib = f"results/{NAME}/calib"
    files = {
        "marker_poses": ["marker_poses.csv"],
        "crosstalk": ["crosstalk.json"],
        "noise_model": ["noise.json"],
        "photometric_maps": ["photometric.h5", "photometric.png"],
        "chromaticity_map": [
            str(p.relative_to(run.workdir / calib))
            for p in (run.workdir / calib / "chromaticity").iterdir()
        ],
    }
    return {(rule, f"{calib}/{name}") for rule, names in files.items() for name in names}
