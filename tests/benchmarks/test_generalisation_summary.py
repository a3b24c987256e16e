"""benchmarks/generalisation.py's summary on hand-made per-seed tables: the
medians and worst rigs, the targets' ``met``, the sigma calibration, the ablation's
not-applicable ML link and the markdown. Nothing is rendered."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from colourhs.common.metrics_csv import DROP_COLUMNS

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))

import generalisation as gen  # noqa: E402

SETS = ("random", "corner")
SEEDS = (0, 1, 2)
SCENES = ("plane", "sheet", "statue", "toy")
VARIANTS = ("vh", "ml_full", "bayes_nocalib", "bayes_ph", "bayes_full")
#: Seed 1's uncalibrated mu is 5 % off: the ML link is not applicable there.
MU_UNCALIBRATED = {0: 0.01, 1: 0.05, 2: 0.01}
#: The Bayesian variants' depth median per seed (random set; corner twice it); the
#: others' errors are larger, in the ablation's order.
BAYES_DEPTH = {
    "plane": (0.05, 0.1, 0.2),
    "sheet": (0.1, 0.2, 0.5),
    "statue": (0.3, 0.5, 0.9),
    "toy": (0.5, 1.0, 2.0),
}
LADDER = {"vh": 9.0, "ml_full": 5.0, "bayes_nocalib": 3.0}
SIGNED = (0.01, -0.04, 0.02)
NORMAL = (1.5, 2.0, 3.0)
COVERAGE = (0.9, 0.95, 0.8)
GOOD_SHARES = (0.68, 0.95, 0.99)
BAD_SHARES = (0.5, 0.8, 0.91)


def row(set_: str, seed: int, scene: str, variant: str) -> dict:
    """One per-seed row: corner's errors twice random's, its sigma shares bad."""
    scale = 1.0 if set_ == "random" else 2.0
    bayes = variant.startswith("bayes")
    depth = LADDER.get(variant, BAYES_DEPTH[scene][seed]) * scale
    shares = (GOOD_SHARES if set_ == "random" else BAD_SHARES) if bayes else (np.nan,) * 3
    return {
        "set": set_,
        "seed": seed,
        "scene": scene,
        "variant": variant,
        "frames": 1,
        "depth_median_mm": depth,
        "depth_signed_median_mm": SIGNED[seed] * scale,
        "depth_rms_mm": 4 * depth,
        "depth_p95_mm": 3 * depth,
        "normal_median_deg": NORMAL[seed] * scale,
        "coverage": COVERAGE[seed],
        "depth_sigma_median_mm": 0.1 * scale if bayes else np.nan,
        **{f"sigma_within_{k}": v for k, v in zip((1, 2, 3), shares, strict=True)},
        "mu_rms_log_worst": 0.003,
        "mu_uncalibrated_rms_log_worst": MU_UNCALIBRATED[seed],
        "chromaticity_median_rel": 0.01,
    }


def select(t: pd.DataFrame, set_="random", scene=None, variant=None, seeds=None) -> pd.Series:
    sel = t["set"] == set_
    if scene is not None:
        sel &= t["scene"] == scene
    if variant is not None:
        sel &= t["variant"] == variant
    if seeds is not None:
        sel &= t["seed"].isin(seeds)
    return sel


@pytest.fixture
def table() -> pd.DataFrame:
    """2 sets x 3 seeds x 4 scenes x 5 variants. In the random set ML beats
    bayes_nocalib on the plane of seeds 0 (mu checked) and 1 (mu 5 % off), and
    bayes_full's 1-sigma share on seed s is 0.58, 0.68, 0.78 (mean 0.68)."""
    t = pd.DataFrame(
        [row(s, seed, sc, v) for s in SETS for seed in SEEDS for sc in SCENES for v in VARIANTS]
    )
    ml = select(t, scene="plane", variant="ml_full", seeds=[0, 1])
    t.loc[ml, ["depth_median_mm", "depth_rms_mm"]] = 1.0
    for seed, share in zip(SEEDS, (0.58, 0.68, 0.78), strict=True):
        t.loc[select(t, variant="bayes_full", seeds=[seed]), "sigma_within_1"] = share
    return t


