"""Per-job seconds and peak memory of the paper preset on a slice of its 201-frame sequence.

Renders the paper preset's calibration captures, the statue (whose
chromatic captures give the chromaticity stage something to do) and ``--frames``
consecutive frames of the sheet (default 20, from ``--first``, default the middle
of the sequence), or takes them from ``--data DIR``; then runs every job of
``colourhs run DATASET --scenes sheet`` one at a time, each as its own
``colourhs <subcommand>`` process with the command line the workflow gives it
(taken from Snakemake's dry run, ``--printshellcmds``), and records its wall
seconds, CPU seconds and peak resident memory (``os.wait4``: the largest resident
set of its process tree) and the longest time its log stayed silent. The
reconstructions of the first ``--check-frames`` frames (not the copies) are run
again with 2 threads (the workflow's command under ``--set-threads
reconstruct_frame=2``) for the target.

Writes ``RESULTS/<preset>_slice.json`` and ``.md`` (default RESULTS =
benchmarks/results): per rule (and variant) the jobs, median / max wall and CPU
seconds, max peak RSS; the whole sequence's projected time on 2 cores and on
1, 8 and 32 nodes of 2 cores; the targets (a reconstruction job at 1280x960 with
192 labels <= 10 s on 2 threads and <= 3 GB; no job over 4 GB); the stages of more
than 5 s whose log stayed silent for more than 5 s (no progress shown).

Run (full scale: frames 90-109, hours on 2 cores; it writes some GB under
data/bench/paper_slice)::

    PYTHONPATH=$PWD .venv/bin/python benchmarks/bench_paper.py

``--frames-only 5`` runs the jobs of 5 of the 20 rendered frames;
``--data DIR`` reuses a rendered dataset (a sheet with those frames); ``--preset
tiny --frames 2`` runs the same at 160 x 120 (tests/benchmarks/test_bench_paper.py
runs one frame's jobs).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shlex
import shutil
import statistics
import subprocess
import sys
import time
from collections import Counter
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SEQUENCE = 201  # frames of the paper's dynamic sequences (the paper preset's sheet)
NODES = (1, 8, 32)  # cluster sizes projected, each node 2 cores
CORES = 2
#: Rules by phase: once before the frames, once per frame (and variant), once after.
ONCE = (
    "validate_dataset",
    "marker_poses",
    "noise_model",
    "crosstalk",
    "photometric_maps",
    "chromaticity_map",
    "effective_config",
)
PER_FRAME = ("visual_hull", "reconstruct_frame", "frame_mesh", "evaluate_frame")
AFTER = ("metrics_table", "scene_figures", "report")
#: Once-only jobs whose work grows with the number of frames: projected to the
#: sequence as measured x SEQUENCE / frames run (an upper bound: part of it is fixed).
SCALED = ("validate_dataset", "metrics_table", "scene_figures", "report")
#: The critical paths: the calibration, one frame's chain.
CALIB_CHAIN = ("marker_poses", "crosstalk", "photometric_maps")
FRAME_CHAIN = PER_FRAME
TARGET_RECONSTRUCT_S, TARGET_RECONSTRUCT_GB, TARGET_JOB_GB = 10.0, 3.0, 4.0
SILENT_S = 5.0  # a stage longer than this, silent this long, shows no progress


# --------------------------------------------------------------------------- plan


def dry_run_jobs(text: str) -> list[dict]:
    """The jobs of a Snakemake dry run with ``--printshellcmds``: rule, variant,
    frame, inputs, outputs, log and shell command of every job with a command."""
    jobs = []
    for block in re.split(r"\n\s*\n", text):
        rule = re.search(r"^(?:local)?(?:rule|checkpoint) (\w+):$", block, re.M)
        cmd = re.search(r"^Shell command: (.+)$", block, re.M)
        if not rule or not cmd or cmd.group(1) == "None":
            continue
        field = dict(re.findall(r"^    (\w+): (.*)$", block, re.M))
        wildcards = dict(kv.split("=", 1) for kv in field.get("wildcards", "").split(", ") if kv)
        name = rule.group(1)
        jobs.append(
            {
                "rule": name,
                "variant": wildcards.get("variant", "vh" if name == "visual_hull" else ""),
                "frame": wildcards.get("frame", ""),
                "inputs": [p for p in field.get("input", "").split(", ") if p],
                "outputs": [p for p in field.get("output", "").split(", ") if p],
                "log": field.get("log", ""),
                "command": cmd.group(1).strip(),
            }
        )
    return jobs


def job_order(job: dict) -> tuple:
    """Execution order: once-before rules, then frame by frame the hull, the
    reconstructions, meshes and evaluations (a copy after what it copies), then the
    closing rules."""
    rules = (*ONCE, *PER_FRAME, *AFTER)
    phase = 0 if job["rule"] in ONCE else 1 if job["rule"] in PER_FRAME else 2
    copy = "--same-as" in job["command"]
    return (phase, job["frame"], rules.index(job["rule"]), copy, job["variant"], job["log"])


def planned_jobs(view: Path, work: Path, name: str, variants: str | None) -> list[dict]:
    """The jobs of ``colourhs run VIEW --scenes sheet [--variants V]`` in execution
    order (Snakemake's dry run)."""
    cmd = [sys.executable, "-m", "colourhs", "run", str(view), "--name", name]
    cmd += ["--directory", str(work), "--scenes", "sheet", "--cores", str(CORES)]
    cmd += ["--variants", variants] if variants else []
    cmd += ["--", "--dry-run", "--printshellcmds", "--forceall"]
    out = subprocess.run(cmd, capture_output=True, text=True, check=True, cwd=work)
    return sorted(dry_run_jobs(out.stdout + out.stderr), key=job_order)


def on_threads(job: dict, threads: int) -> dict | None:
    """A reconstruction job (not a copy of another variant's result) as the workflow
    runs it under ``--set-threads reconstruct_frame=THREADS`` (its rule's command
    starts ``NUMBA_NUM_THREADS={threads}``); None for a copy."""
    if "--same-as" in job["command"]:
        return None
    prefix = "NUMBA_NUM_THREADS=1 "
    if not job["command"].startswith(prefix):
        raise SystemExit(f"reconstruct_frame's command no longer starts {prefix!r}")
    return job | {"command": f"NUMBA_NUM_THREADS={threads} " + job["command"][len(prefix) :]}


def _link(target: Path, link: Path) -> None:
    link.parent.mkdir(parents=True, exist_ok=True)
    link.symlink_to(target.resolve())


def make_view(data: Path, frames: list[str], out: Path) -> Path:
    """A dataset folder of links to ``data`` whose sheet has only ``frames``."""
    sheet = data / "scenes" / "sheet"
    missing = [f for f in frames if not (sheet / "frames" / f).is_dir()]
    if missing:
        raise SystemExit(f"{data}: the sheet has no frame {missing[0]} (of {frames})")
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    for p in data.iterdir():
        if p.name != "scenes":
            _link(p, out / p.name)
    for p in (data / "scenes").iterdir():
        if p.name != "sheet":
            _link(p, out / "scenes" / p.name)
    for p in sheet.iterdir():
        if p.is_file():
            _link(p, out / "scenes" / "sheet" / p.name)
    for kind, ext in (("frames", ""), ("masks", ""), ("gt", ".ply")):
        for f in frames if (sheet / kind).is_dir() else ():
            _link(sheet / kind / f"{f}{ext}", out / "scenes" / "sheet" / kind / f"{f}{ext}")
    return out


# --------------------------------------------------------------------------- measure


def measure(argv: list[str], cwd: Path, log: Path | None = None) -> dict:
    """Run a process: its wall and CPU seconds, peak RSS in GB (the largest process
    of its tree, ``os.wait4``), exit status, and the longest time (s) ``log`` did
    not grow."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(argv, cwd=cwd)
    last_size, last_change, silent = -1, t0, 0.0
    while True:
        pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
        now = time.perf_counter()
        size = log.stat().st_size if log is not None and log.exists() else 0
        if size != last_size:
            silent = max(silent, now - last_change)
            last_size, last_change = size, now
        if pid:
            break
        time.sleep(0.1)
    proc.returncode = os.waitstatus_to_exitcode(status)
    return {
        "wall_s": round(now - t0, 3),
        "cpu_s": round(usage.ru_utime + usage.ru_stime, 3),
        "peak_rss_gb": round(usage.ru_maxrss * 1024 / 1e9, 4),
        "silent_s": round(max(silent, now - last_change), 2),
        "returncode": proc.returncode,
    }


def run_job(job: dict, work: Path) -> dict:
    """One workflow job as Snakemake runs it (bash in strict mode, the rules' prefix)."""
    for path in job["outputs"] + [job["log"]]:
        (work / path).parent.mkdir(parents=True, exist_ok=True)
    prefix = f"set -euo pipefail; export COLOURHS_PYTHON={shlex.quote(sys.executable)}; "
    log = work / job["log"] if job["log"] else None
    if log is not None and log.exists():
        log.unlink()
    result = measure(["bash", "-c", prefix + job["command"]], work, log)
    if result["returncode"] != 0:
        tail = log.read_text()[-2000:] if log is not None and log.exists() else ""
        raise SystemExit(f"{job['rule']} failed ({result['returncode']}): {job['command']}\n{tail}")
    return {k: v for k, v in job.items() if k not in ("inputs", "outputs")} | result


def run_jobs(
    jobs: list[dict], work: Path, parallel: int = 1, partial: Path | None = None
) -> list[dict]:
    """Every job of ``jobs`` (in plan order) measured by :func:`run_job`, up to
    ``parallel`` at once as ``snakemake --cores N`` runs the workflow's 1-thread
    jobs: a job starts once every job that writes one of its inputs has finished.
    Each job's peak memory is its own process tree's; its wall time includes what
    the jobs beside it take from the machine. Returns the measurements in plan order,
    with each job's ``start_s`` and ``end_s`` (seconds since the first started) and
    ``after`` (the plan indices of the jobs it waited for). With ``partial``, the jobs
    measured so far are written there (JSON) as each finishes, so a run stopped early
    still leaves its figures (``--from-partial`` summarises them)."""
    writer = {path: i for i, job in enumerate(jobs) for path in job["outputs"]}
    needs = [
        {writer[p] for p in job["inputs"] if writer.get(p, i) != i} for i, job in enumerate(jobs)
    ]
    done: dict[int, dict] = {}
    running: dict = {}
    waiting = list(range(len(jobs)))
    t0 = time.perf_counter()

    def timed(job: dict) -> dict:
        start = time.perf_counter() - t0
        out = run_job(job, work)
        return out | {"start_s": round(start, 3), "end_s": round(time.perf_counter() - t0, 3)}

    with ThreadPoolExecutor(max_workers=max(1, parallel)) as pool:
        while waiting or running:
            for i in [i for i in waiting if needs[i] <= done.keys()][: parallel - len(running)]:
                waiting.remove(i)
                job = jobs[i]
                print(f"[{i + 1}/{len(jobs)}] {rule_key(job)} {job['frame']}", flush=True)
                running[pool.submit(timed, job)] = i
            if not running:
                raise SystemExit(f"jobs {waiting} wait for inputs no job writes")
            finished, _ = wait(running, return_when=FIRST_COMPLETED)
            for future in finished:
                i = running.pop(future)
                done[i] = future.result() | {"after": sorted(needs[i])}
            if partial is not None:
                partial.write_text(json.dumps([done[i] for i in sorted(done)], indent=1))
    return [done[i] for i in range(len(jobs))]


# --------------------------------------------------------------------------- summarise


def rule_key(job: dict) -> str:
    """A table row: the rule, with the variant for the per-variant rules."""
    per_variant = job["rule"] in ("reconstruct_frame", "frame_mesh", "evaluate_frame")
    return f"{job['rule']} {job['variant']}" if per_variant else job["rule"]


def summarise(jobs: list[dict], n_frames: int) -> list[dict]:
    """Per rule (and variant): jobs, median / max wall and CPU seconds, max peak RSS,
    longest silence, and its jobs and seconds in the whole sequence: its median job's
    seconds (robust to the one job that compiles numba's functions) x its jobs in
    SEQUENCE frames; ``sequence_scaled_s``: a SCALED rule's x SEQUENCE / ``n_frames``
    (the jobs that read every frame, as if all their work grew with the frames)."""
    rows: dict[str, list[dict]] = {}
    for job in jobs:
        rows.setdefault(rule_key(job), []).append(job)
    out = []
    for key, group in rows.items():
        wall = [j["wall_s"] for j in group]
        cpu = [j["cpu_s"] for j in group]
        rule = group[0]["rule"]
        count = len(group) / n_frames * SEQUENCE if rule in PER_FRAME else len(group)
        scale = SEQUENCE / n_frames if rule in SCALED else 1.0
        silent = max(j["silent_s"] for j in group)
        out.append(
            {
                "rule": key,
                "phase": "frame" if rule in PER_FRAME else "once",
                "reads_every_frame": rule in SCALED,
                "jobs": len(group),
                "wall_median_s": round(statistics.median(wall), 2),
                "wall_max_s": round(max(wall), 2),
                "cpu_median_s": round(statistics.median(cpu), 2),
                "cpu_max_s": round(max(cpu), 2),
                "peak_rss_max_gb": round(max(j["peak_rss_gb"] for j in group), 3),
                "silent_max_s": silent,
                "no_progress": max(wall) > SILENT_S and silent > SILENT_S,
                "sequence_jobs": round(count, 2),
                "sequence_s": round(count * statistics.median(wall), 1),
                "sequence_scaled_s": round(count * statistics.median(wall) * scale, 1),
            }
        )
    return out


def _chain(rows: list[dict], rules: tuple[str, ...]) -> float:
    """Seconds of a chain of rules, one job each (the slowest variant's median)."""
    return sum(
        max((r["wall_median_s"] for r in rows if r["rule"].split()[0] == rule), default=0.0)
        for rule in rules
    )


def project(rows: list[dict], reconstruct_2t: dict[str, float], key: str = "sequence_s") -> dict:
    """The whole sequence's time from the per-job figures (seconds): each rule's
    ``key`` (``sequence_s``: the once-only jobs as measured; ``sequence_scaled_s``:
    those that read every frame scaled to the sequence, an upper bound).

    Model: the workflow's, every job on one thread, as many jobs at once as cores
    (the rules declare ``threads: 1``; 201 frames x 14 jobs keep every core busy).
    The opening jobs (calibration, validation) and the frames' jobs each take their
    seconds over the cores, or their critical path if longer (markers, cross-talk,
    photometric; one frame's hull, reconstruction, mesh, evaluation); the closing
    jobs (metrics, figures, report) run one after another. Cluster queueing and
    file-system latency are not counted; jobs measured one at a time are taken to
    run as fast two at a time on a node. ``one_at_a_time_2_threads_s``: the other
    model, jobs one at a time with the reconstructions on 2 threads (their measured
    2-thread median per variant).
    """
    frame = sum(r[key] for r in rows if r["phase"] == "frame")
    closing = sum(r[key] for r in rows if r["rule"] in AFTER)
    opening = sum(r[key] for r in rows) - frame - closing
    chain_open, chain_frame = _chain(rows, CALIB_CHAIN), _chain(rows, FRAME_CHAIN)

    def on(cores: int) -> float:
        return max(opening / cores, chain_open) + max(frame / cores, chain_frame) + closing

    serial_2t = opening + frame + closing
    for r in rows:
        rule, _, variant = r["rule"].partition(" ")
        if rule == "reconstruct_frame" and variant in reconstruct_2t:
            serial_2t += r["sequence_jobs"] * (reconstruct_2t[variant] - r["wall_median_s"])
    return {
        "frames": SEQUENCE,
        "model": "jobs on 1 thread each, one per core (the workflow's threads: 1)",
        "one_core_s": round(opening + frame + closing, 1),
        "per_frame_s": round(frame / SEQUENCE, 2),
        "opening_s": round(opening, 1),
        "closing_s": round(closing, 1),
        "cores_2_s": round(on(CORES), 1),
        "one_at_a_time_2_threads_s": round(serial_2t, 1),
        "nodes_s": {str(n): round(on(n * CORES), 1) for n in NODES},
    }


def targets(jobs: list[dict], real: list[dict]) -> dict:
    """The issue's targets: each reconstruction on 2 threads (``real``) <= 10 s and
    <= 3 GB; no job over 4 GB."""
    worst = max(jobs + real, key=lambda j: j["peak_rss_gb"])
    return {
        "reconstruct_2_threads_max_s": max((j["wall_s"] for j in real), default=None),
        "reconstruct_2_threads_max_gb": max((j["peak_rss_gb"] for j in real), default=None),
        "reconstruct_met": bool(real)
        and all(
            j["wall_s"] <= TARGET_RECONSTRUCT_S and j["peak_rss_gb"] <= TARGET_RECONSTRUCT_GB
            for j in real
        ),
        "max_job_gb": worst["peak_rss_gb"],
        "max_job": f"{rule_key(worst)} {worst['frame']}".strip(),
        "no_job_over_4gb": worst["peak_rss_gb"] <= TARGET_JOB_GB,
    }


def markdown(result: dict) -> str:
    """The results as a markdown table and lists."""
    p, t, frames = result["projection"], result["targets"], result["frames"]
    lines = [
        f"# {result['preset']} preset, sheet frames {frames[0]}-{frames[-1]} ({len(frames)} "
        f"run of {result['frames_rendered']} rendered), {result['width']}x{result['height']}, "
        f"{result.get('parallel', 1)} job(s) at once",
        "",
        "| rule | jobs | wall median s | wall max s | CPU median s | CPU max s | peak RSS GB "
        "| silent max s | jobs in 201 frames | s in 201 frames |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in result["rules"]:
        flag = " (no progress)" if r["no_progress"] else ""
        lines.append(
            f"| {r['rule']} | {r['jobs']} | {r['wall_median_s']} | {r['wall_max_s']} | "
            f"{r['cpu_median_s']} | {r['cpu_max_s']} | {r['peak_rss_max_gb']} | "
            f"{r['silent_max_s']}{flag} | {r['sequence_jobs']:g} | {r['sequence_s']} |"
        )
    for j in result["reconstruct_2_threads"]:
        lines.append(
            f"| reconstruct_frame {j['variant']} {j['frame']}, 2 threads | 1 | {j['wall_s']} | "
            f"{j['wall_s']} | {j['cpu_s']} | {j['cpu_s']} | {j['peak_rss_gb']} | "
            f"{j['silent_s']} | - | - |"
        )
    h, q = 3600, result["projection_scaled"]

    def hours(key: str) -> str:
        return f"{p[key] / h:.2f} h ({q[key] / h:.2f} h)"

    lines += [
        "",
        f"Projected {p['frames']} frames ({p['model']}): each per-frame job x its median "
        f"x its jobs in {p['frames']} frames, the once-only jobs as measured; in brackets "
        f"the once-only jobs that read every frame ({', '.join(SCALED)}) x {p['frames']} / "
        f"{len(frames)}, an upper bound (their memory at {p['frames']} frames is not "
        "measured). "
        + (
            "Jobs run one at a time here, so two at once may be slower."
            if result.get("parallel", 1) == 1
            else f"Jobs ran {result['parallel']} at once here."
        ),
        f"- measured: every job of the {len(frames)} frames, calibration to "
        + (
            "the last frame (a run stopped early: no closing jobs), "
            if result.get("partial")
            else "report, "
        )
        + f"{result.get('jobs_wall_s', '-')} s wall",
        f"- one core: {hours('one_core_s')}, {p['per_frame_s']} s per frame",
        f"- 2 cores: {hours('cores_2_s')}; one job at a time with the reconstructions on 2 "
        f"threads: {hours('one_at_a_time_2_threads_s')}",
        *(
            f"- {n} node(s) of 2 cores: {s / h:.2f} h ({q['nodes_s'][n] / h:.2f} h)"
            for n, s in p["nodes_s"].items()
        ),
        "",
        f"Targets: reconstruction on 2 threads <= {TARGET_RECONSTRUCT_S:g} s and "
        f"<= {TARGET_RECONSTRUCT_GB:g} GB: {'met' if t['reconstruct_met'] else 'NOT met'} "
        f"(max {t['reconstruct_2_threads_max_s']} s, {t['reconstruct_2_threads_max_gb']} GB); "
        f"no job over {TARGET_JOB_GB:g} GB: {'met' if t['no_job_over_4gb'] else 'NOT met'} "
        f"(max {t['max_job_gb']} GB, {t['max_job']}).",
        "",
        f"Stages over {SILENT_S:g} s with no output for over {SILENT_S:g} s (no progress): "
        + (", ".join(r["rule"] for r in result["rules"] if r["no_progress"]) or "none"),
    ]
    if result["render"]:
        r = result["render"]
        lines += ["", f"Render: {r['wall_s']} s wall, {r['cpu_s']} s CPU, {r['peak_rss_gb']} GB."]
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- main


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--preset", default="paper", help="synthetic preset (default paper)")
    ap.add_argument("--seed", type=int, default=0, help="render seed (default 0)")
    ap.add_argument("--frames", type=int, default=20, help="consecutive sheet frames (20)")
    ap.add_argument("--first", type=int, default=None, help="first frame (default: middle)")
    ap.add_argument("--frames-only", type=int, default=None, help="run the jobs of K frames")
    ap.add_argument("--check-frames", type=int, default=2, help="frames rerun on 2 threads")
    ap.add_argument("--variants", default=None, help="colourhs run --variants (default all)")
    ap.add_argument("--data", type=Path, default=None, help="a rendered dataset to reuse")
    ap.add_argument("--work", type=Path, default=None, help="work folder (data/bench/...)")
    ap.add_argument("--results", type=Path, default=ROOT / "benchmarks" / "results")
    ap.add_argument("--workers", type=int, default=CORES, help="render processes (2)")
    ap.add_argument(
        "--from-partial",
        type=Path,
        default=None,
        help="summarise the jobs a stopped run measured (its RESULTS/<preset>_slice.partial.json)",
    )
    ap.add_argument(
        "--parallel", type=int, default=1, help="jobs at once, as snakemake --cores N (1)"
    )
    return ap.parse_args(argv)


def main(argv: list[str] | None = None) -> dict:
    args = parse_args(argv)
    from colourhs.synth.synthesise import PRESETS

    preset = PRESETS[args.preset]
    first = (preset.sheet_frames - args.frames) // 2 if args.first is None else args.first
    last = first + args.frames - 1
    work = (args.work or ROOT / "data" / "bench" / f"{args.preset}_slice").resolve()
    work.mkdir(parents=True, exist_ok=True)
    data, render = args.data, None
    if data is None:
        data = work / f"dataset_{first:06d}_{last:06d}"
        if not data.exists():
            print(f"rendering {args.preset} sheet frames {first}-{last} into {data}", flush=True)
            render = measure(
                [sys.executable, "-m", "colourhs", "synth", str(data), "--preset", args.preset]
                + ["--seed", str(args.seed), "--frames", f"{first}-{last}"]
                + ["--scenes", "statue,sheet", "--workers", str(args.workers)],
                ROOT,
            )
            if render["returncode"] != 0:
                raise SystemExit("rendering failed")
    frames = [f"{i:06d}" for i in range(first, last + 1)][: args.frames_only]
    for folder in ("results", "logs", "reports", ".snakemake"):
        shutil.rmtree(work / folder, ignore_errors=True)
    view = make_view(data.resolve(), frames, work / "view")
    t = time.perf_counter()
    jobs = planned_jobs(view, work, "slice", args.variants)
    plan_s = time.perf_counter() - t
    check = [on_threads(j, 2) for j in jobs if j["rule"] == "reconstruct_frame"]
    check = [j for j in check if j is not None and j["frame"] in frames[: args.check_frames]]
    args.results.mkdir(parents=True, exist_ok=True)
    out = args.results / f"{args.preset}_slice"
    if args.from_partial is not None:
        # A run stopped early: the frames all of whose jobs finished, and the rest.
        measured = json.loads(args.from_partial.read_text())
        have = Counter(j["frame"] for j in measured)
        want = Counter(j["frame"] for j in jobs)
        frames = [f for f in frames if have[f] == want[f]]
        # The once-only jobs have no frame.
        measured = [j for j in measured if j["frame"] in frames or not j["frame"]]
        jobs_wall_s = max(j["end_s"] for j in measured) - min(j["start_s"] for j in measured)
        check = []
    else:
        t = time.perf_counter()
        measured = run_jobs(jobs, work, args.parallel, out.with_suffix(".partial.json"))
        jobs_wall_s = time.perf_counter() - t
    measured_check = []
    for job in check:
        print(f"{rule_key(job)} {job['frame']} on 2 threads", flush=True)
        measured_check.append(run_job(job, work))
    rows = summarise(measured, len(frames))
    by_variant: dict[str, list[float]] = {}
    for j in measured_check:
        by_variant.setdefault(j["variant"], []).append(j["wall_s"])
    two_threads = {v: statistics.median(w) for v, w in by_variant.items()}
    result = {
        "preset": args.preset,
        "seed": args.seed,
        "width": preset.width,
        "height": preset.height,
        "frames": frames,
        "frames_rendered": args.frames,
        "parallel": args.parallel,
        "jobs_wall_s": round(jobs_wall_s, 1),
        "partial": args.from_partial is not None,
        "cpu_count": os.cpu_count(),
        "plan_s": round(plan_s, 1),
        "render": render,
        "rules": rows,
        "reconstruct_2_threads": measured_check,
        "projection": project(rows, two_threads),
        "projection_scaled": project(rows, two_threads, "sequence_scaled_s"),
        "targets": targets(measured, measured_check),
        "jobs": measured,
    }
    out.with_suffix(".json").write_text(json.dumps(result, indent=1))
    out.with_suffix(".md").write_text(markdown(result))
    print(markdown(result))
    return result


if __name__ == "__main__":
    main()
