"""benchmarks/performance_page.py on hand-made benchmark outputs: the page and the
README's table say what the files hold, and nothing else of the README changes."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))

import performance_page as pp  # noqa: E402


def _entry(median, worst):
    return {"median": median, "worst": worst, "rigs": 8, "target": None}


@pytest.fixture
def results(tmp_path) -> Path:
    (tmp_path / "pipeline_demo.json").write_text(
        json.dumps(
            {
                "wall_s": 900.0,
                "rendered": True,
                "cpu_count": 2,
                "commit": "abc1234",
                "rules": [{"rule": "reconstruct_frame", "jobs": 80, "seconds": 600.0}],
            }
        )
    )
    plane = {
        "depth_median_mm": _entry(0.13, 0.25),
        "depth_signed_median_mm": _entry(-0.02, -0.25),
        "depth_rms_mm": _entry(0.26, 0.49),
    }
    calib = {
        f"sigma_within_{k}": {"mean": m} for k, m in zip((1, 2, 3), (0.6, 0.9, 0.95), strict=True)
    }
    summary = {
        "sets": {
            "random": {
                "seeds": [0, 1],
                "scenes": {"plane": {"bayes_ph": plane}},
                "sigma_calibration": {"bayes_ph": calib},
            }
        }
    }
    (tmp_path / "generalisation_summary.json").write_text(json.dumps(summary))
    return tmp_path


def test_page_and_readme_table_state_the_files_figures(results):
    runs = pp.pipeline_runs(results)
    sets = pp.generalisation_sets([results / "generalisation_summary.json", results / "none.json"])
    own = pp.own_variants()
    assert own["plane"] == "bayes_ph" and own["toy"] == "bayes_full"
    page = pp.page(runs, sets, own)
    assert "on 2 cores: 15.0 min (1 run) (`pipeline_demo.json`, commit abc1234)" in page
    assert "| reconstruct_frame | 80 | 600.0 |" in page
    assert "| plane | bayes_ph | 0.130 / 0.250 | -0.020 / -0.250 | 0.260 / 0.490 | - | - |" in page
    assert "| bayes_ph | 0.600 | 0.900 | 0.950 |" in page
    assert "sheet" not in page  # no figure the files do not hold
    table = pp.readme_table(runs, sets, own)
    assert "| main job from nothing, 2 cores | 15.0 min (1 run) |" in table
    assert pp._minutes([14.3, 19.4]) == "14.3-19.4 min (2 runs)"
    assert any(
        "plane depth error" in t and "0.13 / 0.25 mm, signed -0.02 / -0.25" in t for t in table
    )


def test_readme_table_replaces_only_the_text_between_its_markers():
    readme = f"# t\n\nbefore\n{pp.START}\nold\n{pp.END}\nafter\n"
    out = pp.with_readme_table(readme, ["| a |", "new"])
    assert out == f"# t\n\nbefore\n{pp.START}\n| a |\nnew\n{pp.END}\nafter\n"
    with pytest.raises(ValueError, match="markers"):
        pp.with_readme_table("# no markers\n", ["x"])
