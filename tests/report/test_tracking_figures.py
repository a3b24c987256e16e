"""A moving coloured object's chromaticity in the report (colourhs.report.tracking and
its figures in colourhs.report.figures)."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest
from PIL import Image

from colourhs.report.figures import chromaticity_animation, chromaticity_drift_figure
from colourhs.report.tracking import chromaticity_drift

FRAMES = ("000000", "000001", "000002")


def _write(path, maps: dict, sigma: float | None = None, tracked=None):
    with h5py.File(path, "w") as f:
        for cam, p in maps.items():
            f[cam] = p.astype(np.float32)
            if sigma is not None:
                f[f"sigma/{cam}"] = np.full(p.shape[:2], sigma, np.float32)
        if tracked is not None:
            f.attrs["tracked"] = json.dumps(tracked)
            f.attrs["chromatic_frame"] = FRAMES[0]
    return path


@pytest.fixture
def files(tmp_path):
    """Truth: a red and a blue half moving right by 4 px a frame; the tracked maps equal
    it; the calibrated map is frame 0's."""
    truth, tracked = {}, {}
    for k, f in enumerate(FRAMES):
        p = np.ones((24, 32, 3))
        p[:, : 12 + 4 * k] = (2.0, 0.5, 0.5)
        p[:, 12 + 4 * k :] = (0.5, 0.5, 2.0)
        maps = {"cam1": p, "cam2": p}
        truth[f] = _write(tmp_path / f"gt{f}.h5", maps)
        tracked[f] = _write(tmp_path / f"t{f}.h5", maps, 0.01 * k, {"cam1": 1.0, "cam2": 0.9})
    calibrated = _write(tmp_path / "calibrated.h5", {"cam1": p * 0 + 1, "cam2": p * 0 + 1})
    with h5py.File(truth[FRAMES[0]]) as g, h5py.File(calibrated, "a") as c:
        for cam in ("cam1", "cam2"):
            c[cam][...] = g[cam][()]
    return tracked, truth, calibrated


def test_drift_measures_the_tracked_and_the_unchanged_maps(files, tmp_path):
    tracked, truth, calibrated = files
    drift = chromaticity_drift(tracked, truth, calibrated)
    assert list(drift) == list(FRAMES)
    assert all(d["error"] == pytest.approx(0.0, abs=1e-7) for d in drift.values())
    assert drift["000000"]["static_error"] == pytest.approx(0.0, abs=1e-7)
    # Frame 2: 8 of 32 columns red in the calibrated map but blue in the truth.
    swapped = np.log(4.0) * np.sqrt(2 / 3)  # (log 4, 0, -log 4) less its mean, RMS
    assert drift["000002"]["static_error"] == pytest.approx(swapped * np.sqrt(8 / 32), rel=1e-5)
    assert drift["000002"]["sigma"] == pytest.approx(0.02)
    assert drift["000001"]["tracked"] == pytest.approx(0.95)
    png = chromaticity_drift_figure(drift, tmp_path / "drift.png")
    assert Image.open(png).size[0] > 300


def test_animation_shows_one_cameras_map_per_frame(files, tmp_path):
    tracked, _, _ = files
    gif = chromaticity_animation(tracked, tmp_path / "c.gif", camera="cam2")
    im = Image.open(gif)
    assert im.n_frames == 3 and im.size == (320, 240)  # enlarged 10x so the label reads
