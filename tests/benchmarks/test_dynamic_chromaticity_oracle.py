"""benchmarks/dynamic_chromaticity.py's oracles: a tracked map with the true p in its
holes or where it has a p, and a map source run once per scene. Nothing is rendered."""

from __future__ import annotations

import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))

import dynamic_chromaticity as dyn  # noqa: E402

NAN = np.nan
#: One camera's 1 x 3 map: a tracked p, a hole, and a p off the object (no truth).
TRACKED = np.array([[[1.2, 0.9, 0.9], [NAN, NAN, NAN], [0.5, 1.0, 1.5]]], np.float32)
TRUTH = np.array([[[1.0, 1.0, 1.0], [2.0, 0.5, 0.5], [NAN, NAN, NAN]]], np.float32)


def _maps(tmp_path: Path) -> tuple[Path, Path]:
    tracked, truth = tmp_path / "tracked.h5", tmp_path / "truth.h5"
    with h5py.File(tracked, "w") as f:
        f.attrs["frame"], f.attrs["chromatic_frame"] = "000005", "000000"
        f["cam1"] = TRACKED
        f["sigma/cam1"] = np.array([[0.02, NAN, 0.03]], np.float32)
    with h5py.File(truth, "w") as f:
        f["cam1"] = TRUTH
    return tracked, truth


@pytest.mark.parametrize(
    "part, expected",
    [
        ("holes", [[1.2, 0.9, 0.9], [2.0, 0.5, 0.5], [0.5, 1.0, 1.5]]),
        ("known", [[1.0, 1.0, 1.0], [NAN, NAN, NAN], [0.5, 1.0, 1.5]]),
    ],
)
def test_the_truth_goes_into_one_part_of_the_tracked_map_only(tmp_path, part, expected):
    tracked, truth = _maps(tmp_path)
    out = dyn.put_truth(tracked, truth, tmp_path / "out" / "000005.h5", part)
    with h5py.File(out) as f:
        np.testing.assert_array_equal(f["cam1"][()], np.array([expected], np.float32))
        # the rest is the tracked map's: its sigma and that the frame has moved
        np.testing.assert_array_equal(f["sigma/cam1"][()], np.float32([[0.02, NAN, 0.03]]))
        assert (f.attrs["frame"], f.attrs["chromatic_frame"]) == ("000005", "000000")
    with h5py.File(tracked) as f:  # the tracked map itself is untouched
        np.testing.assert_array_equal(f["cam1"][()], TRACKED)


def test_an_unknown_part_is_refused(tmp_path):
    tracked, truth = _maps(tmp_path)
    with pytest.raises(ValueError, match="'holes' or 'known'"):
        dyn.put_truth(tracked, truth, tmp_path / "out.h5", "all")


def test_a_source_shared_by_the_oracles_runs_once_per_scene(tmp_path):
    calls = []

    def source(data, scene, files):
        calls.append((data, scene))
        return {"000000": tmp_path / f"{scene}.h5"}

    once = dyn.once_per_scene(source)
    first = once(tmp_path, "cloth", {})
    assert once(tmp_path, "cloth", {}) is first
    once(tmp_path, "moving-toy", {})
    assert calls == [(tmp_path, "cloth"), (tmp_path, "moving-toy")]
