"""benchmarks/dynamic_chromaticity.py's summary on a hand-made per-seed table: the
chromatic frame against the moved frames, median over seeds and worst seed, the
error bar's calibration beside the depth, and the markdown. Nothing is rendered."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))

import dynamic_chromaticity as dyn  # noqa: E402

#: Per seed: (depth median mm, within 3 sigma) on the chromatic frame 0 and on the
#: moved frames 5 and 11 of one scene and variant.
ROWS = {
    0: ((0.4, 0.99), (0.5, 0.95), (0.6, 0.90)),
    1: ((0.2, 0.98), (14.0, 0.00), (0.3, 0.97)),
    2: ((0.3, 0.97), (0.4, 0.96), (1.0, 0.60)),
}


def _table() -> pd.DataFrame:
    rows = []
    for seed, frames in ROWS.items():
        for frame, (depth, within3) in zip((0, 5, 11), frames, strict=True):
            rows.append(
                {
                    "preset": "random-dynamic",
                    "seed": seed,
                    "scene": "cloth",
                    "frame": frame,
                    "chromatic_frame": 0,
                    "variant": "bayes_dyn",
                    "depth_median_mm": depth,
                    "depth_signed_median_mm": -depth,
                    "normal_median_deg": 2.0,
                    "coverage": 0.8,
                    "depth_sigma_median_mm": 0.1 * depth,
                    "sigma_within_3": within3,
                    "render_s": 1.0,
                    "calib_s": 2.0,
                    "reconstruct_s": 3.0,
                }
            )
    return pd.DataFrame(rows)


def test_the_error_bars_calibration_is_summarised_beside_the_depth():
    s = dyn.summarise(_table())["scenes"]["cloth"]["bayes_dyn"]
    home, moved, worst = s["chromatic_frame"], s["moved"], s["moved_worst_frame"]
    assert home["depth_median_mm"]["median"] == pytest.approx(0.3)
    assert home["sigma_within_3"] == {"median": 0.98, "worst": 0.97, "seeds": 3}
    # moved: per seed the median over frames 5 and 11, then over seeds; the worst
    # of the error bar's calibration is its least share
    per_seed = [np.median([f[1] for f in ROWS[k][1:]]) for k in ROWS]
    assert moved["sigma_within_3"]["median"] == pytest.approx(np.median(per_seed))
    assert moved["sigma_within_3"]["worst"] == pytest.approx(min(per_seed))
    assert worst["sigma_within_3"]["worst"] == pytest.approx(0.0)
    assert worst["depth_median_mm"]["worst"] == pytest.approx(14.0)
    assert s["per_frame"]["5"]["sigma_within_3"]["worst"] == pytest.approx(0.0)
    md = dyn.summarise_markdown(dyn.summarise(_table()))
    row = next(line for line in md.splitlines() if line.startswith("| cloth | bayes_dyn"))
    assert "0.98 / 0.97; 0.78 / 0.48" in row
    head = next(line for line in md.splitlines() if line.startswith("| scene |"))
    assert "within 3 sigma, chromatic / moved" in head


def test_position_error_of_a_tracked_map_against_the_meshes(tmp_path):
    """dyn.position_error: a plane at 1 m moved 5 cm (5 px at f 100 px) between the
    chromatic frame and the frame; a tracked map that saw no motion is 5 px off,
    one that followed it 0 px; a map without positions (the calibrated one) has none."""
    from types import SimpleNamespace

    import h5py
    from capture_helpers import pinhole

    from colourhs.common.ply import write_ply

    w, h = 80, 60
    cam = pinhole(100.0, 40.0, 30.0)
    rig = SimpleNamespace(
        camera_names=("A",), image=SimpleNamespace(width=w, height=h), camera=lambda name: cam
    )
    gt = tmp_path / "scenes" / "plane" / "gt"
    gt.mkdir(parents=True)
    v = np.array([[-0.4, -0.4, 1.0], [0.4, -0.4, 1.0], [0.4, 0.4, 1.0], [-0.4, 0.4, 1.0]])
    tri = np.array([[0, 1, 2], [0, 2, 3]])
    write_ply(gt / "000000.ply", v, tri)
    write_ply(gt / "000001.ply", v + [0.05, 0.0, 0.0], tri)
    gx, gy = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    for name, dx in (("still", 0.0), ("followed", -5.0)):
        with h5py.File(tmp_path / f"{name}.h5", "w") as m:
            m["A"] = np.ones((h, w, 3), np.float32)
            m["position/A"] = np.stack([gx + dx, gy], axis=-1)
    args = (tmp_path, "plane", "000001", "000000", rig)
    still = dyn.position_error(tmp_path / "still.h5", *args)
    assert still["track_position_px"] == pytest.approx(5.0, abs=1e-3)
    assert still["track_motion_px"] == pytest.approx(5.0, abs=1e-3)
    assert still["track_position_known"] == 1.0
    followed = dyn.position_error(tmp_path / "followed.h5", *args)
    assert followed["track_position_px"] == pytest.approx(0.0, abs=1e-3)
    with h5py.File(tmp_path / "calibrated.h5", "w") as m:
        m["A"] = np.ones((h, w, 3), np.float32)
    none = dyn.position_error(tmp_path / "calibrated.h5", *args)
    assert none == dict.fromkeys(dyn.POSITION_COLUMNS)


def test_chroma_sigma_calibration_against_the_truth():
    """A map whose log p errs by independent Gaussian noise of its stated sigma in each
    band (and by an arbitrary scale per pixel, which the calibration cannot measure)
    is honest: 0.68 / 0.95 / 0.997 within 1 / 2 / 3 sigma; the same map stating a
    third of that sigma is not."""
    rng = np.random.default_rng(0)
    n = 200_000
    truth = rng.uniform(0.05, 2.0, (n, 3))
    sigma = rng.uniform(0.01, 0.2, n)
    p = truth * np.exp(sigma[:, None] * rng.standard_normal((n, 3)) + rng.normal(0, 1, (n, 1)))
    honest = dyn.chroma_sigma_error(p, truth, sigma)
    assert honest["chroma_sigma_median"] == pytest.approx(np.median(sigma))
    for k, share in ((1, 0.683), (2, 0.954), (3, 0.997)):
        assert honest[f"chroma_sigma_within_{k}"] == pytest.approx(share, abs=0.005)
    assert dyn.chroma_sigma_error(p, truth, sigma / 3)["chroma_sigma_within_3"] < 0.7
    p[: n // 2] = np.nan  # unknown pixels are left out
    assert dyn.chroma_sigma_error(p, truth, sigma)["chroma_sigma_within_1"] == pytest.approx(
        0.683, abs=0.01
    )
    none = dyn.chroma_sigma_error(p[:1], truth[:1], sigma[:1])
    assert all(v is None for v in none.values())


#: One seed of a coloured sequence, chromatic frame 0, per frame: depth median (mm) of
#: the tracked map, the static map and the true map (NaN: nothing reconstructed) and
#: the tracked map's chroma RMS.
TARGET_ROWS = {
    0: (1.0, 1.0, 1.0, 0.04),
    4: (1.4, 6.0, 1.2, 0.05),  # every bound met
    8: (2.0, 5.0, 2.0, 0.07),  # drifted 2x (the true map 2x too); 2.5x better than static
    11: (1.2, np.nan, np.nan, 0.08),  # only the static and true maps reconstruct nothing
}


def _target_table(tracked_lost_frame: int | None = None) -> pd.DataFrame:
    rows = []
    for frame, (dyn_mm, static_mm, true_mm, chroma) in TARGET_ROWS.items():
        if frame == tracked_lost_frame:
            dyn_mm = np.nan
        for variant, depth in (
            ("bayes_dyn", dyn_mm),
            ("bayes_full_static", static_mm),
            ("bayes_full_true", true_mm),
        ):
            rows.append(
                {
                    "preset": "random-dynamic-tiny",
                    "seed": 3,
                    "scene": "cloth",
                    "frame": frame,
                    "chromatic_frame": 0,
                    "variant": variant,
                    "depth_median_mm": depth,
                    "chroma_rms_log": chroma if variant == "bayes_dyn" else 0.0,
                }
            )
    return pd.DataFrame(rows)


def test_the_tracking_targets_are_counted_per_frame_and_scene():
    """dyn.tracking_targets on a hand-made sequence: the chroma drift is the last frame's
    RMS over the chromatic frame's (0.08 / 0.04); each moved frame's depth drift, gain
    over the static map and ratio to the true map's depth are counted against their
    bounds; a static or true map that reconstructs nothing is a win for the tracked map
    and no comparison, a tracked map that reconstructs nothing misses."""
    t = dyn.tracking_targets(_target_table())
    assert t["scenes"] == [
        {
            "preset": "random-dynamic-tiny",
            "seed": 3,
            "scene": "cloth",
            "last_frame": 11,
            "chroma_drift": pytest.approx(2.0),
        }
    ]
    by_frame = {r["frame"]: r for r in t["frames"]}
    assert sorted(by_frame) == [4, 8, 11]
    assert by_frame[4]["depth_drift"] == pytest.approx(1.4)
    assert by_frame[4]["static_gain"] == pytest.approx(6.0 / 1.4)
    assert by_frame[8]["true_depth_drift"] == pytest.approx(2.0)
    assert by_frame[8]["tracked_over_true"] == pytest.approx(1.0)
    assert by_frame[11]["static_empty"] and by_frame[11]["true_empty"]
    assert by_frame[11]["static_gain"] is None
    assert t["met"] == {
        "chroma_drift": {"met": 0, "of": 1},
        "depth_drift": {"met": 2, "of": 3},
        "static_gain": {"met": 2, "of": 3},
        "true_depth_drift": {"met": 1, "of": 2},
        "tracked_within_true": {"met": 2, "of": 2},
    }
    lost = dyn.tracking_targets(_target_table(tracked_lost_frame=4))["met"]
    assert lost["depth_drift"] == {"met": 1, "of": 3}
    assert lost["static_gain"] == {"met": 1, "of": 3}
    assert lost["tracked_within_true"] == {"met": 1, "of": 2}
    seconds = {"render_s": 1.0, "calib_s": 1.0, "reconstruct_s": 1.0}
    md = dyn.summarise_markdown(dyn.summarise(_target_table().assign(**seconds)))
    assert "| static map's depth median >= 3.0x the tracked one's | 2 of 3 frames |" in md
    assert "| random-dynamic-tiny | 3 | cloth | 000011 | 1.20 | static: nothing |" in md
    alone = dyn.tracking_targets(_table())["met"]  # no static or true map: not judged
    assert alone["static_gain"] == alone["tracked_within_true"] == {"met": 0, "of": 0}
    assert alone["depth_drift"] == {"met": 4, "of": 6}
    untracked = _table().assign(variant="bayes_full_static")
    assert dyn.tracking_targets(untracked) == {"scenes": [], "frames": [], "met": {}}