def test_medians_and_worst_rigs_per_set(table):
    s = gen.summarise(table)
    assert s["seeds"] == [0, 1, 2] and sorted(s["sets"]) == ["corner", "random"]
    assert s["ml_link_mu_limit"] == 0.02 and s["sets"]["random"]["seeds"] == [0, 1, 2]
    r = s["sets"]["random"]["scenes"]
    plane = r["plane"]["bayes_ph"]
    assert plane["depth_median_mm"] == {
        "median": pytest.approx(0.1),
        "worst": pytest.approx(0.2),
        "rigs": 3,
        "target": {"median": 0.1, "worst": 0.3},
        "met": True,
    }
    assert (plane["depth_rms_mm"]["median"], plane["depth_rms_mm"]["worst"]) == (0.4, 0.8)
    assert plane["depth_rms_mm"]["met"] is True
    assert (plane["coverage"]["median"], plane["coverage"]["worst"]) == (0.9, 0.8)
    assert plane["coverage"]["target"] is None and "met" not in plane["coverage"]
    assert plane["depth_signed_median_mm"]["median"] == pytest.approx(0.01)
    assert plane["depth_signed_median_mm"]["worst"] == pytest.approx(-0.04)  # its sign kept
    assert plane["depth_signed_median_mm"]["met"] is True
    statue = r["statue"]["bayes_full"]
    assert (statue["normal_median_deg"]["median"], statue["normal_median_deg"]["worst"]) == (
        2.0,
        3.0,
    )
    assert statue["normal_median_deg"]["met"] and statue["depth_median_mm"]["met"]
    toy = r["toy"]["bayes_full"]["depth_median_mm"]
    assert (toy["median"], toy["worst"], toy["met"]) == (1.0, 2.0, True)
    assert r["sheet"]["bayes_ph"]["depth_median_mm"]["worst"] == 0.5
    assert r["sheet"]["bayes_ph"]["depth_median_mm"]["met"] is True
    # A rig with nothing reconstructed has no depth figures: the others may be within
    # the targets, but the set's are not met.
    empty = table.copy()
    sel = (empty["set"] == "random") & (empty["scene"] == "toy") & (empty["seed"] == 0)
    empty.loc[sel & (empty["variant"] == "bayes_full"), "depth_median_mm"] = np.nan
    toy = gen.summarise(empty)["sets"]["random"]["scenes"]["toy"]["bayes_full"]
    assert toy["depth_median_mm"]["rigs"] == 2 and toy["depth_median_mm"]["met"] is False
    # ML on the plane (ML on a narrow baseline): reported, no target.
    ml = r["plane"]["ml_full"]
    assert (ml["depth_median_mm"]["median"], ml["depth_median_mm"]["worst"]) == (1.0, 5.0)
    assert ml["depth_signed_median_mm"]["worst"] == pytest.approx(-0.04)
    assert ml["depth_median_mm"]["target"] is None and "met" not in ml["depth_median_mm"]
    # Sigma shares: median, and the worst is the furthest from the Gaussian's 0.683.
    one = r["plane"]["bayes_full"]["sigma_within_1"]
    assert (one["median"], one["worst"]) == (0.68, 0.58)
    assert r["plane"]["vh"]["depth_sigma_median_mm"] == {
        "median": None,
        "worst": None,
        "rigs": 0,
        "target": None,
    }
    # The corner set separately: twice the errors, the plane's targets missed.
    c = s["sets"]["corner"]["scenes"]["plane"]["bayes_ph"]
    assert (c["depth_median_mm"]["median"], c["depth_median_mm"]["worst"]) == (0.2, 0.4)
    assert not c["depth_median_mm"]["met"] and not c["depth_rms_mm"]["met"]
    assert c["depth_signed_median_mm"]["worst"] == pytest.approx(-0.08)
    assert not c["depth_signed_median_mm"]["met"]
    assert s["sets"]["random"]["calibration"]["mu_uncalibrated_rms_log_worst"] == {
        "median": 0.01,
        "worst": 0.05,
    }


@pytest.mark.parametrize(
    ("metric", "seed", "value", "which", "expected", "met"),
    [
        ("depth_median_mm", 2, 0.3, "worst", 0.3, True),  # worst at its target
        ("depth_median_mm", 2, 0.3001, "worst", 0.3001, False),
        ("depth_median_mm", 1, 0.1001, "median", 0.1001, False),  # median just above
        ("depth_rms_mm", 2, 1.0, "worst", 1.0, True),
        ("depth_rms_mm", 2, 1.0001, "worst", 1.0001, False),
        ("depth_signed_median_mm", 1, -0.05, "worst", -0.05, True),
        ("depth_signed_median_mm", 1, -0.0501, "worst", -0.0501, False),
        ("depth_signed_median_mm", 1, 0.0501, "worst", 0.0501, False),
    ],
)
def test_met_flips_at_the_targets_boundary(table, metric, seed, value, which, expected, met):
    table.loc[select(table, scene="plane", variant="bayes_ph", seeds=[seed]), metric] = value
    entry = gen.summarise(table)["sets"]["random"]["scenes"]["plane"]["bayes_ph"][metric]
    assert entry[which] == pytest.approx(expected, abs=1e-12)
    assert entry["met"] is met


