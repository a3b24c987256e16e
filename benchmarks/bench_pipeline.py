"""Wall time of the README's main job on the demo preset, and where it goes.

``.venv/bin/python benchmarks/bench_pipeline.py [--fresh]`` runs
``snakemake --cores 2`` in the project folder (``--fresh`` first removes
``results/demo``, ``reports/demo`` and the demo's Snakemake benchmark files, so
everything after the synthetic rendering reruns; the rendered dataset is kept
if present; ``--render`` also removes it, so the run is the README's main job
on a fresh machine) and writes ``benchmarks/results/pipeline_demo.json``: the wall
time and, per rule, the jobs and seconds from the rules' benchmark files.
Target: the whole demo pipeline within 15 minutes on 2 cores.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

from colourhs.report.page import find_benchmarks, read_benchmarks, summarise_benchmarks

ROOT = Path(__file__).resolve().parents[1]
HERE = Path(__file__).parent


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--fresh", action="store_true")
    ap.add_argument("--render", action="store_true", help="with --fresh: render the dataset too")
    ap.add_argument("--cores", type=int, default=2)
    args = ap.parse_args()
    if args.fresh:
        removed = [ROOT / "results" / "demo", ROOT / "reports" / "demo"]
        removed += [ROOT / "data" / "synthetic" / "demo"] if args.render else []
        for p in removed:
            shutil.rmtree(p, ignore_errors=True)
        for f in find_benchmarks(ROOT / "benchmarks" / "snakemake", "demo"):
            if args.render or "synth" not in f.parts:
                f.unlink()
    t = time.perf_counter()
    subprocess.run(
        [sys.executable, "-m", "snakemake", "--cores", str(args.cores)], cwd=ROOT, check=True
    )
    wall = time.perf_counter() - t
    table = summarise_benchmarks(
        read_benchmarks(find_benchmarks(ROOT / "benchmarks" / "snakemake", "demo"))
    )
    commit = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True
    ).stdout.strip()
    result = {
        "command": f"snakemake --cores {args.cores}",
        "commit": commit or None,
        "fresh": args.fresh,
        "rendered": args.fresh and args.render,
        "wall_s": round(wall, 1),
        "cpu_count": os.cpu_count(),
        "rules": table.round(2).to_dict(orient="records"),
    }
    (HERE / "results").mkdir(exist_ok=True)
    (HERE / "results" / "pipeline_demo.json").write_text(json.dumps(result, indent=2))
    print(table.to_string(index=False))
    print(f"wall {wall:.0f} s")


if __name__ == "__main__":
    main()
