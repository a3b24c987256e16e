"""The command line and the Snakemake workflow on the tiny preset."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pandas as pd
import pytest
import yaml

from colourhs.cli.parser import PROJECT_ROOT, _input_problem, main
from colourhs.common.depthfile import DepthResult, write_depth


def test_synth_refuses_to_overwrite(tmp_path, capsys):
    out = tmp_path / "ds"
    out.mkdir()
    assert main(["synth", "--preset", "tiny", str(out)]) == 1
    assert "already exists" in capsys.readouterr().err


def test_validate_reports_good_and_bad_datasets(tiny_dataset, tmp_path, capsys):
    summary = tmp_path / "summary.json"
    assert main(["validate", str(tiny_dataset), "--summary", str(summary)]) == 0
    data = json.loads(summary.read_text())
    assert data["cameras"] == {"cam1": "blue", "cam2": "red", "cam3": "green"}
    assert data["reciprocal_pairs"][0] == ["cam1", "red", "cam2", "blue"]
    assert data["scenes"]["sheet"]["frames"] == 3
    assert 0 < data["saturated_fraction"] < 0.01
    bad = tmp_path / "bad"
    shutil.copytree(tiny_dataset, bad)
    target = bad / "chromatic" / "toy" / "green" / "cam3.png"
    target.write_bytes(target.read_bytes()[:200])  # truncated PNG
    capsys.readouterr()
    assert main(["validate", str(bad), "--summary", str(tmp_path / "bad.json")]) == 1
    err = capsys.readouterr().err
    assert str(target) in err
    assert not (tmp_path / "bad.json").exists()


def test_validate_names_every_problem_at_once_with_near_misses(tiny_dataset, tmp_path, capsys):
    """A rig owner fixing captures sees every problem in one run, each with its file
    and reason, and a hint where a file is there under another name; a valid
    dataset gets a one-line verdict before the JSON summary."""
    assert main(["validate", str(tiny_dataset)]) == 0
    out = capsys.readouterr().out
    verdict, rest = out.split("\n", 1)
    summary = json.loads(rest)
    frames = sum(v["frames"] for v in summary["scenes"].values())
    assert verdict == (
        f"{tiny_dataset.resolve()}: valid: {summary['images']} images of 3 cameras, "
        f"{len(summary['poses'])} board poses, 3 chromatic objects, 4 scenes ({frames} frames)"
    ), verdict
    bad = tmp_path / "bad"
    shutil.copytree(tiny_dataset, bad)
    pose = sorted((bad / "photometric").iterdir())[0]
    (pose / "cam2.png").rename(pose / "cam2.PNG")  # a near miss
    frame = bad / "scenes" / "statue" / "frames" / "000000"
    (frame / "cam1.png").rename(frame / "cam1.TIF")
    truncated = bad / "chromatic" / "toy" / "green" / "cam3.png"
    truncated.write_bytes(truncated.read_bytes()[:200])
    (bad / "scenes" / "plane" / "scene.json").write_text("{")
    assert main(["validate", str(bad)]) == 1
    out, err = capsys.readouterr()
    head = next(i for i, t in enumerate(err.splitlines()) if "problems:" in t)
    assert out == "" and err.splitlines()[head].endswith(f"{bad}: 4 problems:"), err
    lines = err.splitlines()[head + 1 :]
    assert len(lines) == 4, err
    assert any(f"{pose / 'cam2.png'}: missing image" in t and "found cam2.PNG" in t for t in lines)
    assert any(f"{frame / 'cam1.png'}: missing image" in t and "found cam1.TIF" in t for t in lines)
    assert any(str(truncated) in t for t in lines)
    assert any(str(bad / "scenes" / "plane" / "scene.json") in t for t in lines)


def test_workflow_lint_is_clean(tmp_path):
    """Snakemake's linter finds nothing but the lint the project accepts: no rule
    declares a conda environment or container (``--sdm conda`` is not
    supported, README), so it flags each of the 17 rules with a command."""
    snakefile = str(PROJECT_ROOT / "Snakefile")
    config = str(PROJECT_ROOT / "config.yaml")
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "snakemake",
            "--lint",
            "--snakefile",
            snakefile,
            "--directory",
            str(tmp_path),
            "--configfile",
            config,
        ],
        capture_output=True,
        text=True,
    )
    out = done.stdout + done.stderr
    assert done.returncode == 1, out[-2000:]  # 1: lints found
    rules = re.findall(r"^Lints for rule (\w+) ", out, re.M)
    assert len(set(rules)) == len(rules) == 17 and "Lints for snakefile" not in out
    no_software = "Specify a conda environment or container for each rule."
    assert re.findall(r"^ +\* (.+):$", out, re.M) == [no_software] * 17, out[-2000:]


def test_missing_dataset_stops_the_run_before_any_job(tmp_path):
    """A configured dataset path that does not exist: the run stops at once with the
    path named (Snakefile onstart), and writes nothing."""
    config = {"datasets": {"mine": {"path": str(tmp_path / "nowhere")}}, "only": ["mine"]}
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text(yaml.safe_dump(config))
    work = tmp_path / "work"
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "snakemake",
            "--cores",
            "1",
            "--snakefile",
            str(PROJECT_ROOT / "Snakefile"),
            "--directory",
            str(work),
            "--configfile",
            str(PROJECT_ROOT / "config.yaml"),
            str(cfg),
        ],
        capture_output=True,
        text=True,
    )
    out = done.stdout + done.stderr
    assert done.returncode != 0
    assert "nowhere" in out and "dataset folder not found" in out, out[-2000:]
    assert not (work / "results").exists()


def test_run_refuses_a_bad_dataset_in_one_line_and_writes_nothing(tmp_path, capsys):
    """``colourhs run`` on a malformed rig.json, a folder without one, a file and a
    missing folder: exit 1, one line on stderr naming the file and the problem,
    nothing on stdout (no Snakemake lines) and no ``results/NAME/run-config.yaml``."""
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "rig.json").write_text('{"format": "colourhs-capture/1", "units": "m"')
    empty = tmp_path / "empty"
    empty.mkdir()
    (tmp_path / "file").write_text("x")
    cases = {
        bad: "bad/rig.json: not valid JSON",
        empty: "empty/rig.json: missing",
        tmp_path / "file": "file: not a folder",
        tmp_path / "nowhere": "nowhere: no such folder",
    }
    work = tmp_path / "work"
    for dataset, problem in cases.items():
        code = main(["run", str(dataset), "--name", "x", "--directory", str(work)])
        out, err = capsys.readouterr()
        assert code == 1 and out == "", (dataset, out)
        assert err.count("\n") == 1 and problem in err, (dataset, err)
    assert not work.exists()


def test_stage_inputs_of_the_wrong_kind_are_refused_in_one_line(tiny_dataset, tmp_path, capsys):
    """``colourhs photometric`` given a CSV that is not a poses table, or a file that is
    not CSV at all, names the file and what it lacks (it once said "0 usable board
    poses", then raised a KeyError); ``colourhs hull`` refuses an unknown frame before
    any progress line. Exit 1, one line on stderr, nothing written."""
    other = tmp_path / "other.csv"
    other.write_text("a,b\n1,2\n")
    binary = tmp_path / "binary.csv"
    binary.write_bytes(b"\x00\x01\xff\xfe")
    out = tmp_path / "out.h5"
    for table, problem in (
        (other, "not a board poses table (no column pose"),
        (binary, "not a CSV"),
    ):
        assert main(["photometric", str(tiny_dataset), str(table), str(out)]) == 1
        _, err = capsys.readouterr()
        assert err.count("\n") == 1 and f"{table}: {problem}" in err, err
    assert main(["hull", str(tiny_dataset), "statue", "000099", str(tmp_path / "h.ply")]) == 1
    _, err = capsys.readouterr()
    assert err.startswith("colourhs hull: unknown frame") and err.count("\n") == 1, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["binary.csv", "other.csv"]


def test_invalid_config_names_the_key(tmp_path):
    config = yaml.safe_load((PROJECT_ROOT / "config.yaml").read_text())
    config["datasets"]["demo"]["synth"]["preset"] = "huge"
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump(config))
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "snakemake",
            "-n",
            "--cores",
            "1",
            "--snakefile",
            str(PROJECT_ROOT / "Snakefile"),
            "--directory",
            str(tmp_path),
            "--configfile",
            str(bad),
        ],
        capture_output=True,
        text=True,
    )
    assert done.returncode != 0
    assert "huge" in done.stdout + done.stderr
    assert "preset" in done.stdout + done.stderr


def test_missing_dataset_is_a_clear_error(tmp_path, capsys):
    """A missing folder is named as one, not as a missing rig.json inside it."""
    assert main(["run", str(tmp_path / "nowhere")]) == 1
    err = _one_line(capsys)
    assert "nowhere: no such folder" in err and "rig.json" not in err


def _one_line(capsys) -> str:
    """The error: exactly one line on stderr, no traceback, nothing on stdout."""
    out, err = capsys.readouterr()
    assert err.count("\n") == 1 and "Traceback" not in err and out == "", (out, err)
    return err


def _rec(scene: str, *options: str, frame: str = "000000") -> list[str]:
    """``colourhs reconstruct`` of the tiny dataset's ``scene`` into the test's folder."""
    return ["reconstruct", "{d}", scene, frame, "{o}/x.h5", *options]


USER_ERRORS = {  # argv -> what the one line must say
    "scene": (
        _rec("nosuch"),
        ["unknown scene 'nosuch'", "statue", "plane"],
    ),
    "frame": (
        _rec("statue", frame="7"),
        ["unknown frame of scene 'statue' '7'", "000000"],
    ),
    "camera": (
        _rec("statue", "--reference", "cam9"),
        ["no camera 'cam9'", "cam1"],
    ),
    "file": (
        _rec("statue", "--photometric", "{o}/no.h5"),
        ["--photometric", "no.h5: no such file"],
    ),
    "hull scene": (["hull", "{d}", "nosuch", "000000", "{o}/h.ply"], ["unknown scene 'nosuch'"]),
    "object": (["chromaticity", "{d}", "nosuch", "{o}/c.h5"], ["nosuch", "toy"]),
    "dataset": (["markers", "{o}/nowhere", "{o}/p.csv"], ["dataset", "nowhere: no such file"]),
    "preset": (["synth", "{o}/s", "--preset", "huge"], ["unknown preset 'huge'", "demo"]),
    "frames": (
        ["synth", "{o}/s", "--preset", "tiny", "--frames", "2-3"],
        ["frames [3]: the tiny preset's sheet has frames 0-2"],
    ),
    "synth scene": (
        ["synth", "{o}/s", "--scenes", "sheet,nosuch"],
        ["unknown scenes ['nosuch']", "plane, statue, toy, sheet"],
    ),
    "variant": (
        ["run", "{d}", "--directory", "{o}", "--variants", "vh,foo"],
        ["unknown variant(s) 'foo'", "bayes_full"],
    ),
    "run scene": (
        ["run", "{d}", "--directory", "{o}", "--scenes", "statue,nosuch"],
        ["unknown scene(s) 'nosuch'", "plane"],
    ),
    "no variant": (
        ["run", "{d}", "--directory", "{o}", "--variants", ""],
        ["unknown variant(s) (none given)", "bayes_full"],
    ),
    # unreadable inputs: named with the option and the problem ({b}: bad_inputs)
    "not hdf5": (
        _rec("statue", "--photometric", "{b}/bad.h5"),
        ["--photometric", "bad.h5: not an HDF5 file"],
    ),
    "folder": (
        _rec("statue", "--chromaticity", "{b}"),
        ["--chromaticity", ": a folder, not a file"],
    ),
    "other maps": (
        _rec("toy", "--chromaticity", "{b}/other.h5"),
        ["no map cam1, cam2, cam3 of this rig's cameras", "holds: x"],
    ),
    "map size": (
        _rec("toy", "--chromaticity", "{b}/small.h5"),
        ["another image size (cam1 4x5", "rig.json says 120x160"],
    ),
    "not json": (
        _rec("statue", "--crosstalk", "{b}/bad.json"),
        ["--crosstalk", "bad.json: not JSON (Expecting"],
    ),
    "not ply": (
        _rec("statue", "--hull", "{b}/bad.ply"),
        ["--hull", "bad.ply: not a PLY file"],
    ),
    "not yaml": (
        "report {o}/r.html --name x --metrics {b}/m.csv --config {b}/bad.yaml".split(),
        ["--config", "bad.yaml: not YAML"],
    ),
    "folder json": (["metrics", "{b}", "{o}/m.csv"], ["json", ": a folder, not a file"]),
    # Depth files are read in full (colourhs.common.depthfile.read_depth) and maps to
    # their end before a stage starts, not just their signature; the error names the option
    "mesh half depth": (
        ["mesh", "{b}/half.h5", "{o}/m.ply"],
        ["mesh: depth ", "half.h5: not a readable HDF5 depth file (Unable to", "truncated file"],
    ),
    "mesh no normal": (
        ["mesh", "{b}/nonormal.h5", "{o}/m.ply"],
        ["mesh: depth ", "nonormal.h5: missing dataset 'normal'"],
    ),
    "evaluate half depth": (
        ["evaluate", "{b}/half.h5", "{b}/ok.ply", "{o}/e.json", "--same-as", "{b}/ok.json"],
        ["evaluate: depth ", "half.h5: not a readable HDF5 depth file", "truncated file"],
    ),
    "evaluate no normal": (
        ["evaluate", "{b}/nonormal.h5", "{b}/ok.ply", "{o}/e.json"],
        ["evaluate: depth ", "nonormal.h5: missing dataset 'normal'"],
    ),
    "same-as half depth": (
        _rec("statue", "--same-as", "{b}/half.h5"),
        ["reconstruct: --same-as ", "half.h5: not a readable HDF5 depth file", "truncated file"],
    ),
    "same-as no normal": (
        _rec("statue", "--same-as", "{b}/nonormal.h5"),
        ["reconstruct: --same-as ", "nonormal.h5: missing dataset 'normal'"],
    ),
    # figures' VARIANT=PATH inputs are checked like the other stages' inputs
    "figures half depth": (
        ["figures", "{o}/figs", "--depth", "bayes={b}/half.h5", "--mesh", "bayes={b}/ok.ply"],
        ["figures: --depth ", "half.h5: not a readable HDF5 depth file", "truncated file"],
    ),
    "figures no mesh": (
        ["figures", "{o}/figs", "--depth", "bayes={b}/good.h5", "--mesh", "bayes={o}/no.ply"],
        ["figures: --mesh ", "no.ply: no such file or folder"],
    ),
    "figures not ply": (
        "figures {o}/figs --depth vh={b}/good.h5 --mesh vh={b}/ok.ply --gt {b}/bad.ply".split(),
        ["figures: --gt ", "bad.ply: not a PLY file"],
    ),
    "half maps": (
        _rec("toy", "--chromaticity", "{b}/halfmaps.h5"),
        ["reconstruct: --chromaticity ", "halfmaps.h5: not a readable HDF5 file", "truncated file"],
    ),
    # tuning values out of the config schema's ranges, named with their option
    "n labels": (_rec("plane", "--n-labels", "-3"), ["--n-labels -3: -3 is less than", "3"]),
    "alpha": (_rec("plane", "--alpha", "1.5"), ["--alpha 1.5: 1.5 is greater than"]),
    "view": (
        "report {o}/r.html --name x --metrics {b}/m.csv --view".split(),
        ["3D views need results_dir (colourhs report --results)"],
    ),
}


@pytest.fixture(scope="module")
def bad_inputs(tmp_path_factory) -> Path:
    """Files that are not what their option reads: text for HDF5, JSON, YAML and PLY;
    HDF5 files without the tiny rig's chromaticity maps or with maps of another size."""
    import h5py
    import numpy as np

    root = tmp_path_factory.mktemp("bad")
    for name in ("bad.h5", "bad.json", "bad.ply", "bad.yaml"):
        (root / name).write_text("{not: [this kind")
    (root / "m.csv").write_text("scene,frame,variant\n")
    with h5py.File(root / "other.h5", "w") as f:
        f["x"] = np.zeros(3)
    with h5py.File(root / "small.h5", "w") as f:
        for cam in ("cam1", "cam2", "cam3"):
            f[cam] = np.ones((4, 5, 3), np.float32)
    # A good depth file cut to half its bytes, and one without "normal"
    rng = np.random.default_rng(12)
    depth = rng.uniform(0.5, 1.0, (48, 64)).astype(np.float32)
    result = DepthResult(
        depth, np.ones((48, 64, 3), np.float32), np.ones_like(depth), depth > 0, {}
    )
    camera = SimpleNamespace(name="cam1", K=np.eye(3), R=np.eye(3), t=np.zeros(3), dist=[0.0])
    write_depth(root / "good.h5", result, camera, {"method": "bayes"})
    assert _input_problem(root / "good.h5", "depth", False) == ""
    _cut_to_half(root / "good.h5", root / "half.h5")
    with h5py.File(root / "good.h5") as f, h5py.File(root / "nonormal.h5", "w") as g:
        for key in ("depth", "confidence", "mask"):
            g[key] = f[key][()]
        g.attrs.update(f.attrs)
    with h5py.File(root / "maps.h5", "w") as f:  # the tiny rig's chromaticity maps
        for cam in ("cam1", "cam2", "cam3"):
            f[cam] = rng.uniform(0, 1, (120, 160, 3)).astype(np.float32)
    assert _input_problem(root / "maps.h5", "hdf5", False) == ""
    _cut_to_half(root / "maps.h5", root / "halfmaps.h5")
    (root / "ok.ply").write_text("ply\nformat ascii 1.0\nend_header\n")
    (root / "ok.json").write_text("{}")
    return root


def _cut_to_half(src: Path, out: Path) -> None:
    """A half-written copy of ``src``: its first half, the HDF5 signature included."""
    data = src.read_bytes()
    out.write_bytes(data[: len(data) // 2])


@pytest.mark.parametrize("case", USER_ERRORS, ids=list(USER_ERRORS))
def test_user_errors_are_one_line_and_write_nothing(
    case, tiny_dataset, bad_inputs, tmp_path, capsys
):
    """Every user error is one line on stderr naming what is wrong and
    what exists, exit status 1, and leaves no output behind (run validates its
    options before it writes run-config.yaml; input files are checked before a
    stage starts)."""
    argv, phrases = USER_ERRORS[case]
    argv = [a.format(d=tiny_dataset, o=tmp_path, b=bad_inputs) for a in argv]
    assert main(argv) == 1
    err = _one_line(capsys)
    for phrase in phrases:
        assert phrase in err, (phrase, err)
    assert list(tmp_path.iterdir()) == []


def test_each_depth_file_is_read_once(bad_inputs, tmp_path, monkeypatch, capsys):
    """Mesh, evaluate and figures read their depth file once: the input
    check's read (colourhs.cli.parser._check_inputs) is the one the stage uses (it was
    read twice: 0.2 s of a job at 1280 x 960). Measured: 1.0 s (a Poisson mesh
    at octree depth 5, a figure)."""
    import colourhs.common.depthfile as depthfile

    read = []
    real = depthfile.read_depth
    monkeypatch.setattr(depthfile, "read_depth", lambda p: read.append(str(p)) or real(p))
    good, mesh = str(bad_inputs / "good.h5"), str(tmp_path / "m.ply")
    jobs = [
        ["mesh", good, mesh, "--poisson-depth", "5"],
        ["evaluate", good, mesh, str(tmp_path / "e.json")],
        ["figures", str(tmp_path / "figs"), "--depth", f"bayes={good}", "--mesh", f"bayes={mesh}"],
    ]
    for argv in jobs:
        read.clear()
        assert main(argv) == 0, capsys.readouterr().err
        assert read == [good], argv[0]
    assert json.loads((tmp_path / "e.json").read_text())["depth_h5"] == good


def test_version_and_option_help(capsys):
    with pytest.raises(SystemExit) as done:
        main(["--version"])
    assert done.value.code == 0 and capsys.readouterr().out.startswith("colourhs ")
    with pytest.raises(SystemExit):
        main(["reconstruct", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "(default 192)" in text and "(default 0.25)" in text and "(default bayes)" in text
    with pytest.raises(SystemExit):
        main(["photometric", "--help"])
    assert "(default 0.0001)" in " ".join(capsys.readouterr().out.split())  # smoothness


def test_every_option_shows_its_default():
    """Every option with a default, and every tuning option, says it in --help."""
    import argparse

    from colourhs.cli.parser import PHOTOMETRIC_PARAMS, RECONSTRUCT_PARAMS, build_parser

    parser = build_parser(show_defaults=True)
    (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    checked = []
    for command, p in sub.choices.items():
        for a in p._actions:
            if not a.option_strings or a.nargs == 0 or a.required:
                continue  # positionals, flags, --help, required options
            tuning = a.dest in RECONSTRUCT_PARAMS or a.dest in PHOTOMETRIC_PARAMS
            if tuning or a.default not in (None, "", []):
                checked.append(f"{command} {a.option_strings[0]}")
                assert "default" in (a.help or ""), (command, a.option_strings, a.help)
    assert len(checked) == 40, checked  # 40 options with a default (--box-px)


def _subcommands():
    import argparse

    from colourhs.cli.parser import build_parser

    parser = build_parser(show_defaults=True)
    (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return parser, sub.choices


def test_help_speaks_to_users_with_one_description_per_command():
    """``colourhs --help`` says what the tool does and how to start, not the module's
    developer docstring; every command's own --help opens with a description (its
    line in the list); option values are named after the option (with its unit,
    e.g. VOXEL_M), never by type, and no help names code instead of a value."""
    import re

    from colourhs.reconstruct.sides import BLUR_PX

    parser, commands = _subcommands()
    assert parser.description.startswith("Colour Helmholtz Stereopsis")
    assert "colourhs run DATASET" in parser.description
    assert not re.search(r":(func|mod):|``", parser.format_help())
    assert len(commands) == 19
    for name, p in commands.items():
        assert p.description and p.description[0].isupper(), name
        for a in p._actions:
            if not a.option_strings or a.nargs == 0 or a.choices:
                continue
            assert a.metavar is None, (name, a.option_strings, a.metavar)  # dest, upper case
            assert not re.search(r"\b[a-z_]+\.[A-Z_]{3,}\b", a.help or ""), (name, a.help)
    blur = next(a for a in commands["reconstruct"]._actions if a.dest == "blur_px")
    assert f"(default {BLUR_PX:g})" in blur.help


def test_each_option_states_the_unit_its_name_has():
    """An option named in metres says metres and no default in pixels (``--margin-m``
    once said "metres (default 2 px)"); one in pixels says pixels and not metres; one
    in mm says mm."""
    _, commands = _subcommands()
    units = {"_m": "metres", "_px": "pixel", "_mm": "mm"}
    checked = 0
    for name, p in commands.items():
        for a in p._actions:
            suffix = next((u for u in units if a.option_strings and a.dest.endswith(u)), None)
            if suffix is None:
                continue
            checked += 1
            text = a.help or ""
            assert units[suffix] in text, (name, a.dest, text)
            others = [w for u, w in units.items() if u != suffix and w != "pixel"]
            assert not any(f" {w}" in text for w in others), (name, a.dest, text)
            assert suffix != "_m" or " px" not in text, (name, a.dest, text)
    assert checked == 13, checked


def test_readme_minimal_rig_is_valid():
    """The minimal rig.json of the README's "Your own rig" passes the reader's checks."""
    from colourhs.capture import rig_from_dict

    readme = (PROJECT_ROOT / "README.md").read_text().split("## Your own rig", 1)[1]
    rig = rig_from_dict(json.loads(readme.split("```json", 1)[1].split("```", 1)[0]))
    assert rig.camera_names == ("cam1", "cam2", "cam3")
    assert [p.cam_a + p.cam_b for p in rig.reciprocal_pairs()] == [
        "cam1cam2",
        "cam1cam3",
        "cam2cam3",
    ]


def test_readme_commands_exist():
    readme = (PROJECT_ROOT / "README.md").read_text()
    assert "bash scripts/setup.sh && .venv/bin/snakemake --cores 2" in readme
    assert "bash scripts/setup.sh && .venv/bin/python -m pytest" in readme
    ci = (PROJECT_ROOT / ".ci" / "run").read_text()
    assert "bash scripts/setup.sh && .venv/bin/python -m pytest" in ci
    assert Path(PROJECT_ROOT / "scripts" / "setup.sh").exists()


def test_synth_help_names_exactly_the_presets(capsys):
    """The help once named a preset (random-tiny-lens) that ``PRESETS`` refused."""
    import re

    from colourhs.synth.synthesise import PRESETS

    with pytest.raises(SystemExit):
        main(["synth", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    listed = re.search(r"--preset PRESET (.+?) \(default demo\)", text).group(1)
    listed = re.sub(r"-\s+", "-", listed)  # argparse may wrap a line after a hyphen
    assert set(re.split(r", | or ", listed)) == set(PRESETS)


def test_rig_option_replaces_the_datasets_rig_json(tiny_dataset, tmp_path, capsys):
    """--rig: a stage reads that rig.json instead of the dataset's (the workflow's
    calibrated rig). A dataset whose own rig.json swaps two cameras' poses fails the
    rig check; with --rig naming the right description it validates, and its marker
    poses equal the original dataset's."""
    data = tmp_path / "swapped"
    shutil.copytree(tiny_dataset, data, ignore=shutil.ignore_patterns("scenes", "geometric"))
    good = tmp_path / "good rig.json"
    shutil.copy(data / "rig.json", good)
    rig = json.loads(good.read_text())
    a, b = rig["cameras"][0], rig["cameras"][1]
    (a["R"], a["t"]), (b["R"], b["t"]) = (b["R"], b["t"]), (a["R"], a["t"])
    (data / "rig.json").write_text(json.dumps(rig))
    capsys.readouterr()
    assert main(["validate", str(data)]) == 1
    assert str(data / "rig.json") in capsys.readouterr().err
    assert main(["validate", str(data), "--rig", str(good)]) == 0
    ours, theirs = tmp_path / "ours.csv", tmp_path / "theirs.csv"
    assert main(["markers", str(data), str(ours), "--rig", str(good)]) == 0
    assert main(["markers", str(tiny_dataset), str(theirs)]) == 0
    pd.testing.assert_frame_equal(pd.read_csv(ours), pd.read_csv(theirs))
    capsys.readouterr()
    assert main(["markers", str(data), str(tmp_path / "x.csv"), "--rig", str(tmp_path / "no")]) == 1
    assert "--rig" in capsys.readouterr().err and not (tmp_path / "x.csv").exists()


def test_run_calibrate_rig_plans_the_rig_calibration_first(tiny_dataset, tmp_path, capfd):
    """``colourhs run --calibrate-rig``: the run's config turns calibration.calibrate_rig
    on, and the dry run plans rule calibrate_rig with every stage reading its rig."""
    work = tmp_path / "work"
    argv = ["run", str(tiny_dataset), "--name", "c", "--directory", str(work), "--calibrate-rig"]
    assert main([*argv, "--", "-n", "-p"]) == 0
    out = capfd.readouterr().out
    config = yaml.safe_load((work / "results/c/run-config.yaml").read_text())
    assert config["calibration"] == {"calibrate_rig": True}
    assert "rule calibrate_rig:" in out and "--world base" in out
    for stage in ("markers", "photometric", "reconstruct", "chromaticity", "noise"):
        lines = [x for x in out.splitlines() if f"-m colourhs {stage} " in x]
        assert lines and all("--rig results/c/calib/rig.json" in x for x in lines), stage
    assert not (work / "results/c/calib").exists()
