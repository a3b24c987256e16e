"""benchmarks/bench_paper.py at the tiny preset: every rule measured, the
projection is the per-job figures x their counts."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
# About 65-80 s of 20 workflow jobs as processes: opt-in (pytest -m bench), so the
# suite stays within its time on 2 cores.
pytestmark = pytest.mark.bench
#: Every rule of the workflow but `all` (the synthetic checkpoint is no `rule`).
RULES = {
    m
    for f in (ROOT / "workflow" / "rules").glob("*.smk")
    for m in re.findall(r"^rule (\w+):", f.read_text(), re.M)
}


@pytest.fixture(scope="module")
def bench(tiny_dataset, tmp_path_factory) -> dict:
    """The benchmark on sheet frames 1-2 of the tiny dataset (a slice that does not
    start at 000000), the jobs of frame 1 only (--frames-only 1: each frame's jobs
    cost about 20 s), three variants, the reconstruction rerun on 2 threads."""
    tmp = tmp_path_factory.mktemp("bench_paper")
    argv = ["--preset", "tiny", "--data", str(tiny_dataset), "--first", "1", "--frames", "2"]
    argv += ["--frames-only", "1", "--check-frames", "1", "--variants", "vh,bayes_ph,bayes_full"]
    argv += ["--parallel", "2"]  # two jobs at once, each when its inputs exist
    argv += ["--work", str(tmp / "work"), "--results", str(tmp / "results")]
    script = ROOT / "benchmarks" / "bench_paper.py"
    subprocess.run([sys.executable, str(script), *argv], check=True, cwd=ROOT)
    assert (tmp / "results" / "tiny_slice.md").read_text().count("| reconstruct_frame") == 3
    return json.loads((tmp / "results" / "tiny_slice.json").read_text())


def test_every_rule_is_measured_with_sane_numbers(bench):
    assert bench["frames"] == ["000001"] and bench["frames_rendered"] == 2
    assert bench["render"] is None
    assert len(RULES) == 14 and "crosstalk" in RULES
    assert {r["rule"].split()[0] for r in bench["rules"]} == RULES
    per_variant = {r["rule"] for r in bench["rules"] if " " in r["rule"]}
    assert per_variant == {
        f"{rule} {v}"
        for rule in ("reconstruct_frame", "frame_mesh", "evaluate_frame")
        for v in ("vh", "bayes_ph", "bayes_full")
        if (rule, v) != ("reconstruct_frame", "vh")  # the hull is vh's reconstruction
    }
    # 8 opening jobs (2 chromatic objects), 9 of the frame (hull, 2 reconstructions
    # of which one a copy, 3 meshes, 3 evaluations), 3 closing jobs.
    assert len(bench["jobs"]) == 20
    # Two at once (--parallel 2), each after the jobs that write its inputs.
    jobs = bench["jobs"]
    assert bench["parallel"] == 2 and 0 < bench["jobs_wall_s"] < sum(j["wall_s"] for j in jobs)
    assert all(jobs[k]["end_s"] <= j["start_s"] for j in jobs for k in j["after"])
    assert sum(len(j["after"]) > 0 for j in jobs) >= 12  # the frame's chain and the closing
    for job in bench["jobs"] + bench["reconstruct_2_threads"]:
        assert job["returncode"] == 0
        # Measured: 0.25 GB (a copy) to 0.67 GB (crosstalk); 0.2-37 s on a loaded machine.
        assert 0.1 < job["peak_rss_gb"] < 1.5, job
        assert 0.05 < job["wall_s"] < 120 and 0.05 < job["cpu_s"] < 120, job
    # The workflow's command lines: one thread, or two under --set-threads.
    recon = [j for j in bench["jobs"] if j["rule"] == "reconstruct_frame"]
    assert all(j["command"].startswith("NUMBA_NUM_THREADS=1 ") for j in recon)
    check = bench["reconstruct_2_threads"]
    assert [(j["variant"], j["frame"]) for j in check] == [("bayes_ph", "000001")]
    assert check[0]["command"] == recon[0]["command"].replace("THREADS=1", "THREADS=2", 1)
    assert "--same-as" in recon[1]["command"]  # bayes_full: the workflow copies bayes_ph
    t = bench["targets"]
    assert t["reconstruct_2_threads_max_s"] == check[0]["wall_s"]
    assert t["reconstruct_met"] == (check[0]["wall_s"] <= 10 and check[0]["peak_rss_gb"] <= 3)
    assert t["max_job_gb"] == max(j["peak_rss_gb"] for j in bench["jobs"] + check)


def test_projection_is_per_job_figures_times_counts(bench):
    rows = {r["rule"]: r for r in bench["rules"]}
    for r in rows.values():
        n = 201 * r["jobs"] if r["phase"] == "frame" else r["jobs"]  # 1 frame run
        # x the median rounded to 0.01 s (the JSON's)
        assert r["sequence_s"] == pytest.approx(r["wall_median_s"] * n, abs=0.005 * n + 0.06)
        n *= 201 if r["reads_every_frame"] else 1  # scaled to 201 frames
        assert r["sequence_scaled_s"] == pytest.approx(r["wall_median_s"] * n, abs=0.005 * n + 0.06)
    assert rows["reconstruct_frame bayes_ph"]["sequence_jobs"] == 201
    assert rows["chromaticity_map"]["sequence_jobs"] == 2
    assert rows["report"]["reads_every_frame"] and not rows["crosstalk"]["reads_every_frame"]
    for key in ("sequence_s", "sequence_scaled_s"):
        p = bench["projection" if key == "sequence_s" else "projection_scaled"]
        total = sum(r[key] for r in rows.values())
        assert p["one_core_s"] == pytest.approx(total, abs=0.5)
        frame = sum(r[key] for r in rows.values() if r["phase"] == "frame")
        assert p["per_frame_s"] == pytest.approx(frame / 201, abs=0.01)
        closing = sum(rows[k][key] for k in ("metrics_table", "scene_figures", "report"))
        # Two cores: the frames' jobs (thousands) and the opening ones split over both.
        assert p["cores_2_s"] == pytest.approx((total - closing) / 2 + closing, rel=0.02)
        nodes = p["nodes_s"]
        assert p["cores_2_s"] == nodes["1"] and nodes["1"] > nodes["8"] > nodes["32"] >= closing
    assert bench["projection_scaled"]["cores_2_s"] > bench["projection"]["cores_2_s"]
