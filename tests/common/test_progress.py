"""Every stage that runs more than a few seconds at the paper preset's scale
(1280 x 960) shows its progress on stderr (which the Snakemake rules send to the job's
log) through the stage commands, which call :func:`show_progress`; a library call
prints nothing unless its caller shows progress or configures :mod:`logging`.

All on the tiny preset (160 x 120), most on the session's tiny dataset.
"""

from __future__ import annotations

import contextlib
import io
import json
import logging
from dataclasses import replace

import pytest
from logging_helpers import kept_logging

from colourhs.calibration.markers import marker_poses
from colourhs.calibration.noise import calibrate_noise
from colourhs.calibration.photometric import photometric_maps
from colourhs.cli.parser import main
from colourhs.common.progress import BARS, LOGGER, bar, show_progress, stage
from colourhs.evaluation.accuracy import evaluate_frame
from colourhs.report.figures import scene_figures
from colourhs.report.page import PageOptions, ReportInputs, build_report
from colourhs.surfaces.hull import visual_hull
from colourhs.surfaces.poisson import frame_mesh
from colourhs.synth.synthesise import PRESETS, RenderSelection, synthesise


def _lines(err: str) -> list[str]:
    """stderr as its lines, a bar's redraws (carriage returns) each a line."""
    return [line for line in err.replace("\r", "\n").splitlines() if line.strip()]


def _run(argv, capsys) -> str:
    """stderr of ``colourhs ARGV``, which must succeed."""
    return _run_out(argv, capsys)[1]


def _run_out(argv, capsys) -> tuple[str, str]:
    """stdout and stderr of ``colourhs ARGV``, which must succeed; the ``colourhs``
    loggers are left as they were (a command is a process of its own)."""
    with kept_logging():
        assert main([str(a) for a in argv]) == 0
    return capsys.readouterr()


def _records(caplog) -> list[str]:
    """The messages the package logged."""
    return [r.getMessage() for r in caplog.records if r.name.startswith(f"{LOGGER}.")]


# The photometric run here does not unmix the tiny rig's cross-talk, which its model
# check rightly warns about.
@pytest.mark.filterwarnings("ignore:photometric. the board poses disagree")
def test_calibration_stages_show_progress(tiny_dataset, tmp_path, capsys, caplog):
    """validate (10 s at paper scale), markers (7 s), noise (16 s), photometric (21 s) and
    chromaticity (7 s): bars over the images, poses, images, pairs and cameras, a line
    per later step. The same functions called from Python print nothing."""
    poses = tmp_path / "poses.csv"
    err = _run(["markers", tiny_dataset, poses], capsys)
    assert "markers: board poses: 100%" in err and "| 7/7 [" in err  # 7 poses
    err = _run(["validate", tiny_dataset], capsys)
    assert "validating images: 100%" in err
    err = _run(["noise", tiny_dataset, tmp_path / "noise.json"], capsys)
    # 3 cameras x (7 poses + the white object under 3 colours)
    assert "noise model: 100%" in err and "| 30/30 [" in err
    err = _run(["photometric", tiny_dataset, poses, tmp_path / "ph.h5"], capsys)
    lines = _lines(err)
    assert "photometric: reading the board poses: 100%" in err
    assert "photometric: eq. (6) samples: 100%" in err and "| 3/3 [" in err  # 3 pairs
    steps = [line for line in lines if not ("%|" in line or line.startswith("cam"))]
    assert [s.split(" [")[0].split(" of ")[0] for s in steps] == [
        "photometric: solving for 6 maps",
        "photometric: the pair ratios' uncertainty (jackknife over poses)",
        "photometric: dense maps, calibrated regions, eq. (7) residuals",
        "photometric: writing ph.h5",
    ]
    out, err = _run_out(["chromaticity", tiny_dataset, "toy", tmp_path / "toy.h5"], capsys)
    assert "chromaticity toy: 100%" in err and "| 3/3 [" in err  # 3 cameras
    assert "chromaticity toy: writing toy.h5" in err
    assert "pixels with a chromaticity" in out and "wrote" in out
    caplog.clear()
    marker_poses(tiny_dataset, tmp_path / "p2.csv")
    calibrate_noise(tiny_dataset)
    photometric_maps(tiny_dataset, poses, tmp_path / "p2.h5")
    assert capsys.readouterr() == ("", "")
    assert _records(caplog) == []


def test_quiet_hides_the_progress(tiny_dataset, capsys):
    """``colourhs --quiet``: the command's own output, no progress lines or bars."""
    out, err = _run_out(["--quiet", "validate", tiny_dataset], capsys)
    assert ": valid: " in out and "validating images" not in err