def test_normal_target_boundary(table):
    sel = select(table, scene="statue", variant="bayes_full", seeds=[1])
    table.loc[sel, "normal_median_deg"] = 2.0001  # the median over rigs just above 2 deg
    entry = gen.summarise(table)["sets"]["random"]["scenes"]["statue"]["bayes_full"]
    assert entry["normal_median_deg"]["median"] == 2.0001
    assert entry["normal_median_deg"]["met"] is False


def test_ml_link_not_applicable_where_uncalibrated_mu_is_off(table):
    s = gen.summarise(table)
    r = s["sets"]["random"]
    for suffix in ("", "_rms"):
        # Seed 0 (mu 1 % off): checked and broken; seed 1 (5 % off): not applicable.
        assert r[f"ablation_links_broken{suffix}"]["0/plane"] == ["ml_full > bayes_nocalib"]
        assert r[f"ablation_links_broken{suffix}"]["1/plane"] == []
        assert r[f"ablation_order_holds{suffix}"]["0/plane"] is False
        assert r[f"ablation_order_holds{suffix}"]["1/plane"] is True
        assert r[f"ablation_order_all_seeds{suffix}"] is False
        assert r[f"ablation_broken_counts{suffix}"] == {"ml_full > bayes_nocalib": 1, "cases": 12}
    assert r["ablation_ml_link_not_applicable"] == 1
    assert r["ablation_ml_link_not_applicable_seeds"] == [1]
    c = s["sets"]["corner"]
    assert c["ablation_order_all_seeds"] and c["ablation_broken_counts_rms"] == {"cases": 12}
    assert c["ablation_ml_link_not_applicable"] == 1


def test_ml_link_checked_within_two_percent_and_other_links_everywhere(table):
    table.loc[table["seed"] == 1, "mu_uncalibrated_rms_log_worst"] = 0.02  # at the limit
    r = gen.summarise(table)["sets"]["random"]
    assert r["ablation_broken_counts"] == {"ml_full > bayes_nocalib": 2, "cases": 12}
    assert r["ablation_ml_link_not_applicable"] == 0
    # Back to 5 %: the ML link is skipped on seed 1, the others are still checked.
    table.loc[table["seed"] == 1, "mu_uncalibrated_rms_log_worst"] = 0.05
    sel = select(table, scene="plane", variant="vh", seeds=[1])
    table.loc[sel, ["depth_median_mm", "depth_rms_mm"]] = 0.5
    table.loc[select(table, scene="toy", variant="bayes_full", seeds=[1]), "depth_rms_mm"] = 9
    r = gen.summarise(table)["sets"]["random"]
    assert r["ablation_links_broken"]["1/plane"] == ["vh > ml_full"]
    assert r["ablation_links_broken_rms"]["1/toy"] == ["bayes_ph >= bayes_full"]
    assert r["ablation_links_broken"]["1/toy"] == []


def test_sigma_calibration(table):
    s = gen.summarise(table)
    good, bad = s["sets"]["random"]["sigma_calibration"], s["sets"]["corner"]["sigma_calibration"]
    variants = ["bayes_nocalib", "bayes_ph", "bayes_full"]  # not vh, ml_full
    assert list(good) == [*variants, gen.OWN_VARIANT]
    # Each scene's own variant: bayes_ph's plane and sheet, bayes_full's statue and toy.
    own = good[gen.OWN_VARIANT]
    assert own["rows"] == 12 and own["sigma_within_1"]["mean"] == pytest.approx(0.68)
    wrong = table.copy()  # bayes_ph on the coloured scenes: not their own variant
    wrong.loc[
        (wrong["variant"] == "bayes_ph") & wrong["scene"].isin(["statue", "toy"]), "sigma_within_1"
    ] = 0.1
    again = gen.summarise(wrong)["sets"]["random"]["sigma_calibration"]
    assert again[gen.OWN_VARIANT]["sigma_within_1"]["mean"] == pytest.approx(0.68)
    assert again["bayes_ph"]["sigma_within_1"]["mean"] == pytest.approx((6 * 0.68 + 6 * 0.1) / 12)
    for variant in variants:
        assert good[variant]["met"] is True and good[variant]["rows"] == 12
        assert good[variant]["sigma_within_2"]["mean"] == pytest.approx(0.95)
        assert good[variant]["sigma_within_1"]["target"] == pytest.approx(0.6827, abs=1e-4)
        assert bad[variant]["met"] is False
        assert bad[variant]["sigma_within_1"] == {
            "mean": pytest.approx(0.5),
            "target": pytest.approx(0.6827, abs=1e-4),
            "tolerance": 0.1,
            "met": False,
        }
        assert bad[variant]["sigma_within_2"]["met"] is False
        assert bad[variant]["sigma_within_3"]["met"] is True  # 0.91: 0.087 from 0.997
    # Rows weighted equally: bayes_full's 0.58, 0.68, 0.78 average 0.68 (met).
    assert good["bayes_full"]["sigma_within_1"]["mean"] == pytest.approx(0.68)
    table.loc[select(table, variant="bayes_ph", seeds=[0]), "sigma_within_1"] = 0.2
    ph = gen.summarise(table)["sets"]["random"]["sigma_calibration"]["bayes_ph"]
    assert ph["sigma_within_1"]["mean"] == pytest.approx((4 * 0.2 + 8 * 0.68) / 12)
    assert ph["sigma_within_1"]["met"] is False and ph["met"] is False


