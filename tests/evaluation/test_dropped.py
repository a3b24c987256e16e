"""Where the missing depth goes: the depth file's ``dropped`` codes
summarised against the ground truth (colourhs.evaluation.depth_errors.drop_summary), the metrics
columns ``dropped_<reason>`` (colourhs.evaluation.accuracy, colourhs.common.metrics_csv) and
the report's table (colourhs.report.tables.drop_table)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from report_html import as_dicts, page_tables

from colourhs.capture import Camera
from colourhs.common.depthfile import DepthMap, DepthResult, write_depth
from colourhs.common.metrics_csv import DROP_COLUMNS, DROP_REASONS, EXTRA_COLUMNS, REQUIRED_COLUMNS
from colourhs.common.ply import load_mesh, write_ply
from colourhs.common.raycast import render_depth_normals
from colourhs.evaluation.accuracy import FrameKey, evaluate_frame, metrics_table
from colourhs.evaluation.depth_errors import depth_errors, depth_summary, drop_summary
from colourhs.report.page import ReportInputs, build_report
from colourhs.report.tables import drop_table

H, W = 4, 5
#: Why each pixel has no depth (code k + 1: DROP_REASONS[k]); (1, 2) has a depth and
#: a code, which must not count; column 0 lies off the ground truth.
CODES = np.array(
    [
        [1, 0, 0, 5, 5],
        [1, 0, 4, 8, 0],
        [2, 2, 0, 0, 9],
        [1, 1, 3, 9, 0],
    ],
    np.uint8,
)
HAS_DEPTH = np.array(
    [
        [0, 1, 1, 0, 0],
        [0, 1, 1, 0, 0],
        [0, 0, 1, 1, 0],
        [1, 0, 0, 0, 0],
    ],
    bool,
)
#: Where the ground truth has a depth: columns 1 to 4 (16 pixels).
TRUTH = np.zeros((H, W), bool)
TRUTH[:, 1:] = True
#: Of the 16: 6 with a depth, then per reason the pixels without one.
EXPECTED = {
    "dropped_outside": 1 / 16,  # (3, 1)
    "dropped_dark": 1 / 16,  # (2, 1)
    "dropped_saturated": 1 / 16,  # (3, 2)
    "dropped_no_chromaticity": 0.0,  # only (1, 2), which has a depth
    "dropped_data_term": 2 / 16,  # (0, 3), (0, 4)
    "dropped_surface": 0.0,
    "dropped_refinement": 0.0,
    "dropped_uncertain": 1 / 16,  # (1, 3)
    "dropped_rims": 2 / 16,  # (2, 4), (3, 3)
    "dropped_other": 2 / 16,  # (1, 4), (3, 4): no depth, code 0
}
DEPTH_M = 0.5
#: Reference camera at the origin looking along +z: f = 4 px, so pixel columns 0 to 4
#: look along x/z = -0.5 to 0.5 (or -0.375 to 0.625 for half-pixel centres).
CAMERA = Camera(
    "cam1",
    np.array([[4.0, 0.0, 2.0], [0.0, 4.0, 1.5], [0.0, 0.0, 1.0]]),
    np.zeros(5),
    np.eye(3),
    np.zeros(3),
    "red",
    np.zeros(3),
)


def _depth_result(dropped: np.ndarray | None = CODES) -> DepthResult:
    depth = np.where(HAS_DEPTH, DEPTH_M, np.nan).astype(np.float32)
    normal = np.broadcast_to(np.float32([0.0, 0.0, -1.0]), (H, W, 3)).copy()
    normal[~HAS_DEPTH] = np.nan
    return DepthResult(depth, normal, HAS_DEPTH.astype(np.float32), HAS_DEPTH, {}, dropped=dropped)


def _depth_map(dropped: np.ndarray | None = CODES) -> DepthMap:
    r = _depth_result(dropped)
    return DepthMap(
        r.depth,
        r.normal,
        r.confidence,
        r.mask,
        CAMERA.name,
        CAMERA.K,
        CAMERA.dist,
        CAMERA.R,
        CAMERA.t,
        "bayes",
        dropped=dropped,
    )


def test_drop_columns_follow_the_reasons():
    assert DROP_COLUMNS == (*(f"dropped_{r}" for r in DROP_REASONS), "dropped_other")
    assert tuple(EXTRA_COLUMNS[-len(DROP_COLUMNS) :]) == DROP_COLUMNS
    assert tuple(EXPECTED) == DROP_COLUMNS


def test_drop_summary_of_a_hand_made_map():
    """The exact shares of the 16 ground-truth pixels; with the coverage (6 of 16, from
    depth_summary of the same pixels) they add to 1."""
    dm = _depth_map()
    shares = drop_summary(dm, TRUTH)
    assert shares == EXPECTED
    err = np.where(TRUTH, dm.depth - DEPTH_M, np.nan)
    coverage = depth_summary(err, np.zeros_like(err), int(TRUTH.sum()))["coverage"]
    assert coverage == 6 / 16
    assert coverage + sum(shares.values()) == 1.0  # sixteenths: exact
    # a map without codes, or a truth without pixels: every share unknown
    assert drop_summary(_depth_map(None), TRUTH) == dict.fromkeys(DROP_COLUMNS)
    assert drop_summary(dm, np.zeros((H, W), bool)) == dict.fromkeys(DROP_COLUMNS)
    with pytest.raises(ValueError, match=r"truth mask is \(4, 4\)"):
        drop_summary(dm, TRUTH[:, 1:])


def test_depth_errors_give_the_shares_beside_the_coverage():
    """depth_errors on the truth already rendered (nothing cast): the same shares, the
    coverage beside them, adding to 1."""
    gd = np.where(TRUTH, DEPTH_M, np.nan)
    gn = np.broadcast_to([0.0, 0.0, -1.0], (H, W, 3))
    _, _, m = depth_errors(_depth_map(), None, None, None, truth=(gd, gn))
    assert {c: m[c] for c in DROP_COLUMNS} == EXPECTED
    assert m["coverage"] == 6 / 16 and m["truth_pixels"] == 16
    assert m["coverage"] + sum(m[c] for c in DROP_COLUMNS) == 1.0


def test_evaluate_frame_writes_the_dropped_columns(tmp_path):
    """A plane at z = 0.5 m covering pixel columns 1 to 4 as the ground truth: the
    metrics row has the hand-made shares; a depth file without ``dropped`` and a scene
    without ground truth leave the columns empty, in metrics.csv too."""
    v = np.array([[-0.155, -0.5, 0.0], [0.5, -0.5, 0.0], [0.5, 0.5, 0.0], [-0.155, 0.5, 0.0]])
    gt_ply = write_ply(
        tmp_path / "gt.ply",
        v + [0.0, 0.0, DEPTH_M],  # x from -0.31 to 1.0 in units of z
        np.array([[0, 2, 1], [0, 3, 2]]),
        np.tile([0.0, 0.0, -1.0], (4, 1)),
    )
    gd, _ = render_depth_normals(*load_mesh(gt_ply), CAMERA, W, H)
    np.testing.assert_array_equal(np.isfinite(gd), TRUTH)
    np.testing.assert_allclose(gd[TRUTH], DEPTH_M, atol=1e-12)
    with_codes, plain = tmp_path / "d.h5", tmp_path / "plain.h5"
    write_depth(with_codes, _depth_result(), CAMERA, {"method": "bayes"})
    write_depth(plain, _depth_result(None), CAMERA, {"method": "bayes"})
    out = tmp_path / "m"

    def row(variant):
        return FrameKey("s", "000000", variant)

    info = evaluate_frame(with_codes, None, gt_ply, out / "a.json", key=row("bayes_full"))
    assert {c: info[c] for c in DROP_COLUMNS} == EXPECTED
    assert info["coverage"] == 6 / 16
    none = evaluate_frame(plain, None, gt_ply, out / "b.json", key=row("bayes_ph"))
    assert all(none[c] is None for c in DROP_COLUMNS) and none["coverage"] == 6 / 16
    blind = evaluate_frame(with_codes, None, None, out / "c.json", key=row("ml_full"))
    assert all(blind[c] is None for c in DROP_COLUMNS)
    csv = tmp_path / "metrics.csv"
    metrics_table(sorted(out.glob("*.json")), csv)
    read = pd.read_csv(csv, dtype={"frame": str}).set_index("variant")
    assert list(read.columns[-len(DROP_COLUMNS) - 2 :]) == [*DROP_COLUMNS, "method", "same_as"]
    assert read.loc["bayes_full", list(DROP_COLUMNS)].tolist() == list(EXPECTED.values())
    assert read.loc[["bayes_ph", "ml_full"], list(DROP_COLUMNS)].isna().all().all()


def _row(scene, frame, variant, coverage, **shares) -> dict:
    row = {"scene": scene, "frame": frame, "variant": variant, "coverage": coverage}
    if shares:
        row |= dict.fromkeys(DROP_COLUMNS, 0.0) | {f"dropped_{k}": v for k, v in shares.items()}
    return row


def test_report_shows_where_the_missing_depth_goes(tmp_path):
    """The plane's table: per variant with shares, the percentages (one decimal) of the
    mean over its two frames; ``vh`` (no ``dropped``) has no row; the sheet, without
    any share, no table."""
    rows = [
        _row("plane", "000000", "bayes_full", 0.5, outside=0.2, dark=0.1, data_term=0.12,
             uncertain=0.0123, other=0.0677),
        _row("plane", "000001", "bayes_full", 0.6, outside=0.1, dark=0.1, data_term=0.14,
             other=0.06),
        _row("plane", "000000", "vh", 0.9),
        _row("plane", "000001", "vh", 0.9),
        _row("sheet", "000000", "bayes_full", 0.8),
    ]  # fmt: skip
    csv = tmp_path / "metrics.csv"
    cols = [*REQUIRED_COLUMNS, *EXTRA_COLUMNS, "method", "same_as"]
    pd.DataFrame(rows, columns=cols).to_csv(csv, index=False)
    expected = {
        "variant": "bayes_full",
        "frames": "2",
        "reconstructed": "55.0",
        "outside": "15.0",
        "dark": "10.0",
        "saturated": "0.0",
        "no_chromaticity": "0.0",
        "data_term": "13.0",
        "surface": "0.0",
        "refinement": "0.0",
        "uncertain": "0.6",  # 0.615
        "rims": "0.0",
        "other": "6.4",  # 6.385
    }
    table = drop_table(pd.read_csv(csv, dtype={"frame": str}))
    assert table["variant"].tolist() == ["bayes_full"]  # the only rows with shares
    out = build_report(
        tmp_path / "index.html", "demo", ReportInputs(csv, [], {"plane": [], "sheet": []}, [], {})
    )
    text = out.read_text(encoding="utf-8")
    plane = text[text.index('id="scene-plane"') : text.index('id="scene-sheet"')]
    sheet = text[text.index('id="scene-sheet"') : text.index('id="timing"')]
    assert "Where the missing depth goes" in plane and "Where the missing depth goes" not in sheet
    metrics, dropped = page_tables(text)["scene-plane"]
    assert dropped[0] == list(expected)
    assert as_dicts(dropped) == {"bayes_full": expected}
    assert sum(float(x) for x in list(expected.values())[3:]) == pytest.approx(45.0, abs=0.1)
    assert len(page_tables(text)["scene-sheet"]) == 1  # its metrics only
    assert drop_table(pd.DataFrame(rows[2:])).empty
    assert drop_table(pd.DataFrame(rows[2:])).columns.tolist() == list(expected)