@pytest.fixture
def frame_results(tiny_dataset, tmp_path):
    """The tiny statue's visual hull (results/t/statue/...)."""
    root = tmp_path / "results" / "t" / "statue"
    hull, depth = root / "hull" / "000000.ply", root / "vh" / "depth" / "000000.h5"
    visual_hull(tiny_dataset, "statue", 0, hull, out_depth_h5=depth)
    gt = tiny_dataset / "scenes" / "statue" / "gt" / "000000.ply"
    return root, hull, depth, gt


def test_frame_stages_show_progress(frame_results, tmp_path, capsys, caplog):
    """mesh (11 s at paper scale), evaluate (7.5 s), figures (45 s for 5 variants) and
    report (16 s): a line per step (with the seconds since the start) or a bar over the
    variants' maps, renders and 3D views. The same functions called from Python print
    nothing (the visual hull's included)."""
    root, hull, depth, gt = frame_results
    assert capsys.readouterr() == ("", "")  # the fixture's visual hull
    mesh, ev = root / "vh" / "mesh" / "000000.ply", root / "vh" / "eval" / "000000"
    out, err = _run_out(["mesh", depth, mesh, "--hull", hull], capsys)
    steps = [line.split(": ")[1].split(" ")[0] for line in _lines(err)]
    assert steps == ["oriented", str(json.loads(out)["points"]), "Poisson", "cropping"]
    assert all(line.endswith(" s]") for line in _lines(err))
    err = _run(
        ["evaluate", depth, mesh, f"{ev}.json", "--gt", gt, "--coloured", f"{ev}.ply"]
        + ["--scene", "statue", "--frame", "000000", "--variant", "vh"],
        capsys,
    )
    assert _lines(err)[0].startswith("evaluate: casting cam1's 160 x 120 pixel rays")
    assert len(_lines(err)) == 2 and "evaluate: accuracy of " in err
    figures = tmp_path / "figures"
    kw = {"depth": [f"vh={depth}"], "mesh": [f"vh={mesh}"], "coloured": [f"vh={ev}.ply"]}
    err = _run(["figures", figures, *_options(kw), "--gt", gt], capsys)
    for label in ("depth and normal maps, depth errors", "shaded renders", "Hausdorff renders"):
        assert f"figures: {label}: 100%" in err
    assert "figures: depth and normal error maps\n" in err
    metrics = tmp_path / "metrics.csv"
    _run(["metrics", f"{ev}.json", metrics], capsys)
    report = ["report", tmp_path / "index.html", "--name", "t", "--metrics", metrics]
    err = _run([*report, "--results", root.parent, "--view"], capsys)
    assert "report: 3D views of statue: 100%" in err and "| 1/1 [" in err
    caplog.clear()
    frame_mesh(depth, tmp_path / "m.ply", hull_ply=hull)
    evaluate_frame(depth, mesh, gt, tmp_path / "e.json")
    scene_figures(tmp_path / "f", {"vh": depth}, {"vh": mesh}, gt)
    build_report(
        tmp_path / "r.html",
        "t",
        ReportInputs(metrics, [], {}, [], {}),
        PageOptions(views=True),
        results_dir=root.parent,
    )
    assert capsys.readouterr() == ("", "")
    assert _records(caplog) == []


def _options(kw: dict) -> list[str]:
    return [a for k, v in kw.items() for a in (f"--{k}", *v)]


def test_synth_shows_its_steps_before_the_views(tmp_path, capsys, caplog):
    """``colourhs synth --preset paper`` was silent 30 s before its bar: 8 s of
    ground-truth mu maps and 21 s of camera rays (here the tiny preset's board captures
    of one pose). Without :func:`show_progress` nothing is printed, and the lines are
    ordinary log records at INFO: a caller's own logging configuration sees them."""
    preset = replace(PRESETS["tiny"], n_poses=1)
    board_only = RenderSelection(parts=("photometric",))
    first = "synth tiny: ground-truth mu maps (gt/photometric.h5)"
    synthesise(tmp_path / "a", preset, selection=board_only, workers=1)
    assert capsys.readouterr() == ("", "") and _records(caplog) == []
    caplog.set_level(logging.INFO, logger=LOGGER)
    logging.getLogger(BARS).setLevel(logging.WARNING)  # the bars would go to stderr
    synthesise(tmp_path / "b", preset, selection=board_only, workers=1)
    assert capsys.readouterr() == ("", "") and _records(caplog) == [first]
    show_progress()
    synthesise(tmp_path / "c", preset, selection=board_only, workers=1)
    err = capsys.readouterr().err
    assert err.startswith(f"{first}\n")
    assert "synth tiny: camera rays: 100%" in err and "| 3/3 [" in err  # 3 cameras
    assert "synth tiny: 100%" in err and "| 1/1 [" in err  # one job: the board pose


