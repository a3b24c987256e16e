"""rig.json against the photometric captures: each common mistake named, a true rig passed."""

from __future__ import annotations

import json

import numpy as np
import pytest

from colourhs.calibration.rig_check import RigCheck, check_rig, rig_problems
from colourhs.capture import open_dataset
from colourhs.cli.parser import PROJECT_ROOT


def _with_rig(tiny_dataset, tmp_path, change):
    """The tiny dataset's photometric captures under a rig.json that ``change`` edits."""
    root = tmp_path / "data"
    root.mkdir()
    (root / "photometric").symlink_to(tiny_dataset / "photometric")
    rig = json.loads((tiny_dataset / "rig.json").read_text())
    change(rig)
    (root / "rig.json").write_text(json.dumps(rig))
    return open_dataset(root, check_images=False, scenes=())


@pytest.fixture(scope="module")
def true_check(tiny_dataset):
    return check_rig(open_dataset(tiny_dataset, check_images=False, scenes=()))


def test_the_true_rig_agrees_with_its_captures(true_check):
    c = true_check
    assert rig_problems(c) == []
    # measured: pairs 0.035-0.041 px, third views 0.10-0.11 px over 112 corners per pair;
    # marker side 1 + 3e-5, layout 1 - 1e-4, planarity 5.5e-4 of the diagonal
    assert max(c.pair_px.values()) < 0.08 and max(c.third_px.values()) < 0.2
    assert min(c.corners.values()) > 100
    assert abs(c.marker_scale - 1) < 0.001 and abs(c.layout_scale - 1) < 0.001
    assert c.planarity < 0.002 and c.tolerance_px == pytest.approx(0.005 * 200)


def _transpose_r(name):
    def change(rig):
        cam = next(c for c in rig["cameras"] if c["name"] == name)
        cam["R"] = np.asarray(cam["R"]).T.tolist()

    return change


def _camera_to_world(name):
    def change(rig):
        cam = next(c for c in rig["cameras"] if c["name"] == name)
        R, t = np.asarray(cam["R"]), np.asarray(cam["t"])
        cam["R"], cam["t"] = R.T.tolist(), (-R.T @ t).tolist()

    return change


@pytest.mark.parametrize("mistake", [_transpose_r, _camera_to_world])
def test_a_wrong_pose_names_its_camera(tiny_dataset, tmp_path, mistake):
    name = json.loads((tiny_dataset / "rig.json").read_text())["cameras"][1]["name"]
    check = check_rig(_with_rig(tiny_dataset, tmp_path, mistake(name)))
    (problem,) = rig_problems(check)
    assert problem.startswith(f"camera {name!r} disagrees") and "tolerance 1.0 px" in problem
    others = [p for p in check.pair_px if name not in p.split("-")]
    assert check.pair_px[others[0]] < 0.1  # measured 0.035 px
    # transposed R, measured 5.6 and 5.8 px at 160 x 120; camera-to-world, 4.5e7 and more
    assert min(r for p, r in check.pair_px.items() if p not in others) > 5.0


def test_swapped_cameras_disagree(tiny_dataset, tmp_path):
    """Two cameras' images under each other's names (their K, R, t swapped)."""

    def swap(rig):
        a, b = rig["cameras"][0], rig["cameras"][2]
        for key in ("K", "dist", "R", "t"):
            a[key], b[key] = b[key], a[key]

    (problem,) = rig_problems(check_rig(_with_rig(tiny_dataset, tmp_path, swap)))
    assert "disagree" in problem and "px" in problem


@pytest.mark.parametrize(
    "factor, what", [(1.1, "board.marker_length"), (1000.0, "the cameras' t (metres)")]
)
def test_a_wrong_size_is_the_boards(tiny_dataset, tmp_path, factor, what):
    """A marker length 10 % off, and camera positions in millimetres."""

    def change(rig):
        if factor < 2:
            rig["board"]["marker_length"] *= factor
        else:
            for cam in rig["cameras"]:
                cam["t"] = (np.asarray(cam["t"]) * factor).tolist()

    check = check_rig(_with_rig(tiny_dataset, tmp_path, change))
    (problem,) = rig_problems(check)
    assert problem.startswith("board: its markers triangulate") and what in problem
    expected = 1 / factor if factor < 2 else factor
    assert check.marker_scale == pytest.approx(expected, rel=0.01)


