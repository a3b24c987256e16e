"""The report's calibration diagnostics (colourhs.report.calibration) on small hand-made files."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace as NS

import h5py
import numpy as np
import pandas as pd
import pytest
from rig_examples import contract_example

from colourhs.capture import rig_from_dict
from colourhs.cli.parser import main
from colourhs.report.calibration import (
    calibration_diagnostics,
    crosstalk_table,
    marker_table,
    mu_error_table,
    photometric_table,
)
from colourhs.report.page import REQUIRED_COLUMNS

#: The Helmholtz cameras of docs/capture-format.md's example rig (cam1 blue, cam2 red,
#: cam3 green): pairs (cam1 red, cam2 blue), (cam1 green, cam3 blue), (cam2 green, cam3 red).
MAPS = ("cam1/red", "cam2/blue", "cam1/green", "cam3/blue", "cam2/green", "cam3/red")
M = [[1.0, 0.1, 0.2], [0.3, 1.0, 0.4], [0.5, 0.6, 1.0]]


def _calibration(root: Path) -> tuple[Path, Path]:
    """results/NAME/calib files and a gt/photometric.h5 of 4 x 5 maps.

    True log mu rises 0.01 per column; the calibrated maps equal it except cam1/red,
    0.1 too high, and cam3/red is calibrated on its top two rows only.
    """
    calib, truth = root / "calib", root / "data" / "gt" / "photometric.h5"
    calib.mkdir(parents=True)
    truth.parent.mkdir(parents=True)
    pd.DataFrame(
        {"pose": ["p01", "p02"], "markers_cam1": ["0 1 2", "0 1 2 3"], "n_markers": [3, 4]}
        | {"point_x": [0.0, 0.1], "rms_px": [0.05, 0.12]}
    ).to_csv(calib / "marker_poses.csv", index=False)
    cams = {c: {"M": M, "spread": np.zeros((3, 3)).tolist()} for c in ("cam1", "cam2", "cam3")}
    (calib / "crosstalk.json").write_text(json.dumps({"cameras": cams, "method": "test"}))
    g = np.tile(0.01 * np.arange(5), (4, 1))
    with h5py.File(calib / "photometric.h5", "w") as f, h5py.File(truth, "w") as t:
        for k in MAPS:
            f[k] = np.exp(g + (0.1 if k == "cam1/red" else 0.0)).astype(np.float32)
            f[f"calibrated/{k}"] = np.arange(20).reshape(4, 5) < (10 if k == "cam3/red" else 20)
            t[k] = np.exp(g).astype(np.float32)
        f.attrs["constraints"] = json.dumps({k: 100 + i for i, k in enumerate(MAPS)})
        f.attrs["residual_rms_log"] = json.dumps({k: 0.02 for k in MAPS})
        f.attrs["noise_rms_log"] = json.dumps({k: 0.016 for k in MAPS})
    return calib, truth


def test_calibration_tables(tmp_path):
    calib, truth = _calibration(tmp_path)
    rig = rig_from_dict(contract_example())
    markers = marker_table(calib / "marker_poses.csv")
    assert markers.to_dict("list") == {
        "pose": ["p01", "p02"],
        "n_markers": [3, 4],
        "rms_px": [0.05, 0.12],
    }
    cross = crosstalk_table(calib / "crosstalk.json")
    assert cross.columns.tolist() == ["camera", "channel", "red", "green", "blue"]
    assert len(cross) == 9 and cross.iloc[1].tolist() == ["cam1", "G", 0.3, 1.0, 0.4]
    fit = photometric_table(calib / "photometric.h5").set_index("map")
    assert fit.loc["cam3/blue", "constraints"] == 103 and fit["residual_rms_log"].eq(0.02).all()
    assert np.allclose(fit["residual_over_noise"], 1.25)
    assert (
        fit.loc["cam3/red", "calibrated_share"] == 0.5
        and fit.loc["cam1/red", "calibrated_share"] == 1.0
    )
    err = mu_error_table(calib / "photometric.h5", truth, rig).set_index("map")
    assert sorted(err.index) == sorted(MAPS)
    # cam1/red 0.1 too high: its pair's free scale takes 0.05, leaving 0.05 on both maps
    # (float32 maps: measured 6.7e-9 and 4.5e-9 off, the exact maps 0; bound 2e-8)
    assert err.loc["cam1/red", "rms_log_error"] == pytest.approx(0.05, abs=2e-8)
    assert err.loc["cam2/blue", "rms_log_error"] == pytest.approx(0.05, abs=2e-8)
    assert err.loc[["cam1/green", "cam3/blue"], "rms_log_error"].max() < 2e-8
    # mu = 1: the true log mu less its mean, 0.01 * std(0..4) = 0.01 * sqrt(2)
    # (measured 6.9e-7 relative off; bound 1.5e-6)
    assert err.loc["cam1/green", "rms_log_error_mu1"] == pytest.approx(
        0.01 * np.sqrt(2), rel=1.5e-6
    )
    assert err.loc["cam3/red", "calibrated_share"] == 0.5


def test_report_shows_calibration_diagnostics(tmp_path, capsys):
    """colourhs report --calib: the four tables in the Calibration section; without
    ground truth three; truth of other camera names is said in a row."""
    calib, _ = _calibration(tmp_path)
    metrics = tmp_path / "metrics.csv"
    pd.DataFrame([{c: 1.0 for c in REQUIRED_COLUMNS} | {"scene": "s", "frame": "000000"}]).to_csv(
        metrics, index=False
    )
    out = tmp_path / "index.html"
    argv = ["report", str(out), "--name", "t", "--metrics", str(metrics), "--calib", str(calib)]
    assert main(argv) == 0
    text = out.read_text(encoding="utf-8")
    calibration = text[text.index('id="calibration"') : text.index('id="scenes"')]
    titles = ["Board poses", "Channel cross-talk", "Photometric fit"]
    assert [t for t in titles if f"<h3>{t}</h3>" in calibration] == titles
    assert "mu against the ground truth" not in text  # no dataset given
    rig = rig_from_dict(contract_example())
    with_truth = calibration_diagnostics(calib, NS(root=tmp_path / "data", rig=rig))
    assert [d["title"] for d in with_truth][-1] == "mu against the ground truth"
    assert len(with_truth[-1]["table"]) == 6
    renamed = contract_example()
    for cam in renamed["cameras"]:
        cam["name"] = "x" + cam["name"]
    other = calibration_diagnostics(calib, NS(root=tmp_path / "data", rig=rig_from_dict(renamed)))
    assert other[-1]["table"].to_dict("list") == {
        "note": ["no map 'xcam1/red' in the calibration or the truth"]
    }
