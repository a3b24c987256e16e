"""Speed and memory of rendering a synthetic dataset (never a timed test).

Run: ``.venv/bin/python benchmarks/bench_synth.py [--preset demo] [--workers 2]``.
Writes ``benchmarks/results/synth_<preset>.json``: wall time, CPU time, peak
resident memory of the whole process tree (sampled every 0.1 s), the number
of images and the dataset size. Target: demo preset at most 2
minutes and 4 GB on 2 cores.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import threading
import time
from pathlib import Path

from colourhs.synth.synthesise import synthesise

HERE = Path(__file__).parent


def _tree_rss_bytes(root_pid: int) -> int:
    """Resident memory of a process and all its descendants (Linux /proc)."""
    children: dict[int, list[int]] = {}
    rss: dict[int, int] = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            stat = Path(f"/proc/{entry}/stat").read_text()
            statm = Path(f"/proc/{entry}/statm").read_text().split()
        except OSError:
            continue
        ppid = int(stat.rsplit(")", 1)[1].split()[1])
        children.setdefault(ppid, []).append(int(entry))
        rss[int(entry)] = int(statm[1]) * os.sysconf("SC_PAGE_SIZE")
    total, stack = 0, [root_pid]
    while stack:
        pid = stack.pop()
        total += rss.get(pid, 0)
        stack.extend(children.get(pid, []))
    return total


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--preset", default="demo")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    peak = [0]
    done = threading.Event()

    def sample():
        while not done.is_set():
            peak[0] = max(peak[0], _tree_rss_bytes(os.getpid()))
            time.sleep(0.1)

    with tempfile.TemporaryDirectory() as tmp:
        thread = threading.Thread(target=sample, daemon=True)
        thread.start()
        t0, c0 = time.perf_counter(), os.times()
        out = synthesise(Path(tmp) / "ds", args.preset, workers=args.workers)
        wall = time.perf_counter() - t0
        c1 = os.times()
        done.set()
        thread.join()
        files = [p for p in out.rglob("*") if p.is_file()]
        result = {
            "preset": args.preset,
            "workers": args.workers,
            "cpu_count": os.cpu_count(),
            "machine": platform.machine(),
            "wall_s": round(wall, 2),
            "cpu_s": round(
                (c1.user - c0.user)
                + (c1.system - c0.system)
                + (c1.children_user - c0.children_user)
                + (c1.children_system - c0.children_system),
                2,
            ),
            "peak_rss_tree_mb": round(peak[0] / 2**20, 1),
            "images": sum(p.suffix == ".png" for p in files),
            "dataset_mb": round(sum(p.stat().st_size for p in files) / 2**20, 1),
        }
    (HERE / "results").mkdir(exist_ok=True)
    path = HERE / "results" / f"synth_{args.preset}.json"
    path.write_text(json.dumps(result, indent=2))
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