def _check(pairs, third=None, **kw):
    cams = sorted({c for p in pairs for c in p.split("-")})
    return RigCheck(
        pair_px=pairs,
        third_px=third or dict.fromkeys(cams, 0.1),
        marker_scale=kw.get("marker_scale", 1.0),
        layout_scale=kw.get("layout_scale", 1.0),
        planarity=kw.get("planarity", 0.0),
        corners=dict.fromkeys(pairs, 400),
        tolerance_px=2.0,
    )


def test_problems_name_the_camera_common_to_the_pairs_that_disagree():
    ok = {"a-b": 0.2, "a-c": 0.3, "b-c": 0.1}
    assert rig_problems(_check(ok)) == []
    (p,) = rig_problems(_check({"a-b": 40.0, "a-c": 0.3, "b-c": 35.0}))
    assert p.startswith("camera 'b' disagrees") and "40.0 px" in p
    (p,) = rig_problems(_check({"a-b": 40.0, "a-c": 30.0, "b-c": 35.0}))
    assert p.startswith("the cameras disagree")
    (p,) = rig_problems(_check(ok, third={"a": 0.1, "b": 0.2, "c": 9.0}))
    assert p.startswith("camera 'c' disagrees") and "9.0 px" in p
    (p,) = rig_problems(_check(ok, layout_scale=1.05))
    assert "1.050 times as far apart" in p
    (p,) = rig_problems(_check(ok, planarity=0.03))
    assert "3.0% of its diagonal" in p


def _whole_dataset(tiny_dataset, tmp_path, change):
    """Every capture of the tiny dataset (linked) under a rig.json that ``change`` edits."""
    root = tmp_path / "whole"
    root.mkdir()
    for entry in tiny_dataset.iterdir():
        if entry.name != "rig.json":
            (root / entry.name).symlink_to(entry)
    rig = json.loads((tiny_dataset / "rig.json").read_text())
    change(rig)
    (root / "rig.json").write_text(json.dumps(rig))
    return root


def test_validate_refuses_a_rig_its_captures_contradict(tiny_dataset, tmp_path, capsys):
    """colourhs validate: the rig check's figures in the summary; a transposed R is one
    error naming rig.json and the camera, and no summary is written."""
    from colourhs.cli.parser import main

    summary = tmp_path / "summary.json"
    assert main(["validate", str(tiny_dataset), "--summary", str(summary)]) == 0
    check = json.loads(summary.read_text())["rig_check"]
    assert max(check["pair_px"].values()) < 0.08 and check["tolerance_px"] == 1.0
    bad = _whole_dataset(tiny_dataset, tmp_path, _transpose_r("cam2"))
    capsys.readouterr()
    assert main(["validate", str(bad), "--summary", str(tmp_path / "bad.json")]) != 0
    err = capsys.readouterr().err
    assert "rig.json" in err and "camera 'cam2' disagrees" in err
    assert not (tmp_path / "bad.json").exists()
    assert main(["validate", str(bad), "--no-rig-check"]) == 0


def test_the_workflow_plan_refuses_the_dataset_before_any_job(tiny_dataset, tmp_path, monkeypatch):
    """The plan validates a dataset given by path before any job is planned: a
    camera-to-world pose stops it with the camera named."""
    from snakemake.utils import validate

    from colourhs.workflow.plan import MalformedDatasetError, WorkflowPlan

    bad = _whole_dataset(tiny_dataset, tmp_path, _camera_to_world("cam3"))
    monkeypatch.chdir(tmp_path)
    config = {"datasets": {"d": {"path": str(bad)}}}
    validate(config, str(PROJECT_ROOT / "workflow" / "schemas" / "config.schema.yaml"), True)
    plan = WorkflowPlan(config, lambda name: name)
    assert plan.unvalidated_captures() == ["d"]
    with pytest.raises(MalformedDatasetError, match="camera 'cam3' disagrees"):
        plan.check_captures()