def test_show_progress_adds_one_handler_writing_to_the_current_stderr(capsys, caplog):
    """Calling it again (a second ``main()`` in one process) prints each line once; the
    lines go to whatever ``sys.stderr`` is when they are logged (a redirection, a test's
    capture), not through the root logger's handlers."""
    log = logging.getLogger(f"{LOGGER}.test")
    stage(log, "hidden")
    show_progress()
    show_progress()
    assert len(logging.getLogger(LOGGER).handlers) == 1
    stage(log, "step", start=0.0)
    redirected = io.StringIO()
    with contextlib.redirect_stderr(redirected):
        stage(log, "redirected")
    err = capsys.readouterr().err
    assert _lines(err)[0].startswith("step [") and err.endswith(" s]\n") and "hidden" not in err
    assert redirected.getvalue() == "redirected\n"
    assert caplog.records == []  # not propagated to the root logger


def test_bars_have_their_own_switch(capsys):
    """``show_progress(bars=False)`` keeps the stage lines and hides the bars; the bars
    follow the stage lines' level unless their logger is set (``--quiet`` hides both)."""
    log = logging.getLogger(f"{LOGGER}.test")

    def run() -> str:
        stage(log, "step")
        list(bar(range(3), "loop"))
        return capsys.readouterr().err

    assert run() == ""  # nothing configured: a library call
    show_progress(bars=False)
    assert run() == "step\n"
    show_progress()
    err = run()
    assert err.startswith("step\n") and "loop: 100%" in err and "| 3/3 [" in err
    logging.getLogger(BARS).setLevel(logging.WARNING)
    assert run() == "step\n"
    show_progress(level=logging.WARNING)
    assert run() == ""


def test_calibration_bars_close_when_a_fit_fails(tiny_dataset, tmp_path, monkeypatch, capsys):
    """The noise and cross-talk bars are closed before the error is reported: the
    message starts its own line, not the end of a half-drawn bar."""
    import colourhs.calibration.crosstalk as crosstalk
    import colourhs.calibration.noise as noise

    def fail(*args, **kwargs):
        raise ValueError("no usable pixels")

    monkeypatch.setattr(noise, "estimate_noise", fail)
    monkeypatch.setattr(crosstalk, "fit_mixing_field", fail)
    poses = tmp_path / "poses.csv"
    marker_poses(tiny_dataset, poses)
    for argv in (
        ["noise", tiny_dataset, tmp_path / "n.json"],
        ["crosstalk", tiny_dataset, tmp_path / "x.json", "--poses", poses],
    ):
        assert main([str(a) for a in argv]) != 0
        err = capsys.readouterr().err
        assert "no usable pixels" in err
        line = next(x for x in err.replace("\r", "\n").splitlines() if "no usable pixels" in x)
        assert "%|" not in line, line


def test_bar_redraws_when_its_items_slow_down(monkeypatch, capsys):
    """A bar redraws on any update once MIN_INTERVAL_S has passed, also after fast
    items (tqdm's default learns a minimum of items between redraws from the first
    ones: the paper preset's noise model then went 6 s without a line). Here with a
    50 ms interval: 10 instant items, then 8 of 60 ms; measured 9 redraws in the slow
    part (tqdm's default: 2, the last one the closing redraw)."""
    import time

    from colourhs.common import progress

    show_progress()
    monkeypatch.setattr(progress, "MIN_INTERVAL_S", 0.05)
    for i in progress.bar(range(18), "slow down"):
        if i >= 10:
            time.sleep(0.06)
    lines = _lines(capsys.readouterr().err)
    shown = [int(line.split("|")[2].split("/")[0]) for line in lines if "|" in line]
    assert sum(1 for n in shown if n > 10) >= 6  # measured 9


def test_stdout_reaches_a_file_line_by_line():
    """``colourhs`` makes its stdout line-buffered, so a job's printed lines reach its
    log as they are printed (block buffering held the paper preset's chromaticity
    job's lines until it ended, 7 s)."""
    from colourhs.common.progress import line_buffered

    raw = io.BytesIO()
    stream = io.TextIOWrapper(raw, encoding="utf-8")
    print("before", file=stream)
    assert raw.getvalue() == b""  # block-buffered, as a file is
    line_buffered(stream)
    print("cam1: 255715 pixels with a chromaticity", file=stream)
    assert raw.getvalue() == b"before\ncam1: 255715 pixels with a chromaticity\n"
    line_buffered(object())  # a stream without reconfigure is left alone