def test_table_without_set_column_is_one_set(table):
    old = table[table["set"] == "random"].drop(columns="set")
    s = gen.summarise(old)
    assert list(s["sets"]) == ["all"]
    assert s["sets"]["all"]["scenes"]["plane"]["bayes_ph"]["depth_median_mm"]["median"] == 0.1


def test_markdown_has_one_table_per_set(table):
    md = gen.summarise_markdown(gen.summarise(table))
    assert md.count("| scene | variant | depth median (mm) |") == 2
    assert md.count("| variant | within 1 sigma |") == 2
    assert md.count("| statistic |") == 2
    random, corner = md.split("## Set `random`")[1], md.split("## Set `corner`")[1]
    corner = corner.split("## Set")[0]
    plane = next(line for line in random.splitlines() if line.startswith("| plane | bayes_ph |"))
    assert "0.100 / 0.200" in plane and "+0.010 / -0.040" in plane and plane.endswith("| yes |")
    plane = next(line for line in corner.splitlines() if line.startswith("| plane | bayes_ph |"))
    assert "0.200 / 0.400" in plane and plane.endswith("| no (depth, RMS, abs signed) |")
    assert "| plane | ml_full | 1.000 / 5.000 |" in random
    rows = [line for line in random.splitlines() if line.startswith("| ")]
    assert len(rows) == 3 + 5 + 4 + 2  # three headers; scenes, sigma and ablation rows
    assert "| bayes_full | 0.680 | 0.950 | 0.990 | 12 |" in random
    assert "| bayes_ph | 0.500 | 0.800 | 0.910 | 12 |" in corner
    assert "| depth median | no | 0 | 1 | 0 | 0 | 12 |" in random
    assert "on 1 of 3 rigs (seeds 1)" in random


def test_main_summarises_several_csvs(table, tmp_path, monkeypatch):
    monkeypatch.setattr(gen, "HERE", tmp_path)
    paths = []
    for name in SETS:
        paths.append(tmp_path / f"{name}.csv")
        table[table["set"] == name].to_csv(paths[-1], index=False)
    summary = gen.main(["--summarise", *map(str, paths), "--tag", "_both"])
    out = tmp_path / "results"
    assert json.loads((out / "generalisation_summary_both.json").read_text()) == summary
    assert sorted(summary["sets"]) == ["corner", "random"]
    plane = summary["sets"]["corner"]["scenes"]["plane"]["bayes_ph"]["depth_median_mm"]
    assert (plane["median"], plane["worst"]) == (0.2, 0.4)
    md = (out / "generalisation_summary_both.md").read_text()
    assert md.count("| scene | variant |") == 2


