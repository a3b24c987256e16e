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


def test_chroma_sigma_calibration_against_the_truth():
    """A map normalised to sum 3 from captures whose log ratios err by independent
    Gaussian noise of sigma ``s`` in each band (and by an arbitrary scale per pixel, which
    the calibration cannot measure), stating each band's sigma of log p as
    :func:`colourhs.calibration.chromaticity.log_sigma` does (``s sqrt(sum_c (delta_bc -
    p_c / 3)^2)``), is honest: 0.68 / 0.95 / 0.997 within 1 / 2 / 3 sigma; the same map
    stating a third of that sigma is not."""
    rng = np.random.default_rng(0)
    n = 200_000
    truth = rng.uniform(0.05, 2.0, (n, 3))
    s = rng.uniform(0.01, 0.2, n)
    q = truth * np.exp(s[:, None] * rng.standard_normal((n, 3)) + rng.normal(0, 1, (n, 1)))
    p = 3.0 * q / q.sum(axis=1, keepdims=True)
    d = np.eye(3)[None, :, :] - p[:, None, :] / 3.0  # (n, band, c)
    sigma = s[:, None] * np.sqrt(np.sum(d * d, axis=2))
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
#: the tracked map, the static map and the true map (NaN: nothing reconstructed), the
#: tracked map's chroma RMS and the truth carried by the true motion's (its floor).
TARGET_ROWS = {
    0: (1.0, 1.0, 1.0, 0.04, 0.0),
    4: (1.4, 6.0, 1.2, 0.05, 0.02),  # every bound met
    8: (2.0, 5.0, 2.0, 0.07, 0.03),  # drifted 2x (the true map 2x too); 2.5x better than static
    11: (1.2, np.nan, np.nan, 0.08, 0.05),  # only the static and true maps reconstruct nothing
}
#: An oracle's depth median (mm) and chroma RMS per frame: every bound met.
ORACLE_ROWS = {0: (1.0, 0.04), 4: (1.1, 0.05), 8: (1.5, 0.05), 11: (1.3, 0.05)}


def _target_table(tracked_lost_frame: int | None = None, oracle: bool = False) -> pd.DataFrame:
    rows = []
    for frame, (dyn_mm, static_mm, true_mm, chroma, floor) in TARGET_ROWS.items():
        if frame == tracked_lost_frame:
            dyn_mm = np.nan
        variants = [
            ("bayes_dyn", dyn_mm, chroma),
            ("bayes_full_static", static_mm, 0.0),
            ("bayes_full_true", true_mm, 0.0),
        ]
        if oracle:
            variants.append(("bayes_dyn_true_positions", *ORACLE_ROWS[frame]))
        for variant, depth, rms in variants:
            rows.append(
                {
                    "preset": "random-dynamic-tiny",
                    "seed": 3,
                    "scene": "cloth",
                    "frame": frame,
                    "chromatic_frame": 0,
                    "variant": variant,
                    "depth_median_mm": depth,
                    "chroma_rms_log": rms,
                    "chroma_floor_rms_log": floor,
                }
            )
    return pd.DataFrame(rows)