def test_evaluate_variant_pools_sigma_over_the_compared_pixels(monkeypatch, tmp_path):
    """Two frames' errors and sigmas (the reconstruction, hull, mesh and depth files
    faked): sigma is pooled where both it and the error are finite; none for vh."""
    from types import SimpleNamespace

    import colourhs.capture
    import colourhs.common.depthfile
    import colourhs.common.ply
    import colourhs.evaluation.depth_errors
    import colourhs.reconstruct.frame
    import colourhs.surfaces.hull

    nan = np.nan
    errors = {  # metres, per frame
        "000000": [[0.001, nan], [-0.002, 0.004]],
        "000001": [[0.0005, 0.003], [nan, nan]],
    }
    sigmas = {
        "000000": [[0.001, 0.001], [nan, 0.001]],
        "000001": [[0.001, 0.002], [0.001, 0.001]],
    }
    rig = SimpleNamespace(image=SimpleNamespace(width=2, height=2), cameras=[None])
    monkeypatch.setattr(colourhs.capture, "load_rig", lambda data: rig)
    monkeypatch.setattr(colourhs.common.ply, "load_mesh", lambda path: (None, None, None))
    monkeypatch.setattr(colourhs.reconstruct.frame, "reconstruct_frame", lambda *a, **k: None)
    monkeypatch.setattr(colourhs.surfaces.hull, "visual_hull", lambda *a, **k: None)

    def read_depth(h5):
        vh = h5.parent.name == "vh"
        sigma = None if vh else np.array(sigmas[h5.stem], np.float32)
        return SimpleNamespace(frame=h5.stem, depth_sigma=sigma, params={})

    def depth_errors(depth, *args):
        err = np.array(errors[depth.frame])
        lost = dict.fromkeys(DROP_COLUMNS, None if depth.depth_sigma is None else 0.0)
        if depth.depth_sigma is not None:  # frame 0 lost one pixel outside, frame 1 two
            lost["dropped_outside" if depth.frame == "000000" else "dropped_data_term"] = (
                0.25 if depth.frame == "000000" else 0.5
            )
        return err, np.zeros_like(err), {"truth_pixels": 4} | lost

    monkeypatch.setattr(colourhs.common.depthfile, "read_depth", read_depth)
    monkeypatch.setattr(colourhs.evaluation.depth_errors, "depth_errors", depth_errors)
    frames = list(errors)
    files = {"noise": None, "photometric": None, "crosstalk": None}
    m = gen.evaluate_variant(tmp_path, "plane", frames, "bayes_ph", files, None, tmp_path)
    # Errors (mm) -2, 0.5, 1, 3, 4 of 8 truth pixels.
    assert m["depth_median_mm"] == pytest.approx(2.0)
    assert m["depth_signed_median_mm"] == pytest.approx(1.0)
    assert m["coverage"] == pytest.approx(5 / 8)
    # |error| / sigma of the 4 pixels with both: 1, 4, 0.5, 1.5 (sigma 1, 1, 1, 2 mm).
    assert m["depth_sigma_median_mm"] == pytest.approx(1.0)
    assert (m["sigma_within_1"], m["sigma_within_2"], m["sigma_within_3"]) == (0.5, 0.75, 0.75)
    assert "sigma_pixels" not in m and "truth_pixels" not in m
    # Where the 3 lost pixels of 8 went, pooled over the frames' truth pixels.
    assert (m["dropped_outside"], m["dropped_data_term"], m["dropped_rims"]) == (0.125, 0.25, 0)
    # A frame with nothing reconstructed: its 4 truth pixels lost, not an error.
    import colourhs.common.raycast

    def refused(h5):
        if h5.stem == "000001":
            raise ValueError(f"{h5}: no reconstructed pixels (depth is empty or all NaN)")
        return read_depth(h5)

    monkeypatch.setattr(colourhs.common.depthfile, "read_depth", refused)
    truth = np.array([[1.0, 1.0], [1.0, 1.0]])
    monkeypatch.setattr(colourhs.common.raycast, "render_depth_normals", lambda *a: (truth, None))
    empty = gen.evaluate_variant(tmp_path, "plane", frames, "bayes_ph", files, None, tmp_path)
    assert empty["coverage"] == pytest.approx(3 / 8)  # frame 0's 3 of its 4, then 0 of 4
    assert empty["dropped_outside"] == pytest.approx(1 / 8)
    assert empty["dropped_other"] == pytest.approx(4 / 8)
    monkeypatch.setattr(colourhs.common.depthfile, "read_depth", read_depth)
    vh = gen.evaluate_variant(tmp_path, "plane", frames, "vh", {}, None, tmp_path)
    assert vh["depth_median_mm"] == pytest.approx(2.0)
    assert vh["depth_sigma_median_mm"] is None and vh["sigma_within_2"] is None
    assert vh["dropped_outside"] is None


def test_progress_line_of_an_empty_reconstruction():
    """A scene x variant with nothing reconstructed has no depth figures: its
    progress line says so instead of stopping the run (corner seed 3's toy)."""
    empty = {"depth_median_mm": None, "depth_signed_median_mm": None, "coverage": 0.0}
    assert gen._line(empty | {"seconds": 3.2}) == (
        "depth - mm (signed -) rms - normal - deg coverage 0.000 (3 s)"
    )
    full = {"depth_median_mm": 0.1234, "depth_signed_median_mm": -0.05, "depth_rms_mm": 0.2}
    line = gen._line(full | {"normal_median_deg": 1.234, "coverage": 0.9, "seconds": 12.0})
    assert line == "depth 0.123 mm (signed -0.050) rms 0.200 normal 1.23 deg coverage 0.900 (12 s)"