def test_the_tracking_targets_are_counted_per_frame_and_scene():
    """dyn.tracking_targets on a hand-made sequence: the chroma drift is the last frame's
    RMS over the chromatic frame's (0.08 / 0.04), its floor's the carried truth's RMS
    over the same (0.05 / 0.04); each moved frame's depth drift, gain
    over the static map and ratio to the true map's depth are counted against their
    bounds, and so are the true map's own drift and gain over the static map (the bounds
    of any chromaticity), per scene too; a static or true map that reconstructs nothing
    is a win for the tracked map and no comparison, a tracked map that reconstructs
    nothing misses, and so does a true map that reconstructs nothing on its own bounds."""
    t = dyn.tracking_targets(_target_table())
    assert t["scenes"] == [
        {
            "preset": "random-dynamic-tiny",
            "seed": 3,
            "scene": "cloth",
            "last_frame": 11,
            "chroma_drift": pytest.approx(2.0),
            "floor_drift": pytest.approx(1.25),
        }
    ]
    by_frame = {r["frame"]: r for r in t["frames"]}
    assert sorted(by_frame) == [4, 8, 11]
    assert by_frame[4]["depth_drift"] == pytest.approx(1.4)
    assert by_frame[4]["static_gain"] == pytest.approx(6.0 / 1.4)
    assert by_frame[8]["true_depth_drift"] == pytest.approx(2.0)
    assert by_frame[8]["tracked_over_true"] == pytest.approx(1.0)
    assert by_frame[4]["true_static_gain"] == pytest.approx(5.0)
    assert by_frame[8]["true_static_gain"] == pytest.approx(2.5)
    assert by_frame[11]["static_empty"] and by_frame[11]["true_empty"]
    assert by_frame[11]["static_gain"] is None
    assert t["met"] == {
        "chroma_drift": {"met": 0, "of": 1},
        "floor_drift": {"met": 1, "of": 1},
        "depth_drift": {"met": 2, "of": 3},
        "static_gain": {"met": 2, "of": 3},
        "true_depth_drift": {"met": 1, "of": 2},
        "true_static_gain": {"met": 1, "of": 3},
        "tracked_within_true": {"met": 2, "of": 2},
    }
    assert t["met_by_scene"] == {"cloth": t["met"]}
    lost = dyn.tracking_targets(_target_table(tracked_lost_frame=4))["met"]
    assert lost["depth_drift"] == {"met": 1, "of": 3}
    assert lost["static_gain"] == {"met": 1, "of": 3}
    assert lost["tracked_within_true"] == {"met": 1, "of": 2}
    seconds = {"render_s": 1.0, "calib_s": 1.0, "reconstruct_s": 1.0}
    md = dyn.summarise_markdown(dyn.summarise(_target_table().assign(**seconds)))
    assert "| static map's depth median >= 3.0x the tracked one's | 2 of 3 frames |" in md
    assert "| random-dynamic-tiny | 3 | cloth | 000011 | 1.20 | static: nothing |" in md
    assert "| random-dynamic-tiny | 3 | cloth | 000011 | 2.00 | 1.25 |" in md
    assert "the true map's (any chromaticity's bound) | 1 of 3 frames |" in md
    assert "| random-dynamic-tiny | 3 | cloth | 000008 | 2.00 | 2.50 | 2.00 | 2.50 | 1.00 |" in md
    assert "| bound | cloth |\n|---|---|\n| chroma drift | 0 of 1 |\n" in md
    assert "| true map's gain over the static map | 1 of 3 |" in md
    alone = dyn.tracking_targets(_table())["met"]  # no static or true map: not judged
    assert alone["static_gain"] == alone["tracked_within_true"] == {"met": 0, "of": 0}
    assert alone["depth_drift"] == {"met": 4, "of": 6}
    untracked = _table().assign(variant="bayes_full_static")
    empty = {"scenes": [], "frames": [], "met": {}, "met_by_scene": {}}
    assert dyn.tracking_targets(untracked) == empty


def test_an_oracle_is_judged_by_the_same_bounds_beside_the_tracked_map():
    """dyn.summarise with an oracle (a ``bayes_dyn_*`` variant): its own count of every
    bound that judges the tracked map, in a column of its own beside bayes_dyn's (the
    bounds that judge the scene, the carried truth's and the true map's drift, once);
    the per-frame ratios stay bayes_dyn's."""
    seconds = {"render_s": 1.0, "calib_s": 1.0, "reconstruct_s": 1.0}
    s = dyn.summarise(_target_table(oracle=True).assign(**seconds))
    assert list(s["oracle_targets"]) == ["bayes_dyn_true_positions"]
    oracle = s["oracle_targets"]["bayes_dyn_true_positions"]
    assert {k: v["met"] for k, v in oracle.items()} == {
        "chroma_drift": 1,
        "depth_drift": 3,
        "static_gain": 3,
        "tracked_within_true": 2,
    }
    assert s["targets"]["met"]["depth_drift"] == {"met": 2, "of": 3}
    md = dyn.summarise_markdown(s)
    assert "| bound | met | bayes_dyn_true_positions |" in md
    assert "| 2 of 3 frames | 3 of 3 frames |" in md
    assert "(any carry's bound) | 1 of 1 scenes | - |" in md
    assert "(any chromaticity's bound) | 1 of 3 frames | - |" in md
